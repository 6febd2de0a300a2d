// SpatialProgram: evaluation of a spatial multibody description (see nonmin/spatial.hpp).
#include "nonmin/spatial.hpp"

#include "nonmin/dual_terms.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace nonmin {

namespace {

// G(ε) = [−e, e0 I − ẽ] (3 × 4).
template <class S>
inline void G_of(const S* e, S G[3][4]) {
    const S e0 = e[0], e1 = e[1], e2 = e[2], e3 = e[3];
    G[0][0] = -e1; G[0][1] = e0;  G[0][2] = e3;  G[0][3] = -e2;
    G[1][0] = -e2; G[1][1] = -e3; G[1][2] = e0;  G[1][3] = e1;
    G[2][0] = -e3; G[2][1] = e2;  G[2][2] = -e1; G[2][3] = e0;
}

// E(ε) = [−e, e0 I + ẽ] (3 × 4).
template <class S>
inline void E_of(const S* e, S E[3][4]) {
    const S e0 = e[0], e1 = e[1], e2 = e[2], e3 = e[3];
    E[0][0] = -e1; E[0][1] = e0;  E[0][2] = -e3; E[0][3] = e2;
    E[1][0] = -e2; E[1][1] = e3;  E[1][2] = e0;  E[1][3] = -e1;
    E[2][0] = -e3; E[2][1] = -e2; E[2][2] = e1;  E[2][3] = e0;
}

}  // namespace

int SpatialDescription::add_constraint(const std::string& name, ConstraintKind kind, int dim) {
    if (dim < 1) throw EngineError("constraint '" + name + "': dim must be ≥ 1");
    constraints.push_back(ConstraintInfo{name, kind, m_all, dim});
    m_all += dim;
    return static_cast<int>(constraints.size()) - 1;
}

SpatialProgram::SpatialProgram(SpatialDescription desc) : d_(std::move(desc)) {
    const int nb = static_cast<int>(d_.bodies.size());
    if (nb == 0) throw EngineError("a spatial description needs at least one body");
    for (double g : d_.gravity)
        if (!std::isfinite(g)) throw EngineError("gravity must be finite");
    for (const SpatialBody& b : d_.bodies) {
        if (!(std::isfinite(b.mass) && b.mass > 0.0)) throw EngineError("body mass must be > 0");
        for (double x : b.inertia)
            if (!std::isfinite(x)) throw EngineError("body inertia must be finite");
    }
    n_ = 7 * nb;
    m_all_ = d_.m_all;
    k_ = static_cast<int>(d_.actuators.size());
    constraints_ = d_.constraints;
    const int K = static_cast<int>(d_.attachments.size());
    for (const SpatialAttachment& a : d_.attachments)
        if (a.body < -1 || a.body >= nb) throw EngineError("attachment body index out of range");
    auto check_att = [&](int k, const std::string& what) {
        if (k < 0 || k >= K) throw EngineError(what + ": attachment index out of range");
    };
    const int nc = static_cast<int>(d_.constraints.size());
    rows_of_.assign(static_cast<std::size_t>(nc), {});
    std::vector<int> cover(static_cast<std::size_t>(m_all_), 0);
    for (std::size_t i = 0; i < d_.rows.size(); ++i) {
        const SpatialRow& r = d_.rows[i];
        if (r.constraint < 0 || r.constraint >= nc) throw EngineError("row: constraint index out of range");
        const ConstraintInfo& c = d_.constraints[static_cast<std::size_t>(r.constraint)];
        const std::string w = "constraint '" + c.name + "'";
        if (r.offset < 0 || r.offset >= c.dim) throw EngineError(w + ": row offset out of range");
        if (r.norm_body >= nb) throw EngineError(w + ": norm body out of range");
        for (const SpatialTerm& t : r.x) check_att(t.attachment, w);
        for (const SpatialTerm& t : r.y) check_att(t.attachment, w);
        if (r.driver < -1 || r.driver >= static_cast<int>(d_.drivers.size()))
            throw EngineError(w + ": driver index out of range");
        if (r.angle && r.driver < 0) throw EngineError(w + ": an angle row needs a driver");
        for (const SpatialTerm& t : r.x2) check_att(t.attachment, w);
        for (const SpatialTerm& t : r.y2) check_att(t.attachment, w);
        cover[static_cast<std::size_t>(c.row + r.offset)] += 1;
        rows_of_[static_cast<std::size_t>(r.constraint)].push_back(static_cast<int>(i));
    }
    for (const ConstraintInfo& c : d_.constraints)
        for (int r = 0; r < c.dim; ++r)
            if (cover[static_cast<std::size_t>(c.row + r)] != 1)
                throw EngineError("constraint '" + c.name + "': row " + std::to_string(r) + " is defined " +
                                  std::to_string(cover[static_cast<std::size_t>(c.row + r)]) +
                                  " times (expected once)");
    for (std::size_t i = 0; i < d_.drivers.size(); ++i) {
        d_.drivers[i].validate("driver " + std::to_string(i));
        if (!d_.drivers[i].thread_safe()) thread_safe_ = false;
        tape_size_ = std::max(tape_size_, d_.drivers[i].scratch_size());
    }
    for (const SpatialSpring& s : d_.springs) {
        check_att(s.a, "spring");
        check_att(s.b, "spring");
    }
    for (const SpatialActuator& a : d_.actuators) {
        check_att(a.axis, "actuator");
        if (a.kind == SpatialActuatorKind::translation) {
            check_att(a.pa, "actuator");
            check_att(a.pb, "actuator");
        } else if (a.body_a < -1 || a.body_a >= nb || a.body_b < -1 || a.body_b >= nb) {
            throw EngineError("actuator body index out of range");
        }
    }
}

std::unique_ptr<Workspace> SpatialProgram::make_workspace() const {
    auto w = std::make_unique<SpatialWorkspace>();
    size_scratch<double>(*w);
    return w;
}

Status SpatialProgram::evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                                unsigned need, Terms& out, Workspace& wsb) const {
    return eval<double>(t, q, qd, active, need, out, static_cast<SpatialWorkspace&>(wsb));
}

Status SpatialProgram::evaluate_tangent(double t, const double* q, const double* qd, const double* dq,
                                        const double* dqd, const std::uint8_t* active, unsigned need, Terms& out,
                                        Terms& tangent, Workspace& wsb) const {
    auto& w = static_cast<SpatialWorkspace&>(wsb);
    const auto n = static_cast<std::size_t>(n_);
    if (!w.dual) {  // first use of this workspace for derivatives
        w.dual = std::make_unique<SpatialScratch<Dual>>();
        size_scratch(*w.dual);
        w.dq.assign(n, Dual());
        w.dqd.assign(n, Dual());
        w.dterms.resize(n_, k_, m_all_);
    }
    for (std::size_t i = 0; i < n; ++i) {
        w.dq[i] = Dual(q[i], dq[i]);
        w.dqd[i] = Dual(qd[i], dqd[i]);
    }
    const Status st = eval<Dual>(t, w.dq.data(), w.dqd.data(), active, need, w.dterms, *w.dual);
    if (st != Status::ok) return st;
    split_dual(w.dterms, need, out, tangent);
    return Status::ok;
}

Status SpatialProgram::residual_tangents(const ResidualQuery& rq, Workspace& wsb) const {
    auto& w = static_cast<SpatialWorkspace&>(wsb);
    if (!w.wide) {
        w.wide = std::make_unique<SpatialScratch<DualW>>();
        size_scratch(*w.wide);
    }
    return chunked_residual_tangents<DUAL_WIDTH>(
        *this, rq, w.wres, [&](const DualW* q, const DualW* qd, unsigned need, TermsOf<DualW>& terms) {
            return eval<DualW>(rq.t, q, qd, rq.active, need, terms, *w.wide);
        });
}

// The evaluation on the scalar S (double: evaluate; Dual, DualW: derivatives). Drivers are
// functions of t alone, evaluated in double.
template <class S>
Status SpatialProgram::eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need,
                            TermsOf<S>& out, SpatialScratch<S>& w) const {
    using std::isfinite;
    using std::sqrt;
    const int n = n_;
    {
        S acc = S(0.0);
        for (int i = 0; i < n; ++i) acc += q[i] * q[i] + qd[i] * qd[i];
        if (!isfinite(acc)) {
            for (int i = 0; i < n; ++i)
                if (!isfinite(q[i]) || !isfinite(qd[i])) return Status::not_finite;
        }
    }
    const std::size_t K = d_.attachments.size();
    // ---------------------------------------------------------------- attachment kinematics
    for (std::size_t k = 0; k < K; ++k) {
        const SpatialAttachment& at = d_.attachments[k];
        S* val = &w.val[3 * k];
        S* vel = &w.vel[3 * k];
        S* acc = &w.acc[3 * k];
        S* Qe = &w.Qe[12 * k];
        if (at.body < 0) {
            for (int a = 0; a < 3; ++a) {
                val[a] = S(at.value[static_cast<std::size_t>(a)]);
                vel[a] = acc[a] = S(0.0);
            }
            for (int j = 0; j < 12; ++j) Qe[j] = S(0.0);
            continue;
        }
        const int o = 7 * at.body;
        const S* e = q + o + 3;
        const S* ed = qd + o + 3;
        const double* Q = at.Q.data();
        for (int a = 0; a < 3; ++a) {
            S v = S(0.0), vd = S(0.0), ac = S(0.0);
            for (int j = 0; j < 4; ++j) {
                const double* Qaj = Q + 16 * a + 4 * j;
                const S qe = Qaj[0] * e[0] + Qaj[1] * e[1] + Qaj[2] * e[2] + Qaj[3] * e[3];
                const S qed = Qaj[0] * ed[0] + Qaj[1] * ed[1] + Qaj[2] * ed[2] + Qaj[3] * ed[3];
                Qe[4 * a + j] = qe;
                v += qe * e[j];
                vd += qe * ed[j];
                ac += qed * ed[j];
            }
            val[a] = at.point ? v + q[o + a] : v;
            vel[a] = at.point ? 2.0 * vd + qd[o + a] : 2.0 * vd;
            acc[a] = 2.0 * ac;
        }
    }
    // coef · J_kᵀ w added to f (n-vector): J_k = [I (points), 2 Q(s) ε] in the body's columns
    auto add_JT = [&](S* f, int k, const S* wv, const S& coef) {
        const SpatialAttachment& at = d_.attachments[static_cast<std::size_t>(k)];
        if (at.body < 0) return;
        const int o = 7 * at.body;
        if (at.point)
            for (int a = 0; a < 3; ++a) f[o + a] += coef * wv[a];
        const S* Qe = &w.Qe[12 * static_cast<std::size_t>(k)];
        for (int j = 0; j < 4; ++j)
            f[o + 3 + j] += 2.0 * coef * (wv[0] * Qe[j] + wv[1] * Qe[4 + j] + wv[2] * Qe[8 + j]);
    };
    const std::size_t nb = d_.bodies.size();
    // ---------------------------------------------------------------- M
    if (need & NEED_M) {
        out.M.setZero();
        for (std::size_t i = 0; i < nb; ++i) {
            const SpatialBody& b = d_.bodies[i];
            const int o = 7 * static_cast<int>(i);
            for (int a = 0; a < 3; ++a) out.M(o + a, o + a) = S(b.mass);
            S G[3][4], JG[3][4];
            G_of(q + o + 3, G);
            for (int a = 0; a < 3; ++a)
                for (int j = 0; j < 4; ++j)
                    JG[a][j] = b.inertia[3 * a] * G[0][j] + b.inertia[3 * a + 1] * G[1][j] +
                               b.inertia[3 * a + 2] * G[2][j];
            for (int i2 = 0; i2 < 4; ++i2)
                for (int j = 0; j < 4; ++j)
                    out.M(o + 3 + i2, o + 3 + j) =
                        4.0 * (G[0][i2] * JG[0][j] + G[1][i2] * JG[1][j] + G[2][i2] * JG[2][j]);
        }
    }
    // ---------------------------------------------------------------- h, f_passive, energy
    S V = S(0.0), T = S(0.0);
    if (need & (NEED_H | NEED_ENERGY)) {
        S* h = out.h.data();
        S* fp = out.f_passive.data();
        if (need & NEED_H) {
            out.h.setZero();
            out.f_passive.setZero();
        }
        for (std::size_t i = 0; i < nb; ++i) {
            const SpatialBody& b = d_.bodies[i];
            const int o = 7 * static_cast<int>(i);
            const S* e = q + o + 3;
            const S* ed = qd + o + 3;
            S G[3][4];
            G_of(e, G);
            S wb[3], Jw[3];  // G ε̇ (half the body angular velocity) and J G ε̇
            for (int a = 0; a < 3; ++a) wb[a] = G[a][0] * ed[0] + G[a][1] * ed[1] + G[a][2] * ed[2] + G[a][3] * ed[3];
            for (int a = 0; a < 3; ++a)
                Jw[a] = b.inertia[3 * a] * wb[0] + b.inertia[3 * a + 1] * wb[1] + b.inertia[3 * a + 2] * wb[2];
            if (need & NEED_H) {
                for (int a = 0; a < 3; ++a) h[o + a] = S(b.mass * d_.gravity[static_cast<std::size_t>(a)]);
                S Gd[3][4];
                G_of(ed, Gd);
                for (int j = 0; j < 4; ++j)
                    h[o + 3 + j] = -8.0 * (Gd[0][j] * Jw[0] + Gd[1][j] * Jw[1] + Gd[2][j] * Jw[2]);
            }
            if (need & NEED_ENERGY) {
                for (int a = 0; a < 3; ++a) {
                    T += 0.5 * b.mass * qd[o + a] * qd[o + a];
                    V -= b.mass * d_.gravity[static_cast<std::size_t>(a)] * q[o + a];
                }
                T += 2.0 * (wb[0] * Jw[0] + wb[1] * Jw[1] + wb[2] * Jw[2]);
            }
        }
        for (const SpatialSpring& s : d_.springs) {
            const S* pa = &w.val[3 * static_cast<std::size_t>(s.a)];
            const S* pb = &w.val[3 * static_cast<std::size_t>(s.b)];
            const S d[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
            const S ell = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            V += 0.5 * s.stiffness * (ell - s.rest_length) * (ell - s.rest_length);
            if (!(need & NEED_H)) continue;
            if (s.stiffness != 0.0) {
                S coef = S(0.0);
                bool on = false;
                if (s.rest_length == 0.0) coef = S(-s.stiffness), on = true;
                else if (ell > 0.0) coef = -s.stiffness * (ell - s.rest_length) / ell, on = true;
                if (on) {
                    add_JT(h, s.b, d, coef);
                    add_JT(h, s.a, d, -coef);
                }
            }
            if (s.damping != 0.0 && ell > 0.0) {
                const S* va = &w.vel[3 * static_cast<std::size_t>(s.a)];
                const S* vb = &w.vel[3 * static_cast<std::size_t>(s.b)];
                const S u[3] = {d[0] / ell, d[1] / ell, d[2] / ell};
                const S rate = u[0] * (vb[0] - va[0]) + u[1] * (vb[1] - va[1]) + u[2] * (vb[2] - va[2]);
                add_JT(fp, s.b, u, -s.damping * rate);
                add_JT(fp, s.a, u, s.damping * rate);
            }
        }
        if (need & NEED_ENERGY) {
            out.kinetic = T;
            out.potential = V;
        }
    }
    // ---------------------------------------------------------------- B
    if ((need & NEED_B) && k_ > 0) {
        out.B.setZero();
        std::vector<S>& col = w.col;
        for (int c = 0; c < k_; ++c) {
            const SpatialActuator& ac = d_.actuators[static_cast<std::size_t>(c)];
            std::fill(col.begin(), col.end(), S(0.0));
            const S* axis = &w.val[3 * static_cast<std::size_t>(ac.axis)];
            if (ac.kind == SpatialActuatorKind::rotation) {
                const int bodies[2] = {ac.body_b, ac.body_a};
                const double signs[2] = {1.0, -1.0};
                for (int s = 0; s < 2; ++s) {
                    if (bodies[s] < 0) continue;
                    const int o = 7 * bodies[s];
                    S E[3][4];
                    E_of(q + o + 3, E);
                    for (int j = 0; j < 4; ++j)
                        col[static_cast<std::size_t>(o + 3 + j)] +=
                            signs[s] * 2.0 * (E[0][j] * axis[0] + E[1][j] * axis[1] + E[2][j] * axis[2]);
                }
            } else {
                const S* pa = &w.val[3 * static_cast<std::size_t>(ac.pa)];
                const S* pb = &w.val[3 * static_cast<std::size_t>(ac.pb)];
                const S d[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
                add_JT(col.data(), ac.pb, axis, S(1.0));
                add_JT(col.data(), ac.pa, axis, S(-1.0));
                add_JT(col.data(), ac.axis, d, S(1.0));
            }
            for (int i = 0; i < n; ++i) out.B(i, c) = col[static_cast<std::size_t>(i)];
        }
    }
    // ---------------------------------------------------------------- constraints
    const unsigned cneed = need & (NEED_A | NEED_GAMMA | NEED_PHI | NEED_VELOCITY);
    if (cneed && m_all_ > 0) {
        const bool wantA = (need & NEED_A) != 0;
        S* A = out.A.data();
        for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
            if (!active[ci]) continue;
            const ConstraintInfo& c = d_.constraints[ci];
            if (wantA) std::fill(A + static_cast<std::ptrdiff_t>(c.row) * n,
                                 A + static_cast<std::ptrdiff_t>(c.row + c.dim) * n, S(0.0));
            for (int ri : rows_of_[ci]) {
                const SpatialRow& r = d_.rows[static_cast<std::size_t>(ri)];
                const int row = c.row + r.offset;
                S* Ar = A + static_cast<std::ptrdiff_t>(row) * n;
                if (r.norm_body >= 0) {
                    const int o = 7 * r.norm_body + 3;
                    const S* e = q + o;
                    const S* ed = qd + o;
                    out.phi[row] = 0.5 * ((e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3]) - 1.0);
                    out.gamma[row] = ed[0] * ed[0] + ed[1] * ed[1] + ed[2] * ed[2] + ed[3] * ed[3];
                    out.velocity[row] = e[0] * ed[0] + e[1] * ed[1] + e[2] * ed[2] + e[3] * ed[3];
                    if (wantA)
                        for (int j = 0; j < 4; ++j) Ar[o + j] = e[j];
                    continue;
                }
                // φ = X·Y of one (x, y) term pair: value, rate A q̇, bias Ȧ q̇; adds scale·A to the row
                auto dot_row = [&](const std::vector<SpatialTerm>& xs, const std::vector<SpatialTerm>& ys,
                                   double scale, S& P, S& Pd, S& G) {
                    S X[3] = {S(0.0), S(0.0), S(0.0)}, Y[3] = {S(0.0), S(0.0), S(0.0)};
                    S Xd[3] = {S(0.0), S(0.0), S(0.0)}, Yd[3] = {S(0.0), S(0.0), S(0.0)};
                    S Xa[3] = {S(0.0), S(0.0), S(0.0)}, Ya[3] = {S(0.0), S(0.0), S(0.0)};
                    for (const SpatialTerm& tm : xs) {
                        const std::size_t k = static_cast<std::size_t>(tm.attachment);
                        for (int a = 0; a < 3; ++a) {
                            X[a] += tm.coef * w.val[3 * k + a];
                            Xd[a] += tm.coef * w.vel[3 * k + a];
                            Xa[a] += tm.coef * w.acc[3 * k + a];
                        }
                    }
                    for (const SpatialTerm& tm : ys) {
                        const std::size_t k = static_cast<std::size_t>(tm.attachment);
                        for (int a = 0; a < 3; ++a) {
                            Y[a] += tm.coef * w.val[3 * k + a];
                            Yd[a] += tm.coef * w.vel[3 * k + a];
                            Ya[a] += tm.coef * w.acc[3 * k + a];
                        }
                    }
                    P = X[0] * Y[0] + X[1] * Y[1] + X[2] * Y[2];
                    Pd = Xd[0] * Y[0] + Xd[1] * Y[1] + Xd[2] * Y[2] + X[0] * Yd[0] + X[1] * Yd[1] + X[2] * Yd[2];
                    G = 2.0 * (Xd[0] * Yd[0] + Xd[1] * Yd[1] + Xd[2] * Yd[2]) +
                        (X[0] * Ya[0] + X[1] * Ya[1] + X[2] * Ya[2]) + (Y[0] * Xa[0] + Y[1] * Xa[1] + Y[2] * Xa[2]);
                    if (wantA && scale != 0.0) {
                        for (const SpatialTerm& tm : xs) add_JT(Ar, tm.attachment, Y, S(scale * tm.coef));
                        for (const SpatialTerm& tm : ys) add_JT(Ar, tm.attachment, X, S(scale * tm.coef));
                    }
                };
                if (r.angle) {
                    double f[3];
                    const int st = d_.drivers[static_cast<std::size_t>(r.driver)].eval(t, f, w.treg.data());
                    if (st == TimeFunction::EVAL_FAILED) return Status::callback_error;
                    if (st != TimeFunction::EVAL_OK) return Status::not_finite;
                    const double c = std::cos(f[0]), s = std::sin(f[0]);
                    S P1, P1d, G1, P2, P2d, G2;
                    dot_row(r.x, r.y, -s, P1, P1d, G1);
                    dot_row(r.x2, r.y2, c, P2, P2d, G2);
                    const S Sa = s * P2 + c * P1;
                    out.phi[row] = c * P2 - s * P1;
                    out.velocity[row] = c * P2d - s * P1d - f[1] * Sa;
                    out.gamma[row] = c * G2 - s * G1 - 2.0 * f[1] * (s * P2d + c * P1d) - f[2] * Sa -
                                     f[1] * f[1] * (c * P2 - s * P1);
                    continue;
                }
                dot_row(r.x, r.y, 1.0, out.phi[row], out.velocity[row], out.gamma[row]);
                if (r.driver >= 0) {
                    double f[3];
                    const int st = d_.drivers[static_cast<std::size_t>(r.driver)].eval(t, f, w.treg.data());
                    if (st == TimeFunction::EVAL_FAILED) return Status::callback_error;
                    if (st != TimeFunction::EVAL_OK) return Status::not_finite;
                    if (r.square != 0.0) {  // g = s f², ġ = 2 s f ḟ, g̈ = 2 s (ḟ² + f f̈)
                        const double s = r.square;
                        const double g0 = s * f[0] * f[0], g1 = 2.0 * s * f[0] * f[1];
                        f[2] = 2.0 * s * (f[1] * f[1] + f[0] * f[2]);
                        f[0] = g0;
                        f[1] = g1;
                    }
                    out.phi[row] -= f[0];
                    out.velocity[row] -= f[1];
                    out.gamma[row] -= f[2];
                }
            }
        }
    }
    return Status::ok;
}

}  // namespace nonmin
