// Coulomb friction at point contacts in the engine's loop and event layer (see
// nonmin/sim/events.hpp "friction" and docs/theory.md "Coulomb friction"). Specified by the
// NumPy reference nonmin.core.friction (slip_dynamics, the per-state solve; stick_forces).
//
// A contact is open (normal inactive), sticking (normal and tangential rows active: a bilateral
// constraint, its force λ_t read from f_c like the normal force λ_n) or slipping with direction
// s = ±1 (tangential row inactive, the force F = −μ s N along it: f = a_tᵀ F). N is the normal
// force the projection gives with that force applied; f_c is affine in the applied force
// (f_c = −S (f + h − M Ω q̇), eq. (fc_R)), so N = N0 + Σ_j λ_n(f_c(a_tj)) F_j: with
// F_j = −μ_j s_j N_j this is (I + K D) N = N0, K_ij = λ_n,i(f_c(a_tj)) (= −λ_n,i(S a_tj)),
// D = diag(μ_j s_j), solved exactly. When I + K D is not a P-matrix (one contact:
// 1 + K μ s ≤ 0) no consistent normal force exists (Painlevé): reported, not integrated.
#include "nonmin/sim/events.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace nonmin::sim {

namespace {

constexpr int MAX_SLIP = 8;  // slipping contacts solved at once (P-matrix test over 2^k − 1 minors)

// the row of constraint ic among the active rows (−1 when inactive)
int active_row(const Loop& L, int ic) {
    const auto& cons = L.prog->constraints();
    int row = 0;
    for (int c = 0; c < L.c; ++c) {
        if (c == ic) return L.active[static_cast<std::size_t>(c)] ? row : -1;
        if (L.active[static_cast<std::size_t>(c)]) row += cons[static_cast<std::size_t>(c)].dim;
    }
    return -1;
}

// release_forces' buffers sized for the current active rows
void ensure_release(Loop& L) {
    if (L.m > 0 && L.DA.rows() != L.m) {
        L.DA = Mat::Zero(L.m, L.n);
        L.svd_a = Svd(L.m, L.n, Eigen::ComputeThinU | Eigen::ComputeThinV);
    }
    const int sz = std::max(L.m, L.n);
    if (L.lam_c.size() < sz) {
        L.lam_c = Vec::Zero(sz);
        L.lam_tmp = Vec::Zero(sz);
    }
}

// Gaussian elimination with partial pivoting on a k × k row-major copy: the determinant, and
// (when x is given) the solution of a x = b.
double gauss(const double* a_in, int k, const double* b, double* x) {
    double a[MAX_SLIP * MAX_SLIP], r[MAX_SLIP];
    for (int i = 0; i < k * k; ++i) a[i] = a_in[i];
    for (int i = 0; i < k; ++i) r[i] = b ? b[i] : 0.0;
    double det = 1.0;
    for (int c = 0; c < k; ++c) {
        int p = c;
        for (int i = c + 1; i < k; ++i)
            if (std::abs(a[i * k + c]) > std::abs(a[p * k + c])) p = i;
        if (a[p * k + c] == 0.0) return 0.0;
        if (p != c) {
            for (int j = 0; j < k; ++j) std::swap(a[p * k + j], a[c * k + j]);
            std::swap(r[p], r[c]);
            det = -det;
        }
        det *= a[c * k + c];
        for (int i = c + 1; i < k; ++i) {
            const double f = a[i * k + c] / a[c * k + c];
            for (int j = c; j < k; ++j) a[i * k + j] -= f * a[c * k + j];
            r[i] -= f * r[c];
        }
    }
    if (x) {
        for (int i = k - 1; i >= 0; --i) {
            double s = r[i];
            for (int j = i + 1; j < k; ++j) s -= a[i * k + j] * x[j];
            x[i] = s / a[i * k + i];
        }
    }
    return det;
}

// The smallest principal minor of W (k × k) and the subset where it is (bit mask).
double min_principal_minor(const double* W, int k, int& where) {
    double sub[MAX_SLIP * MAX_SLIP];
    int idx[MAX_SLIP];
    double best = 1.0 / 0.0;
    where = 0;
    for (int mask = 1; mask < (1 << k); ++mask) {
        int s = 0;
        for (int i = 0; i < k; ++i)
            if (mask & (1 << i)) idx[s++] = i;
        for (int i = 0; i < s; ++i)
            for (int j = 0; j < s; ++j) sub[i * s + j] = W[idx[i] * k + idx[j]];
        const double d = gauss(sub, s, nullptr, nullptr);
        if (d < best) {
            best = d;
            where = mask;
        }
    }
    return best;
}

// the tangential velocity v_t = A_t q̇ of contact j at (t, q, qd) (one evaluation of its rows;
// vt[0..dim))
Status tangent_velocity(Loop& L, int j, double t, const double* q, const double* qd, double* vt) {
    const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
    const auto& cons = L.prog->constraints();
    L.one_mask[static_cast<std::size_t>(f.tangent)] = 1;
    const Status r = L.prog->evaluate(t, q, qd, L.one_mask.data(), NEED_A, L.T, *L.ws);
    L.one_mask[static_cast<std::size_t>(f.tangent)] = 0;
    if (r != Status::ok) return r;
    const int row = cons[static_cast<std::size_t>(f.tangent)].row;
    for (int k = 0; k < f.dim; ++k) {
        vt[k] = 0.0;
        for (int i = 0; i < L.n; ++i) vt[k] += L.T.A(row + k, i) * qd[i];
        if (!std::isfinite(vt[k])) return Status::not_finite;
    }
    return Status::ok;
}

double norm2(const double* v, int dim) { return dim == 1 ? std::abs(v[0]) : std::hypot(v[0], v[1]); }

// λ_n and λ_t (dim entries) of contact j at the point just evaluated (f_c), current active set
void contact_lambda(Loop& L, int j, const double* fc, double& lam_n, double* lam_t) {
    const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
    ensure_release(L);
    release_forces(L, fc);
    const int rn = active_row(L, f.normal), rt = active_row(L, f.tangent);
    lam_n = rn >= 0 ? L.lam_c[rn] : 0.0;
    for (int k = 0; k < f.dim; ++k) lam_t[k] = rt >= 0 ? L.lam_c[rt + k] : 0.0;
}

// slip along v (dim entries, |v| > 0): s = sign for one row, the unit direction for two
void slip_along(FrictionContact& f, const double* v) {
    if (f.dim == 1) {
        f.slip = v[0] > 0.0 ? 1 : -1;
        f.dir[0] = f.slip;
        return;
    }
    const double nv = norm2(v, 2);
    f.slip = 1;
    f.dir[0] = v[0] / nv;
    f.dir[1] = v[1] / nv;
}

void set_tangent(Loop& L, int j, bool on) {
    const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
    if ((L.active[static_cast<std::size_t>(f.tangent)] != 0) == on) return;
    std::vector<std::uint8_t> act = L.active;
    act[static_cast<std::size_t>(f.tangent)] = on ? 1 : 0;
    set_active(L, act.data());
}

// mode 0: fresh (slip along v_t when |v_t| > threshold, else stick if the sticking force lies
// in the cone, else slip opposite to it); 1: sticking broke (slip opposite to the sticking
// force); 2: slipping stopped (stick if in the cone, else slip opposite to the sticking force)
Status decide(Loop& L, double t, const Vec& y, int j, int mode) {
    FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
    const int n = L.n;
    const double* q = y.data();
    const double* qd = y.data() + n;
    Status r;
    if (!L.active[static_cast<std::size_t>(f.normal)]) {
        set_tangent(L, j, false);
        f.slip = 0;
        friction_mask(L);
        return Status::ok;
    }
    if (mode == 0 || (mode == 2 && f.dim == 2)) {  // (two rows: the slip speed may not reach 0)
        double vt[2] = {0.0, 0.0};
        if ((r = tangent_velocity(L, j, t, q, qd, vt)) != Status::ok) return r;
        if (norm2(vt, f.dim) > L.fr_vthresh) {
            set_tangent(L, j, false);
            slip_along(f, vt);
            friction_mask(L);
            return Status::ok;
        }
    }
    const int slip_before = f.slip;
    const double dir_before[2] = {f.dir[0], f.dir[1]};
    f.slip = 0;
    set_tangent(L, j, true);
    friction_mask(L);
    if ((r = point(L, t, q, qd, L.fr_p, false)) != Status::ok) return r;
    double lam_n = 0.0, lam_t[2] = {0.0, 0.0};
    contact_lambda(L, j, L.fr_p.f_c.data(), lam_n, lam_t);
    if (mode != 1 && norm2(lam_t, f.dim) <= f.mu * lam_n) return Status::ok;  // sticks
    set_tangent(L, j, false);
    if (norm2(lam_t, f.dim) > 0.0) {  // slip opposite to the sticking force
        const double mv[2] = {-lam_t[0], -lam_t[1]};
        slip_along(f, mv);
    } else {
        f.slip = slip_before != 0 ? slip_before : 1;
        f.dir[0] = slip_before != 0 ? dir_before[0] : 1.0;
        f.dir[1] = slip_before != 0 ? dir_before[1] : 0.0;
    }
    friction_mask(L);
    return Status::ok;
}

}  // namespace

void set_friction(Loop& L, const std::vector<FrictionContact>& contacts) {
    L.fric = contacts;
    for (FrictionContact& f : L.fric) {
        f.dim = std::min(L.prog->constraints()[static_cast<std::size_t>(f.tangent)].dim, 2);
        if (f.dim == 1) f.dir[0] = f.slip;
    }
    const int k = static_cast<int>(contacts.size());
    const int mr = std::max(L.m_all, 1);
    L.fr_J.reserve(static_cast<std::size_t>(k));
    L.fr_rown.reserve(static_cast<std::size_t>(k));
    L.fr_N.assign(static_cast<std::size_t>(k), 0.0);
    L.fr_g = Vec::Zero(L.n);
    L.fr_zero = Vec::Zero(mr);
    L.fr_N0 = Vec::Zero(MAX_SLIP);
    L.fr_W = Vec::Zero(MAX_SLIP * MAX_SLIP);
    L.fr_tmp = Vec::Zero(MAX_SLIP);
    L.fr_rq = Mat::Zero(std::max(k, 1), L.n);
    L.fr_rf = Mat::Zero(std::max(k, 1), L.n);
    L.fr_p.q = L.fr_p.qd = L.fr_p.qdd = L.fr_p.f_c = Vec::Zero(L.n);
    L.fr_p.u = Vec::Zero(L.k);
    L.painleve = -1;
    L.fw_f0 = L.fw_f1 = L.fw_ym = Vec::Zero(2 * L.n);
    L.fw_p.q = L.fw_p.qd = L.fw_p.qdd = L.fw_p.f_c = Vec::Zero(L.n);
    L.fw_p.u = Vec::Zero(L.k);
    L.fw_have0 = L.fw_step = false;
    if (L.one_mask.size() != static_cast<std::size_t>(L.c)) L.one_mask.assign(static_cast<std::size_t>(L.c), 0);
    ensure_release(L);
    friction_mask(L);
}

void friction_mask(Loop& L) {
    if (L.fric.empty()) return;
    L.eval_mask = L.active;
    for (const FrictionContact& f : L.fric)
        if (f.slip != 0 && L.active[static_cast<std::size_t>(f.normal)] && !L.active[static_cast<std::size_t>(f.tangent)])
            L.eval_mask[static_cast<std::size_t>(f.tangent)] = 1;
}

Status friction_forces(Loop& L, double t, const double* qd, double* qdd, double* fc) {
    L.fr_J.clear();
    L.fr_power = 0.0;
    const int nf = static_cast<int>(L.fric.size());
    for (int j = 0; j < nf; ++j) {
        const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
        if (f.slip != 0 && L.active[static_cast<std::size_t>(f.normal)] && !L.active[static_cast<std::size_t>(f.tangent)])
            L.fr_J.push_back(j);
    }
    const int k = static_cast<int>(L.fr_J.size());
    if (k == 0) return Status::ok;
    if (k > MAX_SLIP) return Status::bad_shape;
    const int n = L.n;
    const auto& cons = L.prog->constraints();
    double gvel[MAX_SLIP];
    // responses to a unit force along each slipping contact's slip direction, g_j = A_tᵀ e_j
    // (e = s for one row; the slip velocity's unit direction for two — the one at the last
    // event when it vanishes): q̈_j = M̄⁻¹P g_j, f_c,j = −S g_j (the held factorization, zero bias)
    for (int b = 0; b < k; ++b) {
        const FrictionContact& fb = L.fric[static_cast<std::size_t>(L.fr_J[b])];
        const int row = cons[static_cast<std::size_t>(fb.tangent)].row;
        double e[2] = {static_cast<double>(fb.slip), 0.0};
        if (fb.dim == 2) {
            double v[2] = {0.0, 0.0};
            for (int kk = 0; kk < 2; ++kk)
                for (int i = 0; i < n; ++i) v[kk] += L.T.A(row + kk, i) * qd[i];
            const double nv = norm2(v, 2);
            // ahead of the direction of the last event: the exact cone (opposite to v_t); past the
            // plane dir·v_t = 0 (where the guard locates the stop) the force keeps −dir, as s does
            // for one row, so the crossing is not smeared over a step
            if (nv > 0.0 && std::isfinite(nv) && v[0] * fb.dir[0] + v[1] * fb.dir[1] > 0.0) {
                e[0] = v[0] / nv;
                e[1] = v[1] / nv;
            } else {
                e[0] = fb.dir[0];
                e[1] = fb.dir[1];
            }
        }
        double gv = 0.0;  // g_b·q̇ = e_b·v_t: the power of a unit force along g_b
        for (int i = 0; i < n; ++i) {
            double gi = 0.0;
            for (int kk = 0; kk < fb.dim; ++kk) gi += e[kk] * L.T.A(row + kk, i);
            L.fr_g[i] = gi;
            gv += gi * qd[i];
        }
        gvel[b] = gv;
        const SolveInfo info = L.solver.again(L.T.M.data(), L.fr_g.data(), L.fr_zero.data(), &L.fr_rq(b, 0),
                                              &L.fr_rf(b, 0));
        if (info.status != Status::ok) return info.status;
    }
    L.fr_rown.clear();
    for (int a = 0; a < k; ++a) L.fr_rown.push_back(active_row(L, L.fric[static_cast<std::size_t>(L.fr_J[a])].normal));
    ensure_release(L);
    release_forces(L, fc);
    for (int a = 0; a < k; ++a) L.fr_N0[a] = L.lam_c[L.fr_rown[a]];
    for (int b = 0; b < k; ++b) {
        const FrictionContact& fb = L.fric[static_cast<std::size_t>(L.fr_J[b])];
        release_forces(L, &L.fr_rf(b, 0));
        for (int a = 0; a < k; ++a)
            L.fr_W[a * k + b] = (a == b ? 1.0 : 0.0) + L.lam_c[L.fr_rown[a]] * fb.mu;
    }
    int where = 0;
    const double pmin = k == 1 ? L.fr_W[0] : min_principal_minor(L.fr_W.data(), k, where);
    if (!(pmin > 0.0)) {
        int a0 = 0;
        if (k > 1)
            while (a0 < k && !(where & (1 << a0))) ++a0;
        L.painleve = L.fr_J[a0];
        L.painleve_t = t;
        L.painleve_den = pmin;
        const FrictionContact& f = L.fric[static_cast<std::size_t>(L.painleve)];
        L.message = "Painlevé's inconsistency at contact '" + cons[static_cast<std::size_t>(f.normal)].name +
                    "' (slip direction " + std::to_string(f.slip) + ", mu = " + std::to_string(f.mu) +
                    ") at t = " + std::to_string(t) + ": 1 + mu s dN/dF = " + std::to_string(pmin) +
                    " <= 0, no normal force is consistent with sliding";
        return Status::not_finite;
    }
    gauss(L.fr_W.data(), k, L.fr_N0.data(), L.fr_tmp.data());
    for (int b = 0; b < k; ++b) {
        const FrictionContact& fb = L.fric[static_cast<std::size_t>(L.fr_J[b])];
        const double N = L.fr_tmp[b];
        L.fr_N[static_cast<std::size_t>(L.fr_J[b])] = N;
        const double F = -fb.mu * N;  // along g_b = A_tᵀ e_b
        L.fr_power += F * gvel[b];
        for (int i = 0; i < n; ++i) {
            qdd[i] += F * L.fr_rq(b, i);
            fc[i] += F * L.fr_rf(b, i);
        }
    }
    return Status::ok;
}

Status friction_guard_value(Loop& L, const ContactGuard& G, double t, const double* q, const double* qd,
                            double& g) {
    const FrictionContact& f = L.fric[static_cast<std::size_t>(G.fric)];
    if (f.slip != 0) {  // s·v_t (one row), dir·v_t (two rows)
        double vt[2] = {0.0, 0.0};
        const Status r = tangent_velocity(L, G.fric, t, q, qd, vt);
        g = f.dim == 1 ? f.slip * vt[0] : f.dir[0] * vt[0] + f.dir[1] * vt[1];
        return r;
    }
    const int rn = active_row(L, f.normal), rt = active_row(L, f.tangent);
    double lt[2] = {0.0, 0.0};
    for (int k = 0; k < f.dim && rt >= 0; ++k) lt[k] = L.lam_c[rt + k];
    g = (rn >= 0 && rt >= 0) ? f.mu * L.lam_c[rn] - norm2(lt, f.dim) : 0.0;
    return std::isfinite(g) ? Status::ok : Status::not_finite;
}

namespace {

// the friction guards of the current active set (values left 0)
void push_guards(Loop& L) {
    const int nf = static_cast<int>(L.fric.size());
    for (int j = 0; j < nf; ++j) {
        const FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
        if (!L.active[static_cast<std::size_t>(f.normal)]) continue;
        if (f.slip == 0 && !L.active[static_cast<std::size_t>(f.tangent)]) continue;
        ContactGuard G;
        G.constraint = f.tangent;
        G.fric = j;
        L.guards.push_back(G);
    }
    L.guard_new.assign(L.guards.size(), 0.0);
    L.guard_pull.assign(L.guards.size(), 0);
}

Status guard_values(Loop& L, std::size_t from, double t, const Vec& y) {
    const int n = L.n;
    for (std::size_t i = from; i < L.guards.size(); ++i) {
        double g = 0.0;
        const Status r = friction_guard_value(L, L.guards[i], t, y.data(), y.data() + n, g);
        if (r != Status::ok) return r;
        L.guards[i].g = g;
    }
    return Status::ok;
}

}  // namespace

Status friction_arm(Loop& L) {
    if (L.fric.empty()) return Status::ok;
    friction_mask(L);
    const std::size_t from = L.guards.size();
    push_guards(L);
    if (L.guards.size() == from) return Status::ok;
    const int n = L.n;
    Status r;
    if ((r = point(L, L.t, L.y.data(), L.y.data() + n, L.fr_p, false)) != Status::ok) return r;
    ensure_release(L);
    release_forces(L, L.fr_p.f_c.data());
    return guard_values(L, from, L.t, L.y);
}

Status friction_append_guards(Loop& L, double t, const Vec& y) {
    if (L.fric.empty()) return Status::ok;
    const std::size_t from = L.guards.size();
    push_guards(L);
    return guard_values(L, from, t, y);
}

Status friction_transition(Loop& L, double t, Vec& y, const std::vector<int>& fired,
                           const std::vector<std::uint8_t>& act_start, std::vector<int>& changed) {
    changed.clear();
    const int nf = static_cast<int>(L.fric.size());
    for (int j = 0; j < nf; ++j) {
        FrictionContact& f = L.fric[static_cast<std::size_t>(j)];
        const bool stick0 = L.active[static_cast<std::size_t>(f.tangent)] != 0;
        const int slip0 = f.slip;
        const double d00 = f.dir[0], d01 = f.dir[1];
        const bool hit = std::find(fired.begin(), fired.end(), j) != fired.end();
        int mode = -1;
        if (!L.active[static_cast<std::size_t>(f.normal)]) {
            if (stick0 || slip0 != 0) mode = 0;
        } else if (hit) {
            mode = stick0 ? 1 : 2;
        } else if (!act_start[static_cast<std::size_t>(f.normal)] || (!stick0 && slip0 == 0)) {
            mode = 0;
        }
        if (mode < 0) continue;
        const Status r = decide(L, t, y, j, mode);
        if (r != Status::ok) return r;
        if (hit || stick0 != (L.active[static_cast<std::size_t>(f.tangent)] != 0) || slip0 != f.slip ||
            (f.dim == 2 && f.slip != 0 && (d00 != f.dir[0] || d01 != f.dir[1])))
            changed.push_back(j);
    }
    return Status::ok;
}

namespace {

// whether a contact slips under the current modes (else the friction forces vanish)
bool any_slipping(const Loop& L) {
    for (const FrictionContact& f : L.fric)
        if (f.slip != 0 && L.active[static_cast<std::size_t>(f.normal)] && !L.active[static_cast<std::size_t>(f.tangent)])
            return true;
    return false;
}

void set_f(Vec& f, const Point& p, int n) {
    for (int i = 0; i < n; ++i) {
        f[i] = p.qd[i];
        f[n + i] = p.qdd[i];
    }
}

}  // namespace

Status friction_work_step(Loop& L, double t1, const double* y1, const Point& p1) {
    L.fw_step = false;
    if (L.fric.empty()) return Status::ok;
    const int n = L.n;
    const double h = t1 - L.t;
    if (!any_slipping(L) || !(h > 0.0)) {  // no friction force on the step: W constant
        L.fw_have0 = false;
        return Status::ok;
    }
    Status r;
    if (!L.fw_have0) {  // F and the power at the step start (after start, resume or a stick)
        if ((r = point(L, L.t, L.y.data(), L.y.data() + n, L.fw_p, false)) != Status::ok) return r;
        set_f(L.fw_f0, L.fw_p, n);
        L.fw_P0 = L.fw_p.fr_power;
    }
    set_f(L.fw_f1, p1, n);
    hermite_quintic(n, L.y.data(), L.fw_f0.data(), y1, L.fw_f1.data(), h, 0.5 * h, L.fw_ym.data());
    if ((r = point(L, L.t + 0.5 * h, L.fw_ym.data(), L.fw_ym.data() + n, L.fw_p, false)) != Status::ok) return r;
    L.fw_step = true;
    L.fw_t0 = L.t;
    L.fw_h = h;
    L.fw_W0 = L.fw;
    L.fw_Pm = L.fw_p.fr_power;
    L.fw_P1 = p1.fr_power;
    return Status::ok;
}

double friction_work_at(const Loop& L, double t) {
    if (!L.fw_step) return L.fw;
    // ∫₀ᵘ of the quadratic through (0, P0), (½, Pm), (1, P1), u = (t − t0)/h; u = 1: Simpson
    const double u = std::clamp((t - L.fw_t0) / L.fw_h, 0.0, 1.0), u2 = u * u, u3 = u2 * u;
    const double a0 = 2.0 * u3 / 3.0 - 1.5 * u2 + u, am = -4.0 * u3 / 3.0 + 2.0 * u2, a1 = 2.0 * u3 / 3.0 - 0.5 * u2;
    return L.fw_W0 + L.fw_h * (a0 * L.fw_P0 + am * L.fw_Pm + a1 * L.fw_P1);
}

void friction_work_commit(Loop& L, const Point& p) {
    if (L.fric.empty()) return;
    if (L.fw_step) L.fw = friction_work_at(L, L.fw_t0 + L.fw_h);
    L.fw_step = false;
    set_f(L.fw_f0, p, L.n);
    L.fw_P0 = p.fr_power;
    L.fw_have0 = true;
}

}  // namespace nonmin::sim
