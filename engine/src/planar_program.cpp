// PlanarProgram: evaluation of a planar multibody description (see nonmin/planar.hpp).
// Formulas: src/nonmin/model/planar/_elements.py (the per-joint reference) and _compiled.py.
#include "nonmin/planar.hpp"

#include "nonmin/dual_terms.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace nonmin {

namespace {

// Kinematics of one body-fixed point: position p, R s, velocity ṗ, θ̇ and the body's columns
// (−1: none, for the ground and a point mass's rotation). S: double or Dual (dual.hpp).
template <class S>
struct PointKin {
    S px, py, rx, ry, vx, vy, om;
    int ix, iy, ith;
};

template <class S>
inline PointKin<S> point_kin(const PlanarDescription& d, const S* cs, const S* sn, const S* q, const S* qd,
                             const PlanarPoint& P) {
    PointKin<S> k;
    if (P.body < 0) {
        k.px = P.sx;
        k.py = P.sy;
        k.rx = P.sx;
        k.ry = P.sy;
        k.vx = k.vy = k.om = S(0.0);
        k.ix = k.iy = k.ith = -1;
        return k;
    }
    const PlanarBody& B = d.bodies[static_cast<std::size_t>(P.body)];
    const S c = cs[P.body];
    const S s = sn[P.body];
    k.rx = c * P.sx - s * P.sy;
    k.ry = s * P.sx + c * P.sy;
    k.px = q[B.ix] + k.rx;
    k.py = q[B.iy] + k.ry;
    k.om = B.ith >= 0 ? qd[B.ith] : S(0.0);
    k.vx = qd[B.ix] - k.om * k.ry;
    k.vy = qd[B.iy] + k.om * k.rx;
    k.ix = B.ix;
    k.iy = B.iy;
    k.ith = B.ith;
    return k;
}

// The scalar type of a pointer argument, not deduced from the value (so that constants mix).
template <class T>
struct Same {
    using type = T;
};

template <class S>
inline void add(S* v, int i, const typename Same<S>::type& x) {
    if (i >= 0) v[i] += x;
}

// Σ over the two ends: D = J_b − J_a; adds coef·Dᵀw to f (w a 2-vector).
template <class S>
inline void add_DT(S* f, const PointKin<S>& a, const PointKin<S>& b, const typename Same<S>::type& wx,
                   const typename Same<S>::type& wy) {
    add(f, b.ix, wx);
    add(f, b.iy, wy);
    add(f, b.ith, -wx * b.ry + wy * b.rx);  // w·(R s_b)^⊥
    add(f, a.ix, -wx);
    add(f, a.iy, -wy);
    add(f, a.ith, wx * a.ry - wy * a.rx);
}

std::string where(const PlanarDescription& d, const PlanarPrim& p) {
    return "constraint '" + d.constraints[static_cast<std::size_t>(p.constraint)].name + "'";
}

}  // namespace

int PlanarDescription::add_body(double mass, double inertia) {
    if (!(std::isfinite(mass) && mass > 0.0))
        throw EngineError("planar body " + std::to_string(bodies.size()) + ": mass must be > 0, got " +
                          std::to_string(mass));
    PlanarBody b;
    b.mass = mass;
    b.inertia = inertia;
    b.ix = n;
    b.iy = n + 1;
    const bool rigid = std::isfinite(inertia) && inertia > 0.0;
    b.ith = rigid ? n + 2 : -1;
    n += rigid ? 3 : 2;
    bodies.push_back(b);
    return static_cast<int>(bodies.size()) - 1;
}

int PlanarDescription::add_constraint(const std::string& name, ConstraintKind kind, int dim) {
    if (dim < 1) throw EngineError("constraint '" + name + "': dim must be ≥ 1");
    constraints.push_back(ConstraintInfo{name, kind, m_all, dim});
    m_all += dim;
    return static_cast<int>(constraints.size()) - 1;
}

PlanarProgram::PlanarProgram(PlanarDescription desc) : d_(std::move(desc)) {
    const int nb = static_cast<int>(d_.bodies.size());
    if (nb == 0) throw EngineError("a planar description needs at least one body");
    if (!(std::isfinite(d_.gx) && std::isfinite(d_.gy))) throw EngineError("gravity must be finite");
    n_ = d_.n;
    m_all_ = d_.m_all;
    k_ = static_cast<int>(d_.actuators.size());
    constraints_ = d_.constraints;
    mdiag_ = Vec::Zero(n_);
    fg_ = Vec::Zero(n_);
    for (const PlanarBody& b : d_.bodies) {
        mdiag_[b.ix] = b.mass;
        mdiag_[b.iy] = b.mass;
        if (b.ith >= 0) mdiag_[b.ith] = b.inertia;
        fg_[b.ix] = b.mass * d_.gx;
        fg_[b.iy] = b.mass * d_.gy;
    }
    auto check_body = [&](int body, const std::string& what, bool rotation) {
        if (body < -1 || body >= nb)
            throw EngineError(what + ": body index " + std::to_string(body) + " out of range [-1, " +
                              std::to_string(nb) + ")");
        if (rotation && body >= 0 && d_.bodies[static_cast<std::size_t>(body)].ith < 0)
            throw EngineError(what + ": body " + std::to_string(body) +
                              " is a point mass and has no rotation coordinate");
    };
    auto check_point = [&](const PlanarPoint& p, const std::string& what) {
        check_body(p.body, what, false);
        if (!(std::isfinite(p.sx) && std::isfinite(p.sy))) throw EngineError(what + ": point not finite");
    };
    const int nc = static_cast<int>(d_.constraints.size());
    prims_of_.assign(static_cast<std::size_t>(nc), {});
    std::vector<int> cover(static_cast<std::size_t>(m_all_), 0);
    for (std::size_t i = 0; i < d_.prims.size(); ++i) {
        const PlanarPrim& p = d_.prims[i];
        if (p.constraint < 0 || p.constraint >= nc)
            throw EngineError("primitive " + std::to_string(i) + ": constraint index out of range");
        const std::string w = where(d_, p);
        const ConstraintInfo& c = d_.constraints[static_cast<std::size_t>(p.constraint)];
        const int rows = p.kind == PlanarPrimKind::pin ? 2 : 1;
        if (p.offset < 0 || p.offset + rows > c.dim)
            throw EngineError(w + ": primitive rows outside the constraint's " + std::to_string(c.dim));
        for (int r = 0; r < rows; ++r) cover[static_cast<std::size_t>(c.row + p.offset + r)] += 1;
        switch (p.kind) {
            case PlanarPrimKind::pin:
                check_point(p.a, w);
                check_point(p.b, w);
                break;
            case PlanarPrimKind::line:
                check_point(p.a, w);
                check_point(p.b, w);
                if (!(std::isfinite(p.ux) && std::isfinite(p.uy)) || std::hypot(p.ux, p.uy) <= 1e-12)
                    throw EngineError(w + ": line axis must be a finite non-zero vector");
                break;
            case PlanarPrimKind::rod:
                check_point(p.a, w);
                check_point(p.b, w);
                if (!(std::isfinite(p.length) && p.length > 0.0))
                    throw EngineError(w + ": rod length must be > 0");
                if (!(p.sign == 1.0 || p.sign == -1.0)) throw EngineError(w + ": rod sign must be ±1");
                break;
            case PlanarPrimKind::angle:
                if (p.angle_bodies.size() != p.angle_coefs.size())
                    throw EngineError(w + ": angle bodies and coefficients differ in length");
                for (int b : p.angle_bodies) check_body(b, w, true);
                break;
            case PlanarPrimKind::coord:
                if (p.coords.size() != p.angle_coefs.size())
                    throw EngineError(w + ": coordinates and coefficients differ in length");
                for (int j : p.coords)
                    if (j < 0 || j >= n_) throw EngineError(w + ": coordinate index out of range");
                break;
            default:
                throw EngineError(w + ": unknown primitive kind");
        }
        for (int dv : {p.driver, p.driver2})
            if (dv < -1 || dv >= static_cast<int>(d_.drivers.size()))
                throw EngineError(w + ": driver index out of range");
        if (p.driver2 >= 0 && p.kind != PlanarPrimKind::pin) throw EngineError(w + ": a second driver needs a pin");
        prims_of_[static_cast<std::size_t>(p.constraint)].push_back(static_cast<int>(i));
    }
    for (const ConstraintInfo& c : d_.constraints)
        for (int r = 0; r < c.dim; ++r)
            if (cover[static_cast<std::size_t>(c.row + r)] != 1)
                throw EngineError("constraint '" + c.name + "': row " + std::to_string(r) + " is defined " +
                                  std::to_string(cover[static_cast<std::size_t>(c.row + r)]) +
                                  " times by the primitives (expected once)");
    for (const PlanarSpring& s : d_.springs) {
        check_point(s.a, "spring");
        check_point(s.b, "spring");
    }
    for (const PlanarRotationalSpring& s : d_.rotational_springs) {
        check_body(s.body_a, "rotational spring", true);
        check_body(s.body_b, "rotational spring", true);
    }
    for (const PlanarActuator& a : d_.actuators) {
        if (a.kind == PlanarActuatorKind::torque) {
            check_body(a.body_a, "torque actuator", true);
            check_body(a.body_b, "torque actuator", true);
        } else {
            check_point(a.a, "actuator");
            if (a.kind == PlanarActuatorKind::prismatic) check_point(a.b, "actuator");
        }
    }
    for (std::size_t i = 0; i < d_.drivers.size(); ++i) {
        const TimeFunction& f = d_.drivers[i].fn;
        f.validate("driver " + std::to_string(i));
        if (!f.thread_safe()) thread_safe_ = false;  // a Python callable holds the GIL
        tape_size_ = std::max(tape_size_, f.scratch_size());
    }
    // The row pattern of A (program.hpp): the columns each primitive's rows write (eval's
    // `add` calls below; the ground and a point mass's rotation have none).
    std::vector<std::vector<int>> rows(static_cast<std::size_t>(m_all_));
    auto put = [&](int row, int col) {
        if (col >= 0) rows[static_cast<std::size_t>(row)].push_back(col);
    };
    auto put_point = [&](int row, const PlanarPoint& pt, bool x, bool y) {
        if (pt.body < 0) return;
        const PlanarBody& B = d_.bodies[static_cast<std::size_t>(pt.body)];
        if (x) put(row, B.ix);
        if (y) put(row, B.iy);
        put(row, B.ith);
    };
    for (const PlanarPrim& p : d_.prims) {
        const int row = d_.constraints[static_cast<std::size_t>(p.constraint)].row + p.offset;
        switch (p.kind) {
            case PlanarPrimKind::pin:
                put_point(row, p.a, true, false);
                put_point(row, p.b, true, false);
                put_point(row + 1, p.a, false, true);
                put_point(row + 1, p.b, false, true);
                break;
            case PlanarPrimKind::line:
            case PlanarPrimKind::rod:
                put_point(row, p.a, true, true);
                put_point(row, p.b, true, true);
                break;
            case PlanarPrimKind::angle:
                for (int b : p.angle_bodies)
                    if (b >= 0) put(row, d_.bodies[static_cast<std::size_t>(b)].ith);
                break;
            case PlanarPrimKind::coord:
                for (int j : p.coords) put(row, j);
                break;
        }
    }
    a_pattern_.start.assign(static_cast<std::size_t>(m_all_) + 1, 0);
    for (int r = 0; r < m_all_; ++r) {
        std::vector<int>& c = rows[static_cast<std::size_t>(r)];
        std::sort(c.begin(), c.end());
        c.erase(std::unique(c.begin(), c.end()), c.end());
        a_pattern_.cols.insert(a_pattern_.cols.end(), c.begin(), c.end());
        a_pattern_.start[static_cast<std::size_t>(r) + 1] = static_cast<int>(a_pattern_.cols.size());
    }
}

std::unique_ptr<Workspace> PlanarProgram::make_workspace() const {
    auto w = std::make_unique<PlanarWorkspace>();
    w->c.assign(d_.bodies.size(), 1.0);
    w->s.assign(d_.bodies.size(), 0.0);
    w->treg.assign(static_cast<std::size_t>(tape_size_) + 1, 0.0);
    return w;
}

Status PlanarProgram::evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                               unsigned need, Terms& out, Workspace& wsb) const {
    auto& w = static_cast<PlanarWorkspace&>(wsb);
    return eval<double>(t, q, qd, active, need, out, w.c.data(), w.s.data(), w.treg.data());
}

Status PlanarProgram::evaluate_tangent(double t, const double* q, const double* qd, const double* dq,
                                       const double* dqd, const std::uint8_t* active, unsigned need,
                                       Terms& out, Terms& tangent, Workspace& wsb) const {
    auto& w = static_cast<PlanarWorkspace&>(wsb);
    const auto n = static_cast<std::size_t>(n_);
    if (w.dq.size() != n) {  // first use of this workspace for derivatives: size the dual scratch
        w.dq.assign(n, Dual());
        w.dqd.assign(n, Dual());
        w.dc.assign(d_.bodies.size(), Dual(1.0));
        w.ds.assign(d_.bodies.size(), Dual(0.0));
        w.dterms.resize(n_, k_, m_all_);
    }
    for (std::size_t i = 0; i < n; ++i) {
        w.dq[i] = Dual(q[i], dq[i]);
        w.dqd[i] = Dual(qd[i], dqd[i]);
    }
    const Status st = eval<Dual>(t, w.dq.data(), w.dqd.data(), active, need, w.dterms, w.dc.data(), w.ds.data(),
                                 w.treg.data());
    if (st != Status::ok) return st;
    split_dual(w.dterms, need, out, tangent);
    return Status::ok;
}

Status PlanarProgram::residual_tangents(const ResidualQuery& rq, Workspace& wsb) const {
    auto& w = static_cast<PlanarWorkspace&>(wsb);
    if (w.wc.size() != d_.bodies.size()) {
        w.wc.assign(d_.bodies.size(), DualW(1.0));
        w.wsn.assign(d_.bodies.size(), DualW(0.0));
    }
    return chunked_residual_tangents<DUAL_WIDTH>(
        *this, rq, w.wide, [&](const DualW* q, const DualW* qd, unsigned need, TermsOf<DualW>& terms) {
            return eval<DualW>(rq.t, q, qd, rq.active, need, terms, w.wc.data(), w.wsn.data(), w.treg.data());
        });
}

// The evaluation on the scalar S (double: evaluate; Dual: evaluate_tangent). The drivers are
// functions of t alone, evaluated in double.
template <class S>
Status PlanarProgram::eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need,
                           TermsOf<S>& out, S* cs, S* sn, double* treg) const {
    using std::cos;
    using std::hypot;
    using std::isfinite;
    using std::sin;
    const int n = n_;
    {
        S acc = S(0.0);
        for (int i = 0; i < n; ++i) acc += q[i] * q[i] + qd[i] * qd[i];
        if (!isfinite(acc) || !std::isfinite(t)) {
            for (int i = 0; i < n; ++i)
                if (!isfinite(q[i]) || !isfinite(qd[i])) return Status::not_finite;
            if (!std::isfinite(t)) return Status::not_finite;
        }
    }
    const std::size_t nb = d_.bodies.size();
    for (std::size_t i = 0; i < nb; ++i) {
        const int ith = d_.bodies[i].ith;
        if (ith >= 0) {
            cs[i] = cos(q[ith]);
            sn[i] = sin(q[ith]);
        } else {
            cs[i] = S(1.0);
            sn[i] = S(0.0);
        }
    }
    if (need & NEED_M) {
        out.M.setZero();
        for (int i = 0; i < n; ++i) out.M(i, i) = mdiag_[i];
    }
    S V_springs = S(0.0);
    const bool want_springs = (need & (NEED_H | NEED_ENERGY)) != 0;
    if (need & NEED_H) {
        for (int i = 0; i < n; ++i) out.h[i] = fg_[i];
        out.f_passive.setZero();
    }
    if (want_springs) {
        S* h = out.h.data();
        S* fp = out.f_passive.data();
        for (const PlanarSpring& sp : d_.springs) {
            const PointKin<S> a = point_kin(d_, cs, sn, q, qd, sp.a);
            const PointKin<S> b = point_kin(d_, cs, sn, q, qd, sp.b);
            const S dx = b.px - a.px, dy = b.py - a.py;
            const S ell2 = dx * dx + dy * dy;
            const S ell = hypot(dx, dy);
            if (sp.stiffness != 0.0) {
                V_springs += 0.5 * sp.stiffness * (ell - sp.rest_length) * (ell - sp.rest_length);
                if (need & NEED_H) {
                    if (ell > 0.0) {
                        const S coef = -sp.stiffness * (1.0 - sp.rest_length / ell);
                        add_DT(h, a, b, coef * dx, coef * dy);
                    } else if (sp.rest_length != 0.0) {
                        return Status::not_finite;  // zero length: force direction undefined
                    }
                }
            }
            if (sp.damping != 0.0 && (need & NEED_H) && ell2 > 0.0) {
                const S ddx = b.vx - a.vx, ddy = b.vy - a.vy;
                const S coef = -sp.damping * (dx * ddx + dy * ddy) / ell2;
                add_DT(fp, a, b, coef * dx, coef * dy);
            }
        }
        for (const PlanarRotationalSpring& rs : d_.rotational_springs) {
            const int ia = rs.body_a >= 0 ? d_.bodies[static_cast<std::size_t>(rs.body_a)].ith : -1;
            const int ib = rs.body_b >= 0 ? d_.bodies[static_cast<std::size_t>(rs.body_b)].ith : -1;
            const S rel = (ib >= 0 ? q[ib] : 0.0) - (ia >= 0 ? q[ia] : 0.0) - rs.rest_angle;
            if (rs.stiffness != 0.0) {
                V_springs += 0.5 * rs.stiffness * rel * rel;
                if (need & NEED_H) {
                    const S tau = -rs.stiffness * rel;
                    add(h, ib, tau);
                    add(h, ia, -tau);
                }
            }
            if (rs.damping != 0.0 && (need & NEED_H)) {
                const S tau = -rs.damping * ((ib >= 0 ? qd[ib] : 0.0) - (ia >= 0 ? qd[ia] : 0.0));
                add(fp, ib, tau);
                add(fp, ia, -tau);
            }
        }
    }
    if ((need & NEED_B) && k_ > 0) {
        out.B.setZero();
        const int k = k_;
        S* B = out.B.data();
        auto addB = [&](int i, int col, const S& v) {
            if (i >= 0) B[static_cast<std::ptrdiff_t>(i) * k + col] += v;
        };
        for (int col = 0; col < k; ++col) {
            const PlanarActuator& a = d_.actuators[static_cast<std::size_t>(col)];
            if (a.kind == PlanarActuatorKind::torque) {
                addB(a.body_b >= 0 ? d_.bodies[static_cast<std::size_t>(a.body_b)].ith : -1, col, 1.0);
                addB(a.body_a >= 0 ? d_.bodies[static_cast<std::size_t>(a.body_a)].ith : -1, col, -1.0);
            } else if (a.kind == PlanarActuatorKind::force) {
                const PointKin<S> p = point_kin(d_, cs, sn, q, qd, a.a);
                addB(p.ix, col, a.ux);
                addB(p.iy, col, a.uy);
                addB(p.ith, col, -a.ux * p.ry + a.uy * p.rx);
            } else {
                const PointKin<S> pb = point_kin(d_, cs, sn, q, qd, a.b);
                S ca = S(1.0), sa = S(0.0), rax = S(0.0), ray = S(0.0);
                int iax = -1, iay = -1, iath = -1;
                if (a.a.body >= 0) {
                    const PlanarBody& Ba = d_.bodies[static_cast<std::size_t>(a.a.body)];
                    ca = cs[a.a.body];
                    sa = sn[a.a.body];
                    rax = q[Ba.ix];
                    ray = q[Ba.iy];
                    iax = Ba.ix;
                    iay = Ba.iy;
                    iath = Ba.ith;
                }
                const S ux = ca * a.ux - sa * a.uy, uy = sa * a.ux + ca * a.uy;
                addB(pb.ix, col, ux);
                addB(pb.iy, col, uy);
                addB(pb.ith, col, -ux * pb.ry + uy * pb.rx);
                // reaction on body a at the global point p_b: lever p_b − r_a
                const S lx = pb.px - rax, ly = pb.py - ray;
                addB(iax, col, -ux);
                addB(iay, col, -uy);
                addB(iath, col, -(-ux * ly + uy * lx));
            }
        }
    }
    const unsigned cneed = need & (NEED_A | NEED_GAMMA | NEED_PHI | NEED_VELOCITY);
    // f, ḟ, f̈ of driver `idx` at t (zeros for −1)
    auto drive = [&](int idx, double* f) -> Status {
        f[0] = f[1] = f[2] = 0.0;
        if (idx < 0) return Status::ok;
        const int st = d_.drivers[static_cast<std::size_t>(idx)].fn.eval(t, f, treg);
        if (st == TimeFunction::EVAL_FAILED) return Status::callback_error;
        return st == TimeFunction::EVAL_OK ? Status::ok : Status::not_finite;
    };
    if (cneed && m_all_ > 0) {
        const bool wantA = (need & NEED_A) != 0;
        S* A = out.A.data();
        S* gamma = out.gamma.data();
        S* phi = out.phi.data();
        S* vel = out.velocity.data();
        const std::size_t nc = d_.constraints.size();
        for (std::size_t ci = 0; ci < nc; ++ci) {
            if (!active[ci]) continue;
            const ConstraintInfo& c = d_.constraints[ci];
            if (wantA)  // only the pattern's entries: the others stay 0 (program.hpp)
                for (int r = c.row; r < c.row + c.dim; ++r) {
                    S* Ar = A + static_cast<std::ptrdiff_t>(r) * n;
                    const int* cols = a_pattern_.row(r);
                    for (int t = 0, e = a_pattern_.count(r); t < e; ++t) Ar[cols[t]] = S(0.0);
                }
            for (int pi : prims_of_[ci]) {
                const PlanarPrim& p = d_.prims[static_cast<std::size_t>(pi)];
                const int row = c.row + p.offset;
                S* Ar = A + static_cast<std::ptrdiff_t>(row) * n;
                switch (p.kind) {
                    case PlanarPrimKind::pin: {
                        const PointKin<S> a = point_kin(d_, cs, sn, q, qd, p.a);
                        const PointKin<S> b = point_kin(d_, cs, sn, q, qd, p.b);
                        double fx[3], fy[3];
                        if (Status st = drive(p.driver, fx); st != Status::ok) return st;
                        if (Status st = drive(p.driver2, fy); st != Status::ok) return st;
                        phi[row] = a.px - b.px - fx[0];
                        phi[row + 1] = a.py - b.py - fy[0];
                        // γ = −θ̇_a² R_a s_a + θ̇_b² R_b s_b − f̈
                        gamma[row] = -(a.om * a.om) * a.rx + (b.om * b.om) * b.rx - fx[2];
                        gamma[row + 1] = -(a.om * a.om) * a.ry + (b.om * b.om) * b.ry - fy[2];
                        vel[row] = a.vx - b.vx - fx[1];
                        vel[row + 1] = a.vy - b.vy - fy[1];
                        if (wantA) {
                            S* Ar1 = Ar + n;
                            add(Ar, a.ix, 1.0);
                            add(Ar1, a.iy, 1.0);
                            add(Ar, a.ith, -a.ry);
                            add(Ar1, a.ith, a.rx);
                            add(Ar, b.ix, -1.0);
                            add(Ar1, b.iy, -1.0);
                            add(Ar, b.ith, b.ry);
                            add(Ar1, b.ith, -b.rx);
                        }
                        break;
                    }
                    case PlanarPrimKind::line: {
                        const PointKin<S> a = point_kin(d_, cs, sn, q, qd, p.a);
                        const PointKin<S> b = point_kin(d_, cs, sn, q, qd, p.b);
                        S ca = S(1.0), sa = S(0.0);
                        if (p.a.body >= 0) {
                            ca = cs[p.a.body];
                            sa = sn[p.a.body];
                        }
                        // n = R_a u^⊥, n^⊥ = (−n_y, n_x)
                        const double upx = -p.uy, upy = p.ux;
                        const S nx = ca * upx - sa * upy, ny = sa * upx + ca * upy;
                        const S npx = -ny, npy = nx;
                        const S dx = b.px - a.px, dy = b.py - a.py;
                        const S ddx = b.vx - a.vx, ddy = b.vy - a.vy;
                        const S dn = nx * dx + ny * dy;
                        const S dnp = dx * npx + dy * npy;
                        // −θ̇² R s at each end
                        const S abx = -(b.om * b.om) * b.rx + (a.om * a.om) * a.rx;
                        const S aby = -(b.om * b.om) * b.ry + (a.om * a.om) * a.ry;
                        double f[3];
                        if (Status st = drive(p.driver, f); st != Status::ok) return st;
                        phi[row] = dn - f[0];
                        gamma[row] = 2.0 * a.om * (npx * ddx + npy * ddy) + (nx * abx + ny * aby) -
                                     a.om * a.om * dn - f[2];
                        vel[row] = nx * ddx + ny * ddy + dnp * a.om - f[1];
                        if (wantA) {
                            add_DT(Ar, a, b, nx, ny);
                            add(Ar, a.ith, dnp);
                        }
                        if (p.roll != 0.0) {  // + ρ (θ_b − θ_a): constant coefficients, γ unchanged
                            if (b.ith >= 0) {
                                phi[row] += p.roll * q[b.ith];
                                vel[row] += p.roll * qd[b.ith];
                                if (wantA) Ar[b.ith] += p.roll;
                            }
                            if (a.ith >= 0) {
                                phi[row] -= p.roll * q[a.ith];
                                vel[row] -= p.roll * qd[a.ith];
                                if (wantA) Ar[a.ith] -= p.roll;
                            }
                        }
                        break;
                    }
                    case PlanarPrimKind::rod: {
                        const PointKin<S> a = point_kin(d_, cs, sn, q, qd, p.a);
                        const PointKin<S> b = point_kin(d_, cs, sn, q, qd, p.b);
                        const double L = p.length;
                        const double k = p.sign / L;
                        const S dx = b.px - a.px, dy = b.py - a.py;
                        const S ddx = b.vx - a.vx, ddy = b.vy - a.vy;
                        const S abx = -(b.om * b.om) * b.rx + (a.om * a.om) * a.rx;
                        const S aby = -(b.om * b.om) * b.ry + (a.om * a.om) * a.ry;
                        double f[3] = {L, 0.0, 0.0};  // the length: constant, or driven (L: reference)
                        if (p.driver >= 0)
                            if (Status st = drive(p.driver, f); st != Status::ok) return st;
                        phi[row] = p.sign * ((dx * dx + dy * dy) - f[0] * f[0]) / (2.0 * L);
                        gamma[row] = k * ((ddx * ddx + ddy * ddy) + (dx * abx + dy * aby) - (f[1] * f[1] + f[0] * f[2]));
                        vel[row] = k * (dx * ddx + dy * ddy - f[0] * f[1]);
                        if (wantA) add_DT(Ar, a, b, k * dx, k * dy);
                        break;
                    }
                    case PlanarPrimKind::angle: {
                        S ph = S(-p.angle_const), v = S(0.0), g = S(0.0);
                        const std::size_t na = p.angle_bodies.size();
                        for (std::size_t j = 0; j < na; ++j) {
                            const int b = p.angle_bodies[j];
                            if (b < 0) continue;
                            const int ith = d_.bodies[static_cast<std::size_t>(b)].ith;
                            const double cf = p.angle_coefs[j];
                            ph += cf * q[ith];
                            v += cf * qd[ith];
                            if (wantA) Ar[ith] += cf;
                        }
                        if (p.driver >= 0) {
                            double f[3];
                            if (Status st = drive(p.driver, f); st != Status::ok) return st;
                            ph -= f[0];
                            v -= f[1];
                            g = -f[2];
                        }
                        phi[row] = ph;
                        gamma[row] = g;
                        vel[row] = v;
                        break;
                    }
                    case PlanarPrimKind::coord: {
                        S ph = S(-p.angle_const), v = S(0.0);
                        const std::size_t nq = p.coords.size();
                        for (std::size_t j = 0; j < nq; ++j) {
                            const int i = p.coords[j];
                            const double cf = p.angle_coefs[j];
                            ph += cf * q[i];
                            v += cf * qd[i];
                            if (wantA) Ar[i] += cf;
                        }
                        double f[3];
                        if (Status st = drive(p.driver, f); st != Status::ok) return st;
                        phi[row] = ph - f[0];
                        gamma[row] = -f[2];
                        vel[row] = v - f[1];
                        break;
                    }
                }
            }
        }
    }
    if (need & NEED_ENERGY) {
        S T = S(0.0), V = S(0.0);
        for (int i = 0; i < n; ++i) {
            T += mdiag_[i] * qd[i] * qd[i];
            V -= fg_[i] * q[i];
        }
        out.kinetic = 0.5 * T;
        out.potential = V + V_springs;
    }
    return Status::ok;
}

}  // namespace nonmin
