// Bindings of the core layer (solver.hpp): the single-state and batched projection-dynamics
// solve used by nonmin.core (forward_dynamics, constraint_force, solve_dynamics) and the
// minimum-norm solve. Thin: arrays in and out without copies; shapes are checked here and a
// status other than ok is returned as None, on which the Python layer re-runs the NumPy
// reference path, which raises the typed error with its message.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

#include <algorithm>
#include <memory>
#include <thread>
#include <vector>

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

// what: 0 q̈, 1 f_c, 2 (q̈, f_c, P, L, rank, μ), 3 (q̈, rank). None when not ok (or shapes).
nb::object solve_one(In M, In h, In A, In gamma, std::optional<In> f, double mu, double rtol,
                     double spd_rtol, double sym_rtol, int what) {
    if (M.ndim() != 2 || h.ndim() != 1 || A.ndim() != 2 || gamma.ndim() != 1) return nb::none();
    const int n = static_cast<int>(h.shape(0));
    const int m = static_cast<int>(A.shape(0));
    if (n == 0 || M.shape(0) != static_cast<size_t>(n) || M.shape(1) != static_cast<size_t>(n) ||
        A.shape(1) != static_cast<size_t>(n) || gamma.shape(0) != static_cast<size_t>(m))
        return nb::none();
    if (f && (f->ndim() != 1 || f->shape(0) != static_cast<size_t>(n))) return nb::none();
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
        if (info.status != Status::ok) return nb::none();
        NpOut<nb::ndim<1>> qa(q, {un}, own);
        if (what == 0) return nb::cast(qa);
        return nb::make_tuple(qa, info.rank);
    }
    if (what == 1) {
        nb::capsule own;
        double* buf = fresh(2 * un, own);
        const SolveInfo info =
            s.forward(M.data(), g, A.data(), m, gamma.data(), opt, buf + n, buf);
        if (info.status != Status::ok) return nb::none();
        return nb::cast(NpOut<nb::ndim<1>>(buf, {un}, own));
    }
    nb::capsule o1, o2, o3, o4;
    double* q = fresh(un, o1);
    double* fc = fresh(un, o2);
    double* P = fresh(un * un, o3);
    double* L = fresh(un * un, o4);
    const SolveInfo info = s.solve(M.data(), g, A.data(), m, gamma.data(), opt, q, fc, P, L);
    if (info.status != Status::ok) return nb::none();
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

}  // namespace

void bind_core(nb::module_& m) {
    m.def("core_solve_one", &solve_one, nb::arg("M"), nb::arg("h"), nb::arg("A"),
          nb::arg("gamma"), nb::arg("f").none(), nb::arg("mu"), nb::arg("rtol"),
          nb::arg("spd_rtol"), nb::arg("sym_rtol"), nb::arg("what"),
          "One state of the projection dynamics (nonmin.core.solve_dynamics); None if the state "
          "is not regular (the caller re-runs the NumPy path for the typed error).");
    m.def("core_solve_batch", &solve_batch, nb::arg("M"), nb::arg("h"), nb::arg("f").none(),
          nb::arg("A"), nb::arg("gamma"), nb::arg("mu").none(), nb::arg("sM"), nb::arg("sh"),
          nb::arg("sf"), nb::arg("sA"), nb::arg("sg"), nb::arg("smu"), nb::arg("N"),
          nb::arg("n"), nb::arg("m"), nb::arg("rtol"), nb::arg("spd_rtol"), nb::arg("sym_rtol"),
          nb::arg("qdd"), nb::arg("fc"), nb::arg("P"), nb::arg("L"), nb::arg("status"),
          nb::arg("rank"), nb::arg("mu_out"), nb::arg("ratio"), nb::arg("nthreads"),
          "A batch of states (flat buffers with batch strides, 0 = broadcast), threaded.");
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
