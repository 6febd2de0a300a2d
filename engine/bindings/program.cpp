// Bindings of the model layer's interface (nonmin/program.hpp): Program, Terms, Workspace.
// Every concrete Program (planar, tape, spatial, robots, Python callbacks) is bound as a
// subclass of Program, so binding functions of other layers take `const nonmin::Program&`.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/unique_ptr.h>

#include <mutex>
#include <string>
#include <thread>

#include "nonmin/forward.hpp"
#include "nonmin/batch.hpp"
#include "nonmin/program.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

void check_state(const Program& p, std::size_t nq, std::size_t nqd, std::size_t nact) {
    const auto n = static_cast<std::size_t>(p.n());
    if (nq != n) raise_error("ShapeError", "q must have shape (" + std::to_string(n) + ",), got (" +
                                               std::to_string(nq) + ",)");
    if (nqd != n) raise_error("ShapeError", "qd must have shape (" + std::to_string(n) + ",), got (" +
                                                std::to_string(nqd) + ",)");
    const std::size_t nc = p.constraints().size();
    if (nact != nc)
        raise_error("ShapeError", "active must be a mask of shape (" + std::to_string(nc) +
                                      ",) (one entry per constraint), got (" + std::to_string(nact) + ",)");
}

void check_terms(const Program& p, const Terms& T) {
    if (T.M.rows() != p.n() || T.A.rows() != p.m_all() || T.A.cols() != p.n() || T.B.cols() != p.k())
        raise_error("ShapeError", "terms were made by another program (sizes differ)");
}

template <class M>
NpArr view(M& x, nb::handle) {
    std::size_t shape[2] = {static_cast<std::size_t>(x.rows()), static_cast<std::size_t>(x.cols())};
    return NpArr(x.data(), M::ColsAtCompileTime == 1 ? 1 : 2, shape, nb::handle());
}

// q̈ from states for one program and active mask: the model + kernel pipeline.
struct Forward {
    const Program* prog;
    std::vector<std::uint8_t> active;
    SolveOptions opt;
    std::unique_ptr<ForwardScratch> scratch;  // single calls
    ScratchPool pool;                         // batch calls: one scratch per worker, kept
    std::mutex pool_mutex;                    // a concurrent batch call makes its own
};

using OArr1 = nb::ndarray<double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

}  // namespace

void bind_program(nb::module_& m) {
    nb::enum_<ConstraintKind>(m, "ConstraintKind")
        .value("holonomic", ConstraintKind::holonomic)
        .value("rheonomic", ConstraintKind::rheonomic)
        .value("nonholonomic", ConstraintKind::nonholonomic)
        .value("unilateral", ConstraintKind::unilateral);

    m.attr("NEED_M") = static_cast<unsigned>(NEED_M);
    m.attr("NEED_H") = static_cast<unsigned>(NEED_H);
    m.attr("NEED_A") = static_cast<unsigned>(NEED_A);
    m.attr("NEED_GAMMA") = static_cast<unsigned>(NEED_GAMMA);
    m.attr("NEED_PHI") = static_cast<unsigned>(NEED_PHI);
    m.attr("NEED_VELOCITY") = static_cast<unsigned>(NEED_VELOCITY);
    m.attr("NEED_B") = static_cast<unsigned>(NEED_B);
    m.attr("NEED_ENERGY") = static_cast<unsigned>(NEED_ENERGY);
    m.attr("NEED_ALL") = static_cast<unsigned>(NEED_ALL);
    m.attr("NEED_GRAVITY") = static_cast<unsigned>(NEED_GRAVITY);

    nb::class_<Terms>(m, "Terms",
                      "Outputs of one Program evaluation (arrays are views into the object).")
        .def_prop_ro("M", [](Terms& t) { return view(t.M, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("h", [](Terms& t) { return view(t.h, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("f_passive", [](Terms& t) { return view(t.f_passive, nb::handle()); },
                     nb::rv_policy::reference_internal)
        .def_prop_ro("f_g", [](Terms& t) { return view(t.f_g, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("B", [](Terms& t) { return view(t.B, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("A", [](Terms& t) { return view(t.A, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("gamma", [](Terms& t) { return view(t.gamma, nb::handle()); },
                     nb::rv_policy::reference_internal)
        .def_prop_ro("phi", [](Terms& t) { return view(t.phi, nb::handle()); }, nb::rv_policy::reference_internal)
        .def_prop_ro("velocity", [](Terms& t) { return view(t.velocity, nb::handle()); },
                     nb::rv_policy::reference_internal)
        .def_rw("kinetic", &Terms::kinetic)
        .def_rw("potential", &Terms::potential);

    nb::class_<Workspace>(m, "Workspace", "Preallocated scratch of one Program (one per thread).");

    nb::class_<Forward>(m, "Forward",
                        "Forward dynamics from a state (Program evaluation + core solve) for one "
                        "program and active mask; q̈ as nonmin.core.forward_dynamics of the model's "
                        "terms, to round-off.")
        .def(
            "__init__",
            [](Forward* self, const Program& p, CMask active, double rtol, double mu) {
                if (active.shape(0) != p.constraints().size())
                    raise_error("ShapeError", "active must be a mask of shape (" +
                                                  std::to_string(p.constraints().size()) + ",)");
                new (self) Forward();
                self->prog = &p;
                self->active.assign(active.data(), active.data() + active.shape(0));
                self->opt.rtol = rtol;
                self->opt.mu = mu;
                self->scratch = std::make_unique<ForwardScratch>(p, self->active.data());
            },
            nb::arg("program"), nb::arg("active"), nb::arg("rtol") = 1e-10, nb::arg("mu") = 0.0,
            nb::keep_alive<1, 2>())
        .def(
            "__call__",
            [](Forward& f, double t, CArr1 q, CArr1 qd, OArr1 qdd) {
                const Program& p = *f.prog;
                check_state(p, q.shape(0), qd.shape(0), f.active.size());
                if (qdd.shape(0) != static_cast<std::size_t>(p.n())) raise_error("ShapeError", "qdd: shape (n,)");
                SolveInfo info;
                if (p.thread_safe()) {
                    nb::gil_scoped_release release;
                    info = forward_dynamics(p, *f.scratch, t, q.data(), qd.data(), nullptr, f.opt, qdd.data(), nullptr);
                } else {
                    info = forward_dynamics(p, *f.scratch, t, q.data(), qd.data(), nullptr, f.opt, qdd.data(), nullptr);
                }
                if (info.status != Status::ok) raise_status(info.status, "Forward");
                return info.rank;
            },
            nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("qdd"),
            "Write q̈ into qdd (shape (n,)); returns the rank of A used.")
        .def(
            "batch",
            [](Forward& f, CArr1 t, CArr2 q, CArr2 qd, int nthreads) {
                const Program& p = *f.prog;
                const std::size_t N = t.shape(0);
                const auto n = static_cast<std::size_t>(p.n());
                if (q.shape(0) != N || qd.shape(0) != N)
                    raise_error("ShapeError", "t, q and qd must have the same number of states (rows)");
                check_state(p, q.shape(1), qd.shape(1), f.active.size());
                NpArr qdd = new_array({N, n}, false);  // written in full by forward_batch
                std::vector<int> status(N, 0);
                BatchOutputs out;
                out.qdd = qdd.data();
                out.status = status.data();
                int bad;
                std::unique_lock<std::mutex> own(f.pool_mutex, std::try_to_lock);
                ScratchPool* pool = own.owns_lock() ? &f.pool : nullptr;
                if (p.thread_safe()) {
                    nb::gil_scoped_release release;
                    bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), f.active.data(),
                                        nullptr, 0, f.opt, std::max(nthreads, 1), out, pool);
                } else {
                    bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), f.active.data(),
                                        nullptr, 0, f.opt, 1, out, pool);
                }
                if (bad)
                    for (std::size_t i = 0; i < N; ++i)
                        if (status[i] != 0)
                            raise_status(static_cast<Status>(status[i]),
                                         "Forward.batch (state " + std::to_string(i) + ")");
                return qdd;
            },
            nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("nthreads") = 1,
            "q̈ of N states (t: (N,), q, qd: (N, n)) on nthreads threads (one if the program "
            "is not thread safe); an array (N, n).");

    nb::class_<Program>(m, "Program",
                        "A model compiled once to what the engine evaluates at (t, q, qd, active).")
        .def_prop_ro("n", &Program::n)
        .def_prop_ro("k", &Program::k)
        .def_prop_ro("m_all", &Program::m_all)
        .def_prop_ro("constant_mass", &Program::constant_mass)
        .def_prop_ro("thread_safe", &Program::thread_safe)
        .def_prop_ro("gravity_in_pass", &Program::gravity_in_pass)
        .def_prop_ro(
            "constraints",
            [](const Program& p) {
                nb::list out;
                for (const ConstraintInfo& c : p.constraints())
                    out.append(nb::make_tuple(c.name, static_cast<int>(c.kind), c.row, c.dim));
                return out;
            },
            "(name, kind, first row, rows) of every constraint, in row order.")
        .def("make_terms", &Program::make_terms, "Zeroed outputs sized for this program.")
        .def("make_workspace", &Program::make_workspace, "Scratch for evaluate_into (one per thread).")
        .def(
            "evaluate_into",
            [](const Program& p, Terms& out, Workspace& ws, double t, CArr1 q, CArr1 qd, CMask active,
               unsigned need) {
                check_state(p, q.shape(0), qd.shape(0), active.shape(0));
                check_terms(p, out);
                if ((need & NEED_A) && p.a_pattern().known()) {
                    // the program writes only A's pattern (program.hpp): rows written from
                    // Python hold anything, so the active rows start from zeros here
                    for (const ConstraintInfo& c : p.constraints())
                        if (active.data()[&c - p.constraints().data()]) out.A.middleRows(c.row, c.dim).setZero();
                }
                Status s;
                if (p.thread_safe()) {
                    nb::gil_scoped_release release;
                    s = p.evaluate(t, q.data(), qd.data(), active.data(), need, out, ws);
                } else {
                    s = p.evaluate(t, q.data(), qd.data(), active.data(), need, out, ws);
                }
                if (s != Status::ok) raise_status(s, "Program.evaluate");
            },
            nb::arg("terms"), nb::arg("workspace"), nb::arg("t"), nb::arg("q"), nb::arg("qd"),
            nb::arg("active"), nb::arg("need") = static_cast<unsigned>(NEED_ALL),
            "Evaluate what `need` asks (NEED_* flags) into `terms`; rows of inactive constraints "
            "are left as they are.")
        .def(
            "evaluate",
            [](const Program& p, double t, CArr1 q, CArr1 qd, CMask active, unsigned need) {
                check_state(p, q.shape(0), qd.shape(0), active.shape(0));
                Terms out = p.make_terms();
                auto ws = p.make_workspace();
                const Status s = p.evaluate(t, q.data(), qd.data(), active.data(), need, out, *ws);
                if (s != Status::ok) raise_status(s, "Program.evaluate");
                return out;
            },
            nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("active"),
            nb::arg("need") = static_cast<unsigned>(NEED_ALL),
            "Evaluate into new Terms (convenience; evaluate_into reuses its buffers).")
        .def(
            "evaluate_batch",
            [](const Program& p, CArr1 t, CArr2 q, CArr2 qd, CMask active, unsigned need, int nthreads) {
                const std::size_t N = t.shape(0);
                const auto n = static_cast<std::size_t>(p.n());
                const auto m = static_cast<std::size_t>(p.m_all());
                const auto k = static_cast<std::size_t>(p.k());
                if (q.shape(0) != N || qd.shape(0) != N)
                    raise_error("ShapeError", "t, q and qd must have the same number of states (rows)");
                check_state(p, q.shape(1), qd.shape(1), active.shape(0));
                nb::dict res;
                NpArr M, h, fp, B, A, g, ph, v, T, V;
                if (need & NEED_M) M = new_array({N, n, n});
                if (need & NEED_H) {
                    h = new_array({N, n});
                    fp = new_array({N, n});
                }
                if (need & NEED_B) B = new_array({N, n, k});
                if (need & NEED_A) A = new_array({N, m, n});
                if (need & NEED_GAMMA) g = new_array({N, m});
                if (need & NEED_PHI) ph = new_array({N, m});
                if (need & NEED_VELOCITY) v = new_array({N, m});
                if (need & NEED_ENERGY) {
                    T = new_array({N});
                    V = new_array({N});
                }
                std::vector<int> status(N, 0);
                auto run = [&](std::size_t lo, std::size_t hi) {
                    Terms out = p.make_terms();
                    auto ws = p.make_workspace();
                    for (std::size_t i = lo; i < hi; ++i) {
                        const Status st = p.evaluate(t.data()[i], q.data() + i * n, qd.data() + i * n,
                                                     active.data(), need, out, *ws);
                        if (st != Status::ok) {
                            status[i] = static_cast<int>(st);
                            return;
                        }
                        auto put = [](NpArr& dst, const double* src, std::size_t len, std::size_t i_) {
                            std::memcpy(dst.data() + i_ * len, src, len * sizeof(double));
                        };
                        if (need & NEED_M) put(M, out.M.data(), n * n, i);
                        if (need & NEED_H) {
                            put(h, out.h.data(), n, i);
                            put(fp, out.f_passive.data(), n, i);
                        }
                        if (need & NEED_B) put(B, out.B.data(), n * k, i);
                        if (need & NEED_A) put(A, out.A.data(), m * n, i);
                        if (need & NEED_GAMMA) put(g, out.gamma.data(), m, i);
                        if (need & NEED_PHI) put(ph, out.phi.data(), m, i);
                        if (need & NEED_VELOCITY) put(v, out.velocity.data(), m, i);
                        if (need & NEED_ENERGY) {
                            T.data()[i] = out.kinetic;
                            V.data()[i] = out.potential;
                        }
                    }
                };
                if (p.thread_safe()) {
                    const std::size_t T =
                        std::max<std::size_t>(1, std::min<std::size_t>(static_cast<std::size_t>(std::max(nthreads, 1)), N));
                    nb::gil_scoped_release release;
                    std::vector<std::thread> pool;
                    for (std::size_t c = 1; c < T; ++c) pool.emplace_back(run, (c * N) / T, ((c + 1) * N) / T);
                    run(0, N / T);
                    for (auto& th : pool) th.join();
                } else {
                    run(0, N);
                }
                for (std::size_t i = 0; i < N; ++i)
                    if (status[i] != 0)
                        raise_status(static_cast<Status>(status[i]),
                                     "Program.evaluate_batch (state " + std::to_string(i) + ")");
                if (need & NEED_M) res["M"] = M;
                if (need & NEED_H) {
                    res["h"] = h;
                    res["f_passive"] = fp;
                }
                if (need & NEED_B) res["B"] = B;
                if (need & NEED_A) res["A"] = A;
                if (need & NEED_GAMMA) res["gamma"] = g;
                if (need & NEED_PHI) res["phi"] = ph;
                if (need & NEED_VELOCITY) res["velocity"] = v;
                if (need & NEED_ENERGY) {
                    res["kinetic"] = T;
                    res["potential"] = V;
                }
                return res;
            },
            nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("active"),
            nb::arg("need") = static_cast<unsigned>(NEED_ALL), nb::arg("nthreads") = 1,
            "Evaluate N states (t: (N,), q, qd: (N, n)) under one active set; a dict of stacked "
            "arrays (rows of inactive constraints are zero). On nthreads threads with the GIL "
            "released when the program is thread safe (one thread otherwise).");
}

}  // namespace nonmin::bindings
