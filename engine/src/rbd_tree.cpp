// Rigid-body tree algorithms (see nonmin/rbd/tree.hpp): forward kinematics, CRBA, RNEA, frame
// kinematics and Jacobian rows, in world axes at the world origin. No allocation after
// TreeData's constructor.
#include <string>

#include "nonmin/rbd/tree.hpp"

namespace nonmin::rbd {

// The algorithms below are NONMIN_FLATTEN (dual.hpp): every call they make is inlined.

void TreeModel::validate() const {
    if (nq < 0 || nv < 0) throw EngineError("tree model: negative nq or nv");
    std::vector<int> qused(nq, 0), vused(nv, 0);
    for (std::size_t i = 0; i < joints.size(); ++i) {
        const Joint& j = joints[i];
        const int t = static_cast<int>(j.type);
        if (t < 0 || t > 4) throw EngineError("tree model: joint " + std::to_string(i) + " has an unknown type");
        if (j.parent < -1 || j.parent >= static_cast<int>(i))
            throw EngineError("tree model: joint " + std::to_string(i) + " must have a parent in [-1, " +
                              std::to_string(i) + "), got " + std::to_string(j.parent));
        if (j.axis_index < -1 || j.axis_index > 2)
            throw EngineError("tree model: joint " + std::to_string(i) + ": axis_index must be -1, 0, 1 or 2");
        const int nqj = joint_nq(j.type), nvj = joint_nv(j.type);
        if (j.iq < 0 || j.iq + nqj > nq || j.iv < 0 || j.iv + nvj > nv)
            throw EngineError("tree model: joint " + std::to_string(i) + " indices out of range");
        for (int k = 0; k < nqj; ++k) qused[j.iq + k] += 1;
        for (int k = 0; k < nvj; ++k) vused[j.iv + k] += 1;
        if (!(j.mass >= 0.0) || !j.com.allFinite() || !j.inertia.allFinite() || !j.axis.allFinite() ||
            !j.placement.R.allFinite() || !j.placement.p.allFinite())
            throw EngineError("tree model: joint " + std::to_string(i) + " has a non-finite or negative parameter");
        if ((j.type == JointType::revolute || j.type == JointType::prismatic) &&
            std::abs(j.axis.norm() - 1.0) > 1e-12)
            throw EngineError("tree model: joint " + std::to_string(i) + ": axis must be a unit vector");
    }
    for (int k = 0; k < nq; ++k)
        if (qused[k] != 1) throw EngineError("tree model: configuration index " + std::to_string(k) + " is not owned by exactly one joint");
    for (int k = 0; k < nv; ++k)
        if (vused[k] != 1) throw EngineError("tree model: velocity index " + std::to_string(k) + " is not owned by exactly one joint");
    if (armature.size() != nv || !armature.allFinite())
        throw EngineError("tree model: armature must hold nv finite values");
    if (!gravity.allFinite()) throw EngineError("tree model: gravity must be finite");
}

bool TreeModel::has_quaternions() const {
    for (const Joint& j : joints)
        if (j.type == JointType::spherical || j.type == JointType::free_flyer) return true;
    return false;
}

template <class S>
NONMIN_FLATTEN void forward_kinematics(const TreeModel& model, TreeDataT<S>& data, const S* q, bool inertias) {
    using V3 = Vec3T<S>;
    const int nj = static_cast<int>(model.joints.size());
    for (int i = 0; i < nj; ++i) {
        const Joint& jt = model.joints[i];
        const S* qi = q + jt.iq;
        SE3T<S> XJ;
        switch (jt.type) {
            case JointType::revolute:
                XJ.R = jt.axis_index >= 0 ? coordinate_rotation(jt.axis_index, qi[0])
                                          : axis_rotation(jt.axis, qi[0]);
                break;
            case JointType::prismatic: XJ.p = qi[0] * jt.axis; break;
            case JointType::spherical: XJ.R = quaternion_rotation(qi); break;
            case JointType::free_flyer:
                XJ.R = quaternion_rotation(qi + 3);
                XJ.p = V3(qi[0], qi[1], qi[2]);
                break;
            case JointType::translation: XJ.p = V3(qi[0], qi[1], qi[2]); break;
        }
        const SE3T<S> liMi = jt.placement * XJ;
        SE3T<S>& X = data.oMi[i];
        X = jt.parent >= 0 ? data.oMi[jt.parent] * liMi : liMi;
        auto col = [&](int k, const V3& lin, const V3& ang) {
            data.J.col(jt.iv + k).template head<3>() = lin;
            data.J.col(jt.iv + k).template tail<3>() = ang;
        };
        switch (jt.type) {
            case JointType::revolute: {
                const V3 a = X.R * jt.axis;
                col(0, X.p.cross(a), a);
                break;
            }
            case JointType::prismatic: col(0, X.R * jt.axis, V3::Zero()); break;
            case JointType::spherical:
                for (int k = 0; k < 3; ++k) col(k, X.p.cross(X.R.col(k)), X.R.col(k));
                break;
            case JointType::free_flyer:
                for (int k = 0; k < 3; ++k) {
                    col(k, X.R.col(k), V3::Zero());
                    col(3 + k, X.p.cross(X.R.col(k)), X.R.col(k));
                }
                break;
            case JointType::translation:
                for (int k = 0; k < 3; ++k) col(k, X.R.col(k), V3::Zero());
                break;
        }
        if (inertias) data.oI[i] = InertiaT<S>::from_body(jt.mass, jt.com, jt.inertia, X);
    }
}

template <class S>
NONMIN_FLATTEN void body_inertias(const TreeModel& model, TreeDataT<S>& data) {
    const int nj = static_cast<int>(model.joints.size());
    for (int i = 0; i < nj; ++i) {
        const Joint& jt = model.joints[i];
        data.oI[i] = InertiaT<S>::from_body(jt.mass, jt.com, jt.inertia, data.oMi[i]);
    }
}

template <class S>
NONMIN_FLATTEN void forward_motion(const TreeModel& model, TreeDataT<S>& data, const S* v, const S* a) {
    const int nj = static_cast<int>(model.joints.size());
    for (int i = 0; i < nj; ++i) {
        const Joint& jt = model.joints[i];
        const int nvj = joint_nv(jt.type);
        MotionT<S> vJ, aJ;
        for (int k = 0; k < nvj; ++k) {
            const auto c = data.J.col(jt.iv + k);
            vJ.lin += c.template head<3>() * v[jt.iv + k];
            vJ.ang += c.template tail<3>() * v[jt.iv + k];
            if (a != nullptr) {
                aJ.lin += c.template head<3>() * a[jt.iv + k];
                aJ.ang += c.template tail<3>() * a[jt.iv + k];
            }
        }
        MotionT<S>& vi = data.ov[i];
        MotionT<S>& ai = data.oa[i];
        if (jt.parent >= 0) {
            vi = data.ov[jt.parent];
            ai = data.oa[jt.parent];
        } else {
            vi.set_zero();
            ai.set_zero();
        }
        vi += vJ;
        ai += aJ;
        ai += cross(vi, vJ);
    }
}

template <class S>
NONMIN_FLATTEN void crba(const TreeModel& model, TreeDataT<S>& data, S* M, int ld) {
    const int nj = static_cast<int>(model.joints.size());
    for (int i = 0; i < nj; ++i) data.Ic[i] = data.oI[i];
    for (int i = nj - 1; i >= 0; --i) {
        const Joint& jt = model.joints[i];
        const int nvi = joint_nv(jt.type);
        for (int c = 0; c < nvi; ++c) {
            const int col = jt.iv + c;
            MotionT<S> Sm;
            Sm.lin = data.J.col(col).template head<3>();
            Sm.ang = data.J.col(col).template tail<3>();
            const ForceT<S> F = data.Ic[i] * Sm;
            for (int j = i; j >= 0; j = model.joints[j].parent) {
                const Joint& js = model.joints[j];
                const int nvj = joint_nv(js.type);
                for (int d = 0; d < nvj; ++d) {
                    const int row = js.iv + d;
                    if (j == i && d > c) continue;  // upper part of the diagonal block below
                    const S val = data.J.col(row).template head<3>().dot(F.lin) +
                                  data.J.col(row).template tail<3>().dot(F.ang);
                    M[row * ld + col] = val;
                    M[col * ld + row] = val;
                }
            }
        }
        if (jt.parent >= 0) data.Ic[jt.parent] += data.Ic[i];
    }
    for (int k = 0; k < model.nv; ++k) M[k * ld + k] += model.armature[k];
}

template <class S>
NONMIN_FLATTEN void rnea(const TreeModel& model, TreeDataT<S>& data, const S* a, S* tau) {
    const int nj = static_cast<int>(model.joints.size());
    for (int i = 0; i < nj; ++i) {
        MotionT<S> ag = data.oa[i];
        ag.lin -= model.gravity;
        data.of[i] = data.oI[i] * ag;
        data.of[i] += cross_force(data.ov[i], data.oI[i] * data.ov[i]);
    }
    for (int i = nj - 1; i >= 0; --i) {
        const Joint& jt = model.joints[i];
        const int nvi = joint_nv(jt.type);
        for (int c = 0; c < nvi; ++c) {
            const auto col = data.J.col(jt.iv + c);
            tau[jt.iv + c] =
                col.template head<3>().dot(data.of[i].lin) + col.template tail<3>().dot(data.of[i].ang);
        }
        if (jt.parent >= 0) data.of[jt.parent] += data.of[i];
    }
    if (a != nullptr)
        for (int k = 0; k < model.nv; ++k) tau[k] += model.armature[k] * a[k];
}

template <class S>
S potential_energy(const TreeModel& model, const TreeDataT<S>& data) {
    Vec3T<S> h = Vec3T<S>::Zero();
    for (std::size_t i = 0; i < model.joints.size(); ++i) h += data.oI[i].h;
    return -model.gravity.dot(h);
}

template <class S>
NONMIN_FLATTEN SE3T<S> frame_placement(const TreeModel& /*model*/, const TreeDataT<S>& data, const Frame& frame) {
    if (frame.joint >= 0) return data.oMi[frame.joint] * frame.placement;
    return SE3T<S>{frame.placement.R.template cast<S>(), frame.placement.p.template cast<S>()};
}

template <class S>
NONMIN_FLATTEN void frame_kinematics(const TreeModel& model, const TreeDataT<S>& data, const Frame& frame, bool motion,
                      FrameKinematicsT<S>& out) {
    out.oMf = frame_placement(model, data, frame);
    if (!motion) return;
    if (frame.joint < 0) {
        out.v.setZero();
        out.w.setZero();
        out.a.setZero();
        out.alpha.setZero();
        return;
    }
    const Vec3T<S>& p = out.oMf.p;
    const MotionT<S>& v = data.ov[frame.joint];
    const MotionT<S>& a = data.oa[frame.joint];
    out.w = v.ang;
    out.v = v.lin + v.ang.cross(p);
    out.alpha = a.ang;
    out.a = a.lin + a.ang.cross(p) + out.w.cross(out.v);
}

template <class S>
NONMIN_FLATTEN void add_jacobian_row(const TreeModel& model, const TreeDataT<S>& data, int joint, const Vec3T<S>& p,
                      const Vec3T<S>& c_lin, const Vec3T<S>& c_ang, S* row) {
    const Vec3T<S> wa = c_ang + p.cross(c_lin);
    for (int j = joint; j >= 0; j = model.joints[j].parent) {
        const Joint& jt = model.joints[j];
        const int nvj = joint_nv(jt.type);
        for (int k = 0; k < nvj; ++k) {
            const auto col = data.J.col(jt.iv + k);
            row[jt.iv + k] += col.template head<3>().dot(c_lin) + col.template tail<3>().dot(wa);
        }
    }
}

// The instantiations the engine calls (nm -u of the other units): every algorithm on double; on Dual
// (evaluate_tangent) and DualW (residual_tangents) only those the programs call. The copies of
// body_inertias and frame_placement on Dual / DualW, and of crba and potential_energy on DualW,
// were never referenced (the linker dropped them: 25 KB of code compiled for nothing; build time,
// #17 target 7).
#define NONMIN_RBD_INSTANTIATE_TANGENT(S)                                                             \
    template void forward_kinematics<S>(const TreeModel&, TreeDataT<S>&, const S*, bool);             \
    template void forward_motion<S>(const TreeModel&, TreeDataT<S>&, const S*, const S*);             \
    template void rnea<S>(const TreeModel&, TreeDataT<S>&, const S*, S*);                              \
    template void frame_kinematics<S>(const TreeModel&, const TreeDataT<S>&, const Frame&, bool,       \
                                      FrameKinematicsT<S>&);                                           \
    template void add_jacobian_row<S>(const TreeModel&, const TreeDataT<S>&, int, const Vec3T<S>&,     \
                                      const Vec3T<S>&, const Vec3T<S>&, S*);
NONMIN_RBD_INSTANTIATE_TANGENT(double)
NONMIN_RBD_INSTANTIATE_TANGENT(Dual)
NONMIN_RBD_INSTANTIATE_TANGENT(DualW)
#undef NONMIN_RBD_INSTANTIATE_TANGENT
template void body_inertias<double>(const TreeModel&, TreeDataT<double>&);
template void crba<double>(const TreeModel&, TreeDataT<double>&, double*, int);
template void crba<Dual>(const TreeModel&, TreeDataT<Dual>&, Dual*, int);
template double potential_energy<double>(const TreeModel&, const TreeDataT<double>&);
template Dual potential_energy<Dual>(const TreeModel&, const TreeDataT<Dual>&);
template SE3T<double> frame_placement<double>(const TreeModel&, const TreeDataT<double>&, const Frame&);

namespace {

using Mat6 = Eigen::Matrix<double, 6, 6>;

Mat6 inertia_matrix(const Inertia& I) {  // (lin, ang) ordering
    Mat6 X;
    X.topLeftCorner<3, 3>() = I.m * Mat3::Identity();
    X.topRightCorner<3, 3>() = -skew(I.h);
    X.bottomLeftCorner<3, 3>() = skew(I.h);
    X.bottomRightCorner<3, 3>() = I.I;
    return X;
}

Mat6 motion_cross(const Motion& v) {  // μ ↦ ν × μ
    Mat6 X = Mat6::Zero();
    X.topLeftCorner<3, 3>() = skew(v.ang);
    X.topRightCorner<3, 3>() = skew(v.lin);
    X.bottomRightCorner<3, 3>() = skew(v.ang);
    return X;
}

Mat6 force_cross_bar(const Force& f) {  // ν ↦ ν ×* f (skew-symmetric)
    Mat6 X = Mat6::Zero();
    X.topRightCorner<3, 3>() = -skew(f.lin);
    X.bottomLeftCorner<3, 3>() = -skew(f.lin);
    X.bottomRightCorner<3, 3>() = -skew(f.ang);
    return X;
}

Eigen::Matrix<double, 6, 1> col6(const TreeData& data, int k) { return data.J.col(k); }

Eigen::Matrix<double, 6, 1> col6_dot(const TreeData& data, int j, int k) {  // ν_j × J_k
    const Motion d = cross(data.ov[j], joint_twist(data, k));
    Eigen::Matrix<double, 6, 1> out;
    out << d.lin, d.ang;
    return out;
}

}  // namespace

namespace {

using Vec6 = Eigen::Matrix<double, 6, 1>;

Force mat_force(const Mat6& K, const Motion& m) {  // K (lin, ang) applied to a motion
    Vec6 x;
    x << m.lin, m.ang;
    const Vec6 y = K * x;
    return Force{y.head<3>(), y.tail<3>()};
}

double col_dot(const TreeData& data, int col, const Force& f) {
    return data.J.col(col).head<3>().dot(f.lin) + data.J.col(col).tail<3>().dot(f.ang);
}

bool in_subtree(const TreeModel& model, int j, int k) {  // j ⪰ k (parent < child)
    while (j > k) j = model.joints[j].parent;
    return j == k;
}

}  // namespace

void rnea_derivatives(const TreeModel& model, TreeData& data, const double* v, const double* a, double* dtau_dq,
                      double* dtau_dv) {
    const int nj = static_cast<int>(model.joints.size());
    const int nv = model.nv;
    forward_motion(model, data, v, a);
    // per body: α with the gravity offset, f = I α + ν ×* I ν, momentum, K = ν×* I − I ν×
    for (int i = 0; i < nj; ++i) {
        data.oa[i].lin -= model.gravity;
        const Inertia& I = data.oI[i];
        const Motion& nu = data.ov[i];
        data.oh[i] = I * nu;
        data.of[i] = I * data.oa[i];
        data.of[i] += cross_force(nu, data.oh[i]);
        data.Ic[i] = I;
        const Mat6 Im = inertia_matrix(I);
        const Mat6 X = motion_cross(nu);
        data.Bc[i].noalias() = -X.transpose() * Im;
        data.Bc[i].noalias() -= Im * X;
    }
    // subtree sums (children have larger indices)
    for (int i = nj - 1; i > 0; --i) {
        const int p = model.joints[i].parent;
        if (p < 0) continue;
        data.of[p] += data.of[i];
        data.oh[p] += data.oh[i];
        data.Ic[p] += data.Ic[i];
        data.Bc[p] += data.Bc[i];
    }
    for (int i = 0; i < nv * nv; ++i) {
        dtau_dq[i] = 0.0;
        dtau_dv[i] = 0.0;
    }
    // per column c of joint j, the row vectors of the brackets below: J_cᵀ Ic_j x = w_c·x,
    // J_cᵀ (x ×* Hc_j) + J_cᵀ K_j x = y_c·x (w_c = Ic_j J_c, y_c = K_jᵀ J_c − J_c ×* Hc_j, using
    // a·(x ×* f) = −x·(a ×* f)): 12 products per (j, k) pair instead of the 6 × 6 ones
    for (int j = 0; j < nj; ++j) {
        const Joint& jj = model.joints[j];
        for (int d = 0; d < joint_nv(jj.type); ++d) {
            const int c = jj.iv + d;
            const Motion Jc = joint_twist(data, c);
            data.cw[c] = data.Ic[j] * Jc;
            Vec6 x;
            x << Jc.lin, Jc.ang;
            const Vec6 y = data.Bc[j].transpose() * x;
            const Force h = cross_force(Jc, data.oh[j]);
            data.cy[c].lin = y.head<3>() - h.lin;
            data.cy[c].ang = y.tail<3>() - h.ang;
        }
    }
    auto dot = [](const Force& f, const Motion& m) { return f.lin.dot(m.lin) + f.ang.dot(m.ang); };
    for (int k = 0; k < nj; ++k) {
        const Joint& jk = model.joints[k];
        Motion nup, agp;  // the parent's velocity and acceleration
        parent_motion(model, data, k, nup, agp);
        for (int c = 0; c < joint_nv(jk.type); ++c) {
            const int col = jk.iv + c;
            const Motion xi = joint_twist(data, col);
            const Motion eta = cross(xi, nup);
            Motion bq = cross(xi, agp);  // ξ × α_p − η × ν_p
            const Motion en = cross(eta, nup);
            bq.lin -= en.lin;
            bq.ang -= en.ang;
            // −ξ × (ν_p + ν_k): along v_k, δα_i = ξ × ν_i − ξ × ν_p − ξ × ν_k (i ⪰ k); for a
            // 1-dof joint ξ × ν_k = ξ × ν_p (−2 ξ × ν_p), not for a free flyer's or a spherical
            // joint's columns (ξ × J_k v_k ≠ 0)
            Motion bv = cross(xi, data.ov[k]);
            bv.lin = -(bv.lin + eta.lin);
            bv.ang = -(bv.ang + eta.ang);
            // the brackets at j = k in full (the ancestors' rows need them)
            Force Sqk = data.Ic[k] * bq;
            Sqk += cross_force(eta, data.oh[k]);
            Sqk += mat_force(data.Bc[k], eta);
            Force Svk = data.Ic[k] * bv;
            Svk += cross_force(xi, data.oh[k]);
            Svk += mat_force(data.Bc[k], xi);
            for (int j = k; j < nj; ++j) {
                if (!in_subtree(model, j, k)) continue;
                const Joint& jj = model.joints[j];
                for (int d = 0; d < joint_nv(jj.type); ++d) {
                    const int c = jj.iv + d;
                    dtau_dq[col * nv + c] = -(dot(data.cw[c], bq) + dot(data.cy[c], eta));
                    dtau_dv[col * nv + c] = dot(data.cw[c], bv) + dot(data.cy[c], xi);
                }
            }
            // strict ancestors: J_jᵀ (ξ ×* F_k − S_k) and J_jᵀ Sv_k
            Force Fq = cross_force(xi, data.of[k]);
            Fq.lin -= Sqk.lin;
            Fq.ang -= Sqk.ang;
            for (int j = jk.parent; j >= 0; j = model.joints[j].parent) {
                const Joint& jj = model.joints[j];
                for (int d = 0; d < joint_nv(jj.type); ++d) {
                    dtau_dq[col * nv + jj.iv + d] = col_dot(data, jj.iv + d, Fq);
                    dtau_dv[col * nv + jj.iv + d] = col_dot(data, jj.iv + d, Svk);
                }
            }
        }
    }
}

void coriolis(const TreeModel& model, TreeData& data, double* C, int ld) {
    const int nj = static_cast<int>(model.joints.size());
    for (int r = 0; r < model.nv; ++r)  // entries of unrelated joints stay zero
        for (int c = 0; c < model.nv; ++c) C[r * ld + c] = 0.0;
    for (int i = 0; i < nj; ++i) {
        const Inertia& I = data.oI[i];
        const Motion& v = data.ov[i];
        const Mat6 Im = inertia_matrix(I);
        const Mat6 X = motion_cross(v);
        // ν×* = −(ν×)ᵀ
        data.Bc[i] = 0.5 * (-X.transpose() * Im - Im * X + force_cross_bar(I * v));
        data.Ic[i] = I;
    }
    for (int i = nj - 1; i >= 0; --i)
        if (model.joints[i].parent >= 0) {
            data.Ic[model.joints[i].parent] += data.Ic[i];
            data.Bc[model.joints[i].parent] += data.Bc[i];
        }
    for (int j = 0; j < nj; ++j) {
        const Joint& jt = model.joints[j];
        const Mat6 Icm = inertia_matrix(data.Ic[j]);
        const Mat6& B = data.Bc[j];
        for (int c = 0; c < joint_nv(jt.type); ++c) {
            const int b = jt.iv + c;
            // columns a of j and its ancestors: C(a, b) = J_aᵀ (Ic_j J̇_b + Bc_j J_b)
            const Eigen::Matrix<double, 6, 1> F = Icm * col6_dot(data, j, b) + B * col6(data, b);
            for (int a_j = j; a_j >= 0; a_j = model.joints[a_j].parent) {
                const Joint& ja = model.joints[a_j];
                for (int d = 0; d < joint_nv(ja.type); ++d) C[(ja.iv + d) * ld + b] = col6(data, ja.iv + d).dot(F);
            }
            // strict ancestors' columns b' (as the right index) with a = b: C(b, b') =
            // J_bᵀ (Ic_j J̇_b' + Bc_j J_b')
            const Eigen::Matrix<double, 6, 1> G1 = Icm * col6(data, b);
            const Eigen::Matrix<double, 6, 1> G2 = B.transpose() * col6(data, b);
            for (int p = jt.parent; p >= 0; p = model.joints[p].parent) {
                const Joint& jp = model.joints[p];
                for (int d = 0; d < joint_nv(jp.type); ++d) {
                    const int bp = jp.iv + d;
                    C[b * ld + bp] = G1.dot(col6_dot(data, p, bp)) + G2.dot(col6(data, bp));
                }
            }
        }
    }
}

void add_jacobian_dot_row(const TreeModel& model, const TreeData& data, int joint, const Vec3& p,
                          const Vec3& pdot, const Vec3& c_lin, const Vec3& c_ang,
                          const Vec3& cdot_lin, const Vec3& cdot_ang, double* row) {
    Eigen::Matrix<double, 6, 1> w, wd;
    w << c_lin, c_ang + p.cross(c_lin);
    wd << cdot_lin, cdot_ang + pdot.cross(c_lin) + p.cross(cdot_lin);
    for (int j = joint; j >= 0; j = model.joints[j].parent) {
        const Joint& jt = model.joints[j];
        for (int k = 0; k < joint_nv(jt.type); ++k) {
            const int col = jt.iv + k;
            row[col] += col6_dot(data, j, col).dot(w) + col6(data, col).dot(wd);
        }
    }
}

void frame_jacobian(const TreeModel& model, const TreeData& data, const Frame& frame, double* J6,
                    int ld) {
    for (int r = 0; r < 6; ++r)
        for (int k = 0; k < model.nv; ++k) J6[r * ld + k] = 0.0;
    const Vec3 p = frame_placement(model, data, frame).p;
    for (int j = frame.joint; j >= 0; j = model.joints[j].parent) {
        const Joint& jt = model.joints[j];
        const int nvj = joint_nv(jt.type);
        for (int k = 0; k < nvj; ++k) {
            const auto col = data.J.col(jt.iv + k);
            const Vec3 ang = col.tail<3>();
            const Vec3 lin = col.head<3>() + ang.cross(p);
            for (int r = 0; r < 3; ++r) {
                J6[r * ld + jt.iv + k] = lin[r];
                J6[(3 + r) * ld + jt.iv + k] = ang[r];
            }
        }
    }
}

}  // namespace nonmin::rbd
