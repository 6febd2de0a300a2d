// TreeProgram: a robot's M, h, f_p, B, constraint rows and energy from the tree algorithms
// (see nonmin/rbd/tree_program.hpp for the formulas). No allocation in evaluate().
#include <cmath>
#include <cstring>
#include <type_traits>
#include <string>

#include "nonmin/rbd/tree_program.hpp"

#include "nonmin/dual_terms.hpp"

#include <algorithm>

namespace nonmin::rbd {

int row_count(RowType t) {
    switch (t) {
        case RowType::unit_quaternion: return 1;
        case RowType::point: return 3;
        case RowType::weld: return 6;
        case RowType::hinge: return 5;
        case RowType::planar_point: return 2;
        case RowType::planar_weld: return 3;
        case RowType::point_on_plane:
        case RowType::contact:
        case RowType::joint_coupling:
        case RowType::joint_limit:
        case RowType::joint_driver:
        case RowType::distance_driver: return 1;
        case RowType::path_driver: return 3;
    }
    throw EngineError("unknown constraint row type");
}

int row_count(const TreeConstraint& c) {
    if (c.type != RowType::path_driver) return row_count(c.type);
    return static_cast<int>(std::count_if(c.drv.begin(), c.drv.end(), [](int i) { return i >= 0; }));
}

namespace {

bool is_quat(JointType t) { return t == JointType::spherical || t == JointType::free_flyer; }

// First configuration / velocity index of a joint's quaternion / angular velocity.
int quat_q(const Joint& j) { return j.iq + (j.type == JointType::free_flyer ? 3 : 0); }
int ang_v(const Joint& j) { return j.iv + (j.type == JointType::free_flyer ? 3 : 0); }

}  // namespace

template <class S>
TreeScratch<S>::TreeScratch(const TreeDescription& d)
    : data(d.model),
      qn(VecS::Zero(d.model.nq)),
      v(VecS::Zero(d.model.nv)),
      a0(VecS::Zero(d.model.nv)),
      tau(VecS::Zero(d.model.nv)),
      fv(VecS::Zero(d.model.nv)),
      zv(VecS::Zero(d.model.nv)),
      Mv(MatS::Zero(d.model.nv, d.model.nv)),
      R(d.model.joints.size(), Mat3T<S>::Identity()),
      Tq(d.model.joints.size(), Mat34T<S>::Zero()),
      Y(MatS::Zero(7, d.model.nv)),
      Lv(MatS::Zero(2, d.model.nv)),
      tq(VecS::Zero(d.model.nq)),
      fk_q(static_cast<std::size_t>(d.model.nq), 0.0) {
    int m = 0;
    for (const TreeConstraint& c : d.constraints) m += row_count(c);
    Av = MatS::Zero(m, d.model.nv);
    int regs = 0;
    for (const TimeFunction& f : d.drivers) regs = std::max(regs, f.scratch_size());
    treg.assign(static_cast<std::size_t>(regs) + 1, 0.0);
}
template struct TreeScratch<double>;
template struct TreeScratch<Dual>;
template struct TreeScratch<DualW>;

TreeProgram::TreeProgram(TreeDescription description) : d_(std::move(description)) {
    const TreeModel& model = d_.model;
    model.validate();
    quat_ = model.has_quaternions();
    n_ = model.nq;
    k_ = static_cast<int>(d_.actuated.size());
    if (d_.damping.size() != model.nv || !d_.damping.allFinite())
        throw EngineError("tree program: damping must hold nv finite values");
    for (int iv : d_.actuated)
        if (iv < 0 || iv >= model.nv) throw EngineError("tree program: actuated velocity index out of range");
    const int nf = static_cast<int>(d_.frames.size());
    const int nj = static_cast<int>(model.joints.size());
    for (const Frame& f : d_.frames)
        if (f.joint < -1 || f.joint >= nj) throw EngineError("tree program: frame joint index out of range");
    int row = 0;
    for (const TreeConstraint& c : d_.constraints) {
        const int dim = row_count(c);
        const std::string where = "tree program: constraint '" + c.name + "': ";
        switch (c.type) {
            case RowType::unit_quaternion: {
                bool ok = false;
                for (const Joint& j : model.joints)
                    if (is_quat(j.type) && quat_q(j) == c.iq) ok = true;
                if (!ok) throw EngineError(where + "iq is not the start of a quaternion");
                break;
            }
            case RowType::joint_coupling:
                if (c.iq < 0 || c.iq >= n_ || c.iq2 < -1 || c.iq2 >= n_)
                    throw EngineError(where + "joint coordinate index out of range");
                break;
            case RowType::joint_driver:
                if (c.iq < 0 || c.iq >= n_) throw EngineError(where + "joint coordinate index out of range");
                if (c.iq2 < 0 || c.iq2 >= static_cast<int>(d_.drivers.size()))
                    throw EngineError(where + "driver index out of range");
                break;
            case RowType::joint_limit:
                if (c.iq < 0 || c.iq >= n_) throw EngineError(where + "joint coordinate index out of range");
                if (!(c.coef[0] == 1.0 || c.coef[0] == -1.0) || !std::isfinite(c.ref1))
                    throw EngineError(where + "joint limit needs a sign of ±1 and a finite bound");
                break;
            case RowType::path_driver:
            case RowType::distance_driver: {
                if (c.frame_a < 0 || c.frame_a >= nf || c.frame_b < 0 || c.frame_b >= nf)
                    throw EngineError(where + "frame index out of range");
                const int nd = c.type == RowType::path_driver ? 3 : 1;
                for (int i = 0; i < 3; ++i)
                    if (c.drv[i] < -1 || c.drv[i] >= static_cast<int>(d_.drivers.size()) || (i >= nd && c.drv[i] != -1))
                        throw EngineError(where + "driver index out of range");
                if (dim < 1 || (c.type == RowType::distance_driver && c.drv[0] < 0))
                    throw EngineError(where + "a driver needs at least one prescribed motion");
                if (c.type == RowType::distance_driver && !(c.ref1 > 0.0 && std::isfinite(c.ref1)))
                    throw EngineError(where + "distance driver needs a finite reference length > 0");
                break;
            }
            default:
                if (c.frame_a < 0 || c.frame_a >= nf || c.frame_b < 0 || c.frame_b >= nf)
                    throw EngineError(where + "frame index out of range");
        }
        const ConstraintKind kind =
            (c.type == RowType::contact || c.type == RowType::joint_limit) ? ConstraintKind::unilateral
            : (c.type == RowType::joint_driver || c.type == RowType::path_driver ||
               c.type == RowType::distance_driver)
                ? ConstraintKind::rheonomic
                : ConstraintKind::holonomic;
        constraints_.push_back(ConstraintInfo{c.name, kind, row, dim});
        row += dim;
    }
    m_all_ = row;
    for (std::size_t i = 0; i < d_.drivers.size(); ++i) {
        d_.drivers[i].validate("tree program: driver " + std::to_string(i));
        if (!d_.drivers[i].thread_safe()) thread_safe_ = false;
    }
    for (std::size_t i = 0; i < model.joints.size(); ++i) {
        const Joint& j = model.joints[i];
        if (is_quat(j.type)) {
            qblocks_.push_back(QuatBlock{static_cast<int>(i), quat_q(j), ang_v(j), j.iq, j.iv,
                                         j.type == JointType::free_flyer});
            continue;
        }
        const int len = joint_nv(j.type);
        if (!runs_.empty() && runs_.back().iq + runs_.back().len == j.iq &&
            runs_.back().iv + runs_.back().len == j.iv)
            runs_.back().len += len;
        else
            runs_.push_back(Run{j.iq, j.iv, len});
    }
    for (int iv : d_.actuated) {
        int q = -1;
        for (const Run& r : runs_)
            if (iv >= r.iv && iv < r.iv + r.len) q = r.iq + (iv - r.iv);
        act_q_.push_back(q);
    }
}

std::unique_ptr<Workspace> TreeProgram::make_workspace() const {
    return std::make_unique<TreeWorkspace>(d_);
}

template <class S>
Status TreeProgram::normalize(const S* q, TreeScratch<S>& ws) const {
    using std::isfinite;
    using std::sqrt;
    const TreeModel& model = d_.model;
    for (int i = 0; i < model.nq; ++i) {
        if (!isfinite(q[i])) return Status::not_finite;
        ws.qn[i] = q[i];
    }
    if (!quat_) return Status::ok;
    for (std::size_t i = 0; i < model.joints.size(); ++i) {
        const Joint& j = model.joints[i];
        if (!is_quat(j.type)) continue;
        const int s = quat_q(j);
        const S* e = q + s;
        const S s2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + e[3] * e[3];
        if (!(s2 > 0.0) || !isfinite(s2)) return Status::not_finite;
        const S nrm = sqrt(s2);
        for (int k = 0; k < 4; ++k) ws.qn[s + k] = e[k] / nrm;
        ws.Tq[i] = (2.0 / s2) * quaternion_G(e);
        if (j.type == JointType::free_flyer) ws.R[i] = quaternion_rotation(e);
    }
    return Status::ok;
}

template <class S>
void TreeProgram::velocity_map(const S* q, const S* qd, TreeScratch<S>& ws) const {
    const TreeModel& model = d_.model;
    for (std::size_t i = 0; i < model.joints.size(); ++i) {
        const Joint& j = model.joints[i];
        const int nvj = joint_nv(j.type);
        if (!is_quat(j.type)) {
            for (int k = 0; k < nvj; ++k) {
                ws.v[j.iv + k] = qd[j.iq + k];
                ws.a0[j.iv + k] = S(0.0);
            }
            continue;
        }
        const int s = quat_q(j), a = ang_v(j);
        const Eigen::Map<const Vec4T<S>> e(q + s), ed(qd + s);
        const Vec3T<S> w = ws.Tq[i] * ed;
        // Ṫ qd on the quaternion block: G(ε̇) ε̇ = 0 leaves −2 (εᵀε̇)/|ε|² ω
        const S ratio = -2.0 * e.dot(ed) / e.squaredNorm();
        ws.v.template segment<3>(a) = w;
        ws.a0.template segment<3>(a) = ratio * w;
        if (j.type == JointType::free_flyer) {
            const Vec3T<S> vl = ws.R[i].transpose() * Eigen::Map<const Vec3T<S>>(qd + j.iq);
            ws.v.template segment<3>(j.iv) = vl;
            ws.a0.template segment<3>(j.iv) = -w.cross(vl);  // d/dt Rᵀ = −[ω]× Rᵀ
        }
    }
}

template <class S>
void TreeProgram::apply_Tt(const TreeScratch<S>& ws, const S* fv, S* fq) const {
    for (const Run& r : runs_)
        for (int k = 0; k < r.len; ++k) fq[r.iq + k] = fv[r.iv + k];
    for (const QuatBlock& b : qblocks_) {
        Eigen::Map<Vec4T<S>>(fq + b.qs) = ws.Tq[b.joint].transpose() * Eigen::Map<const Vec3T<S>>(fv + b.a);
        if (b.free) Eigen::Map<Vec3T<S>>(fq + b.iq) = ws.R[b.joint] * Eigen::Map<const Vec3T<S>>(fv + b.iv);
    }
}

template <class S>
S TreeProgram::tb(const TreeScratch<S>& ws, const QuatBlock& b, int r, int c) {
    if (!b.free) return ws.Tq[b.joint](r, c);
    if (r < 3) return c < 3 ? ws.R[b.joint](c, r) : S(0.0);  // Rᵀ on the position
    return c >= 3 ? ws.Tq[b.joint](r - 3, c - 3) : S(0.0);
}

template <class S>
void TreeProgram::congruence(TreeScratch<S>& ws, S* M) const {
    using MatS = typename TreeScratch<S>::MatS;
    // M = Tᵀ M_v T with T the identity on the runs: runs × runs blocks are copies of M_v;
    // the rows of a quaternion block b are Y = T_bᵀ M_v[v_b, :] (then Y T on other quaternion
    // blocks), mirrored into its columns, so M is exactly symmetric.
    const int nq = d_.model.nq, nv = d_.model.nv;
    Eigen::Map<MatS> out(M, nq, nq);
    for (const Run& r1 : runs_)
        for (const Run& r2 : runs_)
            out.block(r1.iq, r2.iq, r1.len, r2.len) = ws.Mv.block(r1.iv, r2.iv, r1.len, r2.len);
    // Column c of T_b is zero outside rows k_lo … k_hi − 1 (a free block: Rᵀ on the position,
    // the quaternion map on the rotation); the sums below skip those exact zeros (an acc that
    // starts at +0 and gains only ±0 products stays +0: the same values as the full sums).
    auto krange = [](const QuatBlock& b, int c, int& lo, int& hi) {
        lo = b.free && c >= 3 ? 3 : 0;
        hi = b.free && c < 3 ? 3 : b.nv();
    };
    MatS& Y = ws.Y;
    for (std::size_t bi = 0; bi < qblocks_.size(); ++bi) {
        const QuatBlock& b = qblocks_[bi];
        const int v0 = b.v0(), q0 = b.q0(), nqb = b.nq();
        S t[6];  // column r (or c) of T_b over its nonzero rows
        for (int r = 0; r < nqb; ++r) {
            int lo, hi;
            krange(b, r, lo, hi);
            for (int k = lo; k < hi; ++k) t[k - lo] = tb(ws, b, k, r);
            for (int c = 0; c < nv; ++c) {
                S acc = S(0.0);
                for (int k = lo; k < hi; ++k) acc += t[k - lo] * ws.Mv(v0 + k, c);
                Y(r, c) = acc;
            }
        }
        for (const Run& r : runs_)
            for (int i = 0; i < nqb; ++i)
                for (int c = 0; c < r.len; ++c) {
                    out(q0 + i, r.iq + c) = Y(i, r.iv + c);
                    out(r.iq + c, q0 + i) = Y(i, r.iv + c);
                }
        for (std::size_t bj = bi; bj < qblocks_.size(); ++bj) {
            const QuatBlock& b2 = qblocks_[bj];
            for (int c = 0; c < b2.nq(); ++c) {
                int lo, hi;
                krange(b2, c, lo, hi);
                for (int k = lo; k < hi; ++k) t[k - lo] = tb(ws, b2, k, c);
                for (int i = 0; i < nqb; ++i) {
                    S acc = S(0.0);
                    for (int k = lo; k < hi; ++k) acc += Y(i, b2.v0() + k) * t[k - lo];
                    out(q0 + i, b2.q0() + c) = acc;
                    if (bj != bi) out(b2.q0() + c, q0 + i) = acc;
                }
            }
        }
        for (int i = 0; i < nqb; ++i)  // the diagonal block T_bᵀ M_bb T_b, symmetrized
            for (int c = i + 1; c < nqb; ++c) {
                const S s = 0.5 * (out(q0 + i, q0 + c) + out(q0 + c, q0 + i));
                out(q0 + i, q0 + c) = s;
                out(q0 + c, q0 + i) = s;
            }
    }
}

template <class S>
void TreeProgram::frame_rows(const TreeConstraint& c, TreeScratch<S>& ws, bool rows, bool gamma, bool phi,
                             S* A, S* g, S* p) const {
    using V3 = Vec3T<S>;
    const TreeModel& model = d_.model;
    const TreeDataT<S>& data = ws.data;
    const Frame& fa = d_.frames[c.frame_a];
    const Frame& fb = d_.frames[c.frame_b];
    FrameKinematicsT<S>& ka = ws.ka;
    FrameKinematicsT<S>& kb = ws.kb;
    frame_kinematics(model, data, fa, gamma, ka);
    frame_kinematics(model, data, fb, gamma, kb);
    const int nv = model.nv;
    const V3 zero = V3::Zero();
    auto row = [&](int r, const V3& la, const V3& aa, const V3& lb, const V3& ab) {
        S* a = A + static_cast<std::ptrdiff_t>(r) * nv;
        for (int k = 0; k < nv; ++k) a[k] = S(0.0);
        if (fa.joint >= 0) add_jacobian_row(model, data, fa.joint, ka.oMf.p, la, aa, a);
        if (fb.joint >= 0) add_jacobian_row(model, data, fb.joint, kb.oMf.p, lb, ab, a);
    };
    const V3& pa = ka.oMf.p;
    const V3& pb = kb.oMf.p;
    const Mat3T<S>& Ra = ka.oMf.R;
    const Mat3T<S>& Rb = kb.oMf.R;
    switch (c.type) {
        case RowType::point:
        case RowType::weld:
        case RowType::hinge: {
            for (int i = 0; i < 3; ++i) {
                const V3 e = V3::Unit(i);
                if (rows) row(i, e, zero, -e, zero);
                if (gamma) g[i] = ka.a[i] - kb.a[i];
                if (phi) p[i] = pa[i] - pb[i];
            }
            if (c.type == RowType::weld) {
                for (int i = 0; i < 3; ++i) {
                    const V3 e = V3::Unit(i);
                    if (rows) row(3 + i, zero, e, zero, -e);
                    if (gamma) g[3 + i] = ka.alpha[i] - kb.alpha[i];
                }
                if (phi) Eigen::Map<V3>(p + 3) = log3<S>(Ra * Rb.transpose());
            } else if (c.type == RowType::hinge) {
                const V3 Kb = Rb * c.axis;
                for (int i = 0; i < 2; ++i) {
                    const V3 U = Ra * (i == 0 ? c.u1 : c.u2);
                    const V3 r = U.cross(Kb);
                    if (rows) row(3 + i, zero, r, zero, -r);
                    if (gamma) {
                        const V3 rdot = ka.w.cross(U).cross(Kb) + U.cross(kb.w.cross(Kb));
                        g[3 + i] = rdot.dot(ka.w - kb.w) + r.dot(ka.alpha - kb.alpha);
                    }
                    if (phi) p[3 + i] = U.dot(Kb);
                }
            }
            return;
        }
        case RowType::planar_point:
        case RowType::planar_weld: {
            for (int i = 0; i < 2; ++i) {
                const V3 e = (i == 0 ? c.u1 : c.u2).template cast<S>();
                if (rows) row(i, e, zero, -e, zero);
                if (gamma) g[i] = e.dot(ka.a - kb.a);
                if (phi) p[i] = e.dot(pa - pb);
            }
            if (c.type == RowType::planar_weld) {
                const V3 n = c.axis.template cast<S>();
                if (rows) row(2, zero, n, zero, -n);
                if (gamma) g[2] = n.dot(ka.alpha - kb.alpha);
                if (phi) p[2] = n.dot(log3<S>(Ra * Rb.transpose()));
            }
            return;
        }
        case RowType::point_on_plane:
        case RowType::contact: {
            const V3 N = Ra * c.axis;
            const V3 d = pb - pa;
            const V3 Nxd = N.cross(d);
            if (rows) row(0, -N, Nxd, N, zero);
            if (gamma) {
                const V3 dv = kb.v - ka.v;
                const V3 Nd = ka.w.cross(N);
                g[0] = ka.alpha.dot(Nxd) + ka.w.dot(Nd.cross(d) + N.cross(dv)) + Nd.dot(dv) +
                       N.dot(kb.a - ka.a);
            }
            if (phi) p[0] = N.dot(d);
            return;
        }
        default: return;
    }
}

template <class S>
Status TreeProgram::driver_rows(const TreeConstraint& c, double t, TreeScratch<S>& ws, bool rows, bool gamma,
                                bool phi, S* A, S* g, S* p, double* phit) const {
    using V3 = Vec3T<S>;
    const TreeModel& model = d_.model;
    const TreeDataT<S>& data = ws.data;
    const Frame& fa = d_.frames[c.frame_a];
    const Frame& fb = d_.frames[c.frame_b];
    FrameKinematicsT<S>& ka = ws.ka;
    FrameKinematicsT<S>& kb = ws.kb;
    frame_kinematics(model, data, fa, gamma, ka);
    frame_kinematics(model, data, fb, gamma, kb);
    const int nv = model.nv;
    const V3 zero = V3::Zero();
    auto row = [&](int r, const V3& la, const V3& lb) {  // la·J_a + lb·J_b (position Jacobians)
        S* a = A + static_cast<std::ptrdiff_t>(r) * nv;
        for (int k = 0; k < nv; ++k) a[k] = S(0.0);
        if (fa.joint >= 0) add_jacobian_row(model, data, fa.joint, ka.oMf.p, la, zero, a);
        if (fb.joint >= 0) add_jacobian_row(model, data, fb.joint, kb.oMf.p, lb, zero, a);
    };
    double f[3];
    auto motion = [&](int i) -> Status {
        const int st = d_.drivers[static_cast<std::size_t>(i)].eval(t, f, ws.treg.data());
        if (st == TimeFunction::EVAL_FAILED) return Status::callback_error;
        return st == TimeFunction::EVAL_OK ? Status::ok : Status::not_finite;
    };
    const V3 d = kb.oMf.p - ka.oMf.p;
    if (c.type == RowType::path_driver) {
        int r = 0;
        for (int i = 0; i < 3; ++i) {
            if (c.drv[i] < 0) continue;
            const Status st = motion(c.drv[i]);
            if (st != Status::ok) return st;
            const V3 e = V3::Unit(i);
            if (rows) row(r, -e, e);
            if (gamma) g[r] = (kb.a[i] - ka.a[i]) - f[2];
            if (phi) p[r] = d[i] - f[0];
            phit[r] = -f[1];
            ++r;
        }
        return Status::ok;
    }
    const Status st = motion(c.drv[0]);  // distance_driver
    if (st != Status::ok) return st;
    const double L = c.ref1;
    if (rows) row(0, -d / L, d / L);
    if (gamma) {
        const V3 dd = kb.v - ka.v;
        g[0] = (dd.dot(dd) + d.dot(kb.a - ka.a) - f[1] * f[1] - f[0] * f[2]) / L;
    }
    if (phi) p[0] = (d.dot(d) - f[0] * f[0]) / (2.0 * L);
    phit[0] = -f[0] * f[1] / L;
    return Status::ok;
}

Status TreeProgram::evaluate(double t, const double* q, const double* qd,
                             const std::uint8_t* active, unsigned need, Terms& out,
                             Workspace& wsb) const {
    TreeWorkspace& ws = static_cast<TreeWorkspace&>(wsb);
    return eval<double>(t, q, qd, active, need, out, ws);
}

Status TreeProgram::evaluate_tangent(double t, const double* q, const double* qd, const double* dq,
                                     const double* dqd, const std::uint8_t* active, unsigned need,
                                     Terms& out, Terms& tangent, Workspace& wsb) const {
    TreeWorkspace& ws = static_cast<TreeWorkspace&>(wsb);
    const auto nq = static_cast<std::size_t>(d_.model.nq);
    if (!ws.dual) {  // first use of this workspace for derivatives
        ws.dual = std::make_unique<TreeScratch<Dual>>(d_);
        ws.dq.assign(nq, Dual());
        ws.dqd.assign(nq, Dual());
        ws.dterms.resize(n_, k_, m_all_);
    }
    for (std::size_t i = 0; i < nq; ++i) {
        ws.dq[i] = Dual(q[i], dq[i]);
        ws.dqd[i] = Dual(qd[i], dqd[i]);
    }
    const Status st = eval<Dual>(t, ws.dq.data(), ws.dqd.data(), active, need, ws.dterms, *ws.dual);
    if (st != Status::ok) return st;
    split_dual(ws.dterms, need, out, tangent);
    return Status::ok;
}

template <class S>
void TreeProgram::apply_T(const TreeScratch<S>& ws, const double* xq, S* xv) const {
    for (const Run& r : runs_)
        for (int k = 0; k < r.len; ++k) xv[r.iv + k] = S(xq[r.iq + k]);
    for (const QuatBlock& b : qblocks_) {
        Eigen::Map<Vec3T<S>>(xv + b.a) = ws.Tq[b.joint] * Eigen::Map<const Vec4>(xq + b.qs);
        if (b.free) Eigen::Map<Vec3T<S>>(xv + b.iv) = ws.R[b.joint].transpose() * Eigen::Map<const Vec3>(xq + b.iq);
    }
}

template <class S>
NONMIN_FLATTEN Status TreeProgram::residuals(const ResidualQuery& rq, const S* q, const S* qd, TreeScratch<S>& ws,
                                             S* rd, S* rl, S* rc, const TreeData* fixed, bool seeded,
                                             bool dynamics) const {
    using std::isfinite;
    const TreeModel& model = d_.model;
    const int nq = model.nq, nv = model.nv;
    Status st = normalize(q, ws);
    if (st != Status::ok) return st;
    for (int i = 0; i < nq; ++i)
        if (!isfinite(qd[i])) return Status::not_finite;
    velocity_map(q, qd, ws);
    // joint acceleration a_v = T a + Ṫ q̇ (in ws.fv)
    apply_T(ws, rq.a, ws.fv.data());
    ws.fv += ws.a0;
    if (seeded) {
        // ws.data holds the kinematics at q and their tangents (seed_kinematics)
    } else if (fixed != nullptr) {
        const std::size_t nj = model.joints.size();
        for (std::size_t i = 0; i < nj; ++i) {
            ws.data.oMi[i].R = fixed->oMi[i].R.template cast<S>();
            ws.data.oMi[i].p = fixed->oMi[i].p.template cast<S>();
            ws.data.oI[i].m = S(fixed->oI[i].m);
            ws.data.oI[i].h = fixed->oI[i].h.template cast<S>();
            ws.data.oI[i].I = fixed->oI[i].I.template cast<S>();
        }
        ws.data.J = fixed->J.template cast<S>();
    } else {
        forward_kinematics(model, ws.data, ws.qn.data(), true);
    }
    forward_motion(model, ws.data, ws.v.data(), ws.fv.data());
    if (dynamics) {
        rnea(model, ws.data, ws.fv.data(), ws.tau.data());  // M_v a_v + C_v v + g_v
        for (int k = 0; k < nv; ++k) ws.tau[k] += d_.damping[k] * ws.v[k];
        if (rq.u != nullptr)
            for (int c = 0; c < k_; ++c) ws.tau[d_.actuated[static_cast<std::size_t>(c)]] -= rq.u[c];
        apply_Tt(ws, ws.tau.data(), rd);
    }
    const int nlam = rq.nlam;
    for (int i = 0; i < nlam * nq; ++i) rl[i] = S(0.0);
    for (int r = 0; r < m_all_; ++r) rc[r] = S(0.0);
    if (nlam == 0) return Status::ok;
    ws.Lv.setZero();
    bool any_frame = false;
    const double* a = rq.a;
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (!rq.active[ci]) continue;
        const TreeConstraint& c = d_.constraints[ci];
        const int r0 = constraints_[ci].row;
        const int dim = constraints_[ci].dim;
        const double* lam = rq.lam + r0;  // λ_l at row r0: lam[l * m_all]
        auto add_rl = [&](int iq, const S& coef) {
            for (int l = 0; l < nlam; ++l) rl[l * nq + iq] += lam[l * m_all_] * coef;
        };
        if (c.type == RowType::unit_quaternion) {
            S acc = S(0.0);
            for (int k = 0; k < 4; ++k) {
                acc += q[c.iq + k] * a[c.iq + k] + qd[c.iq + k] * qd[c.iq + k];
                add_rl(c.iq + k, q[c.iq + k]);
            }
            rc[r0] = acc;
        } else if (c.type == RowType::joint_coupling) {
            const auto& co = c.coef;
            S d1 = S(0.0), d2 = S(0.0), qd2 = S(0.0);
            if (c.iq2 >= 0) {
                const S x = q[c.iq2] - c.ref2;
                d1 = co[1] + 2 * co[2] * x + 3 * co[3] * x * x + 4 * co[4] * x * x * x;
                d2 = 2 * co[2] + 6 * co[3] * x + 12 * co[4] * x * x;
                qd2 = qd[c.iq2];
            }
            S acc = S(a[c.iq]);
            add_rl(c.iq, S(1.0));
            if (c.iq2 >= 0) {
                acc -= d1 * a[c.iq2];
                add_rl(c.iq2, -d1);
            }
            rc[r0] = acc - d2 * qd2 * qd2;
        } else if (c.type == RowType::joint_limit) {
            rc[r0] = S(c.coef[0] * a[c.iq]);
            add_rl(c.iq, S(c.coef[0]));
        } else if (c.type == RowType::joint_driver) {
            double f[3];
            const int ev = d_.drivers[static_cast<std::size_t>(c.iq2)].eval(rq.t, f, ws.treg.data());
            if (ev == TimeFunction::EVAL_FAILED) return Status::callback_error;
            if (ev != TimeFunction::EVAL_OK) return Status::not_finite;
            rc[r0] = S(a[c.iq] - f[2]);
            add_rl(c.iq, S(1.0));
        } else {
            // frame rows in velocity space: γ at the acceleration a_v is A_v a_v + γ_v
            frame_rows(c, ws, true, true, false, ws.Av.row(r0).data(), rc + r0, rc + r0);
            for (int l = 0; l < nlam; ++l)
                for (int r = 0; r < dim; ++r) {
                    const double lv = lam[l * m_all_ + r];
                    if (lv != 0.0) ws.Lv.row(l) += lv * ws.Av.row(r0 + r);
                }
            any_frame = true;
        }
    }
    if (any_frame)
        for (int l = 0; l < nlam; ++l) {
            apply_Tt(ws, ws.Lv.row(l).data(), ws.tq.data());
            for (int i = 0; i < nq; ++i) rl[l * nq + i] += ws.tq[i];
        }
    return Status::ok;
}

NONMIN_FLATTEN void TreeProgram::seed_kinematics(const ResidualQuery& rq, int j0, int w, TreeWorkspace& ws) const {
    constexpr int W = DUAL_WIDTH;
    const TreeModel& model = d_.model;
    const TreeData& fx = ws.data;  // the kinematics at q in double
    TreeDataT<DualW>& out = ws.wide->data;
    const int nj = static_cast<int>(model.joints.size());
    const int nq = model.nq;
    // world twists ξ_i = Σ_{j ≤ i} J_j δv_j per lane (lin: velocity of the point at the origin)
    for (int l = 0; l < w; ++l) {
        Vec& dv = ws.dv;
        dv.setZero();
        for (const Run& r : runs_)
            for (int k = 0; k < r.len; ++k) dv[r.iv + k] = rq.dq[(j0 + l) * nq + r.iq + k];
        for (int i = 0; i < nj; ++i) {
            const Joint& jt = model.joints[i];
            Vec3& lin = ws.xl[static_cast<std::size_t>(i * W + l)];
            Vec3& ang = ws.xa[static_cast<std::size_t>(i * W + l)];
            if (jt.parent >= 0) {
                lin = ws.xl[static_cast<std::size_t>(jt.parent * W + l)];
                ang = ws.xa[static_cast<std::size_t>(jt.parent * W + l)];
            } else {
                lin.setZero();
                ang.setZero();
            }
            for (int c = 0; c < joint_nv(jt.type); ++c) {
                const double x = dv[jt.iv + c];
                if (x == 0.0) continue;
                lin += fx.J.col(jt.iv + c).head<3>() * x;
                ang += fx.J.col(jt.iv + c).tail<3>() * x;
            }
        }
    }
    for (int i = 0; i < nj; ++i) {
        const Joint& jt = model.joints[i];
        const Mat3& R = fx.oMi[i].R;
        const Vec3& p = fx.oMi[i].p;
        const Inertia& I = fx.oI[i];
        SE3T<DualW>& X = out.oMi[i];
        InertiaT<DualW>& Io = out.oI[i];
        for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) {
                X.R(r, c) = DualW(R(r, c));
                Io.I(r, c) = DualW(I.I(r, c));
            }
            X.p[r] = DualW(p[r]);
            Io.h[r] = DualW(I.h[r]);
        }
        Io.m = DualW(I.m);
        const int nvj = joint_nv(jt.type);
        for (int c = 0; c < nvj; ++c)
            for (int r = 0; r < 6; ++r) out.J(r, jt.iv + c) = DualW(fx.J(r, jt.iv + c));
        for (int l = 0; l < w; ++l) {
            const Vec3& v = ws.xl[static_cast<std::size_t>(i * W + l)];
            const Vec3& om = ws.xa[static_cast<std::size_t>(i * W + l)];
            if (v.isZero(0.0) && om.isZero(0.0)) continue;  // the body does not move along l
            const Vec3 hv = I.h.dot(v) * Vec3::Ones();
            for (int c = 0; c < 3; ++c) {
                // column c of δR = [ω]× R and of [ω]× I
                const Vec3 dRc = om.cross(R.col(c));
                const Vec3 WIc = om.cross(I.I.col(c));
                for (int r = 0; r < 3; ++r) X.R(r, c).d[l] = dRc[r];
                // δI = [ω]× I − I [ω]× + 2 (h·v) 1 − v hᵀ − h vᵀ; (I [ω]×)(r, c) = −([ω]× I)(c, r) (I symmetric)
                for (int r = 0; r < 3; ++r) Io.I(r, c).d[l] = WIc[r] - v[r] * I.h[c] - I.h[r] * v[c];
            }
            for (int c = 0; c < 3; ++c) {
                const Vec3 WIc = om.cross(I.I.col(c));
                for (int r = 0; r < 3; ++r) Io.I(c, r).d[l] += WIc[r];
                Io.I(c, c).d[l] += 2.0 * hv[c];
            }
            const Vec3 dp = om.cross(p) + v;
            const Vec3 dh = om.cross(I.h) + I.m * v;
            for (int r = 0; r < 3; ++r) {
                X.p[r].d[l] = dp[r];
                Io.h[r].d[l] = dh[r];
            }
            for (int c = 0; c < nvj; ++c) {  // δJ_c = ξ × J_c (motion cross product)
                const Vec3 jl = fx.J.col(jt.iv + c).head<3>();
                const Vec3 ja = fx.J.col(jt.iv + c).tail<3>();
                const Vec3 djl = om.cross(jl) + v.cross(ja);
                const Vec3 dja = om.cross(ja);
                for (int r = 0; r < 3; ++r) {
                    out.J(r, jt.iv + c).d[l] = djl[r];
                    out.J(3 + r, jt.iv + c).d[l] = dja[r];
                }
            }
        }
    }
}

Status TreeProgram::residual_tangents(const ResidualQuery& rq, Workspace& wsb) const {
    TreeWorkspace& ws = static_cast<TreeWorkspace&>(wsb);
    ws.fk_valid = false;  // (writes ws.data)
    constexpr int W = DUAL_WIDTH;
    const int nq = d_.model.nq;
    if (!ws.wide) {
        ws.wide = std::make_unique<TreeScratch<DualW>>(d_);
        ws.wq.assign(static_cast<std::size_t>(nq), DualW());
        ws.wqd.assign(static_cast<std::size_t>(nq), DualW());
        ws.wrd.assign(static_cast<std::size_t>(nq), DualW());
        ws.wrl.assign(static_cast<std::size_t>(2 * nq), DualW());
        ws.wrc.assign(static_cast<std::size_t>(m_all_), DualW());
        ws.xl.assign(d_.model.joints.size() * W, Vec3::Zero());
        ws.xa.assign(d_.model.joints.size() * W, Vec3::Zero());
        ws.dv = Vec::Zero(d_.model.nv);
    }
    if (rq.nlam > 2) return Status::bad_shape;
    bool have_fixed = false;
    // analytic: the dynamics' tangents from rnea_derivatives (every tree) and, when every active
    // row has them, the rows' from row_tangents; a tree with quaternion joints whose rows are not
    // all analytic keeps the all-dual pass
    const bool analytic = !quat_ || rq.nlam == 0 || rows_analytic(rq.active);
    if (analytic) {
        const TreeModel& model = d_.model;
        const int nv = model.nv;
        const Status st = normalize<double>(rq.q, ws);
        if (st != Status::ok) return st;
        for (int i = 0; i < nq; ++i)
            if (!std::isfinite(rq.qd[i])) return Status::not_finite;
        const double* v = rq.qd;  // v = q̇, a_v = a without quaternions
        const double* av = rq.a;
        if (quat_) {  // v = T q̇, a_v = T a + Ṫ q̇
            velocity_map(rq.q, rq.qd, ws);
            apply_T(ws, rq.a, ws.fv.data());
            ws.fv += ws.a0;
            v = ws.v.data();
            av = ws.fv.data();
        }
        forward_kinematics(model, ws.data, ws.qn.data(), true);
        have_fixed = true;
        if (ws.dtq.rows() != nv) {
            ws.dtq.resize(nv, nv);
            ws.dtv.resize(nv, nv);
        }
        rnea_derivatives(model, ws.data, v, av, ws.dtq.data(), ws.dtv.data());
        for (int k = 0; k < nv; ++k) ws.dtv(k, k) += d_.damping[k];
        if (quat_) quat_dynamics(rq, ws);
        // row k of Dq, Dv: ∂r_dyn/∂q_k, ∂r_dyn/∂q̇_k (rnea_derivatives' layout: column k of ∂τ/∂q at k nv)
        const double* Dq = quat_ ? ws.Eq.data() : ws.dtq.data();
        const double* Dv = quat_ ? ws.Ev.data() : ws.dtv.data();
        for (int j = 0; j < rq.nd; ++j) {
            double* o = rq.r_dyn + static_cast<std::ptrdiff_t>(j) * nq;
            const double* dq = rq.dq + static_cast<std::ptrdiff_t>(j) * nq;
            const double* dqd = rq.dqd + static_cast<std::ptrdiff_t>(j) * nq;
            for (int i = 0; i < nq; ++i) o[i] = 0.0;
            for (int k = 0; k < nq; ++k) {
                if (dq[k] != 0.0)
                    for (int i = 0; i < nq; ++i) o[i] += Dq[k * nq + i] * dq[k];
                if (dqd[k] != 0.0)
                    for (int i = 0; i < nq; ++i) o[i] += Dv[k * nq + i] * dqd[k];
            }
        }
        if (rq.nlam == 0) {  // no active rows: nothing else moves
            for (int j = 0; j < rq.nd; ++j)
                for (int r = 0; r < m_all_; ++r) rq.r_con[static_cast<std::ptrdiff_t>(j) * m_all_ + r] = 0.0;
            return Status::ok;
        }
        if (quat_ || rows_analytic(rq.active)) {  // the rows' tangents from the frames' kinematics
            row_tangents(rq, ws);
            return Status::ok;
        }
    }
    for (int j0 = 0; j0 < rq.nd; j0 += W) {
        const int w = std::min(W, rq.nd - j0);
        bool moves_q = false;  // a chunk of q̇ directions only: the kinematics at q in double
        for (int i = 0; i < w * nq && !moves_q; ++i) moves_q = rq.dq[j0 * nq + i] != 0.0;
        // without quaternions the kinematics' tangents are the bodies' world twists (seed_kinematics)
        const bool seed = moves_q && !quat_;
        if ((!moves_q || seed) && !have_fixed) {
            const Status st = normalize<double>(rq.q, ws);
            if (st != Status::ok) return st;
            forward_kinematics(d_.model, ws.data, ws.qn.data(), true);
            have_fixed = true;
        }
        seed_directions<W>(rq, nq, j0, w, ws.wq.data(), ws.wqd.data());
        if (seed) seed_kinematics(rq, j0, w, ws);
        const Status st = residuals<DualW>(rq, ws.wq.data(), ws.wqd.data(), *ws.wide, ws.wrd.data(), ws.wrl.data(),
                                           ws.wrc.data(), moves_q ? nullptr : &ws.data, seed, !analytic);
        if (st != Status::ok) return st;
        if (!analytic) scatter_lanes<W>(ws.wrd.data(), nq, j0, w, nq, rq.r_dyn);
        scatter_lanes<W>(ws.wrl.data(), rq.nlam * nq, j0, w, static_cast<std::ptrdiff_t>(rq.nlam) * nq, rq.r_lam);
        scatter_lanes<W>(ws.wrc.data(), m_all_, j0, w, m_all_, rq.r_con);
    }
    return Status::ok;
}

// ---------------------------------------------------------------- quaternion joints: the chain rule
// (docs/theory.md, "Analytic derivatives with quaternion joints"). The velocity-space derivatives
// (rnea_derivatives, row_tangents' frame tangents) are along Pinocchio's tangent: q_k moved by
// δ = T(q) dq (the joint's local twist), v and a_v held. The residuals in q are
//   r_dyn = Tᵀ τ_v(q, v, a_v),  r_con = A_v a_v + γ_v,  r_lam = Tᵀ A_vᵀ λ   (+ the joint-space rows)
// with v = T q̇, a_v = T a + Ṫ q̇ (a held), so along q_k and q̇_k
//   ∂r_dyn/∂q_k = ∂Tᵀ/∂q_k τ_v + Tᵀ (∂τ/∂δ T_k + ∂τ/∂v ∂v/∂q_k + M_v ∂a_v/∂q_k),
//   ∂r_dyn/∂q̇_k = Tᵀ (∂τ/∂v T_k + M_v ∂a_v/∂q̇_k),
// and the same for the rows (A_v in place of M_v, no outer Tᵀ for r_con). T, ∂v/∂q, ∂a_v/∂q,
// ∂a_v/∂q̇ differ from the identity / zero only inside a quaternion block (quat_maps).

void TreeProgram::quat_maps(const QuatBlock& b, const double* q, const double* qd, const double* a,
                            const TreeWorkspace& ws, QuatMaps& m) const {
    m.T.setZero();
    m.Vq.setZero();
    m.Aq.setZero();
    m.Aqd.setZero();
    const int i = b.joint;
    const int eo = b.free ? 3 : 0;  // the block-local row of ω and column of ε
    const Eigen::Map<const Vec4> e(q + b.qs), ed(qd + b.qs), ae(a + b.qs);
    const double s2 = e.squaredNorm();
    const Mat34& Tq = ws.Tq[static_cast<std::size_t>(i)];
    const Vec3 w = Tq * ed;                    // ω = T_q ε̇
    const double ratio = -2.0 * e.dot(ed) / s2;  // Ṫ_q ε̇ = ratio ω (G(ε̇) ε̇ = 0)
    Vec3 vl = Vec3::Zero(), al = Vec3::Zero();
    if (b.free) {
        const Mat3& R = ws.R[static_cast<std::size_t>(i)];
        vl = R.transpose() * Eigen::Map<const Vec3>(qd + b.iq);  // v_lin = Rᵀ ṗ
        al = R.transpose() * Eigen::Map<const Vec3>(a + b.iq);
        for (int c = 0; c < 3; ++c) {
            const Vec3 rc = R.row(c).transpose();  // Rᵀ e_c
            m.T.block<3, 1>(0, c) = rc;
            m.Aqd.block<3, 1>(0, c) = -w.cross(rc);  // a0_lin = −ω × v_lin
        }
    }
    for (int k = 0; k < 4; ++k) {
        double u[4] = {0.0, 0.0, 0.0, 0.0};
        u[k] = 1.0;
        // T_q = 2 G(ε)/|ε|²: ∂T_q/∂ε_k = 2 G(e_k)/|ε|² − (2 ε_k/|ε|²) T_q
        m.dTq[k] = (2.0 / s2) * quaternion_G(u) - (2.0 * e[k] / s2) * Tq;
        const Vec3 th = Tq.col(k);          // δθ of a unit ε_k step
        const Vec3 dw = m.dTq[k] * ed;      // ∂ω/∂ε_k
        const double dr = (-2.0 * ed[k] - 2.0 * ratio * e[k]) / s2;  // ∂ratio/∂ε_k
        const int c = eo + k;
        m.T.block<3, 1>(eo, c) = th;
        m.Vq.block<3, 1>(eo, c) = dw;
        m.Aq.block<3, 1>(eo, c) = m.dTq[k] * ae + dr * w + ratio * dw;
        m.Aqd.block<3, 1>(eo, c) = (-2.0 * e[k] / s2) * w + ratio * th;
        if (b.free) {
            // ∂Rᵀ/∂ε_k = −[δθ]× Rᵀ: ∂v_lin = −δθ × v_lin; a0_lin = −ω × v_lin
            m.Vq.block<3, 1>(0, c) = -th.cross(vl);
            m.Aq.block<3, 1>(0, c) = -th.cross(al) - dw.cross(vl) + w.cross(th.cross(vl));
            m.Aqd.block<3, 1>(0, c) = -th.cross(vl);
        }
    }
}

void TreeProgram::add_dTt(const QuatBlock& b, const QuatMaps& m, const TreeWorkspace& ws, int kl, const double* yv,
                          double* yq) const {
    const int eo = b.free ? 3 : 0;
    if (kl < eo) return;  // T does not depend on the position
    const int k = kl - eo;
    const Eigen::Map<const Vec3> ya(yv + eo);
    Eigen::Map<Vec4>(yq + eo) += m.dTq[k].transpose() * ya;
    if (b.free) {  // (−[δθ]× Rᵀ)ᵀ y = R (δθ × y)
        const Vec3 th = ws.Tq[static_cast<std::size_t>(b.joint)].col(k);
        Eigen::Map<Vec3>(yq) += ws.R[static_cast<std::size_t>(b.joint)] * th.cross(Eigen::Map<const Vec3>(yv));
    }
}

void TreeProgram::quat_dynamics(const ResidualQuery& rq, TreeWorkspace& ws) const {
    const TreeModel& model = d_.model;
    const TreeData& D = ws.data;
    const int nq = model.nq, nv = model.nv;
    if (ws.Eq.rows() != nq) {
        ws.Eq.resize(nq, nq);
        ws.Ev.resize(nq, nq);
        ws.Mb = Mat::Zero(nv, nv);
        ws.tauv = Vec::Zero(nv);
        ws.gv = Vec::Zero(nv);
    }
    // runs: T_k = e_iv, nothing else moves: row k = Tᵀ (∂τ/∂δ_iv) (rows of dtq are ∂τ/∂δ_c)
    for (const Run& r : runs_)
        for (int k = 0; k < r.len; ++k) {
            apply_Tt(ws, ws.dtq.row(r.iv + k).data(), ws.Eq.row(r.iq + k).data());
            apply_Tt(ws, ws.dtv.row(r.iv + k).data(), ws.Ev.row(r.iq + k).data());
        }
    auto in_subtree = [&](int j, int k) {  // j ⪰ k
        while (j > k) j = model.joints[static_cast<std::size_t>(j)].parent;
        return j == k;
    };
    QuatMaps mp;
    for (const QuatBlock& b : qblocks_) {
        const int v0 = b.v0(), q0 = b.q0(), nvb = b.nv(), nqb = b.nq(), jb = b.joint;
        // M_v's columns of the block from the composite inertias (cw[c] = Ic_j J_c):
        // M(r, c) = J_r·cw[c] for r on j's support, J_c·cw[r] for r below j
        for (int cc = 0; cc < nvb; ++cc) {
            const int c = v0 + cc;
            for (std::size_t j = 0; j < model.joints.size(); ++j) {
                const Joint& jt = model.joints[j];
                const int jr = static_cast<int>(j);
                const bool above = in_subtree(jb, jr), below = !above && in_subtree(jr, jb);
                for (int r = jt.iv; r < jt.iv + joint_nv(jt.type); ++r) {
                    double val = 0.0;
                    if (above)
                        val = D.J.col(r).head<3>().dot(D.cw[static_cast<std::size_t>(c)].lin) +
                              D.J.col(r).tail<3>().dot(D.cw[static_cast<std::size_t>(c)].ang);
                    else if (below)
                        val = D.J.col(c).head<3>().dot(D.cw[static_cast<std::size_t>(r)].lin) +
                              D.J.col(c).tail<3>().dot(D.cw[static_cast<std::size_t>(r)].ang);
                    ws.Mb(c, r) = val;
                }
            }
            ws.Mb(c, c) += model.armature[c];
            // τ_v(c) = J_c·F_j + armature a_v + d v − (S u)_c
            double t = D.J.col(c).head<3>().dot(D.of[static_cast<std::size_t>(jb)].lin) +
                       D.J.col(c).tail<3>().dot(D.of[static_cast<std::size_t>(jb)].ang);
            t += model.armature[c] * ws.fv[c] + d_.damping[c] * ws.v[c];
            if (rq.u != nullptr)
                for (int a = 0; a < k_; ++a)
                    if (d_.actuated[static_cast<std::size_t>(a)] == c) t -= rq.u[a];
            ws.tauv[c] = t;
        }
        quat_maps(b, rq.q, rq.qd, rq.a, ws, mp);
        for (int kl = 0; kl < nqb; ++kl) {
            // along q_k: g = ∂τ/∂δ T_k + ∂τ/∂v ∂v/∂q_k + M_v ∂a_v/∂q_k
            Vec& g = ws.gv;
            g.setZero();
            for (int cc = 0; cc < nvb; ++cc) {
                const int c = v0 + cc;
                if (mp.T(cc, kl) != 0.0) g += mp.T(cc, kl) * ws.dtq.row(c).transpose();
                if (mp.Vq(cc, kl) != 0.0) g += mp.Vq(cc, kl) * ws.dtv.row(c).transpose();
                if (mp.Aq(cc, kl) != 0.0) g += mp.Aq(cc, kl) * ws.Mb.row(c).transpose();
            }
            double* eq = ws.Eq.row(q0 + kl).data();
            apply_Tt(ws, g.data(), eq);
            add_dTt(b, mp, ws, kl, ws.tauv.data() + v0, eq + q0);
            // along q̇_k: g = ∂τ/∂v T_k + M_v ∂a_v/∂q̇_k
            g.setZero();
            for (int cc = 0; cc < nvb; ++cc) {
                const int c = v0 + cc;
                if (mp.T(cc, kl) != 0.0) g += mp.T(cc, kl) * ws.dtv.row(c).transpose();
                if (mp.Aqd(cc, kl) != 0.0) g += mp.Aqd(cc, kl) * ws.Mb.row(c).transpose();
            }
            apply_Tt(ws, g.data(), ws.Ev.row(q0 + kl).data());
        }
    }
}

// inline (also frame_tangents, add_wrench_tangents): called only by row_tangents, which is flattened, so no
// out-of-line copy is compiled (build time, #17 target 7).
inline void TreeProgram::quat_rows(const ResidualQuery& rq, TreeWorkspace& ws) const {
    const int nq = d_.model.nq, nv = d_.model.nv, nlam = rq.nlam;
    if (ws.Cq.rows() != nq || ws.Cq.cols() != m_all_) {
        ws.Cq.resize(nq, m_all_);
        ws.Cv.resize(nq, m_all_);
        ws.Lq.resize(nq, 2 * nq);
        ws.AtL.resize(2, nv);
        ws.gv = Vec::Zero(nv);
    }
    // A_vᵀ λ_l = Σ_r λ_l,r A_v(r, ·) (frame rows: dca's columns)
    for (int l = 0; l < nlam; ++l)
        for (int c = 0; c < nv; ++c) {
            double acc = 0.0;
            for (int r = 0; r < m_all_; ++r) acc += ws.dca(c, r) * rq.lam[l * m_all_ + r];
            ws.AtL(l, c) = acc;
        }
    for (const Run& r : runs_)
        for (int k = 0; k < r.len; ++k) {
            const int kq = r.iq + k, kv = r.iv + k;
            ws.Cq.row(kq) = ws.dcq.row(kv);
            ws.Cv.row(kq) = ws.dcv.row(kv);
            for (int l = 0; l < nlam; ++l)
                apply_Tt(ws, ws.dlq.row(kv).data() + l * nv, ws.Lq.row(kq).data() + l * nq);
        }
    QuatMaps mp;
    for (const QuatBlock& b : qblocks_) {
        const int v0 = b.v0(), q0 = b.q0(), nvb = b.nv(), nqb = b.nq();
        quat_maps(b, rq.q, rq.qd, rq.a, ws, mp);
        for (int kl = 0; kl < nqb; ++kl) {
            const int kq = q0 + kl;
            auto cq = ws.Cq.row(kq);
            auto cv = ws.Cv.row(kq);
            cq.setZero();
            cv.setZero();
            for (int cc = 0; cc < nvb; ++cc) {
                const int c = v0 + cc;
                const double t = mp.T(cc, kl), vq = mp.Vq(cc, kl), aq = mp.Aq(cc, kl), aqd = mp.Aqd(cc, kl);
                if (t != 0.0) {
                    cq += t * ws.dcq.row(c);
                    cv += t * ws.dcv.row(c);
                }
                if (vq != 0.0) cq += vq * ws.dcv.row(c);
                if (aq != 0.0) cq += aq * ws.dca.row(c);
                if (aqd != 0.0) cv += aqd * ws.dca.row(c);
            }
            for (int l = 0; l < nlam; ++l) {
                Vec& g = ws.gv;
                g.setZero();
                for (int cc = 0; cc < nvb; ++cc)
                    if (mp.T(cc, kl) != 0.0) g += mp.T(cc, kl) * ws.dlq.row(v0 + cc).segment(l * nv, nv).transpose();
                double* lq = ws.Lq.row(kq).data() + l * nq;
                apply_Tt(ws, g.data(), lq);
                add_dTt(b, mp, ws, kl, ws.AtL.row(l).data() + v0, lq + q0);
            }
        }
    }
}

// ---------------------------------------------------------------- analytic row tangents
// (velocity space; quaternion trees then quat_rows; docs/theory.md, "Analytic derivatives of the constraint rows")

bool TreeProgram::rows_analytic(const std::uint8_t* active) const {
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (!active[ci]) continue;
        switch (d_.constraints[ci].type) {
            case RowType::point:
            case RowType::weld:
            case RowType::hinge:
            case RowType::planar_point:
            case RowType::planar_weld:
            case RowType::path_driver:
            case RowType::joint_coupling:
            case RowType::joint_limit:
            case RowType::joint_driver:
            case RowType::unit_quaternion: break;
            default: return false;
        }
    }
    return true;
}

inline void TreeProgram::frame_tangents(const Frame& f, const TreeWorkspace& ws, FrameTangent* tq, FrameTangent* tv) const {
    const TreeModel& model = d_.model;
    const TreeData& D = ws.data;
    for (int k = 0; k < model.nv; ++k) {
        tq[k] = FrameTangent();
        tv[k] = FrameTangent();
    }
    if (f.joint < 0) return;
    const int i = f.joint;
    const Vec3 p = frame_placement(model, D, f).p;
    const Motion& nu = D.ov[i];
    const Motion& al = D.oa[i];  // with the gravity offset: only differences and its angular part enter
    const Vec3& w = nu.ang;
    const Vec3 vp = nu.lin + w.cross(p);
    for (int jk = i; jk >= 0; jk = model.joints[jk].parent) {
        const Joint& jt = model.joints[jk];
        Motion nup, alp;  // the parent's velocity and acceleration
        parent_motion(model, D, jk, nup, alp);
        Motion nrel, arel;  // ν_i − ν_p, α_i − α_p
        nrel.lin = nu.lin - nup.lin;
        nrel.ang = nu.ang - nup.ang;
        arel.lin = al.lin - alp.lin;
        arel.ang = al.ang - alp.ang;
        for (int c = 0; c < joint_nv(jt.type); ++c) {
            const int col = jt.iv + c;
            const Motion xi = joint_twist(D, col);
            const Vec3 dpt = xi.lin + xi.ang.cross(p);  // velocity of the point p in the twist ξ
            const Motion eta = cross(xi, nup);
            // along v_k: δν_i = ξ, δα_i = ξ × ν_i − ξ × ν_p − ξ × ν_k (= ξ × ν_i − 2 ξ × ν_p for a
            // 1-dof joint; a free flyer's or spherical joint's columns do not commute)
            Motion dav = cross(xi, nu);
            const Motion ek = cross(xi, D.ov[jk]);
            dav.lin -= eta.lin + ek.lin;
            dav.ang -= eta.ang + ek.ang;
            FrameTangent& v = tv[col];
            v.dw = xi.ang;
            v.dv = dpt;
            v.dal = dav.ang;
            v.da = dav.lin + dav.ang.cross(p) + xi.ang.cross(vp) + w.cross(dpt);
            // along q_k: the subtree moves rigidly with ξ: δp = ξ(p), δR = [ξ_ω]× R,
            // δν_i = ξ × (ν_i − ν_p), δα_i = ξ × (α_i − α_p) − (ξ × ν_p) × (ν_i − ν_p)
            const Motion dn = cross(xi, nrel);
            Motion daq = cross(xi, arel);
            const Motion en = cross(eta, nrel);
            daq.lin -= en.lin;
            daq.ang -= en.ang;
            FrameTangent& t = tq[col];
            t.dp = dpt;
            t.dth = xi.ang;
            t.dw = dn.ang;
            t.dv = dn.lin + dn.ang.cross(p) + w.cross(dpt);
            t.dal = daq.ang;
            t.da = daq.lin + daq.ang.cross(p) + al.ang.cross(dpt) + dn.ang.cross(vp) + w.cross(t.dv);
        }
    }
}

inline void TreeProgram::add_wrench_tangents(const Frame& f, const Force& F, const Force* dF, int l, TreeWorkspace& ws) const {
    if (f.joint < 0) return;
    const TreeModel& model = d_.model;
    const TreeData& D = ws.data;
    const int n = model.nv, i = f.joint;
    Mat& out = ws.dlq;
    // the wrench's own change: J_jᵀ δF
    for (int k = 0; k < n; ++k) {
        const Force& d = dF[k];
        if (d.lin.isZero(0.0) && d.ang.isZero(0.0)) continue;
        for (int j = i; j >= 0; j = model.joints[j].parent) {
            const Joint& jt = model.joints[j];
            for (int c = 0; c < joint_nv(jt.type); ++c) {
                const int col = jt.iv + c;
                out(k, l * n + col) += D.J.col(col).head<3>().dot(d.lin) + D.J.col(col).tail<3>().dot(d.ang);
            }
        }
    }
    // the motion subspaces of the subtree of k: δJ_j = ξ_k × J_j for j ⪰ k
    for (int jk = i; jk >= 0; jk = model.joints[jk].parent) {
        const Joint& jtk = model.joints[jk];
        for (int ck = 0; ck < joint_nv(jtk.type); ++ck) {
            const int k = jtk.iv + ck;
            const Motion xi = joint_twist(D, k);
            // (ξ × J_j)·F = J_j · (−ξ ×* F)
            const Force xf = cross_force(xi, F);
            for (int j = i; j >= jk; j = model.joints[j].parent) {
                const Joint& jt = model.joints[j];
                for (int c = 0; c < joint_nv(jt.type); ++c) {
                    const int col = jt.iv + c;
                    out(k, l * n + col) -= D.J.col(col).head<3>().dot(xf.lin) + D.J.col(col).tail<3>().dot(xf.ang);
                }
            }
        }
    }
}

NONMIN_FLATTEN void TreeProgram::row_tangents(const ResidualQuery& rq, TreeWorkspace& ws) const {
    const TreeModel& model = d_.model;
    const TreeData& D = ws.data;
    const int n = model.nv, nlam = rq.nlam;
    if (ws.dcq.rows() != n || ws.dcq.cols() != m_all_) {
        ws.dcq.resize(n, m_all_);
        ws.dcv.resize(n, m_all_);
        ws.dlq.resize(n, 2 * n);
        for (auto* v : {&ws.tqa, &ws.tva, &ws.tqb, &ws.tvb}) v->assign(static_cast<std::size_t>(n), FrameTangent());
        ws.dF.assign(static_cast<std::size_t>(n), Force());
        if (quat_) ws.dca.resize(n, m_all_);
    }
    ws.dcq.setZero();
    ws.dcv.setZero();
    ws.dlq.setZero();
    if (quat_) ws.dca.setZero();
    FrameTangent *tqa = ws.tqa.data(), *tva = ws.tva.data(), *tqb = ws.tqb.data(), *tvb = ws.tvb.data();
    Force* dF = ws.dF.data();
    const double* a = rq.a;
    const Vec3 zero = Vec3::Zero();
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (!rq.active[ci]) continue;
        const TreeConstraint& c = d_.constraints[ci];
        const int r0 = constraints_[ci].row;
        const double* lam = rq.lam + r0;  // λ_l of row r0 + r: lam[l m_all + r]
        // joint-space rows: in q after the frame rows (below); joint limits and drivers are constant
        if (c.type == RowType::joint_limit || c.type == RowType::joint_driver ||
            c.type == RowType::joint_coupling || c.type == RowType::unit_quaternion)
            continue;
        // frame rows: coefficients (lin, ang) on frame a and frame b of each row with constant
        // world coefficients; hinge rows 3, 4 below
        const Frame& fa = d_.frames[c.frame_a];
        const Frame& fb = d_.frames[c.frame_b];
        frame_tangents(fa, ws, tqa, tva);
        frame_tangents(fb, ws, tqb, tvb);
        Vec3 la[6], aa[6];  // frame b's coefficients are their negatives
        int nc = 0;
        switch (c.type) {
            case RowType::point:
            case RowType::weld:
            case RowType::hinge:
                for (int i = 0; i < 3; ++i) la[nc] = Vec3::Unit(i), aa[nc++] = zero;
                if (c.type == RowType::weld)
                    for (int i = 0; i < 3; ++i) la[nc] = zero, aa[nc++] = Vec3::Unit(i);
                break;
            case RowType::planar_point:
            case RowType::planar_weld:
                la[nc] = c.u1, aa[nc++] = zero;
                la[nc] = c.u2, aa[nc++] = zero;
                if (c.type == RowType::planar_weld) la[nc] = zero, aa[nc++] = c.axis;
                break;
            case RowType::path_driver:  // e_i · (p_b − p_a): frame a's coefficient −e_i
                for (int i = 0; i < 3; ++i)
                    if (c.drv[i] >= 0) la[nc] = -Vec3::Unit(i), aa[nc++] = zero;
                break;
            default: break;
        }
        for (int k = 0; k < n; ++k) {
            for (int r = 0; r < nc; ++r) {
                ws.dcq(k, r0 + r) = la[r].dot(tqa[k].da - tqb[k].da) + aa[r].dot(tqa[k].dal - tqb[k].dal);
                ws.dcv(k, r0 + r) = la[r].dot(tva[k].da - tvb[k].da) + aa[r].dot(tva[k].dal - tvb[k].dal);
            }
        }
        if (quat_)  // A_v's columns: ∂a/∂a_v,k = ∂v/∂v_k (dv), ∂α/∂a_v,k = ∂ω/∂v_k (dw)
            for (int k = 0; k < n; ++k)
                for (int r = 0; r < nc; ++r)
                    ws.dca(k, r0 + r) = la[r].dot(tva[k].dv - tvb[k].dv) + aa[r].dot(tva[k].dw - tvb[k].dw);
        const SE3 Xa = frame_placement(model, D, fa), Xb = frame_placement(model, D, fb);
        // hinge: rows 3 + i = r_i·(α_a − α_b) + ṙ_i·(ω_a − ω_b), r_i = U_i × K, U_i = R_a u_i, K = R_b k,
        // ṙ_i = (ω_a × U_i) × K + U_i × (ω_b × K)
        const bool hinge = c.type == RowType::hinge;
        Vec3 U[2], r[2], rd[2], K = zero, wa = zero, wb = zero, dal = zero;
        if (hinge) {
            if (fa.joint >= 0) wa = D.ov[fa.joint].ang, dal += D.oa[fa.joint].ang;
            if (fb.joint >= 0) wb = D.ov[fb.joint].ang, dal -= D.oa[fb.joint].ang;
            K = Xb.R * c.axis;
            for (int i = 0; i < 2; ++i) {
                U[i] = Xa.R * (i == 0 ? c.u1 : c.u2);
                r[i] = U[i].cross(K);
                rd[i] = wa.cross(U[i]).cross(K) + U[i].cross(wb.cross(K));
            }
            const Vec3 dw = wa - wb;
            for (int k = 0; k < n; ++k)
                for (int i = 0; i < 2; ++i) {
                    for (int pass = 0; pass < 2; ++pass) {  // 0: q_k, 1: q̇_k
                        const FrameTangent& A = pass == 0 ? tqa[k] : tva[k];
                        const FrameTangent& B = pass == 0 ? tqb[k] : tvb[k];
                        const Vec3 dU = A.dth.cross(U[i]), dK = B.dth.cross(K);
                        const Vec3 dr = dU.cross(K) + U[i].cross(dK);
                        const Vec3 drd = (A.dw.cross(U[i]) + wa.cross(dU)).cross(K) + wa.cross(U[i]).cross(dK) +
                                         dU.cross(wb.cross(K)) + U[i].cross(B.dw.cross(K) + wb.cross(dK));
                        const double val = dr.dot(dal) + r[i].dot(A.dal - B.dal) + drd.dot(dw) + rd[i].dot(A.dw - B.dw);
                        (pass == 0 ? ws.dcq : ws.dcv)(k, r0 + 3 + i) = val;
                    }
                    if (quat_) ws.dca(k, r0 + 3 + i) = r[i].dot(tva[k].dw - tvb[k].dw);
                }
        }
        // Aᵀλ_l: the wrenches λ_l puts on the two frames (force at the world origin) and their
        // changes along q_k at fixed bodies (the points move; the hinge's r_i turns)
        for (int l = 0; l < nlam; ++l) {
            Vec3 fl = zero, tau = zero;
            for (int rr = 0; rr < nc; ++rr) {
                const double lv = lam[l * m_all_ + rr];
                fl += lv * la[rr];
                tau += lv * aa[rr];
            }
            double lh[2] = {0.0, 0.0};
            if (hinge)
                for (int i = 0; i < 2; ++i) {
                    lh[i] = lam[l * m_all_ + 3 + i];
                    tau += lh[i] * r[i];
                }
            for (int side = 0; side < 2; ++side) {
                const Frame& f = side == 0 ? fa : fb;
                if (f.joint < 0) continue;
                const double s = side == 0 ? 1.0 : -1.0;
                const Vec3& p = side == 0 ? Xa.p : Xb.p;
                const FrameTangent* tq = side == 0 ? tqa : tqb;
                Force F;
                F.lin = s * fl;
                F.ang = s * tau + p.cross(F.lin);
                for (int k = 0; k < n; ++k) {
                    dF[k].lin.setZero();
                    dF[k].ang = tq[k].dp.cross(F.lin);
                    if (hinge && (lh[0] != 0.0 || lh[1] != 0.0))
                        for (int i = 0; i < 2; ++i) {
                            const Vec3 dU = tqa[k].dth.cross(U[i]), dK = tqb[k].dth.cross(K);
                            dF[k].ang += (s * lh[i]) * (dU.cross(K) + U[i].cross(dK));
                        }
                }
                add_wrench_tangents(f, F, dF, l, ws);
            }
        }
    }
    // in q: the chain rule through T for quaternion trees (T = 1 otherwise)
    const int nq = model.nq;
    if (quat_) quat_rows(rq, ws);
    Mat& Cq = quat_ ? ws.Cq : ws.dcq;
    Mat& Cv = quat_ ? ws.Cv : ws.dcv;
    Mat& Lq = quat_ ? ws.Lq : ws.dlq;
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (!rq.active[ci]) continue;
        const TreeConstraint& c = d_.constraints[ci];
        const int r0 = constraints_[ci].row;
        const double* lam = rq.lam + r0;
        if (c.type == RowType::unit_quaternion) {
            // A a + γ = εᵀ a + ε̇ᵀ ε̇;  Aᵀλ = λ ε
            for (int k = 0; k < 4; ++k) {
                const int iq = c.iq + k;
                Cq(iq, r0) = a[iq];
                Cv(iq, r0) = 2.0 * rq.qd[iq];
                for (int l = 0; l < nlam; ++l) Lq(iq, l * nq + iq) += lam[l * m_all_];
            }
        } else if (c.type == RowType::joint_coupling && c.iq2 >= 0) {
            const auto& co = c.coef;
            const double x = rq.q[c.iq2] - c.ref2, qd2 = rq.qd[c.iq2];
            const double d2 = 2 * co[2] + 6 * co[3] * x + 12 * co[4] * x * x;
            const double d3 = 6 * co[3] + 24 * co[4] * x;
            // A a + γ = a₁ − d₁(x) a₂ − d₂(x) q̇₂²;  Aᵀλ = λ (e₁ − d₁(x) e₂)
            Cq(c.iq2, r0) = -d2 * a[c.iq2] - d3 * qd2 * qd2;
            Cv(c.iq2, r0) = -2.0 * d2 * qd2;
            for (int l = 0; l < nlam; ++l) Lq(c.iq2, l * nq + c.iq2) -= lam[l * m_all_] * d2;
        }
    }
    // the tangents along rq's directions (the pipeline's seeds are unit vectors: one row each)
    for (int j = 0; j < rq.nd; ++j) {
        const double* dq = rq.dq + static_cast<std::ptrdiff_t>(j) * nq;
        const double* dqd = rq.dqd + static_cast<std::ptrdiff_t>(j) * nq;
        double* rc = rq.r_con + static_cast<std::ptrdiff_t>(j) * m_all_;
        double* rl = rq.r_lam + static_cast<std::ptrdiff_t>(j) * nlam * nq;
        for (int r = 0; r < m_all_; ++r) rc[r] = 0.0;
        for (int r = 0; r < nlam * nq; ++r) rl[r] = 0.0;
        for (int k = 0; k < nq; ++k) {
            if (dq[k] != 0.0) {
                const double x = dq[k];
                const double* cq = Cq.row(k).data();
                const double* lq = Lq.row(k).data();
                for (int r = 0; r < m_all_; ++r) rc[r] += x * cq[r];
                for (int r = 0; r < nlam * nq; ++r) rl[r] += x * lq[r];
            }
            if (dqd[k] != 0.0) {
                const double x = dqd[k];
                const double* cv = Cv.row(k).data();
                for (int r = 0; r < m_all_; ++r) rc[r] += x * cv[r];
            }
        }
    }
}

// The evaluation on the scalar S; the drivers are functions of t alone, evaluated in double.
template <class S>
Status TreeProgram::eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need,
                         TermsOf<S>& out, TreeScratch<S>& ws) const {
    using std::isfinite;
    using MatS = typename TreeScratch<S>::MatS;
    using VecS = typename TreeScratch<S>::VecS;
    const TreeModel& model = d_.model;
    const int nq = model.nq, nv = model.nv;
    Status st = normalize(q, ws);
    if (st != Status::ok) return st;
    for (int i = 0; i < nq; ++i)
        if (!isfinite(qd[i])) return Status::not_finite;
    velocity_map(q, qd, ws);

    const bool want_M = need & NEED_M;
    const bool want_h = need & NEED_H;
    const bool want_energy = need & NEED_ENERGY;
    const bool want_rows = need & (NEED_A | NEED_VELOCITY);
    const bool want_gamma = need & NEED_GAMMA;
    const bool want_phi = need & NEED_PHI;
    bool any_frame = false;
    if (want_rows || want_gamma || want_phi)
        for (std::size_t c = 0; c < d_.constraints.size(); ++c)
            if ((active == nullptr || active[c]) && d_.constraints[c].type != RowType::unit_quaternion &&
                d_.constraints[c].type != RowType::joint_coupling &&
                d_.constraints[c].type != RowType::joint_limit &&
                d_.constraints[c].type != RowType::joint_driver)
                any_frame = true;
    const bool want_g = need & NEED_GRAVITY;
    const bool motion = want_h || (want_gamma && any_frame);
    const bool dynamics = want_M || want_h || want_energy || want_g;
    if (dynamics || any_frame) {
        if constexpr (std::is_same_v<S, double>) {
            // the loop evaluates at one q several times (the projection's last evaluation and the
            // next stage, the guards, a controller's projections): the kinematics of the same q
            // (bitwise) are kept. (A q with a NaN never matches: normalize() rejected it.)
            // The inertias are added when first needed (body_inertias: the same bits as
            // forward_kinematics with `inertias`).
            const std::size_t bytes = sizeof(double) * static_cast<std::size_t>(nq);
            if (!(ws.fk_valid && std::memcmp(ws.fk_q.data(), q, bytes) == 0)) {
                forward_kinematics(model, ws.data, ws.qn.data(), dynamics);
                ws.fk_valid = true;
                ws.fk_inertias = dynamics;
                std::memcpy(ws.fk_q.data(), q, bytes);
            } else if (dynamics && !ws.fk_inertias) {
                body_inertias(model, ws.data);
                ws.fk_inertias = true;
            }
        } else {
            forward_kinematics(model, ws.data, ws.qn.data(), dynamics);
        }
    }
    if (want_g) {
        // f_g = h(t, q, 0) on this pass's kinematics: the motion and RNEA passes of an
        // evaluation at q̇ = 0 (v = Ṫq̇ = 0), before the pass at q̇ overwrites the motion
        forward_motion(model, ws.data, ws.zv.data(), ws.zv.data());
        rnea(model, ws.data, ws.zv.data(), ws.tau.data());
        ws.tau = -ws.tau;
        apply_Tt(ws, ws.tau.data(), out.f_g.data());
    }
    if (motion) forward_motion(model, ws.data, ws.v.data(), ws.a0.data());

    if (want_M || want_energy) {
        crba(model, ws.data, ws.Mv.data(), nv);
        if (want_M) {
            if (quat_)
                congruence(ws, out.M.data());
            else
                out.M = ws.Mv;
        }
        if (want_energy) {
            ws.fv.noalias() = ws.Mv * ws.v;
            out.kinetic = 0.5 * ws.v.dot(ws.fv);
            out.potential = potential_energy(model, ws.data);
        }
    }
    if (want_h) {
        rnea(model, ws.data, ws.a0.data(), ws.tau.data());
        ws.tau = -ws.tau;
        apply_Tt(ws, ws.tau.data(), out.h.data());
        for (int k = 0; k < nv; ++k) ws.fv[k] = -d_.damping[k] * ws.v[k];
        apply_Tt(ws, ws.fv.data(), out.f_passive.data());
    }
    if (need & NEED_B) {  // column c of B = Tᵀ e_{actuated[c]}
        out.B.setZero();
        for (int c = 0; c < k_; ++c) {
            if (act_q_[c] >= 0) {
                out.B(act_q_[c], c) = S(1.0);
                continue;
            }
            const int iv = d_.actuated[c];
            for (const QuatBlock& b : qblocks_) {
                if (iv >= b.a && iv < b.a + 3)
                    for (int k = 0; k < 4; ++k) out.B(b.qs + k, c) = ws.Tq[b.joint](iv - b.a, k);
                if (b.free && iv >= b.iv && iv < b.iv + 3)
                    for (int k = 0; k < 3; ++k) out.B(b.iq + k, c) = ws.R[b.joint](k, iv - b.iv);
            }
        }
    }
    if (!(want_rows || want_gamma || want_phi)) return Status::ok;

    MatS& target = quat_ ? ws.Av : out.A;  // frame rows in velocity space
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (active != nullptr && !active[ci]) continue;
        const TreeConstraint& c = d_.constraints[ci];
        const int r0 = constraints_[ci].row;
        const int dim = constraints_[ci].dim;
        S* g = out.gamma.data() + r0;
        S* p = out.phi.data() + r0;
        if (c.type == RowType::unit_quaternion) {
            const Eigen::Map<const Vec4T<S>> e(q + c.iq), ed(qd + c.iq);
            if (want_rows) {
                out.A.row(r0).setZero();
                for (int k = 0; k < 4; ++k) out.A(r0, c.iq + k) = e[k];
            }
            if (want_gamma) g[0] = ed.squaredNorm();
            if (want_phi) p[0] = 0.5 * (e.squaredNorm() - 1.0);
        } else if (c.type == RowType::joint_coupling) {
            const auto& a = c.coef;
            S val = q[c.iq] - c.ref1 - a[0], d1 = S(0.0), d2 = S(0.0), qd2 = S(0.0);
            if (c.iq2 >= 0) {
                const S x = q[c.iq2] - c.ref2;
                val -= a[1] * x + a[2] * x * x + a[3] * x * x * x + a[4] * x * x * x * x;
                d1 = a[1] + 2 * a[2] * x + 3 * a[3] * x * x + 4 * a[4] * x * x * x;
                d2 = 2 * a[2] + 6 * a[3] * x + 12 * a[4] * x * x;
                qd2 = qd[c.iq2];
            }
            if (want_rows) {
                out.A.row(r0).setZero();
                out.A(r0, c.iq) = S(1.0);
                if (c.iq2 >= 0) out.A(r0, c.iq2) -= d1;
            }
            if (want_gamma) g[0] = -d2 * qd2 * qd2;
            if (want_phi) p[0] = val;
        } else if (c.type == RowType::joint_limit) {
            const double s = c.coef[0];
            if (want_rows) {
                out.A.row(r0).setZero();
                out.A(r0, c.iq) = S(s);
            }
            if (want_gamma) g[0] = S(0.0);
            if (want_phi) p[0] = s * (q[c.iq] - c.ref1);
        } else if (c.type == RowType::joint_driver) {
            double f[3];
            const int st = d_.drivers[static_cast<std::size_t>(c.iq2)].eval(t, f, ws.treg.data());
            if (st == TimeFunction::EVAL_FAILED) return Status::callback_error;
            if (st != TimeFunction::EVAL_OK) return Status::not_finite;
            if (want_rows) {
                out.A.row(r0).setZero();
                out.A(r0, c.iq) = S(1.0);
            }
            if (want_gamma) g[0] = -f[2];
            if (want_phi) p[0] = q[c.iq] - f[0];
            if (need & NEED_VELOCITY) out.velocity[r0] = qd[c.iq] - f[1];
            continue;
        } else if (c.type == RowType::path_driver || c.type == RowType::distance_driver) {
            double phit[3] = {0.0, 0.0, 0.0};
            st = driver_rows(c, t, ws, want_rows, want_gamma, want_phi, target.row(r0).data(), g, p, phit);
            if (st != Status::ok) return st;
            if (want_rows && quat_)
                for (int r = 0; r < dim; ++r) apply_Tt(ws, ws.Av.row(r0 + r).data(), out.A.row(r0 + r).data());
            if (need & NEED_VELOCITY)
                for (int r = 0; r < dim; ++r)
                    out.velocity[r0 + r] = out.A.row(r0 + r).dot(Eigen::Map<const VecS>(qd, nq)) + phit[r];
            continue;
        } else {
            frame_rows(c, ws, want_rows, want_gamma, want_phi, target.row(r0).data(), g, p);
            if (want_rows && quat_)
                for (int r = 0; r < dim; ++r) apply_Tt(ws, ws.Av.row(r0 + r).data(), out.A.row(r0 + r).data());
        }
        if (need & NEED_VELOCITY)
            for (int r = 0; r < dim; ++r)
                out.velocity[r0 + r] = out.A.row(r0 + r).dot(Eigen::Map<const VecS>(qd, nq));
    }
    return Status::ok;
}

void TreeProgram::add_Tdot_row(const TreeWorkspace& ws, const double* q, const double* qd,
                               const double* av, double* aq) const {
    for (const QuatBlock& b : qblocks_) {
        const Eigen::Map<const Vec4> e(q + b.qs), ed(qd + b.qs);
        const double s2 = e.squaredNorm();
        // d/dt (2 G(ε)/|ε|²) = 2 G(ε̇)/|ε|² − 2 (εᵀε̇)/|ε|² · 2 G(ε)/|ε|²
        const Mat34 Td = (2.0 / s2) * quaternion_G(ed.data()) - (2.0 * e.dot(ed) / s2) * ws.Tq[b.joint];
        Eigen::Map<Vec4>(aq + b.qs) += Td.transpose() * Eigen::Map<const Vec3>(av + b.a);
        if (b.free) {  // d/dt Rᵀ = −[ω]× Rᵀ on the position columns
            const Vec3 w = ws.Tq[b.joint] * ed;
            const Mat3 Rd = -skew(w) * ws.R[b.joint].transpose();
            Eigen::Map<Vec3>(aq + b.iq) += Rd.transpose() * Eigen::Map<const Vec3>(av + b.iv);
        }
    }
}

Status TreeProgram::coriolis_matrix(const double* q, const double* qd, TreeWorkspace& ws,
                                    double* C) const {
    ws.fk_valid = false;  // (writes ws.data)
    const TreeModel& model = d_.model;
    const int nq = model.nq, nv = model.nv;
    Status st = normalize(q, ws);
    if (st != Status::ok) return st;
    for (int i = 0; i < nq; ++i)
        if (!std::isfinite(qd[i])) return Status::not_finite;
    velocity_map(q, qd, ws);
    forward_kinematics(model, ws.data, ws.qn.data(), true);
    forward_motion<double>(model, ws.data, ws.v.data(), nullptr);
    crba(model, ws.data, ws.Mv.data(), nv);
    Mat Cv = Mat::Zero(nv, nv);
    coriolis(model, ws.data, Cv.data(), nv);
    Mat X = Mat::Zero(nv, nq);  // C_v T + M_v Ṫ
    for (int r = 0; r < nv; ++r) {
        apply_Tt(ws, Cv.row(r).data(), X.row(r).data());
        add_Tdot_row(ws, q, qd, ws.Mv.row(r).data(), X.row(r).data());
    }
    Eigen::Map<Mat> out(C, nq, nq);
    Vec col(nv), res(nq);
    for (int c = 0; c < nq; ++c) {  // column c of Tᵀ X
        col = X.col(c);
        apply_Tt(ws, col.data(), res.data());
        out.col(c) = res;
    }
    return Status::ok;
}

Status TreeProgram::jacobian_dot(const double* q, const double* qd, const std::uint8_t* active,
                                 TreeWorkspace& ws, double* Adot) const {
    ws.fk_valid = false;  // (writes ws.data)
    const TreeModel& model = d_.model;
    const int nq = model.nq, nv = model.nv;
    Status st = normalize(q, ws);
    if (st != Status::ok) return st;
    for (int i = 0; i < nq; ++i)
        if (!std::isfinite(qd[i])) return Status::not_finite;
    velocity_map(q, qd, ws);
    forward_kinematics(model, ws.data, ws.qn.data(), false);
    forward_motion<double>(model, ws.data, ws.v.data(), nullptr);
    Eigen::Map<Mat> out(Adot, m_all_, nq);
    Vec av(nv), adv(nv);
    const Vec3 zero = Vec3::Zero();
    for (std::size_t ci = 0; ci < d_.constraints.size(); ++ci) {
        if (active != nullptr && !active[ci]) continue;
        const TreeConstraint& c = d_.constraints[ci];
        const int r0 = constraints_[ci].row;
        if (c.type == RowType::unit_quaternion) {
            out.row(r0).setZero();
            for (int k = 0; k < 4; ++k) out(r0, c.iq + k) = qd[c.iq + k];
            continue;
        }
        if (c.type == RowType::joint_limit || c.type == RowType::joint_driver) {
            out.row(r0).setZero();
            continue;
        }
        if (c.type == RowType::joint_coupling) {
            out.row(r0).setZero();
            if (c.iq2 >= 0) {
                const auto& a = c.coef;
                const double x = q[c.iq2] - c.ref2;
                const double d2 = 2 * a[2] + 6 * a[3] * x + 12 * a[4] * x * x;
                out(r0, c.iq2) = -d2 * qd[c.iq2];
            }
            continue;
        }
        const Frame& fa = d_.frames[c.frame_a];
        const Frame& fb = d_.frames[c.frame_b];
        FrameKinematics& ka = ws.ka;
        FrameKinematics& kb = ws.kb;
        frame_kinematics(model, ws.data, fa, true, ka);
        frame_kinematics(model, ws.data, fb, true, kb);
        // one row: coefficients (c, ċ) on frame a and frame b
        auto row = [&](int r, const Vec3& la, const Vec3& aa, const Vec3& lb, const Vec3& ab,
                       const Vec3& dla, const Vec3& daa, const Vec3& dlb, const Vec3& dab) {
            av.setZero();
            adv.setZero();
            if (fa.joint >= 0) {
                add_jacobian_row(model, ws.data, fa.joint, ka.oMf.p, la, aa, av.data());
                add_jacobian_dot_row(model, ws.data, fa.joint, ka.oMf.p, ka.v, la, aa, dla, daa, adv.data());
            }
            if (fb.joint >= 0) {
                add_jacobian_row(model, ws.data, fb.joint, kb.oMf.p, lb, ab, av.data());
                add_jacobian_dot_row(model, ws.data, fb.joint, kb.oMf.p, kb.v, lb, ab, dlb, dab, adv.data());
            }
            double* dst = out.row(r0 + r).data();
            apply_Tt(ws, adv.data(), dst);
            if (quat_) add_Tdot_row(ws, q, qd, av.data(), dst);
        };
        const Mat3& Ra = ka.oMf.R;
        const Mat3& Rb = kb.oMf.R;
        switch (c.type) {
            case RowType::point:
            case RowType::weld:
            case RowType::hinge:
                for (int i = 0; i < 3; ++i) {
                    const Vec3 e = Vec3::Unit(i);
                    row(i, e, zero, -e, zero, zero, zero, zero, zero);
                }
                if (c.type == RowType::weld)
                    for (int i = 0; i < 3; ++i) {
                        const Vec3 e = Vec3::Unit(i);
                        row(3 + i, zero, e, zero, -e, zero, zero, zero, zero);
                    }
                if (c.type == RowType::hinge) {
                    const Vec3 Kb = Rb * c.axis;
                    for (int i = 0; i < 2; ++i) {
                        const Vec3 U = Ra * (i == 0 ? c.u1 : c.u2);
                        const Vec3 r = U.cross(Kb);
                        const Vec3 rd = ka.w.cross(U).cross(Kb) + U.cross(kb.w.cross(Kb));
                        row(3 + i, zero, r, zero, -r, zero, rd, zero, -rd);
                    }
                }
                break;
            case RowType::planar_point:
            case RowType::planar_weld:
                for (int i = 0; i < 2; ++i) {
                    const Vec3& e = i == 0 ? c.u1 : c.u2;
                    row(i, e, zero, -e, zero, zero, zero, zero, zero);
                }
                if (c.type == RowType::planar_weld) row(2, zero, c.axis, zero, -c.axis, zero, zero, zero, zero);
                break;
            case RowType::point_on_plane:
            case RowType::contact: {
                const Vec3 N = Ra * c.axis;
                const Vec3 d = kb.oMf.p - ka.oMf.p;
                const Vec3 Nd = ka.w.cross(N);
                const Vec3 dd = kb.v - ka.v;
                row(0, -N, N.cross(d), N, zero, -Nd, Nd.cross(d) + N.cross(dd), Nd, zero);
                break;
            }
            case RowType::path_driver: {
                int r = 0;
                for (int i = 0; i < 3; ++i)
                    if (c.drv[i] >= 0) {
                        const Vec3 e = Vec3::Unit(i);
                        row(r++, -e, zero, e, zero, zero, zero, zero, zero);
                    }
                break;
            }
            case RowType::distance_driver: {
                const double L = c.ref1;
                const Vec3 d = (kb.oMf.p - ka.oMf.p) / L;
                const Vec3 dd = (kb.v - ka.v) / L;
                row(0, -d, zero, d, zero, -dd, zero, dd, zero);
                break;
            }
            default: break;
        }
    }
    return Status::ok;
}

template Status TreeProgram::normalize<double>(const double*, TreeScratch<double>&) const;
template void TreeProgram::velocity_map<double>(const double*, const double*, TreeScratch<double>&) const;

}  // namespace nonmin::rbd
