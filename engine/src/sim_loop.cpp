// The engine's simulation loop (see nonmin/sim/loop.hpp): evaluation and gathering of the
// active rows, the drift-aware rank tolerance, the right-hand side, the sample evaluation with
// its diagnostics, the mass-metric projection and the stepping driver (the integrators are in
// sim_integrators.cpp, declared in sim_detail.hpp).
// Each function names the Python function it mirrors; the order of the decisions is theirs.
#include "nonmin/sim/loop.hpp"
#include "nonmin/sim/events.hpp"
#include "nonmin/linalg.hpp"
#include "sim_detail.hpp"

#include <algorithm>
#include <mutex>
#include <cmath>

namespace nonmin::sim {

using detail::adaptive;
using detail::clip;
using detail::dp_dense;
using detail::dp_step;
using detail::dp_advance;
using detail::d8_advance;
using detail::d8_dense;
using detail::d8_dense_setup;
using detail::d8_step;
using detail::fixed_advance;

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();

// A run whose end lies within this fraction of the placed step from the predicted singular
// instant ends by interpolation (run(): end_star).
constexpr double PASSAGE_END_BAND = 0.05;

// A fixed step that starts within this fraction of a step of the grid t_grid + k·dt is on it
// (passage_align; _integrators.PASSAGE_ALIGN_RTOL).
constexpr double PASSAGE_ALIGN_RTOL = 1e-6;

// SingularPassages.align: a fixed step that the placement left at dt, with no predicted
// instant ahead, ends on the grid t_grid + k·dt when its start is off it (a placed or widened
// step before, or an event, moved the steps off the grid): the step to the next grid point
// (≤ dt). Output samples on that grid (t_eval every dt, or a multiple of it) then fall on step
// ends again instead of inside every step, where each costs a projection and an evaluation more.
double passage_align(const Loop& L, double t, double h, double hp) {
    if (!L.opt.passages || hp != h || !(h > 0.0) || !std::isfinite(L.opt.t_grid)) return hp;
    if (L.pas.have_star && L.pas.t_star > t) return hp;
    const double r = (t - L.opt.t_grid) / h;
    const double k = std::floor(r);
    if (r - k <= PASSAGE_ALIGN_RTOL || (k + 1.0) - r <= PASSAGE_ALIGN_RTOL) return hp;
    return (L.opt.t_grid + (k + 1.0) * h) - t;
}

// The Solver's Known bits for a constant M (solver.hpp), by the checks its forward call makes:
// every entry finite, max|M − Mᵀ| ≤ sym_rtol · max|M|; diagonal when every off-diagonal entry is
// 0. An M that fails gets 0 (the solver checks it and reports the failure at each call).
// Row by row first (finite, max|M|, diagonal): a diagonal M has M − Mᵀ = 0 exactly, so only a
// full M compares M(i, j) with M(j, i), over the lower triangle (|a − b| = |b − a|) in tiles
// that stay in cache (A02 N = 80: M is 483 × 483, 1.8 MB; the column-order reads of the
// whole matrix missed the cache on every entry, once per simulate call). The same bits as the
// one pass over every (i, j).
unsigned mass_known(const Mat& M, double sym_rtol) {
    const int n = static_cast<int>(M.rows());
    double scale = 0.0;
    bool diagonal = true;
    for (int i = 0; i < n; ++i) {
        const double* Mi = M.data() + static_cast<std::ptrdiff_t>(i) * n;
        for (int j = 0; j < n; ++j) {
            const double v = Mi[j];
            if (!std::isfinite(v)) return 0u;
            scale = std::max(scale, std::fabs(v));
            if (i != j && v != 0.0) diagonal = false;
        }
    }
    double asym = 0.0;
    if (!diagonal) {
        constexpr int TILE = 32;
        for (int i0 = 0; i0 < n; i0 += TILE)
            for (int j0 = 0; j0 <= i0; j0 += TILE)
                for (int i = i0; i < std::min(i0 + TILE, n); ++i)
                    for (int j = j0; j < std::min({j0 + TILE, n, i}); ++j)
                        asym = std::max(asym, std::fabs(M(i, j) - M(j, i)));
    }
    if (asym > sym_rtol * std::max(scale, std::numeric_limits<double>::min())) return 0u;
    return KNOWN_M_VALID | (diagonal ? KNOWN_M_DIAGONAL : 0u);
}

bool finite(const double* x, int len) {
    for (int i = 0; i < len; ++i)
        if (!std::isfinite(x[i])) return false;
    return true;
}

double base_rtol(const Options& o) { return o.rank_rtol > 0.0 ? o.rank_rtol : DEFAULT_RTOL; }

// Projection.velocity_rank_rtol(rtol) (None → the core default)
double velocity_rtol(const Options& o, const ProjectionOptions& po) {
    if (po.velocity_rtol <= 0.0) return base_rtol(o);
    return std::max(po.velocity_rtol, o.rank_rtol > 0.0 ? o.rank_rtol : 0.0);
}

SolveOptions solve_options(const Loop& L, double rtol, const std::vector<int>* pst = nullptr,
                           const std::vector<int>* pco = nullptr, unsigned known = 0) {
    SolveOptions so;
    so.rtol = rtol;
    so.spd_rtol = L.opt.spd_rtol;
    so.sym_rtol = L.opt.sym_rtol;
    so.known = known;
    if (pst && !pst->empty() && !L.gathered.empty() && L.gathered == L.rows) {  // A's known pattern
        so.a_start = pst->data();
        so.a_cols = pco->data();
    }
    return so;
}

// _stabilization._correction: Δ = Sᵀ(−A⁺r) = forward dynamics with zero force and bias r.
// A: L.Ac (its m rows) or L.Alin (the m_hol position-level rows), with their known pattern.
Status correction(Loop& L, const Mat& A, int m, const double* r, double rtol, double* out, int* rank) {
    L.vheld = false;
    L.nheld = false;
    const bool hol = &A == &L.Alin;
    // the metric's Known bits: the identity, or the constant M validated once (m_known)
    const unsigned known = L.mq == 1 ? KNOWN_M_VALID | KNOWN_M_DIAGONAL : L.mq == 2 ? L.m_known : 0u;
    const SolveOptions so = hol ? solve_options(L, rtol, &L.ph_start, &L.ph_cols, known)
                                : solve_options(L, rtol, &L.pc_start, &L.pc_cols, known);
    const SolveInfo info = L.solver.forward(L.Mq.data(), L.zero_n.data(), A.data(), m, r, so, out, nullptr);
    L.lq_full = info.status == Status::ok && info.method != 0 && info.rank == m;
    if (hol) {  // (a position correction: its factorization may serve the velocity step, Solver::near)
        L.pfull = L.lq_full && info.null_space_form && m == L.m;
        L.plq = L.lq_full;
        L.pgen = L.solver.generation();
        L.prtol = rtol;
    }
    if (rank) *rank = info.rank;
    if (info.status != Status::ok) return info.status;
    return Status::ok;
}

// Solver::near pays only with many rows: below this count (the dense certified LQ) a fresh
// factorization is cheaper than near()'s refinement passes (callgrind, crossed four-bar 2 s
// RK4 dt 1e-2: 39.08M Ir fresh, 42.25M with near(); A02 N = 40, 242 rows, 0.5 s dt 2e-2:
// 139.16M fresh, 118.67M with near()).
constexpr int NEAR_MIN_ROWS = 33;

// Solver::forward at the evaluation just made at (t, q) (M = T.M, A = Ac, g, bias), or
// Solver::again on the velocity correction's factorization when it was taken at this (t, q)
// with the same M and rank tolerance (or a larger one, when it was a certified LQ of every
// row: Loop::vlq): A is a function of (t, q), so the factorization is this A's (certified LQ:
// bitwise the fresh result).
SolveInfo dynamics_solve(Loop& L, double t, const double* q, double rtol, double* qdd, double* fc) {
    if (L.nheld && L.solver.generation() == L.pgen && t == L.vt && rtol <= L.prtol &&
        (L.prog->constant_mass() || L.Mq == L.T.M)) {  // the velocity step's near() at this (t, q)
        bool same = true;
        for (int i = 0; i < L.n && same; ++i) same = q[i] == L.vq[i];
        if (same) {
            const SolveInfo info = L.solver.near(
                L.T.M.data(), L.g.data(), L.Ac.data(), L.m, L.bias.data(),
                solve_options(L, rtol, &L.pc_start, &L.pc_cols, L.m_held ? L.m_known : 0u), true, qdd, fc);
            if (info.status == Status::ok) return info;
        }
    }
    L.nheld = false;
    if (L.vheld && L.solver.generation() == L.vgen && t == L.vt && L.solver.held() &&
        (rtol == L.vrtol || (L.vlq && rtol <= L.vrtol))) {
        bool same = true;
        for (int i = 0; i < L.n && same; ++i) same = q[i] == L.vq[i];
        if (same && (L.prog->constant_mass() || L.Mq == L.T.M))
            return L.solver.again(L.T.M.data(), L.g.data(), L.bias.data(), qdd, fc);
    }
    L.vheld = false;
    return L.solver.forward(L.T.M.data(), L.g.data(), L.Ac.data(), L.m, L.bias.data(),
                            solve_options(L, rtol, &L.pc_start, &L.pc_cols, L.m_held ? L.m_known : 0u), qdd, fc);
}

}  // namespace

void Samples::clear() {
    for (auto* v : {&t, &q, &qd, &qdd, &f_c, &u, &cond, &mu, &energy, &phi_norm, &vel_norm, &fr_work, &work}) v->clear();
    rank.clear();
    active.clear();
}

namespace {

// The workspace of the last loop destroyed (its solver, whose scratch is O(m n + m² + n²), its
// terms and its m × n and n × n matrices), taken by the next make_loop of the same sizes: a run after
// another does not allocate and zero them afresh (A02 N = 80, 483 coordinates and 482 rows:
// ~70 MB, whose page faults and zeroing took ~36 ms of every simulate call against ~30 ms for
// its 25 RK4 steps at dt 1e-2). Results do not depend on it: a Solver's results depend only
// on its inputs (its scratch invariants, e.g. B zero between calls, hold after every call; a
// resumed run is bitwise the uninterrupted one), the loop's matrices are zeroed as when
// allocated or are written before they are read (A's gathered rows, the linearization, the
// projection's M; the indicator's scratch, passage_setup). One spare at most; a loop of other
// sizes frees it before allocating its own.
struct Spare {
    int m_max = -1, n = -1;
    std::unique_ptr<Solver> solver;
    Terms T;
    Mat Ac, Ah, Alin, Mq, L;
    Mat pB, pG, pC;               // the indicator's B, G, C
    std::vector<int> pcol_rows;  // and its column lists
};
std::mutex spare_mutex;
Spare spare;

Spare take_spare(int m_max, int n) {
    Spare s;
    std::lock_guard<std::mutex> lock(spare_mutex);
    if (spare.solver && spare.m_max == m_max && spare.n == n) s = std::move(spare);
    spare = Spare{};
    return s;
}

// dst = an r × c matrix: from's storage as it is when it has that shape (a matrix written
// before it is read), else a zero one
void reused(Mat& dst, Mat& from, int r, int c) {
    if (from.rows() == r && from.cols() == c)
        dst.swap(from);
    else
        dst = Mat::Zero(r, c);
}

// dst = the zero r × c matrix, in from's storage when it has that shape
void zeroed(Mat& dst, Mat& from, int r, int c) {
    reused(dst, from, r, c);
    dst.setZero();
}

}  // namespace

std::unique_ptr<Loop> make_loop(const Program& prog, const std::uint8_t* active, const Options& opt,
                                const std::vector<double>& t_out, bool every, Controller* ctrl) {
    const int n = prog.n(), m_all = prog.m_all();
    const int mr = std::max(m_all, 1);
    Spare got = take_spare(mr, n);
    auto Lp = got.solver ? std::make_unique<Loop>(std::move(*got.solver)) : std::make_unique<Loop>(mr, n);
    Loop& L = *Lp;
    L.prog = &prog;
    L.ctrl = ctrl;
    L.opt = opt;
    L.ws = prog.make_workspace();
    for (const ConstraintInfo& c : prog.constraints())
        if (c.kind == ConstraintKind::rheonomic || c.kind == ConstraintKind::nonholonomic) L.wk_fc = true;
    if (got.solver && got.T.M.rows() == n && got.T.B.cols() == prog.k() && got.T.A.rows() == m_all) {
        L.T = std::move(got.T);  // (resize: make_terms' zeros in the same storage)
        L.T.resize(n, prog.k(), m_all);
        L.T.kinetic = L.T.potential = 0.0;
    } else {
        L.T = prog.make_terms();
    }
    L.n = n;
    L.k = prog.k();
    L.m_all = m_all;
    const auto& cons = prog.constraints();
    L.c = static_cast<int>(cons.size());
    L.active.assign(active, active + L.c);
    for (const ConstraintInfo& ci : cons) {
        if (!L.active[&ci - cons.data()]) continue;
        L.any_active = true;
        for (int r = 0; r < ci.dim; ++r) {
            L.rows.push_back(ci.row + r);
            L.hol.push_back(ci.kind != ConstraintKind::nonholonomic);
        }
    }
    L.m = static_cast<int>(L.rows.size());
    L.m_hol = static_cast<int>(std::count(L.hol.begin(), L.hol.end(), 1));
    // (A's active rows are gathered in full at the first evaluation of A, and the
    // linearization copied in full from them: rows are written before they are read)
    reused(L.Ac, got.Ac, mr, n);
    reused(L.Ah, got.Ah, mr, n);
    reused(L.Alin, got.Alin, mr, n);
    for (Vec* v : {&L.gam, &L.phi, &L.vel, &L.phih, &L.bias, &L.floor_, &L.rnorm}) *v = Vec::Zero(mr);
    for (Vec* v : {&L.g, &L.qdd, &L.fc, &L.zero_n, &L.aq, &L.dq, &L.vq, &L.ev_q}) *v = Vec::Zero(n);
    L.ev_strip = prog.constraint_terms_on_request();
    L.u = Vec::Zero(L.k);
    reused(L.Mq, got.Mq, n, n);  // (assigned in full by the projection: M or I)
    zeroed(L.L, got.L, n, n);
    for (Vec* v : {&L.y, &L.f, &L.y0, &L.f0, &L.y1, &L.yq1, &L.ys, &L.yp, &L.fp1, &L.tmp2n, &L.k1, &L.k2,
                   &L.k3, &L.k4, &L.kn, &L.ev, &L.d_ydiff, &L.d_bspl, &L.d_r3, &L.d_r4})
        *v = Vec::Zero(2 * n);
    L.K = Mat::Zero(7, 2 * n);
    if (opt.method == Method::dop853 || opt.method == Method::rk8) {
        L.K8 = Mat::Zero(16, 2 * n);
        L.F8 = Mat::Zero(7, 2 * n);
        L.e3 = Vec::Zero(2 * n);
    }
    L.half.assign(static_cast<std::size_t>(std::max(opt.max_halvings, 0)) + 1, Vec::Zero(2 * n));
    for (Point* p : {&L.p1, &L.ps}) {
        p->q = p->qd = p->qdd = p->f_c = Vec::Zero(n);
        p->u = Vec::Zero(L.k);
    }
    L.svd = Svd(n, n);  // singular values only
    L.t_out = t_out;
    L.every = every;
    L.rec.n = n;
    L.rec.k = L.k;
    L.rec.c = L.c;
    // the indicator's B, G, C and column lists are written before they are read (passage_setup
    // sizes the rest of its scratch)
    reused(L.pas.B, got.pB, mr, n);
    reused(L.pas.G, got.pG, mr, mr);
    reused(L.pas.C, got.pC, mr, mr);
    const std::size_t ncr = static_cast<std::size_t>(mr) * static_cast<std::size_t>(n);
    if (got.pcol_rows.size() == ncr)
        L.pas.col_rows.swap(got.pcol_rows);
    else
        L.pas.col_rows.assign(ncr, 0);
    passage_setup(L);
    L.spare_m = mr;
    if (ctrl) ctrl->attach(L.T, L.Ac, L.m, L.rows);
    return Lp;
}

Loop::~Loop() {
    if (spare_m < 0) return;
    Spare s;
    s.m_max = spare_m;
    s.n = n;
    s.solver = std::make_unique<Solver>(std::move(solver));
    s.T = std::move(T);
    s.Ac.swap(Ac);
    s.Ah.swap(Ah);
    s.Alin.swap(Alin);
    s.Mq.swap(Mq);
    s.L.swap(L);
    s.pB.swap(pas.B);
    s.pG.swap(pas.G);
    s.pC.swap(pas.C);
    s.pcol_rows.swap(pas.col_rows);
    std::lock_guard<std::mutex> lock(spare_mutex);
    spare = std::move(s);  // (the spare held before, if any, is freed)
}

// ------------------------------------------------------------------------------ evaluation

Status evaluate(Loop& L, double t, const double* q, const double* qd, unsigned need) {
    const std::uint8_t* mask = L.fric.empty() ? L.active.data() : L.eval_mask.data();  // + slipping rows
    const int n = L.n;
    // A and φ gathered at this very (t, q) for these rows (Loop::ev_ok): kept, bitwise the same
    bool same = false;
    if (L.ev_ok && (need & (NEED_A | NEED_PHI)) && t == L.ev_t && L.ev_gen == L.gather_gen && !L.ctrl &&
        L.fric.empty() && L.gathered == L.rows) {
        same = true;
        for (int i = 0; i < n && same; ++i) same = q[i] == L.ev_q[i];
    }
    unsigned pneed = L.m_held ? need & ~NEED_M : need;
    if (same) {
        need &= ~(NEED_A | NEED_PHI);
        if (L.ev_strip) pneed &= ~(NEED_A | NEED_PHI);
    }
    const Status s = L.prog->evaluate(t, q, qd, mask, pneed, L.T, *L.ws);
    if (s != Status::ok) {
        L.ev_ok = false;
        return s;
    }
    if ((need & NEED_M) && !L.m_held && L.prog->constant_mass()) {  // a constant M: kept, validated once
        L.m_held = true;
        L.m_known = mass_known(L.T.M, L.opt.sym_rtol);
    }
    const RowPattern& pat = L.prog->a_pattern();
    // A: the pattern's entries only, once the rows were gathered in full for this active set
    const bool sparse = (need & NEED_A) && pat.known() && L.gathered == L.rows;
    if ((need & NEED_A) && !sparse) {  // a new active set: its rows in full, and their pattern
        L.gathered.clear();
        ++L.gather_gen;
        for (auto* v : {&L.pc_start, &L.pc_cols, &L.ph_start, &L.ph_cols}) v->clear();
        if (pat.known()) {
            L.gathered = L.rows;
            L.pc_start.push_back(0);
            L.ph_start.push_back(0);
            for (int i = 0; i < L.m; ++i) {
                const int r = L.rows[i];
                L.pc_cols.insert(L.pc_cols.end(), pat.row(r), pat.row(r) + pat.count(r));
                L.pc_start.push_back(static_cast<int>(L.pc_cols.size()));
                if (L.hol[i]) {
                    L.ph_cols.insert(L.ph_cols.end(), pat.row(r), pat.row(r) + pat.count(r));
                    L.ph_start.push_back(static_cast<int>(L.ph_cols.size()));
                }
            }
        }
    }
    const double* TA = L.T.A.data();
    const bool ah = L.m_hol != L.m;  // (every row holonomic: Ah's rows are Ac's, hol_rows)
    int ih = 0;
    for (int i = 0; i < L.m; ++i) {
        const int r = L.rows[i];
        if (sparse) {
            const int* cols = pat.row(r);
            const int e = pat.count(r);
            double* Aci = L.Ac.data() + static_cast<std::ptrdiff_t>(i) * n;
            const double* Ar = TA + static_cast<std::ptrdiff_t>(r) * n;
            for (int t = 0; t < e; ++t) Aci[cols[t]] = Ar[cols[t]];
            if (ah && L.hol[i]) {
                double* Ahi = L.Ah.data() + static_cast<std::ptrdiff_t>(ih) * n;
                for (int t = 0; t < e; ++t) Ahi[cols[t]] = Ar[cols[t]];
            }
        } else if (need & NEED_A) {
            L.Ac.row(i) = L.T.A.row(r);
            if (ah && L.hol[i]) L.Ah.row(ih) = L.T.A.row(r);
        }
        if (need & NEED_GAMMA) L.gam[i] = L.T.gamma[r];
        if (need & NEED_PHI) L.phi[i] = L.T.phi[r];
        if (need & NEED_VELOCITY) L.vel[i] = L.T.velocity[r];
        if (L.hol[i]) {
            if (need & NEED_PHI) L.phih[ih] = L.T.phi[r];
            ++ih;
        }
    }
    if ((need & NEED_A) && (need & NEED_PHI)) {  // A and φ at (t, q) now
        L.ev_ok = true;
        L.ev_t = t;
        L.ev_gen = L.gather_gen;
        for (int i = 0; i < n; ++i) L.ev_q[i] = q[i];
    } else if (need & (NEED_A | NEED_PHI)) {  // one of them at another (t, q)
        L.ev_ok = false;
    }
    return Status::ok;
}

namespace {
// Whether Ah (and Ac) hold the gathered rows of the current active set with their pattern
bool hol_pattern(const Loop& L) { return !L.gathered.empty() && L.gathered == L.rows; }
// The m_hol position-level rows of A: Ah, or Ac itself when every active row is holonomic
// (evaluate() then gathers Ac alone; the same rows in the same order)
const Mat& hol_rows(const Loop& L) { return L.m_hol == L.m ? L.Ac : L.Ah; }
}  // namespace

// _simulate.drift_rank_rtol over the gathered A and φ (position-level rows)
double drift_rank_rtol(Loop& L) {
    const double base = base_rtol(L.opt);
    if (L.m == 0 || L.m_hol == 0) return base;
    double big = 0.0;
    const bool pat = hol_pattern(L);
    const Mat& Ah = hol_rows(L);
    for (int i = 0; i < L.m_hol; ++i) {
        double s = 0.0;
        if (pat)  // the pattern's entries, in the same order (the others add zeros)
            for (int t = L.ph_start[i]; t < L.ph_start[i + 1]; ++t) s += Ah(i, L.ph_cols[t]) * Ah(i, L.ph_cols[t]);
        else
            for (int j = 0; j < L.n; ++j) s += Ah(i, j) * Ah(i, j);
        const double nr = std::sqrt(s);
        L.rnorm[i] = nr;
        big = std::max(big, nr);
    }
    bool any = false;
    double drift = 0.0;
    for (int i = 0; i < L.m_hol; ++i) {
        const double nr = L.rnorm[i];
        if (nr > base * big) {
            any = true;
            drift = std::max(drift, std::abs(L.phih[i]) / nr);
        }
    }
    if (!any) return base;
    return std::min(std::max(base, L.opt.drift_factor * drift), DRIFT_RTOL_CAP);
}

namespace {

// _System._forces (g = h + f_passive + B u) and the stabilization's bias (Stabilization.bias).
Status forces_and_bias(Loop& L, double t, const double* q, const double* qd) {
    const int n = L.n;
    for (int i = 0; i < n; ++i) L.g[i] = L.T.h[i] + L.T.f_passive[i];
    if (L.ctrl) {
        const Status s = L.ctrl->control(t, q, qd, L.active.data(), L.u.data());
        if (s != Status::ok) return s;
        for (int i = 0; i < n; ++i) {
            double bu = 0.0;
            for (int j = 0; j < L.k; ++j) bu += L.T.B(i, j) * L.u[j];
            L.g[i] += bu;
        }
    } else if (L.k) {
        L.u.setZero();
    }
    if (L.opt.stab == Stabilization::baumgarte) {
        const double a2 = 2.0 * L.opt.alpha, b2 = L.opt.beta * L.opt.beta;
        for (int i = 0; i < L.m; ++i) L.bias[i] = L.gam[i] + a2 * L.vel[i] + b2 * L.phi[i];
    } else {
        for (int i = 0; i < L.m; ++i) L.bias[i] = L.gam[i];
    }
    return Status::ok;
}

unsigned dyn_need(const Loop& L) {
    unsigned need = NEED_M | NEED_H | NEED_A | NEED_GAMMA | NEED_PHI;
    if (L.opt.stab == Stabilization::baumgarte) need |= NEED_VELOCITY;
    if (L.ctrl) need |= NEED_B | L.ctrl->need();
    return need;
}

}  // namespace

// _System.rhs: F(t, y) = (qd, qdd)
Status rhs(Loop& L, double t, const double* y, double* out) {
    const int n = L.n;
    const double* q = y;
    const double* qd = y + n;
    ++L.n_rhs;
    Status s = evaluate(L, t, q, qd, dyn_need(L));
    if (s != Status::ok) return s;
    s = forces_and_bias(L, t, q, qd);
    if (s != Status::ok) return s;
    const double rtol = drift_rank_rtol(L);
    const bool fr = !L.fric.empty();
    const SolveInfo info = dynamics_solve(L, t, q, rtol, L.qdd.data(), fr ? L.fc.data() : nullptr);
    if (info.status != Status::ok) return info.status;
    if (fr && (s = friction_forces(L, t, qd, L.qdd.data(), L.fc.data())) != Status::ok) return s;
    if (!finite(L.qdd.data(), n)) return Status::not_finite;
    for (int i = 0; i < n; ++i) {
        out[i] = qd[i];
        out[n + i] = L.qdd[i];
    }
    L.wk_P = work_power(L, qd, L.qdd.data());
    return Status::ok;
}

// q̇ᵀ(B u + f_passive) = q̇ᵀ(g − h) (L.g of the evaluation just made); with rheonomic (or
// nonholonomic) constraints, whose forces work, q̇ᵀ(B u + f_passive + f_c) = q̇ᵀ(M q̈ − h)
// (M q̈ = h + f_passive + B u + f_c) less the friction forces' power (their work is W_fr,
// recorded apart). Scleronomic constraint forces do no work on the manifold (A q̇ = 0): their
// power at a stage state off it (O(h²) there) is the integrator's error, not work, and is left
// to the drift. O(n) or O(n²), no evaluation.
double work_power(const Loop& L, const double* qd, const double* qdd) {
    const int n = L.n;
    double p = 0.0;
    if (!L.wk_fc) {
        for (int i = 0; i < n; ++i) p += qd[i] * (L.g[i] - L.T.h[i]);
        return p;
    }
    for (int i = 0; i < n; ++i) {
        double mi = -L.T.h[i];
        for (int j = 0; j < n; ++j) mi += L.T.M(i, j) * qdd[j];
        p += qd[i] * mi;
    }
    return L.fric.empty() ? p : p - L.fr_power;
}

// the cubic Hermite interpolant of W on the step being recorded (W and its derivative, the
// power, at both ends): exact at the ends, O(h⁴) inside
double work_at(const Loop& L, double t) {
    if (!L.wk_on) return L.wk;
    const double u = std::clamp((t - L.wk_t0) / L.wk_h, 0.0, 1.0);
    if (u == 1.0) return L.wk_W1;
    if (u == 0.0) return L.wk_W0;
    const double u2 = u * u, u3 = u2 * u;
    return (2.0 * u3 - 3.0 * u2 + 1.0) * L.wk_W0 + (u3 - 2.0 * u2 + u) * L.wk_h * L.wk_P0 +
           (-2.0 * u3 + 3.0 * u2) * L.wk_W1 + (u3 - u2) * L.wk_h * L.wk_P1;
}

// _System.point (and the diagnostics _Recorder.add derives from it)
Status point(Loop& L, double t, const double* q, const double* qd, Point& p, bool diagnostics) {
    const int n = L.n;
    ++L.n_rhs;
    Status s = evaluate(L, t, q, qd, dyn_need(L) | NEED_VELOCITY | NEED_ENERGY);
    if (s != Status::ok) return s;
    s = forces_and_bias(L, t, q, qd);
    if (s != Status::ok) return s;
    const double rtol = drift_rank_rtol(L);
    const SolveInfo info = dynamics_solve(L, t, q, rtol, p.qdd.data(), p.f_c.data());
    if (info.status != Status::ok) return info.status;
    if (!L.fric.empty() && (s = friction_forces(L, t, qd, p.qdd.data(), p.f_c.data())) != Status::ok) return s;
    if (!finite(p.qdd.data(), n)) return Status::not_finite;
    p.t = t;
    p.fr_power = L.fric.empty() ? 0.0 : L.fr_power;
    p.power = work_power(L, qd, p.qdd.data());
    p.work = std::numeric_limits<double>::quiet_NaN();
    for (int i = 0; i < n; ++i) {
        p.q[i] = q[i];
        p.qd[i] = qd[i];
    }
    p.u = L.u;
    p.rank = info.rank;
    p.mu = info.mu;
    p.energy = L.T.kinetic + L.T.potential;
    double pn = 0.0, vn = 0.0;
    for (int i = 0; i < L.m_hol; ++i) pn = std::max(pn, std::abs(L.phih[i]));
    for (int i = 0; i < L.m; ++i) vn = std::max(vn, std::abs(L.vel[i]));
    p.phi_norm = pn;
    p.vel_norm = vn;
    if (diagnostics) {  // cond(M̄): from S in the null-space form, else (σ_max(L)/σ_min(L))²
        p.cond = L.solver.cond_mbar();
        if (std::isnan(p.cond) && L.solver.mbar_factor(L.L.data())) {
            L.svd.compute(L.L);
            const auto& sv = L.svd.singularValues();
            const double r = sv[0] / sv[n - 1];
            p.cond = r * r;
        }
    } else {
        p.cond = std::numeric_limits<double>::quiet_NaN();
    }
    return Status::ok;
}

namespace {

void record(Loop& L, const Point& p, double t) {
    Samples& R = L.rec;
    R.t.push_back(t);
    R.q.insert(R.q.end(), p.q.data(), p.q.data() + L.n);
    R.qd.insert(R.qd.end(), p.qd.data(), p.qd.data() + L.n);
    R.qdd.insert(R.qdd.end(), p.qdd.data(), p.qdd.data() + L.n);
    R.f_c.insert(R.f_c.end(), p.f_c.data(), p.f_c.data() + L.n);
    R.u.insert(R.u.end(), p.u.data(), p.u.data() + L.k);
    R.active.insert(R.active.end(), L.active.begin(), L.active.end());
    R.rank.push_back(p.rank);
    R.cond.push_back(p.cond);
    R.mu.push_back(p.mu);
    R.energy.push_back(p.energy);
    R.phi_norm.push_back(p.phi_norm);
    R.vel_norm.push_back(p.vel_norm);
    R.fr_work.push_back(friction_work_at(L, t));
    R.work.push_back(std::isnan(p.work) ? work_at(L, t) : p.work);
}

}  // namespace

// ------------------------------------------------------------------------------ projection

namespace {

// The velocity correction Δq̇ = Sᵀ(−A⁺ A q̇) on the factorization the position correction just
// made (Solver::again: O(mn + n²) instead of a factorization), when that is the fresh result
// to round-off: a program whose M varies (a constant M keeps the factorization of A(q) for the
// next dynamics solve instead: dynamics_solve), every active row holonomic (the factorization's
// rows are L.Ac's, at the linearization point q_lin instead of q), a certified LQ of full rank
// at a tolerance ≥ vr (then its rank at vr is the same, and the solve bitwise the fresh one's
// for those rows), and the rows moved by ‖A(q) − A(q_lin)‖_max ≤ eps ‖A‖_max ‖q̇‖_∞ / ‖Δq̇‖_∞:
// the projection along the old rows differs from the new one by O(‖ΔA‖/‖A‖ · ‖Δq̇‖), below the
// round-off of q̇ itself (the fresh solve's own error is eps·κ·‖q̇‖). Applies Δq̇ to qd and
// returns true; false (nothing changed) when a condition fails.
bool velocity_again(Loop& L, double vr, unsigned long long gen, bool lq_full, double pos_rtol, double* qd) {
    if (L.prog->constant_mass() || L.m_hol != L.m || !lq_full || pos_rtol < vr || !L.solver.held() ||
        L.solver.generation() != gen)
        return false;
    const int n = L.n, m = L.m;
    double da = 0.0, a = 0.0;
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < n; ++j) {
            da = std::max(da, std::abs(L.Ac(i, j) - L.Alin(i, j)));
            a = std::max(a, std::abs(L.Alin(i, j)));
        }
    if (!(da * 0.0 == 0.0) || !(a > 0.0)) return false;
    if (L.solver.again(L.Mq.data(), L.zero_n.data(), L.vel.data(), L.dq.data(), nullptr).status != Status::ok)
        return false;
    double dqn = 0.0, qdn = 0.0;
    for (int j = 0; j < n; ++j) {
        dqn = std::max(dqn, std::abs(L.dq[j]));
        qdn = std::max(qdn, std::abs(qd[j]));
    }
    if (!(da * dqn <= std::numeric_limits<double>::epsilon() * a * qdn)) return false;
    for (int j = 0; j < n; ++j) qd[j] = qd[j] + L.dq[j];
    return true;
}

}  // namespace

// Projection.project (mass or Euclidean metric), in place on y = (q, qd).
Status project(Loop& L, double t, double* y, const ProjectionOptions& po) {
    if (!L.any_active) return Status::ok;
    const int n = L.n;
    double* q = y;
    double* qd = y + n;
    Status s = evaluate(L, t, q, qd, NEED_M | NEED_A | NEED_PHI | NEED_VELOCITY);
    if (s != Status::ok) return s;
    if (po.euclidean) {
        if (L.mq != 1) L.Mq.setIdentity();
        L.mq = 1;
    } else if (!(L.m_held && L.mq == 2)) {  // (a constant M is copied once)
        L.Mq = L.T.M;  // M at the uncorrected q (the corrections are at the integrator's error)
        L.mq = L.m_held ? 2 : 0;
    }
    const int mh = L.m_hol;
    // a fresh position correction was made in this call: its factorization (Alin, Mq; L.pgen,
    // L.prtol, L.plq, L.pfull, set by correction()) may serve the velocity correction below
    bool pos_held = false;
    if (mh > 0) {
        double prev = inf;
        for (int j = 0; j < n; ++j) L.aq[j] = std::abs(q[j]);
        const double full = base_rtol(L.opt);
        double cut = std::max(POSITION_CUT_RTOL, full);
        bool have_lin = false;  // A of a last linearization is held
        bool fresh = false;     // the last step was a Gauss–Newton step
        int lin_count = 0;
        while (true) {
            double err = 0.0;
            for (int i = 0; i < mh; ++i) err = std::max(err, std::abs(L.phih[i]));
            if (err <= po.tol || err == 0.0) break;  // converged
            bool at_floor = true;
            const bool pat = hol_pattern(L);
            const Mat& Ah = hol_rows(L);
            for (int i = 0; i < mh; ++i) {
                double sa = 0.0;
                if (pat)  // the pattern's entries, in the same order (the others add zeros)
                    for (int t = L.ph_start[i]; t < L.ph_start[i + 1]; ++t)
                        sa += std::abs(Ah(i, L.ph_cols[t])) * L.aq[L.ph_cols[t]];
                else
                    for (int j = 0; j < n; ++j) sa += std::abs(Ah(i, j)) * L.aq[j];
                L.floor_[i] = ROUNDOFF_FLOOR * (1.0 + sa);
                if (!(std::abs(L.phih[i]) <= L.floor_[i])) at_floor = false;
            }
            if (at_floor) break;  // every row at its round-off level
            bool relin = !have_lin || cut == full;
            if (have_lin && err > (fresh ? 0.5 : CHORD_RATE) * prev) {
                if (fresh) {  // a Gauss–Newton step stalled
                    if (cut == full && err >= prev) break;  // round-off floor reached
                    cut = full;
                } else if (err > 0.5 * prev) {  // a chord step without real progress
                    cut = full;
                }
                relin = true;
            }
            if (relin) {
                if (lin_count >= po.max_iter) break;
                ++lin_count;
                if (hol_pattern(L) && L.alin_gen == L.gather_gen) {  // the pattern's entries (the others 0)
                    for (int i = 0; i < mh; ++i)
                        for (int t = L.ph_start[i]; t < L.ph_start[i + 1]; ++t)
                            L.Alin(i, L.ph_cols[t]) = Ah(i, L.ph_cols[t]);
                } else {
                    L.Alin.topRows(mh) = Ah.topRows(mh);
                    L.alin_gen = hol_pattern(L) ? L.gather_gen : ~0ull;
                }
                have_lin = true;
            }
            fresh = relin;
            prev = err;
            const double c2 = std::max(SINGULAR_CUT_RTOL, full);
            if (lin_count == 1 && fresh && cut > c2) {  // _stabilization._first_step
                int rank = 0;
                s = correction(L, L.Alin, mh, L.phih.data(), c2, L.dq.data(), &rank);
                if (s != Status::ok) return s;
                if (rank == mh) {  // no singular value below c2: the full-rank step
                    cut = c2;
                    pos_held = true;
                } else {  // next to a singular configuration: without the directions below the cut
                    cut = std::max(POSITION_CUT_RTOL, full);
                    s = correction(L, L.Alin, mh, L.phih.data(), cut, L.dq.data(), nullptr);
                    pos_held = true;
                }
            } else if (fresh) {
                s = correction(L, L.Alin, mh, L.phih.data(), cut, L.dq.data(), nullptr);
                pos_held = true;
            } else {  // a chord step: the last linearization's factorization, new residual
                s = L.solver.again(L.Mq.data(), L.zero_n.data(), L.phih.data(), L.dq.data(), nullptr).status;
            }
            if (s != Status::ok) return s;
            for (int j = 0; j < n; ++j) q[j] = q[j] + L.dq[j];
            s = evaluate(L, t, q, qd, NEED_A | NEED_PHI | NEED_VELOCITY);
            if (s != Status::ok) return s;
        }
    }
    if (po.velocity && L.m > 0) {
        const double vr = velocity_rtol(L.opt, po);
        // the position correction's last factorization (a certified LQ of every active row, at a
        // tolerance ≥ vr), refined to A at the corrected q (Solver::near: exact to round-off;
        // the dynamics at this (t, q) then reuse it too)
        bool near = false;
        if (L.m >= NEAR_MIN_ROWS && pos_held && mh == L.m && L.pfull && L.solver.generation() == L.pgen &&
            vr <= L.prtol) {
            const unsigned known = L.mq == 1 ? KNOWN_M_VALID | KNOWN_M_DIAGONAL : L.mq == 2 ? L.m_known : 0u;
            const SolveInfo info = L.solver.near(L.Mq.data(), L.zero_n.data(), L.Ac.data(), L.m, L.vel.data(),
                                                 solve_options(L, vr, &L.pc_start, &L.pc_cols, known), false,
                                                 L.dq.data(), nullptr);
            near = info.status == Status::ok;
        }
        if (near) {
            for (int j = 0; j < n; ++j) qd[j] = qd[j] + L.dq[j];
            L.nheld = !po.euclidean;  // (the Euclidean metric is not M)
            L.vheld = false;
            L.vt = t;
            L.vrtol = vr;
            for (int j = 0; j < n; ++j) L.vq[j] = q[j];
        } else if (pos_held && velocity_again(L, vr, L.pgen, L.plq, L.prtol, qd)) {
            L.vheld = false;  // (the factorization held is the position correction's A, not A(q))
            L.nheld = false;
        } else {
            s = correction(L, L.Ac, L.m, L.vel.data(), vr, L.dq.data(), nullptr);
            if (s != Status::ok) return s;
            for (int j = 0; j < n; ++j) qd[j] = qd[j] + L.dq[j];
            L.vheld = !po.euclidean;  // (the Euclidean metric is not M)
            L.vlq = L.lq_full;
            L.vgen = L.solver.generation();
            L.vt = t;
            L.vrtol = vr;
            for (int j = 0; j < n; ++j) L.vq[j] = q[j];
        }
    }
    if (std::isfinite(po.energy_level)) {  // _stabilization.energy_scale
        if ((s = L.prog->evaluate(t, q, qd, L.active.data(), NEED_ENERGY, L.T, *L.ws)) != Status::ok) return s;
        const double T = L.T.kinetic;
        if (T > 0.0) {
            const double a2 = (po.energy_level - L.T.potential) / T;
            if (std::abs(a2 - 1.0) <= ENERGY_MAX_CHANGE) {
                const double a = std::sqrt(a2);
                for (int j = 0; j < n; ++j) qd[j] *= a;
            }
        }
    }
    return Status::ok;
}

namespace {

// Stabilization.project for the run's stabilization (none and Baumgarte: no correction)
Status stab_project(Loop& L, double t, double* y) {
    if (L.opt.stab != Stabilization::projection) return Status::ok;
    return project(L, t, y, L.opt.projection);
}

// Stabilization.project_sample: a sample from a continuous extension, the velocity step's rank
// tolerance raised to SAMPLE_VELOCITY_RTOL (_stabilization.py)
Status stab_project_sample(Loop& L, double t, double* y) {
    if (L.opt.stab != Stabilization::projection) return Status::ok;
    ProjectionOptions po = L.opt.projection;
    po.velocity_rtol = std::max(velocity_rtol(L.opt, po), SAMPLE_VELOCITY_RTOL);
    return project(L, t, y, po);
}

// SingularPassages after a state reached elsewhere (resume, an event's transition): the
// history restarts with the indicator at (L.t, L.y) under the active set (as the driver's
// reset + observe)
void passage_restart(Loop& L) {
    passage_reset(L);
    if (L.opt.passages && L.any_active && evaluate(L, L.t, L.y.data(), L.y.data() + L.n, NEED_A) == Status::ok)
        passage_observe(L, L.t, L.Ac, L.m);
}

Outcome fail(Loop& L, Status s) {
    if (s == Status::callback_error) return Outcome::callback;
    if (L.message.empty()) L.message = "kernel status " + std::to_string(static_cast<int>(s));
    return Outcome::handover;
}

}  // namespace

// ------------------------------------------------------------------------------ for the event layer
// (the contact guards, their location and transitions: sim_events.cpp)

Status partial_step(Loop& L, double t, const Vec& y, const Vec* f, double s, Vec& out) {
    Status st;
    if (s <= 0.0) {
        out = y;
        L.wk_dW = 0.0;
    } else if (L.opt.method == Method::dop853) {
        if ((st = d8_advance(L, t, y, f, s, out)) != Status::ok) return st;
    } else if (adaptive(L)) {
        if ((st = dp_advance(L, t, y, f, s, out)) != Status::ok) return st;
    } else if ((st = fixed_advance(L, t, y, f, s, out)) != Status::ok) {
        return st;
    }
    return stab_project(L, t + s, out.data());
}

void record_sample(Loop& L, const Point& p, double t) { record(L, p, t); }

void dense_output(const Loop& L, double t0, double h, double tt, double* out) {
    if (L.opt.method == Method::dop853)
        d8_dense(L, tt, out);  // (set up by run() when a sample falls inside the step)
    else
        dp_dense(L, t0, h, tt, out);
}

Status stabilize(Loop& L, double t, double* y) { return stab_project(L, t, y); }

Status stabilize_sample(Loop& L, double t, double* y) { return stab_project_sample(L, t, y); }

// ------------------------------------------------------------------------------ driver

Outcome start(Loop& L, double t0, const double* q0, const double* qd0) {
    const int n = L.n;
    L.message.clear();
    for (int i = 0; i < n; ++i) {
        L.y[i] = q0[i];
        L.y[n + i] = qd0[i];
    }
    Status s;
    if (L.opt.project_initial && L.any_active) {
        const ProjectionOptions& po =
            L.opt.stab == Stabilization::projection ? L.opt.projection : L.opt.initial_projection;
        if ((s = project(L, t0, L.y.data(), po)) != Status::ok) return fail(L, s);
    }
    L.t = t0;
    L.wk_on = false;
    const bool rec0 = L.every || (!L.t_out.empty() && L.t_out[0] == t0);
    if ((s = point(L, t0, L.y.data(), L.y.data() + n, L.p1, rec0)) != Status::ok) return fail(L, s);
    if (rec0) record(L, L.p1, t0);
    friction_work_commit(L, L.p1);
    passage_reset(L);
    if (L.opt.passages) passage_observe(L, t0, L.Ac, L.m);  // A at the first point
    L.out_i = static_cast<std::size_t>(std::upper_bound(L.t_out.begin(), L.t_out.end(), t0) - L.t_out.begin());
    L.have_f = false;
    L.h = adaptive(L) ? L.opt.h0 : L.opt.dt;
    L.n_steps = 0;
    return Outcome::done;
}

void resume(Loop& L, double t, const double* y, double h, long long n_steps, std::size_t out_i) {
    for (int i = 0; i < 2 * L.n; ++i) L.y[i] = y[i];
    L.t = t;
    L.have_f = false;
    L.h = adaptive(L) ? h : L.opt.dt;
    L.n_steps = n_steps;
    L.out_i = out_i;
    L.message.clear();
    L.fw_have0 = L.fw_step = false;
    L.wk_on = false;
    passage_restart(L);  // a state reached elsewhere: the history starts afresh, from this state
}

void passage_seed(Loop& L, const double* ts, const double* ys, int k) {
    if (!L.opt.passages) return;
    passage_reset(L);
    const int n = L.n;
    for (int i = 0; i < k; ++i) {
        const double* y = ys + static_cast<std::ptrdiff_t>(2 * n) * i;
        if (evaluate(L, ts[i], y, y + n, NEED_A) == Status::ok) passage_observe(L, ts[i], L.Ac, L.m);
    }
    if (evaluate(L, L.t, L.y.data(), L.y.data() + n, NEED_A) == Status::ok) passage_observe(L, L.t, L.Ac, L.m);
}

Outcome run(Loop& L, long long max_steps) {
    const int n = L.n;
    const int n2 = 2 * n;
    const double t1 = L.opt.t1;
    const bool adapt = adaptive(L);
    const bool dop853 = L.opt.method == Method::dop853;
    const std::size_t n_out = L.t_out.size();
    L.message.clear();
    long long taken = 0;
    Status s;
    while (L.t < t1 && taken < max_steps) {
        if (L.n_steps >= L.opt.max_steps) {
            L.message = "max_steps reached";
            return Outcome::handover;
        }
        if (!L.have_f && !adapt && !L.every && L.out_i < n_out) {
            // F at the step start: the method needs it, the output samples inside the step too
            if ((s = rhs(L, L.t, L.y.data(), L.f.data())) != Status::ok) return fail(L, s);
            L.have_f = true;
            L.wk_f = L.wk_P;
        }
        const double t_start = L.t;
        const bool f_start = L.have_f;
        const double h_before = L.h;
        double h = 0.0, t_new = 0.0;
        double h_wk = 0.0, dW_step = 0.0;  // the step the work's increment dW_step is over
        bool dense_samples = true;         // adaptive: samples from the continuous extension
        bool end_star_p = false;           // L.ps: the point at the end of a step taken past t1
        bool fsal = false;
        if (adapt) {
            const long long rej0 = L.n_rejected;
            if ((s = dop853 ? d8_step(L, h, t_new) : dp_step(L, h, t_new)) != Status::ok) {
                L.n_rejected = rej0;
                return fail(L, s);
            }
            h_wk = h;
            dW_step = L.wk_dW;
            // dopri5: L.K.row(6) = F(t_new, y1 raw); dop853: L.K8.row(12) when evaluated
            fsal = !dop853 || L.d8_fsal;
            // samples inside the step: a partial step of the method from its start (its error
            // is a local error of the method, ≤ the step's), except next to a singular passage,
            // where the continuous extension keeps the stages off the instant (_simulate.py:
            // ADAPTIVE_PARTIAL_SAMPLES)
            dense_samples = !L.opt.partial_samples ||
                            (L.any_active && passage_holds(L, t_start, h));
            if (dop853 && dense_samples && !L.every && L.out_i < n_out &&
                L.t_out[L.out_i] < t_new - 1e-12 * std::max(1.0, std::abs(t_new)) &&
                (s = d8_dense_setup(L)) != Status::ok)  // a sample inside the step
                return fail(L, s);
            if (L.opt.stab == Stabilization::projection && t_new != t_start + h) {  // clipped to t1
                L.yq1 = L.y1;
                if ((s = stab_project(L, t_new, L.yq1.data())) != Status::ok) return fail(L, s);
            }
        } else {
            const double hp = passage_align(L, L.t, L.opt.dt, passage_place(L, L.t, L.opt.dt));
            h = clip(L.t, hp, t1);
            L.y0 = L.y;
            // the run ends at (within PASSAGE_END_BAND of a step from) a predicted singular
            // instant: a step ending there would evaluate F at the singular configuration (the
            // Gauss solution, not the limit along the branch: measured, crossed four-bar ending
            // at a change point, q̇ off by up to 5 m/s). The placed step is taken past it and
            // the end state is the step's quintic Hermite interpolant at t1, projected as a
            // sample (the samples at change points: ≤ 3e-9 m/s).
            const bool end_star = L.opt.passages && L.any_active && L.opt.stab == Stabilization::projection &&
                                  L.pas.have_star && h == t1 - L.t && L.t + hp > t1 && L.pas.t_star > L.t &&
                                  std::abs(t1 - L.pas.t_star) <= PASSAGE_END_BAND * hp;
            const double hs = end_star ? hp : h;
            if (end_star && !f_start) {
                if ((s = rhs(L, L.t, L.y.data(), L.f.data())) != Status::ok) return fail(L, s);
                L.have_f = true;
                L.wk_f = L.wk_P;
            }
            L.stage_proj = L.opt.method == Method::rk4 && L.any_active;  // (rk4_advance: passage_stages)
            s = fixed_advance(L, L.t, L.y, (f_start || end_star) ? &L.f : nullptr, hs, L.y1);
            L.stage_proj = false;
            if (s != Status::ok) return fail(L, s);
            h_wk = hs;
            dW_step = L.wk_dW;
            t_new = (h == t1 - L.t) ? t1 : L.t + h;
            L.yq1 = L.y1;
            if (end_star) {
                const double tf = L.t + hs;
                if ((s = stab_project(L, tf, L.yq1.data())) != Status::ok) return fail(L, s);
                if ((s = point(L, tf, L.yq1.data(), L.yq1.data() + n, L.ps, false)) != Status::ok) return fail(L, s);
                end_star_p = true;
                for (int i = 0; i < n; ++i) {
                    L.fp1[i] = L.yq1[n + i];
                    L.fp1[n + i] = L.ps.qdd[i];
                }
                hermite_quintic(n, L.y0.data(), L.f.data(), L.yq1.data(), L.fp1.data(), hs, t1 - L.t, L.yp.data());
                if ((s = stab_project_sample(L, t1, L.yp.data())) != Status::ok) return fail(L, s);
                L.yq1 = L.yp;
                L.y1 = L.yp;
            } else if ((s = stab_project(L, t_new, L.yq1.data())) != Status::ok) {
                return fail(L, s);
            }
        }
        const double end_tol = 1e-12 * std::max(1.0, std::abs(t_new));
        const bool inside = !adapt && f_start && !L.every && L.out_i < n_out && L.t_out[L.out_i] < t_new - end_tol;
        bool end_sampled = false;  // a requested time is the step end
        for (std::size_t j = L.out_i; j < n_out && L.t_out[j] <= t_new + end_tol; ++j)
            if (std::abs((L.t_out[j] - t_start) - h) <= end_tol) end_sampled = true;
        bool have_p1 = false;
        const bool watching = L.watch || !L.guards.empty();
        if (L.every || inside || watching) {
            if ((s = point(L, t_new, L.yq1.data(), L.yq1.data() + n, L.p1, L.every || end_sampled)) != Status::ok)
                return fail(L, s);
            have_p1 = true;
        }
        // the work's step record: W at both ends, the powers there (F at the start: L.f; at the
        // end: the point there, else the methods' last stage at the raw end)
        L.wk_on = true;
        L.wk_t0 = t_start;
        L.wk_h = h_wk;
        L.wk_W0 = L.wk;
        L.wk_W1 = L.wk + dW_step;
        L.wk_P0 = L.wk_f;
        L.wk_P1 = end_star_p ? L.ps.power
                  : have_p1  ? L.p1.power
                  : !adapt   ? 0.0
                  : dop853   ? (L.d8_fsal ? L.wk_K[12] : 0.0)
                             : L.wk_K[6];
        if (L.opt.passages && L.any_active) {  // the indicator at the projected step end
            if (!have_p1 && (adapt || L.opt.stab != Stabilization::projection) &&
                (s = evaluate(L, t_new, L.yq1.data(), L.yq1.data() + n, NEED_A)) != Status::ok)
                return fail(L, s);
        }
        if (watching) {  // the guards at the step end, against their values at its start
            bool fired = false;
            if (!L.guards.empty() &&
                (s = contact_guards(L, t_new, L.yq1.data(), L.yq1.data() + n, L.p1.f_c.data(), fired)) != Status::ok)
                return fail(L, s);
            if (!fired && L.watch &&
                (s = L.watch->check(t_new, L.yq1.data(), L.yq1.data() + n, L.p1.f_c.data(), fired)) != Status::ok)
                return fail(L, s);
            if (fired && !L.watch) {  // contact guards only: the engine's event layer
                if (inside) {
                    for (int i = 0; i < n; ++i) {
                        L.fp1[i] = L.yq1[n + i];
                        L.fp1[n + i] = L.p1.qdd[i];
                    }
                }
                FiredStep st;
                st.t_start = t_start;
                st.h = h;
                st.t_new = t_new;
                st.f_start = f_start;
                st.have_p1 = have_p1;
                st.inside = inside;
                st.h_next = adapt ? L.h : L.opt.dt;
                L.h = h_before;
                if ((s = contact_event(L, st)) == Status::ok) {
                    ++L.n_steps;
                    passage_restart(L);
                    return Outcome::transition;
                }
                if (s == Status::callback_error) return Outcome::callback;
                L.message.clear();  // the Python driver takes the step (and raises what fails)
                L.have_f = false;
                return Outcome::event;
            }
            if (fired) {  // not accepted: the event layer takes this step from its start
                L.h = h_before;
                L.have_f = false;
                return Outcome::event;
            }
            for (std::size_t i = 0; i < L.guards.size(); ++i) L.guards[i].g = L.guard_new[i];
        }
        if (L.opt.passages && L.any_active) passage_observe(L, t_new, L.Ac, L.m);  // (L.Ac: A at yq1)
        if (inside) {  // the Hermite interpolant's end slope: F at the projected step end
            for (int i = 0; i < n; ++i) {
                L.fp1[i] = L.yq1[n + i];
                L.fp1[n + i] = L.p1.qdd[i];
            }
        }
        if (!L.fric.empty()) {  // the friction forces' work over the step (sim_friction.cpp)
            if (!have_p1) {
                if ((s = point(L, t_new, L.yq1.data(), L.yq1.data() + n, L.p1, L.every || end_sampled)) != Status::ok)
                    return fail(L, s);
                have_p1 = true;
            }
            if ((s = friction_work_step(L, t_new, L.yq1.data(), L.p1)) != Status::ok) return fail(L, s);
        }
        if (!L.every) {  // _sample_t_eval over (t_start, t_new + end_tol]
            const std::size_t o0 = L.out_i;
            std::size_t j = o0;
            for (; j < n_out && L.t_out[j] <= t_new + end_tol; ++j) {
                const double sj = L.t_out[j] - t_start;
                if (std::abs(sj - h) <= end_tol) {
                    if (!have_p1 || std::isnan(L.p1.cond)) {
                        if ((s = point(L, t_new, L.yq1.data(), L.yq1.data() + n, L.p1, true)) != Status::ok)
                            return fail(L, s);
                        have_p1 = true;
                    }
                    record(L, L.p1, L.t_out[j]);
                    continue;
                }
                const double tt = t_start + sj;
                bool partial = false;  // W there from the partial step's own quadrature
                if (adapt && !dense_samples) {  // the method's own partial step (K overwritten)
                    if ((s = dop853 ? d8_advance(L, t_start, L.y0, &L.f, sj, L.yp)
                                    : dp_advance(L, t_start, L.y0, &L.f, sj, L.yp)) != Status::ok)
                        return fail(L, s);
                    if (!dop853) fsal = false;  // (K.row(6) overwritten; K8's row 12 is not)
                    partial = true;
                } else if (dop853) {
                    d8_dense(L, tt, L.yp.data());
                } else if (adapt) {
                    dp_dense(L, t_start, h, tt, L.yp.data());
                } else if (f_start && have_p1) {
                    hermite_quintic(n, L.y0.data(), L.f.data(), L.yq1.data(), L.fp1.data(), h, tt - t_start,
                                    L.yp.data());
                } else {  // a partial step of the method (the driver's `at`)
                    if (sj <= 0.0) {
                        L.yp = L.y0;
                        L.wk_dW = 0.0;
                    } else if ((s = fixed_advance(L, t_start, L.y0, f_start ? &L.f : nullptr, sj, L.yp)) !=
                               Status::ok) {
                        return fail(L, s);
                    }
                    partial = true;
                }
                if ((s = ((adapt && dense_samples) || (!adapt && f_start && have_p1))
                             ? stab_project_sample(L, tt, L.yp.data())
                                                          : stab_project(L, tt, L.yp.data())) != Status::ok)
                    return fail(L, s);
                if ((s = point(L, tt, L.yp.data(), L.yp.data() + n, L.ps, true)) != Status::ok) return fail(L, s);
                if (partial) L.ps.work = L.wk + L.wk_dW;
                record(L, L.ps, L.t_out[j]);
            }
            L.out_i = j;
        } else {
            record(L, L.p1, t_new);
        }
        // the next step's F(t, y): FSAL when the projection left y1 unchanged, else the full
        // evaluation at the projected step end (without a controller, whose state updates)
        bool changed = false;
        for (int i = 0; i < n2; ++i)
            if (!(L.yq1[i] == L.y1[i])) {
                changed = true;
                break;
            }
        if (!changed && fsal) {
            L.f = dop853 ? L.K8.row(12).transpose() : L.K.row(6).transpose();
            L.wk_f = dop853 ? L.wk_K[12] : L.wk_K[6];
            L.have_f = true;
        } else if (have_p1 && (!L.ctrl || L.ctrl->stateless())) {
            for (int i = 0; i < n; ++i) {
                L.f[i] = L.yq1[n + i];
                L.f[n + i] = L.p1.qdd[i];
            }
            L.wk_f = L.p1.power;
            L.have_f = true;
        } else {
            L.have_f = false;
        }
        L.wk = work_at(L, t_new);
        L.wk_on = false;
        L.t = t_new;
        L.y = L.yq1;
        if (!L.fric.empty()) {
            friction_work_commit(L, L.p1);
            if (L.ctrl && !L.ctrl->stateless()) L.fw_have0 = false;  // (u changes with update)
        }
        ++L.n_steps;
        ++taken;
        if (L.ctrl) {
            s = L.ctrl->update(L.t, L.y.data(), L.y.data() + n, L.active.data());
            if (s != Status::ok) return fail(L, s);
        }
    }
    return Outcome::done;
}

}  // namespace nonmin::sim
