// Bindings of the forward-mode derivatives of the model terms (Program::evaluate_tangent,
// dual.hpp): the terms at one state and their exact directional derivatives along d
// directions (dq, dqd), for nonmin.linear (derivatives of the projection dynamics).
#include <nanobind/nanobind.h>

#include <cmath>
#include <cstring>
#include <string>

#include "nonmin/derivatives.hpp"
#include "nonmin/program.hpp"
#include "program_common.hpp"
#include "register.hpp"

#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

namespace nonmin::bindings {

namespace {
// An exact numpy.ndarray of float64 (native byte order, aligned, C-contiguous) with nd dimensions.
PyArrayObject* f64_array(PyObject* o, int nd) {
    if (!PyArray_CheckExact(o)) return nullptr;
    auto* a = reinterpret_cast<PyArrayObject*>(o);
    if (PyArray_NDIM(a) != nd || PyArray_TYPE(a) != NPY_DOUBLE || !PyArray_ISCARRAY_RO(a) || !PyArray_ISNOTSWAPPED(a))
        return nullptr;
    return a;
}
}  // namespace

void bind_derivatives(nb::module_& m) {
    if (_import_array() < 0) throw nb::python_error();  // NumPy's C API table (this file's copy)
    m.def(
        "term_tangents",
        [](const Program& p, double t, CArr1 q, CArr1 qd, CArr2 dq, CArr2 dqd, CMask active, unsigned need) {
            const auto n = static_cast<std::size_t>(p.n());
            const auto mm = static_cast<std::size_t>(p.m_all());
            const auto k = static_cast<std::size_t>(p.k());
            if (q.shape(0) != n || qd.shape(0) != n)
                raise_error("ShapeError", "q and qd must have shape (" + std::to_string(n) + ",)");
            if (active.shape(0) != p.constraints().size())
                raise_error("ShapeError", "active must be a mask of shape (" +
                                              std::to_string(p.constraints().size()) + ",)");
            const std::size_t D = dq.shape(0);
            if (dq.shape(1) != n || dqd.shape(0) != D || dqd.shape(1) != n)
                raise_error("ShapeError", "dq and dqd must both have shape (d, " + std::to_string(n) + ")");
            if (!p.differentiable()) raise_status(Status::not_differentiable, "term_tangents");
            NpArr M, h, fp, B, A, g, ph, v, T, V, dM, dh, dfp, dB, dA, dg, dph, dv, dT, dV;
            const bool wM = need & NEED_M, wH = need & NEED_H, wB = need & NEED_B, wA = need & NEED_A,
                       wG = need & NEED_GAMMA, wP = need & NEED_PHI, wV = need & NEED_VELOCITY,
                       wE = need & NEED_ENERGY;
            if (wM) M = new_array({n, n}), dM = new_array({D, n, n});
            if (wH) h = new_array({n}), fp = new_array({n}), dh = new_array({D, n}), dfp = new_array({D, n});
            if (wB) B = new_array({n, k}), dB = new_array({D, n, k});
            if (wA) A = new_array({mm, n}), dA = new_array({D, mm, n});
            if (wG) g = new_array({mm}), dg = new_array({D, mm});
            if (wP) ph = new_array({mm}), dph = new_array({D, mm});
            if (wV) v = new_array({mm}), dv = new_array({D, mm});
            if (wE) T = new_array({}), V = new_array({}), dT = new_array({D}), dV = new_array({D});
            Terms out = p.make_terms();
            Terms tan = p.make_terms();
            auto ws = p.make_workspace();
            auto put = [](NpArr& dst, const double* src, std::size_t len, std::size_t i) {
                std::memcpy(dst.data() + i * len, src, len * sizeof(double));
            };
            for (std::size_t i = 0; i < D; ++i) {
                Status st;
                if (p.thread_safe()) {
                    nb::gil_scoped_release release;
                    st = p.evaluate_tangent(t, q.data(), qd.data(), dq.data() + i * n, dqd.data() + i * n,
                                            active.data(), need, out, tan, *ws);
                } else {
                    st = p.evaluate_tangent(t, q.data(), qd.data(), dq.data() + i * n, dqd.data() + i * n,
                                            active.data(), need, out, tan, *ws);
                }
                if (st != Status::ok) raise_status(st, "term_tangents");
                if (wM) put(dM, tan.M.data(), n * n, i);
                if (wH) put(dh, tan.h.data(), n, i), put(dfp, tan.f_passive.data(), n, i);
                if (wB) put(dB, tan.B.data(), n * k, i);
                if (wA) put(dA, tan.A.data(), mm * n, i);
                if (wG) put(dg, tan.gamma.data(), mm, i);
                if (wP) put(dph, tan.phi.data(), mm, i);
                if (wV) put(dv, tan.velocity.data(), mm, i);
                if (wE) dT.data()[i] = tan.kinetic, dV.data()[i] = tan.potential;
            }
            if (D == 0) {
                const Status st = p.evaluate(t, q.data(), qd.data(), active.data(), need, out, *ws);
                if (st != Status::ok) raise_status(st, "term_tangents");
            }
            nb::dict res;
            if (wM) put(M, out.M.data(), n * n, 0), res["M"] = M, res["dM"] = dM;
            if (wH) {
                put(h, out.h.data(), n, 0), put(fp, out.f_passive.data(), n, 0);
                res["h"] = h, res["f_passive"] = fp, res["dh"] = dh, res["df_passive"] = dfp;
            }
            if (wB) put(B, out.B.data(), n * k, 0), res["B"] = B, res["dB"] = dB;
            if (wA) put(A, out.A.data(), mm * n, 0), res["A"] = A, res["dA"] = dA;
            if (wG) put(g, out.gamma.data(), mm, 0), res["gamma"] = g, res["dgamma"] = dg;
            if (wP) put(ph, out.phi.data(), mm, 0), res["phi"] = ph, res["dphi"] = dph;
            if (wV) put(v, out.velocity.data(), mm, 0), res["velocity"] = v, res["dvelocity"] = dv;
            if (wE) {
                T.data()[0] = out.kinetic, V.data()[0] = out.potential;
                res["kinetic"] = T, res["potential"] = V, res["dkinetic"] = dT, res["dpotential"] = dV;
            }
            return res;
        },
        nb::arg("program"), nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("dq"), nb::arg("dqd"),
        nb::arg("active"), nb::arg("need") = static_cast<unsigned>(NEED_ALL),
        "The terms at (t, q, qd) and their exact directional derivatives (forward mode, dual "
        "numbers) along each row of dq, dqd (shape (d, n)): a dict with the values (M, h, ...) "
        "and the derivatives stacked over the directions (dM: (d, n, n), dh: (d, n), ...). "
        "Rows of inactive constraints are not written. ModelError when the program has no "
        "forward-mode evaluation.");
    nb::class_<DerivativeScratch>(m, "DerivativeScratch",
                                  "Preallocated scratch of forward_derivatives for one program (one per thread).")
        .def(nb::init<const Program&>(), nb::arg("program"));
    m.def(
        "forward_derivatives",
        [](const Program& p, DerivativeScratch& s, double t, nb::handle q, nb::handle qd, nb::handle f, nb::handle u,
           nb::handle active, double rtol, nb::handle res) {
            // arrays through NumPy's C API (a few loads each; nanobind's ndarray import was ~2 k
            // instructions per array, a tenth of the whole call on a Panda)
            const long n = p.n(), k = p.k();
            auto vec = [](nb::handle o, long len, const char* name) -> const double* {
                PyArrayObject* a = f64_array(o.ptr(), 1);
                if (a == nullptr || PyArray_DIM(a, 0) != len)
                    raise_error("ShapeError", std::string(name) + " must be a C-contiguous float64 array of shape (" +
                                                  std::to_string(len) + ",)");
                return static_cast<const double*>(PyArray_DATA(a));
            };
            const double* qp = vec(q, n, "q");
            const double* qdp = vec(qd, n, "qd");
            const double* fp = f.is_none() ? nullptr : vec(f, n, "f");
            const double* up = u.is_none() || k == 0 ? nullptr : vec(u, k, "u");
            PyArrayObject* am = PyArray_CheckExact(active.ptr()) ? reinterpret_cast<PyArrayObject*>(active.ptr()) : nullptr;
            if (am == nullptr || PyArray_NDIM(am) != 1 || PyArray_TYPE(am) != NPY_UINT8 || !PyArray_ISCARRAY_RO(am) ||
                PyArray_DIM(am, 0) != static_cast<npy_intp>(p.constraints().size()))
                raise_error("ShapeError", "active must be a uint8 mask of shape (" +
                                              std::to_string(p.constraints().size()) + ",)");
            const auto* mask = static_cast<const std::uint8_t*>(PyArray_DATA(am));
            PyArrayObject* ar = f64_array(res.ptr(), 2);
            if (ar == nullptr || !PyArray_ISWRITEABLE(ar) || PyArray_DIM(ar, 0) != 2 + 6 * n + 2 * k ||
                PyArray_DIM(ar, 1) != n)
                raise_error("ShapeError", "out must be a writeable C-contiguous float64 array of shape (2 + 6n + 2k, n) = (" +
                                              std::to_string(2 + 6 * n + 2 * k) + ", " + std::to_string(n) + ")");
            if (s.dq.size() != p.n()) raise_error("ShapeError", "scratch made for another program");
            // the boundary's finiteness check (the Python wrapper leaves it here: one pass in C++)
            auto finite = [](const double* x, long len, const char* name) {
                for (long i = 0; i < len; ++i)
                    if (!std::isfinite(x[i]))
                        raise_error("NonFiniteError", std::string(name) + " must be finite, got a non-finite entry at index " +
                                                          std::to_string(i));
            };
            finite(qp, n, "q");
            finite(qdp, n, "qd");
            if (fp != nullptr) finite(fp, n, "f");
            if (up != nullptr) finite(up, k, "u");
            DerivativeOutputs& out = s.out;
            Status st;
            if (p.thread_safe()) {
                nb::gil_scoped_release release;
                st = forward_derivatives(p, s, t, qp, qdp, fp, up, mask, rtol, out);
            } else {
                st = forward_derivatives(p, s, t, qp, qdp, fp, up, mask, rtol, out);
            }
            if (st != Status::ok) raise_status(st, "forward_derivatives");
            double* at = static_cast<double*>(PyArray_DATA(ar));
            auto put = [&](const double* src, long len) {
                if (len) std::memcpy(at, src, static_cast<std::size_t>(len) * sizeof(double));
                at += len;
            };
            const long nn = n * n;
            put(out.qdd.data(), n);
            put(out.fc.data(), n);
            put(out.dqdd_dq.data(), nn);  // row-major n × n
            put(out.dqdd_dqd.data(), nn);
            put(out.dqdd_df.data(), nn);
            put(out.dfc_dq.data(), nn);
            put(out.dfc_dqd.data(), nn);
            put(out.dfc_df.data(), nn);
            // ∂/∂u = ∂/∂f · B (u held fixed in the state derivatives), stored transposed (k × n)
            put(out.dqdd_du_t.data(), n * k);
            put(out.dfc_du_t.data(), n * k);
            return out.rank;
        },
        nb::arg("program"), nb::arg("scratch"), nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("f").none(),
        nb::arg("u").none(), nb::arg("active"), nb::arg("rtol"), nb::arg("out"),
        "q̈, f_c and their derivatives at one state (forward-mode model terms, the kernel's derivative at its "
        "rank; nonmin/derivatives.hpp) written into out, shape (2 + 6n + 2k, n), by rows: q̈, f_c, "
        "∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂f, ∂f_c/∂q, ∂f_c/∂q̇, ∂f_c/∂f (n rows each), (∂q̈/∂u)ᵀ, (∂f_c/∂u)ᵀ (k rows each: "
        "∂/∂f · B(q)). Returns the rank used. q, qd (n), f (n or None), u (k or None): C-contiguous float64 "
        "arrays (ShapeError otherwise; the Python wrapper converts); active: the uint8 mask. NonFiniteError "
        "names a non-finite argument.");
    m.def("differentiable", [](const Program& p) { return p.differentiable(); }, nb::arg("program"),
          "Whether the program evaluates on dual numbers (term_tangents).");
}

}  // namespace nonmin::bindings
