// Bindings of the core layer (solver.hpp): the single-state and batched projection-dynamics
// solve used by nonmin.core (forward_dynamics, constraint_force, solve_dynamics) and the
// minimum-norm solve. Thin: arrays in and out without copies; shapes are checked here and a
// status other than ok is returned as None, on which the Python layer re-runs the NumPy
// reference path, which raises the typed error with its message.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

#include <Eigen/Cholesky>

#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <chrono>
#include <memory>
#include <thread>
#include <vector>

#include "nonmin/dynamics.hpp"
#include "nonmin/solver.hpp"
#include "register.hpp"

namespace nb = nanobind;

namespace nonmin::bindings {

namespace {

using In = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<double, nb::c_contig, nb::device::cpu>;
template <typename... Shape>
using NpOut = nb::ndarray<nb::numpy, double, Shape...>;

// One Solver per thread for single calls, regrown when a call needs more rows or other n.
Solver& thread_solver(int m, int n) {
    thread_local std::unique_ptr<Solver> s;
    if (!s || s->n() != n || s->m_max() < m) {
        const int m_max = std::max(m, s && s->n() == n ? s->m_max() : 0);
        s = std::make_unique<Solver>(std::max(m_max, 1), n);
    }
    return *s;
}

double* fresh(std::size_t count, nb::capsule& owner) {
    double* p = new double[count > 0 ? count : 1];
    owner = nb::capsule(p, [](void* q) noexcept { delete[] static_cast<double*>(q); });
    return p;
}

SolveOptions options(double mu, double rtol, double spd_rtol, double sym_rtol) {
    SolveOptions o;
    o.mu = mu;
    o.rtol = rtol;
    o.spd_rtol = spd_rtol;
    o.sym_rtol = sym_rtol;
    return o;
}

// ---------------------------------------------------------------- the public calls' fast entry
// An exact numpy.ndarray of float64 (native byte order, aligned, C-contiguous) with nd
// dimensions, read through NumPy's C API (a few loads: the buffer protocol cost ~0.1 µs per
// array, a third of a small call).
inline PyArrayObject* f64_array(PyObject* o, int nd) {
    if (!PyArray_CheckExact(o)) return nullptr;
    auto* a = reinterpret_cast<PyArrayObject*>(o);
    if (PyArray_NDIM(a) != nd || PyArray_TYPE(a) != NPY_DOUBLE || !PyArray_ISCARRAY_RO(a) ||
        !PyArray_ISNOTSWAPPED(a))
        return nullptr;
    return a;
}
inline const double* f64_data(PyArrayObject* a) { return static_cast<const double*>(PyArray_DATA(a)); }
inline long f64_dim(PyArrayObject* a, int i) { return static_cast<long>(PyArray_DIM(a, i)); }

// forward_dynamics / constraint_force / (q̈, rank) for one state with the public arguments:
// mu and rtol None or Python floats, f None or an array. Returns None whenever the call is not
// the plain regular single-state case (arrays that are not float64 C-contiguous of one state's
// shapes, other argument types, invalid values, an irregular state): the Python layer then takes
// its general path, which converts, batches, or raises the typed error.
nb::object fast_solve(nb::handle M, nb::handle h, nb::handle A, nb::handle gamma, nb::handle f,
                      nb::handle mu, nb::handle rtol, int what) {
    SolveOptions opt;
    if (!mu.is_none()) {
        if (!PyFloat_CheckExact(mu.ptr())) return nb::none();
        opt.mu = PyFloat_AS_DOUBLE(mu.ptr());
        if (!(opt.mu > 0.0) || !std::isfinite(opt.mu)) return nb::none();
    }
    if (!rtol.is_none()) {
        if (!PyFloat_CheckExact(rtol.ptr())) return nb::none();
        opt.rtol = PyFloat_AS_DOUBLE(rtol.ptr());
        if (!(opt.rtol > 0.0 && opt.rtol < 1.0)) return nb::none();
    }
    PyArrayObject *aM = f64_array(M.ptr(), 2), *ah = f64_array(h.ptr(), 1),
                  *aA = f64_array(A.ptr(), 2), *ag = f64_array(gamma.ptr(), 1);
    if (!aM || !ah || !aA || !ag) return nb::none();
    const long n = f64_dim(ah, 0), m = f64_dim(aA, 0);
    if (n == 0 || f64_dim(aM, 0) != n || f64_dim(aM, 1) != n || f64_dim(aA, 1) != n ||
        f64_dim(ag, 0) != m)
        return nb::none();
    const double* g = f64_data(ah);
    thread_local std::vector<double> gbuf, fcbuf;
    if (!f.is_none()) {
        PyArrayObject* af = f64_array(f.ptr(), 1);
        if (!af || f64_dim(af, 0) != n) return nb::none();
        gbuf.resize(n);
        const double* fp = f64_data(af);
        for (long i = 0; i < n; ++i) gbuf[i] = g[i] + fp[i];
        g = gbuf.data();
    }
    Solver& s = thread_solver(static_cast<int>(m), static_cast<int>(n));
    npy_intp dims[1] = {static_cast<npy_intp>(n)};
    nb::object res = nb::steal(PyArray_SimpleNew(1, dims, NPY_DOUBLE));
    if (!res.is_valid()) throw nb::python_error();
    double* out = static_cast<double*>(PyArray_DATA(reinterpret_cast<PyArrayObject*>(res.ptr())));
    SolveInfo info;
    if (what == 1) {
        fcbuf.resize(n);
        info = s.forward(f64_data(aM), g, f64_data(aA), static_cast<int>(m), f64_data(ag), opt,
                         fcbuf.data(), out);
    } else {
        info = s.forward(f64_data(aM), g, f64_data(aA), static_cast<int>(m), f64_data(ag), opt,
                         out, nullptr);
    }
    if (info.status != Status::ok) return nb::none();
    if (what == 3) return nb::make_tuple(res, info.rank);
    return res;
}

nb::object status_of(Status s) { return nb::int_(static_cast<int>(s)); }

// what: 0 q̈, 1 f_c, 2 (q̈, f_c, P, L, rank, μ), 3 (q̈, rank). None when the arrays are not those
// of one state (a batch: the caller's batched path); the status code (int) when the state is
// not regular (wrong sizes, non-finite, asymmetric M, M̄ not SPD).
nb::object solve_one(In M, In h, In A, In gamma, std::optional<In> f, double mu, double rtol,
                     double spd_rtol, double sym_rtol, int what) {
    if (M.ndim() != 2 || h.ndim() != 1 || A.ndim() != 2 || gamma.ndim() != 1 ||
        (f && f->ndim() != 1))
        return nb::none();
    const int n = static_cast<int>(h.shape(0));
    const int m = static_cast<int>(A.shape(0));
    if (n == 0 || M.shape(0) != static_cast<size_t>(n) || M.shape(1) != static_cast<size_t>(n) ||
        A.shape(1) != static_cast<size_t>(n) || gamma.shape(0) != static_cast<size_t>(m) ||
        (f && f->shape(0) != static_cast<size_t>(n)))
        return status_of(Status::bad_shape);
    Solver& s = thread_solver(m, n);
    const SolveOptions opt = options(mu, rtol, spd_rtol, sym_rtol);
    thread_local std::vector<double> gbuf;
    const double* g = h.data();
    if (f) {
        gbuf.resize(n);
        const double* fp = f->data();
        for (int i = 0; i < n; ++i) gbuf[i] = h.data()[i] + fp[i];
        g = gbuf.data();
    }
    const size_t un = static_cast<size_t>(n);
    if (what == 0 || what == 3) {
        nb::capsule own;
        double* q = fresh(un, own);
        const SolveInfo info = s.forward(M.data(), g, A.data(), m, gamma.data(), opt, q, nullptr);
        if (info.status != Status::ok) return status_of(info.status);
        NpOut<nb::ndim<1>> qa(q, {un}, own);
        if (what == 0) return nb::cast(qa);
        return nb::make_tuple(qa, info.rank);
    }
    if (what == 1) {
        nb::capsule own;
        double* buf = fresh(2 * un, own);
        const SolveInfo info =
            s.forward(M.data(), g, A.data(), m, gamma.data(), opt, buf + n, buf);
        if (info.status != Status::ok) return status_of(info.status);
        return nb::cast(NpOut<nb::ndim<1>>(buf, {un}, own));
    }
    nb::capsule o1, o2, o3, o4;
    double* q = fresh(un, o1);
    double* fc = fresh(un, o2);
    double* P = fresh(un * un, o3);
    double* L = fresh(un * un, o4);
    const SolveInfo info = s.solve(M.data(), g, A.data(), m, gamma.data(), opt, q, fc, P, L);
    if (info.status != Status::ok) return status_of(info.status);
    return nb::make_tuple(NpOut<nb::ndim<1>>(q, {un}, o1), NpOut<nb::ndim<1>>(fc, {un}, o2),
                          NpOut<nb::ndim<2>>(P, {un, un}, o3), NpOut<nb::ndim<2>>(L, {un, un}, o4),
                          info.rank, info.mu);
}

// Batched solve over N states: every input is a flat C-contiguous buffer with a batch stride
// (0: the same array for every state, i.e. broadcast). Outputs are (N, …) buffers; fc, P, L
// may be empty (not computed). Threads split the batch in contiguous chunks, each with its own
// Solver; the per-state arithmetic is that of a single call, so results are bitwise the same.
void solve_batch(In M, In h, std::optional<In> f, In A, In gamma, std::optional<In> mu, long sM,
                 long sh, long sf, long sA, long sg, long smu, long N, int n, int m, double rtol,
                 double spd_rtol, double sym_rtol, Out qdd, Out fc, Out P, Out L,
                 nb::ndarray<int64_t, nb::c_contig, nb::device::cpu> status,
                 nb::ndarray<int64_t, nb::c_contig, nb::device::cpu> rank, Out mu_out, Out ratio,
                 int nthreads) {
    const double* Mp = M.data();
    const double* hp = h.data();
    const double* fp = f ? f->data() : nullptr;
    const double* Ap = A.data();
    const double* gp = gamma.data();
    const double* mup = mu ? mu->data() : nullptr;
    double* qp = qdd.data();
    double* fcp = fc.size() ? fc.data() : nullptr;
    double* Pp = P.size() ? P.data() : nullptr;
    double* Lp = L.size() ? L.data() : nullptr;
    int64_t* stp = status.data();
    int64_t* rkp = rank.data();
    double* mop = mu_out.data();
    double* rap = ratio.data();
    auto run = [=](long lo, long hi) {
        Solver s(std::max(m, 1), n);
        std::vector<double> g(n);
        SolveOptions opt;
        opt.rtol = rtol;
        opt.spd_rtol = spd_rtol;
        opt.sym_rtol = sym_rtol;
        const long nn = static_cast<long>(n) * n;
        for (long b = lo; b < hi; ++b) {
            const double* hb = hp + b * sh;
            if (fp) {
                const double* fb = fp + b * sf;
                for (int i = 0; i < n; ++i) g[i] = hb[i] + fb[i];
            } else {
                for (int i = 0; i < n; ++i) g[i] = hb[i];
            }
            opt.mu = mup ? mup[b * smu] : 0.0;
            const SolveInfo info =
                s.solve(Mp + b * sM, g.data(), Ap + b * sA, m, gp + b * sg, opt, qp + b * n,
                        fcp ? fcp + b * n : nullptr, Pp ? Pp + b * nn : nullptr,
                        Lp ? Lp + b * nn : nullptr);
            stp[b] = static_cast<int64_t>(info.status);
            rkp[b] = info.rank;
            mop[b] = info.mu;
            rap[b] = info.pivot_ratio;
        }
    };
    nb::gil_scoped_release release;
    const long T = std::max(1L, std::min<long>(nthreads, N));
    if (T == 1) {
        run(0, N);
        return;
    }
    std::vector<std::thread> pool;
    pool.reserve(T - 1);
    for (long c = 1; c < T; ++c) pool.emplace_back(run, (c * N) / T, ((c + 1) * N) / T);
    run(0, N / T);
    for (auto& t : pool) t.join();
}

// Split [0, N) into contiguous chunks over up to `nthreads` threads (GIL released by the
// caller); f(lo, hi) evaluates one chunk with its own scratch.
template <class F>
void parallel_chunks(long N, int nthreads, const F& f) {
    const long T = std::max(1L, std::min<long>(nthreads, N));
    if (T == 1) {
        f(0L, N);
        return;
    }
    std::vector<std::thread> pool;
    pool.reserve(T - 1);
    for (long c = 1; c < T; ++c) pool.emplace_back(f, (c * N) / T, ((c + 1) * N) / T);
    f(0L, N / T);
    for (auto& t : pool) t.join();
}

using I64 = nb::ndarray<int64_t, nb::c_contig, nb::device::cpu>;

// The batched kernels of dynamics.hpp: inputs are flat buffers with batch strides (0 =
// broadcast), outputs (N, …) buffers.
void mbar_batch(In M, In P, In mu, long sM, long sP, long smu, long N, int n, Out out,
                int nthreads) {
    const double *Mp = M.data(), *Pp = P.data(), *mp = mu.data();
    double* o = out.data();
    const long nn = static_cast<long>(n) * n;
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        for (long b = lo; b < hi; ++b)
            constraint_inertia(Mp + b * sM, Pp + b * sP, mp[b * smu], n, o + b * nn);
    });
}

void optimal_mu_batch(In M, In P, long sM, long sP, long N, int n, Out out, int nthreads) {
    const double *Mp = M.data(), *Pp = P.data();
    double* o = out.data();
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        for (long b = lo; b < hi; ++b) o[b] = optimal_virtual_mass(Mp + b * sM, Pp + b * sP, n);
    });
}

void force_projector_batch(In M, In P, In mu, long sM, long sP, long smu, long N, int n, Out out,
                           I64 status, int nthreads) {
    const double *Mp = M.data(), *Pp = P.data(), *mp = mu.data();
    double* o = out.data();
    int64_t* st = status.data();
    const long nn = static_cast<long>(n) * n;
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        std::vector<double> work(2 * nn + 3 * n + 1);
        for (long b = lo; b < hi; ++b)
            st[b] = static_cast<int64_t>(constraint_force_projector(
                Mp + b * sM, Pp + b * sP, mp[b * smu], n, o + b * nn, work.data()));
    });
}

void actuation_batch(In B, In P, long sB, long sP, long N, int n, int k, double rtol, Out R,
                     Out Gamma, I64 rank_pb, I64 dof, int nthreads) {
    const double *Bp = B.data(), *Pp = P.data();
    double *Rp = R.data(), *Gp = Gamma.data();
    int64_t *rp = rank_pb.data(), *dp = dof.data();
    const long nn = static_cast<long>(n) * n, kn = static_cast<long>(k) * n;
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        for (long b = lo; b < hi; ++b) {
            int r = 0, d = 0;
            actuation_projectors(Bp + b * sB, Pp + b * sP, n, k, rtol, Rp + b * nn, Gp + b * kn,
                                 &r, &d);
            rp[b] = r;
            dp[b] = d;
        }
    });
}

void cbar_batch(In M, In C, In A, In Adot, In mu, long sM, long sC, long sA, long sAd, long smu,
                long N, int n, int m, double rtol, Out out, int nthreads) {
    const double *Mp = M.data(), *Cp = C.data(), *Ap = A.data(), *Dp = Adot.data(),
                 *mp = mu.data();
    double* o = out.data();
    const long nn = static_cast<long>(n) * n;
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        Solver s(std::max(m, 1), n);
        for (long b = lo; b < hi; ++b)
            coriolis_bar(s, Mp + b * sM, Cp + b * sC, Ap + b * sA, Dp + b * sAd, m, mp[b * smu],
                         rtol, o + b * nn);
    });
}

// kind 0: impact map (x = q̇⁻, e = restitution); 1: position correction (x = φ).
void solver_kernel_batch(int kind, In M, In A, In x, std::optional<In> mu, long sM, long sA,
                         long sx, long smu, long N, int n, int m, double e, double rtol, Out out,
                         I64 status, I64 rank, int nthreads) {
    const double *Mp = M.data(), *Ap = A.data(), *xp = x.data();
    const double* mp = mu ? mu->data() : nullptr;
    double* o = out.data();
    int64_t *st = status.data(), *rk = rank.data();
    nb::gil_scoped_release release;
    parallel_chunks(N, nthreads, [=](long lo, long hi) {
        Solver s(std::max(m, 1), n);
        std::vector<double> work(2 * static_cast<size_t>(n));
        for (long b = lo; b < hi; ++b) {
            const double mu_b = mp ? mp[b * smu] : 0.0;
            const SolveInfo info =
                kind == 0 ? impact_map(s, Mp + b * sM, Ap + b * sA, m, xp + b * sx, e, mu_b,
                                       rtol, o + b * n, work.data())
                          : position_correction(s, Mp + b * sM, Ap + b * sA, m, xp + b * sx,
                                                mu_b, rtol, o + b * n, work.data());
            st[b] = static_cast<int64_t>(info.status);
            rk[b] = info.rank;
        }
    });
}

}  // namespace

void bind_core(nb::module_& m) {
    if (_import_array() < 0) throw nb::python_error();  // NumPy's C API table (this file only)
    m.def("core_mbar", &mbar_batch, "M̄ = PMP + μ(I − P) over a batch (strided inputs).");
    m.def("core_optimal_mu", &optimal_mu_batch, "μ = tr(PMP)/(n − r) over a batch.");
    m.def("core_force_projector", &force_projector_batch,
          "S = I − M M̄⁻¹ P over a batch; status per state.");
    m.def("core_actuation", &actuation_batch,
          "Γ = (PB)⁺ and R = BΓ over a batch; rank(PB) and n − rank(A) per state.");
    m.def("core_cbar", &cbar_batch, "C̄ = PCP + PM(ΛP + PΛᵀ) − μΛP over a batch.");
    m.def("core_solver_kernel", &solver_kernel_batch, nb::arg("kind"), nb::arg("M"),
          nb::arg("A"), nb::arg("x"), nb::arg("mu").none(), nb::arg("sM"), nb::arg("sA"),
          nb::arg("sx"), nb::arg("smu"), nb::arg("N"), nb::arg("n"), nb::arg("m"), nb::arg("e"),
          nb::arg("rtol"), nb::arg("out"), nb::arg("status"), nb::arg("rank"),
          nb::arg("nthreads"),
          "Impact map (kind 0) or mass-metric position correction (kind 1) over a batch.");
    m.def("core_fast", &fast_solve, nb::arg("M"), nb::arg("h"), nb::arg("A"), nb::arg("gamma"),
          nb::arg("f").none(), nb::arg("mu").none(), nb::arg("rtol").none(), nb::arg("what"),
          "The public kernels' fast entry (what 0: q̈, 1: f_c, 3: (q̈, rank)) for one regular "
          "state of float64 C-contiguous arrays; None otherwise (take the general path).");
    m.def("core_solve_one", &solve_one, nb::arg("M"), nb::arg("h"), nb::arg("A"),
          nb::arg("gamma"), nb::arg("f").none(), nb::arg("mu"), nb::arg("rtol"),
          nb::arg("spd_rtol"), nb::arg("sym_rtol"), nb::arg("what"),
          "One state of the projection dynamics (nonmin.core.solve_dynamics); None for arrays "
          "that are not one state's, the status code (int) when the state is not regular (the "
          "caller re-runs the NumPy path for the typed error).");
    m.def("core_solve_batch", &solve_batch, nb::arg("M"), nb::arg("h"), nb::arg("f").none(),
          nb::arg("A"), nb::arg("gamma"), nb::arg("mu").none(), nb::arg("sM"), nb::arg("sh"),
          nb::arg("sf"), nb::arg("sA"), nb::arg("sg"), nb::arg("smu"), nb::arg("N"),
          nb::arg("n"), nb::arg("m"), nb::arg("rtol"), nb::arg("spd_rtol"), nb::arg("sym_rtol"),
          nb::arg("qdd"), nb::arg("fc"), nb::arg("P"), nb::arg("L"), nb::arg("status"),
          nb::arg("rank"), nb::arg("mu_out"), nb::arg("ratio"), nb::arg("nthreads"),
          "A batch of states (flat buffers with batch strides, 0 = broadcast), threaded.");
    m.def(
        "core_solve_info",
        [](In M, In g, In A, In gamma, double rtol) {
            const int n = static_cast<int>(g.shape(0)), m = static_cast<int>(A.shape(0));
            if (M.size() != static_cast<size_t>(n) * n || A.ndim() != 2 ||
                A.shape(1) != static_cast<size_t>(n) || gamma.size() != static_cast<size_t>(m))
                throw nb::value_error("core_solve_info: shapes");
            Solver s(std::max(m, 1), n);
            std::vector<double> q(n);
            SolveOptions opt;
            opt.rtol = rtol;
            const SolveInfo i = s.forward(M.data(), g.data(), A.data(), m, gamma.data(), opt,
                                          q.data(), nullptr);
            nb::dict d;
            d["status"] = static_cast<int>(i.status);
            d["rank"] = i.rank;
            d["mu"] = i.mu;
            d["method"] = i.method;
            d["null_space_form"] = i.null_space_form;
            return d;
        },
        nb::arg("M"), nb::arg("g"), nb::arg("A"), nb::arg("gamma"), nb::arg("rtol"),
        "Test helper: how the Solver decided one state (status, rank, μ, method: 0 SVD, 1 "
        "certified LQ with L⁻¹, 2 certified LQ over L's profile; null_space_form).");
    m.def(
        "core_solve_near",
        [](In M, In g, In Ah, In gh, In A, In gamma, double rtol) {
            const int n = static_cast<int>(g.shape(0)), m = static_cast<int>(A.shape(0));
            if (M.size() != static_cast<size_t>(n) * n || A.ndim() != 2 || Ah.ndim() != 2 ||
                A.shape(1) != static_cast<size_t>(n) || Ah.shape(0) != A.shape(0) ||
                Ah.shape(1) != A.shape(1) || gamma.size() != static_cast<size_t>(m) ||
                gh.size() != static_cast<size_t>(m))
                throw nb::value_error("core_solve_near: shapes");
            Solver s(std::max(m, 1), n);
            SolveOptions opt;
            opt.rtol = rtol;
            opt.known = KNOWN_M_VALID;
            const size_t un = static_cast<size_t>(n);
            nb::capsule o0, o1, o2;
            double* held = fresh(2 * un, o0);  // q̈, f_c of the held factorization (Ah, gh)
            double* first = fresh(2 * un, o1);
            double* again = fresh(2 * un, o2);
            const SolveInfo i0 = s.forward(M.data(), g.data(), Ah.data(), m, gh.data(), opt, held, held + n);
            const SolveInfo i1 = s.near(M.data(), g.data(), A.data(), m, gamma.data(), opt, false, first, first + n);
            const SolveInfo i2 = s.near(M.data(), g.data(), A.data(), m, gamma.data(), opt, true, again, again + n);
            nb::dict d;
            d["held_status"] = static_cast<int>(i0.status);
            d["held_method"] = i0.method;
            d["held_null_space_form"] = i0.null_space_form;
            d["status"] = static_cast<int>(i1.status);
            d["status_same"] = static_cast<int>(i2.status);
            d["rank"] = i1.rank;
            d["held"] = nb::cast(NpOut<nb::ndim<2>>(held, {2, un}, o0));
            d["near"] = nb::cast(NpOut<nb::ndim<2>>(first, {2, un}, o1));
            d["near_same"] = nb::cast(NpOut<nb::ndim<2>>(again, {2, un}, o2));
            return d;
        },
        nb::arg("M"), nb::arg("g"), nb::arg("A_held"), nb::arg("gamma_held"), nb::arg("A"),
        nb::arg("gamma"), nb::arg("rtol"),
        "Test helper of Solver::near: factorize (M, g, A_held, gamma_held) (M stated valid), "
        "then near() at (A, gamma) twice, the second with same = true. A dict of the statuses "
        "(status 0 ok, 4 declined), the held call's method and form, and the rows [q̈, f_c] of "
        "the three calls.");
    m.def(
        "core_time_solve",
        [](In M, In g, In A, In gamma, long reps, int what) -> double {
            const int n = static_cast<int>(g.shape(0)), m = static_cast<int>(A.shape(0));
            if (M.size() != static_cast<size_t>(n) * n || A.ndim() != 2 ||
                A.shape(1) != static_cast<size_t>(n) || gamma.size() != static_cast<size_t>(m))
                throw nb::value_error("core_time_solve: shapes");
            Solver s(std::max(m, 1), n);
            std::vector<double> q(n), fc(n), P(static_cast<size_t>(n) * n), L(P.size());
            SolveOptions opt;
            nb::gil_scoped_release release;
            const auto t0 = std::chrono::steady_clock::now();
            for (long r = 0; r < reps; ++r)
                s.solve(M.data(), g.data(), A.data(), m, gamma.data(), opt, q.data(),
                        what >= 1 ? fc.data() : nullptr, what == 2 ? P.data() : nullptr,
                        what == 2 ? L.data() : nullptr);
            const auto t1 = std::chrono::steady_clock::now();
            return std::chrono::duration<double>(t1 - t0).count() / static_cast<double>(reps);
        },
        nb::arg("M"), nb::arg("g"), nb::arg("A"), nb::arg("gamma"), nb::arg("reps"),
        nb::arg("what") = 0,
        "Benchmark helper: seconds per Solver call (one preallocated Solver, no Python in the "
        "loop); what 0: q̈, 1: q̈ and f_c, 2: also P and L.");
    m.def(
        "core_time_kkt",
        [](In M, In g, In A, In gamma, long reps) -> double {
            // The like-for-like reference where no peer takes these terms: the dense KKT solve
            // of Pinocchio's forwardDynamics(model, data, τ, J, γ) written with Eigen —
            // LLT(M), LLT(J M⁻¹ Jᵀ), λ, q̈ = M⁻¹(g + Jᵀλ) — for a full-row-rank J.
            const int n = static_cast<int>(g.shape(0)), m = static_cast<int>(A.shape(0));
            if (M.size() != static_cast<size_t>(n) * n || A.ndim() != 2 ||
                A.shape(1) != static_cast<size_t>(n) || gamma.size() != static_cast<size_t>(m))
                throw nb::value_error("core_time_kkt: shapes");
            Eigen::Map<const Mat> Mm(M.data(), n, n), Am(A.data(), m, n);
            Eigen::Map<const Vec> gv(g.data(), n), gam(gamma.data(), m);
            Eigen::LLT<Eigen::MatrixXd> llt_m(n), llt_s(m);
            Eigen::MatrixXd U(n, m), S(m, m);
            Vec a(n), lam(m), qdd(n);
            nb::gil_scoped_release release;
            const auto t0 = std::chrono::steady_clock::now();
            for (long r = 0; r < reps; ++r) {
                llt_m.compute(Mm);
                U = Am.transpose();
                llt_m.matrixL().solveInPlace(U);  // U = L⁻¹ Jᵀ
                S.noalias() = U.transpose() * U;  // J M⁻¹ Jᵀ
                llt_s.compute(S);
                a = llt_m.solve(gv);  // unconstrained acceleration
                lam = llt_s.solve(-gam - Am * a);
                qdd = llt_m.solve(gv + Am.transpose() * lam);
            }
            const auto t1 = std::chrono::steady_clock::now();
            if (!qdd.allFinite()) throw nb::value_error("core_time_kkt: singular");
            return std::chrono::duration<double>(t1 - t0).count() / static_cast<double>(reps);
        },
        nb::arg("M"), nb::arg("g"), nb::arg("A"), nb::arg("gamma"), nb::arg("reps"),
        "Benchmark helper: seconds per dense KKT solve (Pinocchio's forwardDynamics algorithm "
        "given M, g, J, γ, in Eigen; full-row-rank J only).");
    m.def(
        "core_min_norm",
        [](In A, In b, double rtol, Out x) -> int {
            if (A.ndim() != 2 || b.ndim() != 1 || b.shape(0) != A.shape(0) ||
                x.size() != A.shape(1) || A.shape(1) == 0)
                throw nb::value_error("core_min_norm: shapes");
            const int m = static_cast<int>(A.shape(0)), n = static_cast<int>(A.shape(1));
            Solver& s = thread_solver(m, n);
            return s.min_norm(A.data(), m, b.data(), rtol, x.data()).rank;
        },
        nb::arg("A"), nb::arg("b"), nb::arg("rtol"), nb::arg("x"),
        "Minimum-norm solution x = (DA)⁺ D b of A x = b (rank policy of nonmin.core); returns "
        "the rank.");
}

}  // namespace nonmin::bindings
