// The engine's event layer for unilateral contact (see nonmin/sim/events.hpp). Each function
// names the Python function it mirrors (nonmin/sim/_simulate.py, nonmin/core/impact.py); the
// order of the decisions is theirs, so the two drivers agree to round-off and to the event
// tolerance.
#include "nonmin/sim/events.hpp"
#include "nonmin/linalg.hpp"
#include "sim_detail.hpp"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

namespace nonmin::sim {

namespace {

constexpr double inf = std::numeric_limits<double>::infinity();
constexpr double tiny = std::numeric_limits<double>::min();
constexpr int RELEASE_FAST_ROWS = 12;        // release_forces: Cholesky path up to this many rows
constexpr double RELEASE_FAST_COND = 1e4;    // … when cond(DA) is certified below this

double base_rtol(const Options& o) { return o.rank_rtol > 0.0 ? o.rank_rtol : DEFAULT_RTOL; }

SolveOptions solve_options(const Loop& L) {
    SolveOptions so;
    so.rtol = base_rtol(L.opt);
    so.spd_rtol = L.opt.spd_rtol;
    so.sym_rtol = L.opt.sym_rtol;
    return so;
}

double max_abs(const double* x, int n) {
    double a = 0.0;
    for (int i = 0; i < n; ++i) a = std::max(a, std::abs(x[i]));
    return a;
}

double abs_row_sum(const double* a, int n) {
    double s = 0.0;
    for (int j = 0; j < n; ++j) s += std::abs(a[j]);
    return s;
}

double dot(const double* a, const double* b, int n) {
    double s = 0.0;
    for (int j = 0; j < n; ++j) s += a[j] * b[j];
    return s;
}

}  // namespace

// Everything the event layer needs, sized once when the guards are set.
struct EventScratch {
    PolyWork pw;
    int n = 0, c = 0;
    std::vector<int> unilateral;  // constraint indices, declaration order
    std::vector<std::uint8_t> uni_mask, mask, act_before, act_tmp;
    std::vector<double> restitution;  // per constraint (Newton's e of automatic impacts)
    double v_thresh = 1e-6;
    Mat M, Ab, Ac, Aeq, Ain, G, Li;  // (G, Li: release_forces' fast path)
    Vec gam_c, u, target, v, un, qdd, qdd_free, y, yt, gam_b, flight, rin, req, zero_m;
    std::vector<int> contacts;
    std::vector<std::uint8_t> fired, plastic, closed, forced, at_bound;
    Point pe, pa;
    std::vector<std::pair<double, int>> roots;
};

// ------------------------------------------------------------------------------ polyhedron

void PolyWork::reserve(int m_max, int n) {
    const int m = std::max(m_max, 1);
    A = Mat::Zero(m, n);
    for (Vec* v : {&r, &bias, &res, &scale_eq0}) *v = Vec::Zero(m);
    for (Vec* v : {&dx, &xf, &zero, &best}) *v = Vec::Zero(n);
    idx.reserve(MAX_INEQUALITY_ROWS);
}

// nonmin.core.polyhedral_projection
bool polyhedral_projection(Solver& S, const SolveOptions& so, int n, const double* M, const double* x0,
                           const double* A_eq, const double* r_eq, int m_eq, const double* A_in,
                           const double* r_in, int m_in, double* x, std::uint8_t* at_bound, PolyWork& w,
                           Status& status) {
    status = Status::ok;
    if (m_in > MAX_INEQUALITY_ROWS || m_eq + m_in > w.A.rows()) {
        status = Status::bad_shape;
        return false;
    }
    const double tol = FEASIBILITY_RTOL;
    w.feasible.clear();
    w.empty.clear();
    bool have_best = false, have_eq0 = false;
    double best_d = 0.0;
    const double x0max = max_abs(x0, n);
    for (int size = 0; size <= m_in; ++size) {
        w.idx.resize(static_cast<std::size_t>(size));
        std::iota(w.idx.begin(), w.idx.end(), 0);
        while (true) {
            std::uint32_t mask = 0;
            for (int i : w.idx) mask |= 1u << i;
            bool skip = false;
            for (std::uint32_t f : w.feasible) skip = skip || (f & mask) == f;
            for (std::uint32_t f : w.empty) skip = skip || (f & mask) == f;
            if (!skip) {
                const int m = m_eq + size;
                for (int i = 0; i < m; ++i) {
                    const double* a = i < m_eq ? A_eq + static_cast<long>(i) * n
                                               : A_in + static_cast<long>(w.idx[i - m_eq]) * n;
                    for (int j = 0; j < n; ++j) w.A(i, j) = a[j];
                    w.r[i] = i < m_eq ? r_eq[i] : r_in[w.idx[i - m_eq]];
                    w.bias[i] = dot(a, x0, n) + w.r[i];
                }
                if (m > 0) {
                    const SolveInfo info = S.forward(M, w.zero.data(), w.A.data(), m, w.bias.data(), so, w.dx.data(),
                                                     nullptr);
                    if (info.status != Status::ok) {
                        status = info.status;
                        return false;
                    }
                } else {
                    w.dx.setZero();
                }
                for (int j = 0; j < n; ++j) w.xf[j] = x0[j] + w.dx[j];
                const double xmax = std::max(max_abs(w.xf.data(), n), x0max);
                bool bad = false;
                for (int i = 0; i < m; ++i) {
                    const double res = std::abs(dot(&w.A(i, 0), w.xf.data(), n) + w.r[i]);
                    const double sc = abs_row_sum(&w.A(i, 0), n) * xmax + std::abs(w.r[i]) + tiny;
                    if (i < m_eq) {
                        if (!have_eq0) w.scale_eq0[i] = res;  // the equality rows' own residual
                        if (res > w.scale_eq0[i] + tol * sc) bad = true;
                    } else if (res > tol * sc) {
                        bad = true;
                    }
                }
                have_eq0 = true;
                if (bad) {
                    w.empty.push_back(mask);
                } else {
                    bool feasible = true;
                    for (int i = 0; i < m_in && feasible; ++i) {
                        const double* a = A_in + static_cast<long>(i) * n;
                        const double g = dot(a, w.xf.data(), n) + r_in[i];
                        feasible = g >= -tol * (abs_row_sum(a, n) * xmax + std::abs(r_in[i]) + tiny);
                    }
                    if (feasible) {
                        w.feasible.push_back(mask);
                        double d = 0.0;
                        for (int i = 0; i < n; ++i) d += w.dx[i] * dot(M + static_cast<long>(i) * n, w.dx.data(), n);
                        if (!have_best || d < best_d) {
                            have_best = true;
                            best_d = d;
                            w.best = w.xf;
                        }
                    }
                }
            }
            // the next combination of `size` rows in lexicographic order (itertools.combinations)
            int k = size - 1;
            while (k >= 0 && w.idx[k] == m_in - size + k) --k;
            if (k < 0) break;
            ++w.idx[k];
            for (int j = k + 1; j < size; ++j) w.idx[j] = w.idx[j - 1] + 1;
        }
    }
    if (!have_best) return false;
    for (int j = 0; j < n; ++j) x[j] = w.best[j];
    const double xmax = std::max(max_abs(x, n), x0max);
    for (int i = 0; i < m_in; ++i) {
        const double* a = A_in + static_cast<long>(i) * n;
        at_bound[i] = std::abs(dot(a, x, n) + r_in[i]) <= tol * (abs_row_sum(a, n) * xmax + std::abs(r_in[i]) + tiny);
    }
    return true;
}

// ------------------------------------------------------------------------------ active set

void set_active(Loop& L, const std::uint8_t* active) {
    const auto& cons = L.prog->constraints();
    L.active.assign(active, active + L.c);
    L.rows.clear();
    L.hol.clear();
    L.any_active = false;
    for (std::size_t ic = 0; ic < cons.size(); ++ic) {
        if (!L.active[ic]) continue;
        L.any_active = true;
        for (int r = 0; r < cons[ic].dim; ++r) {
            L.rows.push_back(cons[ic].row + r);
            L.hol.push_back(cons[ic].kind != ConstraintKind::nonholonomic);
        }
    }
    L.m = static_cast<int>(L.rows.size());
    L.m_hol = static_cast<int>(std::count(L.hol.begin(), L.hol.end(), 1));
    if (L.ctrl_select)
        if (Controller* c = L.ctrl_select->select(L.active.data())) L.ctrl = c;
    if (L.ctrl) L.ctrl->attach(L.T, L.Ac, L.m, L.rows);
    L.vheld = false;  // a held velocity-correction factorization is the old rows'
    friction_mask(L);
}

// ------------------------------------------------------------------------------ guards

void set_guards(Loop& L, const std::vector<ContactGuard>& guards) {
    L.guards = guards;
    L.guard_new.assign(guards.size(), 0.0);
    L.guard_pull.assign(guards.size(), 0);
    L.one_mask.assign(static_cast<std::size_t>(L.c), 0);
    bool release = false;
    for (const ContactGuard& g : guards) release |= g.release;
    if (release && L.m > 0) {
        L.DA = Mat::Zero(L.m, L.n);
        L.lam_c = Vec::Zero(std::max(L.m, L.n));
        L.lam_tmp = Vec::Zero(std::max(L.m, L.n));
        L.svd_a = Svd(L.m, L.n, Eigen::ComputeThinU | Eigen::ComputeThinV);
    }
    if (!L.evs && !guards.empty()) {
        auto E = std::make_shared<EventScratch>();
        const int n = L.n, c = L.c, m_all = std::max(L.m_all, 1);
        E->n = n;
        E->c = c;
        const auto& cons = L.prog->constraints();
        E->uni_mask.assign(static_cast<std::size_t>(c), 0);
        for (int ic = 0; ic < c; ++ic)
            if (cons[ic].kind == ConstraintKind::unilateral) {
                E->unilateral.push_back(ic);
                E->uni_mask[ic] = 1;
            }
        E->restitution.assign(static_cast<std::size_t>(c), 0.0);
        E->pw.reserve(m_all, n);
        E->M = Mat::Zero(n, n);
        E->G = Mat::Zero(RELEASE_FAST_ROWS, RELEASE_FAST_ROWS);
        E->Li = Mat::Zero(RELEASE_FAST_ROWS, RELEASE_FAST_ROWS);
        for (Mat* A : {&E->Ab, &E->Ac, &E->Aeq, &E->Ain}) *A = Mat::Zero(m_all, n);
        for (Vec* v : {&E->gam_c, &E->u, &E->target, &E->un, &E->gam_b, &E->flight, &E->rin, &E->req, &E->zero_m})
            *v = Vec::Zero(m_all);
        for (Vec* v : {&E->v, &E->qdd, &E->qdd_free}) *v = Vec::Zero(n);
        for (Vec* v : {&E->y, &E->yt}) *v = Vec::Zero(2 * n);
        for (Point* p : {&E->pe, &E->pa}) {
            p->q = p->qd = p->qdd = p->f_c = Vec::Zero(n);
            p->u = Vec::Zero(L.k);
        }
        L.evs = std::move(E);
    }
}

void set_contact_options(Loop& L, const std::vector<double>& restitution, double v_thresh) {
    if (!L.evs) return;
    for (std::size_t i = 0; i < restitution.size() && i < L.evs->restitution.size(); ++i)
        L.evs->restitution[i] = restitution[i];
    L.evs->v_thresh = v_thresh;
    L.fr_vthresh = v_thresh;
}

// λ = ((DA)⁺ D)ᵀ f_c over the active rows (nonmin.core.linalg.range_basis(A, rtol).pinv().T @ f_c),
// A = L.Ac at the point just evaluated; into L.lam_c (m).
void release_forces(Loop& L, const double* f_c) {
    const int m = L.m, n = L.n;
    const double tol = base_rtol(L.opt);
    double big = 0.0;
    for (int i = 0; i < m; ++i) {
        L.rnorm[i] = linalg::row_norm(&L.Ac(i, 0), n);  // scaled: no overflow above ~1e154
        big = std::max(big, L.rnorm[i]);
    }
    bool vanished = false;
    for (int i = 0; i < m; ++i) {
        const double d = L.rnorm[i] > tol * big ? 1.0 / L.rnorm[i] : 0.0;
        vanished = vanished || d == 0.0;
        L.rnorm[i] = d;
        for (int j = 0; j < n; ++j) L.DA(i, j) = L.Ac(i, j) * d;
    }
    if (!vanished && m <= RELEASE_FAST_ROWS && m <= n) {
        // Certified full row rank (the usual case, every step with an active contact): with
        // G = (DA)(DA)ᵀ, σ_min² ≥ 1/tr(G⁻¹) and σ_max² ≤ tr(G); when their ratio is above
        // RELEASE_FAST_COND⁻² the SVD's rank is m, and (DA)⁺ = (DA)ᵀG⁻¹, so
        // λ = D G⁻¹ (DA) f_c (Cholesky of the m × m G) equals the SVD path to round-off.
        auto G = L.evs->G.topLeftCorner(m, m);
        G.noalias() = L.DA.topRows(m) * L.DA.topRows(m).transpose();
        const double trG = G.trace();
        Eigen::LLT<Eigen::Ref<Mat>> llt(G);
        if (llt.info() == Eigen::Success) {
            auto Li = L.evs->Li.topLeftCorner(m, m);
            Li.setIdentity();
            llt.matrixL().solveInPlace(Li);  // L⁻¹: tr(G⁻¹) = ‖L⁻¹‖²_F
            const double trGi = Li.squaredNorm();
            if (trGi * trG < RELEASE_FAST_COND * RELEASE_FAST_COND) {
                auto b = L.lam_tmp.head(m);
                b.noalias() = L.DA.topRows(m) * Eigen::Map<const Vec>(f_c, n);
                llt.solveInPlace(b);
                for (int i = 0; i < m; ++i) L.lam_c[i] = L.rnorm[i] * b[i];
                return;
            }
        }
    }
    L.svd_a.compute(L.DA);
    const auto& sv = L.svd_a.singularValues();
    const auto& U = L.svd_a.matrixU();
    const auto& V = L.svd_a.matrixV();
    const int kk = static_cast<int>(sv.size());
    for (int k = 0; k < kk; ++k) {  // c_k = (1/s_k) v_kᵀ f_c where kept
        double c = 0.0;
        if (sv[k] > tol * sv[0]) {
            for (int j = 0; j < n; ++j) c += V(j, k) * f_c[j];
            c /= sv[k];
        }
        L.lam_tmp[k] = c;
    }
    for (int i = 0; i < m; ++i) {
        double s = 0.0;
        for (int k = 0; k < kk; ++k) s += U(i, k) * L.lam_tmp[k];
        L.lam_c[i] = L.rnorm[i] * s;
    }
}

namespace {

// The gaps φ of the constraints flagged in `mask` at q (one evaluation; each constraint's rows
// are its own), read from L.T.phi at their first rows.
Status gaps(Loop& L, double t, const double* q, const double* qd, const std::uint8_t* mask) {
    return L.prog->evaluate(t, q, qd, mask, NEED_PHI, L.T, *L.ws);
}

}  // namespace

namespace {

// λ of active row `row` (from release_forces, whose L.rnorm holds 1/‖A_row‖) clearly pulling:
// −λ‖A_row‖ > RELEASE_RTOL ‖f_c‖ (_simulate._pulling)
bool pulling(const Loop& L, int row, double lam, const double* f_c) {
    const double rn = L.rnorm[row];
    if (!(lam < 0.0) || rn <= 0.0) return false;
    return -lam > RELEASE_RTOL * Eigen::Map<const Vec>(f_c, L.n).norm() * rn;
}

}  // namespace

// The contact guards at the step end: every impact gap from one evaluation, the release forces
// from one SVD of the active rows.
Status contact_guards(Loop& L, double t, const double* q, const double* qd, const double* f_c, bool& fired) {
    fired = false;
    const auto& cons = L.prog->constraints();
    bool any_gap = false;
    for (const ContactGuard& G : L.guards)
        if (!G.release && G.fric < 0) {
            L.one_mask[static_cast<std::size_t>(G.constraint)] = 1;
            any_gap = true;
        }
    if (any_gap) {
        const Status s = gaps(L, t, q, qd, L.one_mask.data());
        std::fill(L.one_mask.begin(), L.one_mask.end(), 0);
        if (s != Status::ok) return s;
    }
    bool lam_done = false;
    for (std::size_t i = 0; i < L.guards.size(); ++i) {
        const ContactGuard& G = L.guards[i];
        double g1;
        if (G.fric >= 0) {  // friction guards: below, once the gaps are read
            continue;
        } else if (G.release) {
            if (!lam_done) {
                release_forces(L, f_c);
                lam_done = true;
            }
            g1 = L.lam_c[G.row];
        } else {
            g1 = L.T.phi[cons[static_cast<std::size_t>(G.constraint)].row];
            if (!std::isfinite(g1)) return Status::not_finite;
        }
        L.guard_new[i] = g1;
        const double g0 = G.g;
        L.guard_pull[i] = G.release && g0 < 0.0 && pulling(L, G.row, g1, f_c);
        if ((g0 > 0.0 && g1 <= 0.0) || (!G.release && g0 <= 0.0 && g1 < 0.0) || L.guard_pull[i]) fired = true;
    }
    for (std::size_t i = 0; i < L.guards.size(); ++i) {  // friction (sim_friction.cpp)
        const ContactGuard& G = L.guards[i];
        if (G.fric < 0) continue;
        if (!lam_done) {
            release_forces(L, f_c);
            lam_done = true;
        }
        double g1 = 0.0;
        const Status s = friction_guard_value(L, G, t, q, qd, g1);
        if (s != Status::ok) return s;
        L.guard_new[i] = g1;
        if ((G.g > 0.0 && g1 <= 0.0) || (G.g <= 0.0 && g1 < 0.0)) fired = true;
    }
    return Status::ok;
}

// The contact guards' values at the run's first point (after start(): L.p1 is the point
// evaluated at (L.t, L.y), L.Ac its rows): the Python driver's _guard_values at its first point
// (the gaps from one evaluation, the release forces from release_forces).
Status arm_guards(Loop& L) {
    if (L.guards.empty()) return Status::ok;
    bool fired = false;
    const Status s = contact_guards(L, L.t, L.y.data(), L.y.data() + L.n, L.p1.f_c.data(), fired);
    if (s != Status::ok) return s;
    for (std::size_t i = 0; i < L.guards.size(); ++i) L.guards[i].g = L.guard_new[i];
    return Status::ok;
}

// ------------------------------------------------------------------------------ location

namespace {

// The driver's at(s): the projected state after a partial step of size s, and its point.
Status at_point(Loop& L, const FiredStep& st, double s, Point& p, bool diagnostics) {
    EventScratch& E = *L.evs;
    Status r = partial_step(L, st.t_start, L.y, st.f_start ? &L.f : nullptr, s, E.yt);
    if (r != Status::ok) return r;
    const double dW = L.wk_dW;  // the partial step's own quadrature of the work
    if ((r = point(L, st.t_start + s, E.yt.data(), E.yt.data() + L.n, p, diagnostics)) != Status::ok) return r;
    p.work = L.wk + dW;
    return Status::ok;
}

// _guard_value of contact guard G at at(s)
Status guard_at(Loop& L, const FiredStep& st, const ContactGuard& G, double s, double& g) {
    EventScratch& E = *L.evs;
    Status r;
    if (G.release || G.fric >= 0) {
        if ((r = at_point(L, st, s, E.pa, false)) != Status::ok) return r;
        release_forces(L, E.pa.f_c.data());
        if (G.fric >= 0) return friction_guard_value(L, G, st.t_start + s, E.pa.q.data(), E.pa.qd.data(), g);
        g = L.lam_c[G.row];
        return Status::ok;
    }
    if ((r = partial_step(L, st.t_start, L.y, st.f_start ? &L.f : nullptr, s, E.yt)) != Status::ok) return r;
    L.one_mask[static_cast<std::size_t>(G.constraint)] = 1;
    r = gaps(L, st.t_start + s, E.yt.data(), E.yt.data() + L.n, L.one_mask.data());
    L.one_mask[static_cast<std::size_t>(G.constraint)] = 0;
    if (r != Status::ok) return r;
    g = L.T.phi[L.prog->constraints()[static_cast<std::size_t>(G.constraint)].row];
    return std::isfinite(g) ? Status::ok : Status::not_finite;
}

// Brent's method (scipy.optimize.brentq's algorithm: inverse quadratic interpolation, secant,
// bisection) for f on [a, b]; `bracket` false when f(a), f(b) have the same sign (brentq's
// ValueError).
template <class F>
Status brent(F&& f, double a, double b, double xtol, double rtol, int max_iter, double& root, bool& bracket) {
    double xpre = a, xcur = b, fpre, fcur;
    Status s;
    if ((s = f(xpre, fpre)) != Status::ok) return s;
    if ((s = f(xcur, fcur)) != Status::ok) return s;
    bracket = true;
    if (fpre == 0.0) {
        root = xpre;
        return Status::ok;
    }
    if (fcur == 0.0) {
        root = xcur;
        return Status::ok;
    }
    if (std::signbit(fpre) == std::signbit(fcur)) {
        bracket = false;
        return Status::ok;
    }
    double xblk = 0.0, fblk = 0.0, spre = 0.0, scur = 0.0;
    for (int it = 0; it < max_iter; ++it) {
        if (fpre != 0.0 && fcur != 0.0 && std::signbit(fpre) != std::signbit(fcur)) {
            xblk = xpre;
            fblk = fpre;
            spre = scur = xcur - xpre;
        }
        if (std::abs(fblk) < std::abs(fcur)) {
            xpre = xcur;
            xcur = xblk;
            xblk = xpre;
            fpre = fcur;
            fcur = fblk;
            fblk = fpre;
        }
        const double delta = (xtol + rtol * std::abs(xcur)) / 2.0;
        const double sbis = (xblk - xcur) / 2.0;
        if (fcur == 0.0 || std::abs(sbis) < delta) break;
        if (std::abs(spre) > delta && std::abs(fcur) < std::abs(fpre)) {
            double stry;
            if (xpre == xblk) {  // secant
                stry = -fcur * (xcur - xpre) / (fcur - fpre);
            } else {  // inverse quadratic interpolation
                const double dpre = (fpre - fcur) / (xpre - xcur);
                const double dblk = (fblk - fcur) / (xblk - xcur);
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre));
            }
            if (2.0 * std::abs(stry) < std::min(std::abs(spre), 3.0 * std::abs(sbis) - delta)) {
                spre = scur;  // a good short step
                scur = stry;
            } else {
                spre = sbis;
                scur = sbis;
            }
        } else {
            spre = sbis;
            scur = sbis;
        }
        xpre = xcur;
        fpre = fcur;
        xcur += std::abs(scur) > delta ? scur : (sbis > 0.0 ? delta : -delta);
        if ((s = f(xcur, fcur)) != Status::ok) return s;
    }
    root = xcur;
    return Status::ok;
}

// _past_root: nudge the located root to the side where the guard has left g0's sign
template <class F>
Status past_root(F&& f, double& s, double h, double g0) {
    if (g0 == 0.0) return Status::ok;
    const double sign0 = std::copysign(1.0, g0);
    double g;
    Status r;
    if ((r = f(s, g)) != Status::ok) return r;
    double step = EVENT_XTOL / 4.0;
    int tries = 0;
    while (g * sign0 > 0.0 && tries < 8 && s < h) {
        s = std::min(h, s + step);
        if ((r = f(s, g)) != Status::ok) return r;
        step *= 2.0;
        ++tries;
    }
    return Status::ok;
}

void truncate(Samples& R, std::size_t N) {
    const std::size_t n = static_cast<std::size_t>(R.n), k = static_cast<std::size_t>(R.k),
                      c = static_cast<std::size_t>(R.c);
    R.t.resize(N);
    for (auto* v : {&R.q, &R.qd, &R.qdd, &R.f_c}) v->resize(N * n);
    R.u.resize(N * k);
    R.active.resize(N * c);
    R.rank.resize(N);
    for (auto* v : {&R.cond, &R.mu, &R.energy, &R.phi_norm, &R.vel_norm, &R.fr_work, &R.work}) v->resize(N);
}

// _sample_t_eval over (t_start, te] with the driver's out_at
Status sample_until(Loop& L, const FiredStep& st, double te, std::size_t& out_i) {
    EventScratch& E = *L.evs;
    const int n = L.n;
    const double end_tol = 1e-12 * std::max(1.0, std::abs(st.t_new));
    const bool adapt = detail::adaptive(L);
    Status r;
    while (out_i < L.t_out.size() && L.t_out[out_i] <= te) {
        const double tj = L.t_out[out_i];
        const double sj = tj - st.t_start;
        if (std::abs(sj - st.h) <= end_tol) {
            if (!st.have_p1 || std::isnan(L.p1.cond)) {
                if ((r = point(L, st.t_new, L.yq1.data(), L.yq1.data() + n, L.p1, true)) != Status::ok) return r;
            }
            record_sample(L, L.p1, tj);
        } else if (adapt || st.inside) {
            if (adapt)
                dense_output(L, st.t_start, st.h, st.t_start + sj, E.yt.data());
            else
                hermite_quintic(n, L.y0.data(), L.f.data(), L.yq1.data(), L.fp1.data(), st.h, sj, E.yt.data());
            if ((r = stabilize_sample(L, st.t_start + sj, E.yt.data())) != Status::ok) return r;
            if ((r = point(L, st.t_start + sj, E.yt.data(), E.yt.data() + n, L.ps, true)) != Status::ok) return r;
            record_sample(L, L.ps, tj);
        } else {
            if ((r = at_point(L, st, sj, L.ps, true)) != Status::ok) return r;
            record_sample(L, L.ps, tj);
        }
        ++out_i;
    }
    return Status::ok;
}

// ------------------------------------------------------------------------------ transitions

// The own rows (A, γ, φ) of every unilateral constraint at (t, q, qd), one evaluation.
Status own_rows(Loop& L, double t, const double* q, const double* qd) {
    return L.prog->evaluate(t, q, qd, L.evs->uni_mask.data(), NEED_A | NEED_GAMMA | NEED_PHI, L.T, *L.ws);
}

std::string join(const Loop& L, const std::vector<int>& idx, const char* sep) {
    std::string s;
    for (std::size_t i = 0; i < idx.size(); ++i) {
        if (i) s += sep;
        s += L.prog->constraints()[static_cast<std::size_t>(idx[i])].name;
    }
    return s;
}

// _System.rhs's q̈ at (t, q, v) under the active mask `act` (the loop's set is restored by the
// caller).
Status qdd_under(Loop& L, const std::vector<std::uint8_t>& act, double t, const double* q, const double* v,
                 Vec& out) {
    EventScratch& E = *L.evs;
    set_active(L, act.data());
    for (int i = 0; i < L.n; ++i) {
        E.yt[i] = q[i];
        E.yt[L.n + i] = v[i];
    }
    const Status r = rhs(L, t, E.yt.data(), L.tmp2n.data());
    if (r != Status::ok) return r;
    for (int i = 0; i < L.n; ++i) out[i] = L.tmp2n[L.n + i];
    return Status::ok;
}

// _set_impact: one impact over every contact closed at (t, y); y's velocity is replaced.
Status set_impact(Loop& L, double t, Vec& y, const std::vector<int>& fired_c,
                  const std::vector<std::uint8_t>& plastic_c, double dt_fixed, double& h_cap) {
    EventScratch& E = *L.evs;
    const int n = L.n;
    const auto& cons = L.prog->constraints();
    const double* q = y.data();
    const double* qd = y.data() + n;
    Status r;
    if ((r = own_rows(L, t, q, qd)) != Status::ok) return r;
    E.contacts.clear();
    std::vector<std::uint8_t>& bil = E.mask;
    bil = L.active;
    for (int ic : E.unilateral) {
        const int row = cons[static_cast<std::size_t>(ic)].row;
        const bool fired = std::find(fired_c.begin(), fired_c.end(), ic) != fired_c.end();
        const bool touching = L.T.phi[row] <= 0.0 && dot(&L.T.A(row, 0), qd, n) <= 0.0;
        if (fired || L.active[ic] || touching) {
            E.contacts.push_back(ic);
            bil[ic] = 0;
        }
    }
    const int mc = static_cast<int>(E.contacts.size());
    if (mc > MAX_INEQUALITY_ROWS) return Status::bad_shape;
    for (int i = 0; i < mc; ++i) {
        const int ic = E.contacts[i];
        const int row = cons[static_cast<std::size_t>(ic)].row;
        E.Ac.row(i) = L.T.A.row(row);
        E.u[i] = dot(&L.T.A(row, 0), qd, n);
        const bool pl = std::find(fired_c.begin(), fired_c.end(), ic) != fired_c.end() &&
                        plastic_c[static_cast<std::size_t>(std::find(fired_c.begin(), fired_c.end(), ic) - fired_c.begin())];
        const double e = (pl || L.active[ic]) ? 0.0 : E.restitution[static_cast<std::size_t>(ic)];
        E.target[i] = e * std::max(-E.u[i], 0.0);
    }
    // M and the bilateral rows at (t, q)
    if ((r = L.prog->evaluate(t, q, qd, bil.data(), NEED_M | NEED_A, L.T, *L.ws)) != Status::ok) return r;
    E.M = L.T.M;
    int mb = 0;
    for (std::size_t ic = 0; ic < cons.size(); ++ic)
        if (bil[ic])
            for (int k = 0; k < cons[ic].dim; ++k) E.Ab.row(mb++) = L.T.A.row(cons[ic].row + k);
    const SolveOptions so = solve_options(L);
    E.forced.assign(static_cast<std::size_t>(mc), 0);
    E.closed.assign(static_cast<std::size_t>(mc), 0);
    E.at_bound.assign(static_cast<std::size_t>(MAX_INEQUALITY_ROWS), 0);
    const double qdmax = max_abs(qd, n);
    while (true) {
        int me = 0, mi = 0;
        for (int i = 0; i < mb; ++i) E.Aeq.row(me++) = E.Ab.row(i);
        for (int i = 0; i < mc; ++i) {
            if (E.forced[i]) {
                E.Aeq.row(me++) = E.Ac.row(i);
            } else {
                E.Ain.row(mi) = E.Ac.row(i);
                E.rin[mi++] = -E.target[i];
            }
        }
        for (int i = 0; i < me; ++i) E.req[i] = 0.0;
        if (!polyhedral_projection(L.solver, so, n, E.M.data(), qd, E.Aeq.data(), E.req.data(), me, E.Ain.data(),
                                   E.rin.data(), mi, E.v.data(), E.at_bound.data(), E.pw, r))
            return r == Status::ok ? Status::not_finite : r;
        const double scale_x = std::max(max_abs(E.v.data(), n), qdmax);
        E.act_tmp = bil;
        for (int i = 0; i < mc; ++i) {
            E.un[i] = dot(&E.Ac(i, 0), E.v.data(), n);
            E.closed[i] = E.forced[i] || std::abs(E.un[i]) <= FEASIBILITY_RTOL * abs_row_sum(&E.Ac(i, 0), n) * scale_x;
            if (E.closed[i]) E.act_tmp[E.contacts[i]] = 1;
        }
        if ((r = qdd_under(L, E.act_tmp, t, q, E.v.data(), E.qdd)) != Status::ok) return r;
        if ((r = own_rows(L, t, q, E.v.data())) != Status::ok) return r;  // γ at the new velocity
        bool weak = false;
        for (int i = 0; i < mc; ++i) {
            const int row = cons[static_cast<std::size_t>(E.contacts[i])].row;
            E.gam_c[i] = L.T.gamma[row];
            const double a_gap = dot(&E.Ac(i, 0), E.qdd.data(), n) + E.gam_c[i];
            E.flight[i] = a_gap < 0.0 ? 2.0 * E.un[i] / (-a_gap) : inf;
            if (!E.closed[i] && (E.un[i] <= E.v_thresh || E.flight[i] <= 2.0 * dt_fixed)) {
                E.forced[i] = 1;
                weak = true;
            }
        }
        if (!weak) break;
    }
    h_cap = 0.0;
    double fmin = inf;
    bool any_closed = false;
    for (int i = 0; i < mc; ++i) {
        if (!E.closed[i] && std::isfinite(E.flight[i])) fmin = std::min(fmin, E.flight[i]);
        any_closed = any_closed || E.closed[i];
    }
    if (std::isfinite(fmin)) h_cap = fmin / 4.0;
    E.act_tmp = bil;
    if (any_closed) {  // Gauss's principle with the closed contacts as inequalities
        if ((r = qdd_under(L, bil, t, q, E.v.data(), E.qdd_free)) != Status::ok) return r;
        if ((r = L.prog->evaluate(t, q, E.v.data(), bil.data(), NEED_A | NEED_GAMMA, L.T, *L.ws)) != Status::ok)
            return r;
        int me = 0;
        for (std::size_t ic = 0; ic < cons.size(); ++ic)
            if (bil[ic])
                for (int k = 0; k < cons[ic].dim; ++k) {
                    E.Aeq.row(me) = L.T.A.row(cons[ic].row + k);
                    E.req[me++] = L.T.gamma[cons[ic].row + k];
                }
        int mi = 0;
        for (int i = 0; i < mc; ++i)
            if (E.closed[i]) {
                E.Ain.row(mi) = E.Ac.row(i);
                E.rin[mi++] = E.gam_c[i];
            }
        if (!polyhedral_projection(L.solver, so, n, E.M.data(), E.qdd_free.data(), E.Aeq.data(), E.req.data(), me,
                                   E.Ain.data(), E.rin.data(), mi, E.qdd.data(), E.at_bound.data(), E.pw, r))
            return r == Status::ok ? Status::not_finite : r;
        mi = 0;
        for (int i = 0; i < mc; ++i)
            if (E.closed[i] && E.at_bound[mi++]) E.act_tmp[E.contacts[i]] = 1;
    }
    for (int i = 0; i < n; ++i) y[n + i] = E.v[i];
    set_active(L, E.act_tmp.data());
    return Status::ok;
}

// _apply's release: refused only if the free motion would clearly penetrate
Status release(Loop& L, double t, const Vec& y, int ic, bool& released) {
    EventScratch& E = *L.evs;
    const int n = L.n;
    const auto& cons = L.prog->constraints();
    E.act_tmp = L.active;
    E.act_tmp[ic] = 0;
    const std::vector<std::uint8_t> saved = L.active;
    Status r = qdd_under(L, E.act_tmp, t, y.data(), y.data() + n, E.qdd);
    set_active(L, saved.data());
    if (r != Status::ok) return r;
    if ((r = own_rows(L, t, y.data(), y.data() + n)) != Status::ok) return r;
    const int row = cons[static_cast<std::size_t>(ic)].row;
    double a_free = 0.0, scale = 0.0;
    for (int j = 0; j < n; ++j) {
        const double term = L.T.A(row, j) * E.qdd[j];
        a_free += term;
        scale += std::abs(term);
    }
    a_free += L.T.gamma[row];
    scale += std::abs(L.T.gamma[row]);
    released = a_free > -RELEASE_RTOL * scale;
    return Status::ok;
}

void set_event(EventInfo& ev, const Loop& L, double t, const Point& before, const Vec& y_after,
               const std::vector<std::uint8_t>& act_before) {
    ev.t = t;
    ev.q_before = before.q;
    ev.qd_before = before.qd;
    ev.q_after = y_after.head(L.n);
    ev.qd_after = y_after.tail(L.n);
    ev.active_before = act_before;
    ev.active_after = L.active;
}

Status apply_and_record(Loop& L, const FiredStep& st, double best_s, const std::vector<int>& group) {
    EventScratch& E = *L.evs;
    const int n = L.n;
    const double te = st.t_start + best_s;
    Status r;
    // the point at the event (the step end itself when the crossing is there)
    if (best_s < st.h || !st.have_p1) {
        if ((r = at_point(L, st, best_s, E.pe, true)) != Status::ok) return r;
    } else {
        E.pe = L.p1;
        if (std::isnan(E.pe.cond) && (r = point(L, te, L.yq1.data(), L.yq1.data() + n, E.pe, true)) != Status::ok)
            return r;
    }
    for (int i = 0; i < n; ++i) {
        E.y[i] = E.pe.q[i];
        E.y[n + i] = E.pe.qd[i];
    }
    // the friction forces' work up to the event (sim_friction.cpp)
    if (!L.fric.empty() && (r = friction_work_step(L, te, E.y.data(), E.pe)) != Status::ok) return r;
    std::size_t out_i = L.out_i;
    if (!L.every && (r = sample_until(L, st, te, out_i)) != Status::ok) return r;
    record_sample(L, E.pe, te);
    // W is continuous across the event: the samples after it read W at te
    L.wk = std::isnan(E.pe.work) ? work_at(L, te) : E.pe.work;
    L.wk_on = false;
    std::vector<int> impacts;
    std::vector<std::uint8_t> plastic;
    const std::vector<std::uint8_t> act_start = L.active;
    std::vector<int> fired_fric;  // friction contacts whose guard fired (sim_friction.cpp)
    for (int gi : group)
        if (L.guards[static_cast<std::size_t>(gi)].fric >= 0) fired_fric.push_back(L.guards[static_cast<std::size_t>(gi)].fric);
    for (int gi : group)
        if (!L.guards[static_cast<std::size_t>(gi)].release && L.guards[static_cast<std::size_t>(gi)].fric < 0) {
            impacts.push_back(L.guards[static_cast<std::size_t>(gi)].constraint);
            plastic.push_back(L.guards[static_cast<std::size_t>(gi)].g <= 0.0);
        }
    double h_cap = 0.0;
    Point* p = &E.pe;
    if (!impacts.empty()) {
        E.act_before = L.active;
        std::vector<int> names;  // the fired contacts in declaration order
        for (int ic : E.unilateral)
            if (std::find(impacts.begin(), impacts.end(), ic) != impacts.end()) names.push_back(ic);
        if ((r = set_impact(L, te, E.y, impacts, plastic, detail::adaptive(L) ? 0.0 : L.opt.dt, h_cap)) !=
            Status::ok)
            return r;
        if (L.any_active && (r = stabilize(L, te, E.y.data())) != Status::ok) return r;
        EventInfo ev;
        set_event(ev, L, te, *p, E.y, E.act_before);
        ev.name = "impact:" + join(L, names, "+");
        ev.text = "impact " + join(L, names, "+");
        L.events.push_back(std::move(ev));
        if ((r = point(L, te, E.y.data(), E.y.data() + n, E.pa, true)) != Status::ok) return r;
        p = &E.pa;
    } else {
        for (int gi : group) {
            if (L.guards[static_cast<std::size_t>(gi)].fric >= 0) continue;
            const int ic = L.guards[static_cast<std::size_t>(gi)].constraint;
            bool released = false;
            if ((r = release(L, te, E.y, ic, released)) != Status::ok) return r;
            E.act_before = L.active;
            if (released) {
                E.act_tmp = L.active;
                E.act_tmp[ic] = 0;
                set_active(L, E.act_tmp.data());
            }
            if (L.any_active && (r = stabilize(L, te, E.y.data())) != Status::ok) return r;
            EventInfo ev;
            set_event(ev, L, te, *p, E.y, E.act_before);
            const std::string& nm = L.prog->constraints()[static_cast<std::size_t>(ic)].name;
            ev.name = (released ? "release:" : "release-refused:") + nm;
            ev.text = "release " + nm;
            L.events.push_back(std::move(ev));
            if ((r = point(L, te, E.y.data(), E.y.data() + n, E.pa, true)) != Status::ok) return r;
            p = &E.pa;
        }
    }
    if (!L.fric.empty()) {  // Coulomb friction: the modes after the event (sim_friction.cpp)
        std::vector<int> changed;
        const std::vector<std::uint8_t> before = L.active;
        if ((r = friction_transition(L, te, E.y, fired_fric, act_start, changed)) != Status::ok) return r;
        if (!changed.empty()) {
            if (L.any_active && (r = stabilize(L, te, E.y.data())) != Status::ok) return r;
            for (int j : changed) {
                const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
                const std::string& nm = L.prog->constraints()[static_cast<std::size_t>(f.normal)].name;
                EventInfo ev;
                set_event(ev, L, te, *p, E.y, before);
                const bool stick = L.active[static_cast<std::size_t>(f.tangent)] != 0;
                ev.name = (stick ? "stick:" : (f.slip != 0 ? "slip:" : "open:")) + nm;
                ev.text = stick ? nm + " sticks"
                                : (f.slip != 0 ? nm + " slips (s = " + std::to_string(f.slip) + ")" : nm + " opens");
                L.events.push_back(std::move(ev));
            }
            if ((r = point(L, te, E.y.data(), E.y.data() + n, E.pa, true)) != Status::ok) return r;
            p = &E.pa;
        }
    }
    // the guards of the new active set, at the point after the event
    std::vector<ContactGuard> gs;
    int row_i = 0;
    const auto& cons = L.prog->constraints();
    std::vector<int> first_row(cons.size(), -1);
    for (std::size_t ic = 0; ic < cons.size(); ++ic)
        if (L.active[ic]) {
            first_row[ic] = row_i;
            row_i += cons[ic].dim;
        }
    for (int ic : E.unilateral) gs.push_back({L.active[ic] != 0, ic, L.active[ic] ? first_row[ic] : 0, 0.0});
    const Point& pa = *p;
    // release forces need the rows of the point just evaluated (before any other evaluation)
    const std::vector<ContactGuard> keep = gs;
    set_guards(L, gs);
    bool any_release = false;
    for (const ContactGuard& G : keep) any_release = any_release || G.release;
    if (any_release) release_forces(L, pa.f_c.data());
    for (std::size_t i = 0; i < keep.size(); ++i)
        if (keep[i].release) L.guards[i].g = L.lam_c[keep[i].row];
    bool any_gap = false;
    for (const ContactGuard& G : keep)
        if (!G.release) {
            L.one_mask[static_cast<std::size_t>(G.constraint)] = 1;
            any_gap = true;
        }
    if (any_gap) {
        r = gaps(L, te, E.y.data(), E.y.data() + n, L.one_mask.data());
        std::fill(L.one_mask.begin(), L.one_mask.end(), 0);
        if (r != Status::ok) return r;
        for (std::size_t i = 0; i < keep.size(); ++i)
            if (!keep[i].release) L.guards[i].g = L.T.phi[cons[static_cast<std::size_t>(keep[i].constraint)].row];
    }
    if (!L.fric.empty()) {  // (L.lam_c: the release forces at the point after the event)
        if ((r = friction_append_guards(L, te, E.y)) != Status::ok) return r;
    }
    record_sample(L, pa, te);
    friction_work_commit(L, pa);  // (W continuous across the event; F after it)
    // leave the loop at the event
    while (out_i < L.t_out.size() && L.t_out[out_i] <= te) ++out_i;
    L.out_i = out_i;
    L.t = te;
    L.y = E.y;
    L.have_f = false;
    L.h = detail::adaptive(L) ? (h_cap > 0.0 ? std::min(st.h_next, h_cap) : st.h_next) : L.opt.dt;
    return Status::ok;
}

}  // namespace

// The `fired` branch of the driver's loop for contact guards.
Status contact_event(Loop& L, const FiredStep& st) {
    EventScratch& E = *L.evs;
    L.events.clear();
    const std::size_t rec_mark = L.rec.size();
    const std::vector<std::uint8_t> active0 = L.active;
    const std::vector<ContactGuard> guards0 = L.guards;
    const std::vector<FrictionContact> fric0 = L.fric;
    const double wk0 = L.wk;
    E.roots.clear();
    Status r = Status::ok;
    for (std::size_t i = 0; i < L.guards.size() && r == Status::ok; ++i) {
        const ContactGuard G = L.guards[i];
        const double g0 = G.g, g1 = L.guard_new[i];
        const bool pull = L.guard_pull[i] != 0;
        if (!((g0 > 0.0 && g1 <= 0.0) || (!G.release && g0 <= 0.0 && g1 < 0.0) || pull)) continue;
        double s_root;
        if ((!G.release && g0 <= 0.0) || pull) {
            // a bounce too short to resolve, a start inside the obstacle, or a contact pulling
            // from the step start (run start, after a transition): the event is at the start
            s_root = 0.0;
        } else if (g1 == 0.0) {
            s_root = st.h;
        } else {
            auto gfun = [&](double s, double& g) { return guard_at(L, st, G, s, g); };
            bool bracket = true;
            r = brent(gfun, 0.0, st.h, EVENT_XTOL, EVENT_RTOL, EVENT_MAX_ITER, s_root, bracket);
            if (r == Status::ok && !bracket) s_root = st.h;  // re-evaluated ends lost the sign change
            if (r == Status::ok) r = past_root(gfun, s_root, st.h, g0);
        }
        E.roots.emplace_back(s_root, static_cast<int>(i));
    }
    if (r == Status::ok && E.roots.empty()) r = Status::not_finite;  // (cannot happen: a guard fired)
    if (r == Status::ok) {
        std::sort(E.roots.begin(), E.roots.end());
        const double best_s = E.roots.front().first;
        std::vector<int> group;
        for (const auto& [s_i, i] : E.roots)
            if (s_i <= best_s + 4.0 * EVENT_XTOL) group.push_back(i);
        std::sort(group.begin(), group.end());
        r = apply_and_record(L, st, best_s, group);
    }
    if (r != Status::ok) {  // nothing happened: the Python driver takes the step
        truncate(L.rec, rec_mark);
        L.fw_step = false;
        L.wk = wk0;
        L.wk_on = false;
        L.fric = fric0;
        set_active(L, active0.data());
        set_guards(L, guards0);
        L.events.clear();
    }
    return r;
}

}  // namespace nonmin::sim
