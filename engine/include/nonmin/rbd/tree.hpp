// Rigid-body trees: the plain-data model description (extracted once, at load time, from
// Pinocchio or MuJoCo by nonmin.model.robots) and the free-function algorithms over
// (model, data, q, v, a): forward kinematics, CRBA, RNEA, frame kinematics and Jacobians.
//
// Conventions are Pinocchio's, so that every quantity can be checked against it: joints are
// numbered with parent < child, joint i's frame is oMi = oM_parent · placement_i · X_J(q_i), its
// velocity v_i (nv_i components) is expressed in the joint frame (free flyer: body-frame linear
// velocity and body angular velocity; spherical: body angular velocity), the generalized
// velocity v and acceleration a are Pinocchio's (nv), and a configuration holds each quaternion
// as (x, y, z, w) (normalized by the algorithms). Internally all spatial quantities are in world
// axes at the world origin (spatial.hpp): the joint motion subspace J_i = Ad(oMi) S_i, the body
// velocity ν_i = ν_parent + J_i v_i and the spatial acceleration
// α_i = α_parent + J_i a_i + ν_i × J_i v_i (S_i is constant in the joint frame for every joint
// type here, so the joint bias c_J is zero).
#pragma once
#include <vector>

#include "../types.hpp"
#include "spatial.hpp"

namespace nonmin::rbd {

enum class JointType : int {
    revolute = 0,     // 1 dof about `axis` (Pinocchio RX/RY/RZ, RevoluteUnaligned)
    prismatic = 1,    // 1 dof along `axis` (PX/PY/PZ, PrismaticUnaligned)
    spherical = 2,    // nq 4 (quaternion), nv 3 (body angular velocity)
    free_flyer = 3,   // nq 7 (position, quaternion), nv 6 (body linear, body angular velocity)
    translation = 4,  // nq = nv = 3, translation in the joint frame
};

constexpr int joint_nq(JointType t) {
    return t == JointType::free_flyer ? 7 : t == JointType::spherical ? 4 : t == JointType::translation ? 3 : 1;
}
constexpr int joint_nv(JointType t) {
    return t == JointType::free_flyer ? 6 : (t == JointType::spherical || t == JointType::translation) ? 3 : 1;
}

struct Joint {
    JointType type = JointType::revolute;
    int parent = -1;       // parent joint index, −1 for the world; parent < this joint's index
    int axis_index = -1;   // 0, 1, 2 when `axis` is that coordinate axis (exact rotations), else −1
    Vec3 axis = Vec3::UnitZ();  // unit axis in the joint frame (revolute, prismatic)
    int iq = 0;            // first configuration index
    int iv = 0;            // first velocity index
    SE3 placement;         // joint frame in the parent joint frame (Pinocchio jointPlacements)
    double mass = 0.0;     // body carried by the joint (Pinocchio inertias), in the joint frame:
    Vec3 com = Vec3::Zero();        // centre of mass
    Mat3 inertia = Mat3::Zero();    // rotational inertia about the centre of mass
};

// An operational frame: rigidly attached to `joint` (−1: the world) at `placement`.
struct Frame {
    int joint = -1;
    SE3 placement;
};

struct TreeModel {
    int nq = 0;
    int nv = 0;
    std::vector<Joint> joints;
    Vec3 gravity = Vec3(0.0, 0.0, -9.81);
    Vec armature;  // nv, added to the diagonal of M (Pinocchio's model.armature)

    // Throws EngineError when the description is inconsistent (indices, sizes, parents).
    void validate() const;
    bool has_quaternions() const;
};

// Mutable scratch of the algorithms, sized once from the model (no allocation afterwards).
// Templated on the scalar (double; Dual for forward-mode derivatives, dual.hpp).
template <class S>
struct TreeDataT {
    explicit TreeDataT(const TreeModel& model)
        : oMi(model.joints.size()),
          J(Eigen::Matrix<S, 6, Eigen::Dynamic>::Zero(6, model.nv)),
          oI(model.joints.size()),
          Ic(model.joints.size()),
          ov(model.joints.size()),
          oa(model.joints.size()),
          of(model.joints.size()),
          Bc(model.joints.size()),
          oh(model.joints.size()),
          cw(static_cast<std::size_t>(model.nv)),
          cy(static_cast<std::size_t>(model.nv)) {}

    std::vector<SE3T<S>> oMi;       // joint placements in the world
    Eigen::Matrix<S, 6, Eigen::Dynamic> J;  // 6 × nv: world joint motion subspaces
    std::vector<InertiaT<S>> oI;    // body inertias in world axes at the world origin
    std::vector<InertiaT<S>> Ic;    // composite (subtree) inertias (crba scratch)
    std::vector<MotionT<S>> ov;     // body spatial velocities
    std::vector<MotionT<S>> oa;     // body spatial accelerations (without gravity)
    std::vector<ForceT<S>> of;      // subtree forces (rnea scratch)
    std::vector<Eigen::Matrix<S, 6, 6>> Bc;  // composite Coriolis operators (coriolis); rnea_derivatives: K_j
    std::vector<ForceT<S>> oh;      // subtree momenta Σ I_i ν_i (rnea_derivatives scratch)
    // rnea_derivatives, per velocity column c of joint j: Ic_j J_c and K_jᵀ J_c − J_c ×* Hc_j
    std::vector<ForceT<S>> cw, cy;
};
using TreeData = TreeDataT<double>;

// Column col of the world motion subspaces J (forward_kinematics) as a twist ξ.
inline Motion joint_twist(const TreeData& data, int col) {
    Motion xi;
    xi.lin = data.J.col(col).template head<3>();
    xi.ang = data.J.col(col).template tail<3>();
    return xi;
}

// The spatial velocity and acceleration of joint j's parent as data holds them (ov, oa); for a
// root joint the world: at rest, with the gravity offset −g as its acceleration.
inline void parent_motion(const TreeModel& model, const TreeData& data, int j, Motion& nu_p, Motion& al_p) {
    const int p = model.joints[static_cast<std::size_t>(j)].parent;
    if (p >= 0) {
        nu_p = data.ov[static_cast<std::size_t>(p)];
        al_p = data.oa[static_cast<std::size_t>(p)];
    } else {
        nu_p = Motion();
        al_p = Motion();
        al_p.lin = -model.gravity;
    }
}

// The algorithms below marked "(S)" are templates on the scalar, instantiated for double and
// Dual in rbd_tree.cpp; the others are double only.

// (S) Placements oMi, world motion subspaces J and (when `inertias`) world body inertias oI at
// q (nq). crba, rnea and potential_energy need the inertias; frame kinematics do not.
template <class S>
void forward_kinematics(const TreeModel& model, TreeDataT<S>& data, const S* q, bool inertias = true);

// (S) The world body inertias oI of the placements in data: what forward_kinematics adds with
// `inertias` (the same operations on the same placements: the same bits).
template <class S>
void body_inertias(const TreeModel& model, TreeDataT<S>& data);

// (S) Spatial velocities ν_i and accelerations α_i (without gravity) for Pinocchio's joint
// velocity v and acceleration a (nv each; a == nullptr means a = 0). Needs forward_kinematics.
template <class S>
void forward_motion(const TreeModel& model, TreeDataT<S>& data, const S* v, const S* a);

// (S) Joint-space inertia M (nv × nv, full symmetric, armature on the diagonal): the composite
// rigid-body algorithm, M_ij = J_iᵀ Ic_j J_j for i in the support of j. Needs forward_kinematics.
template <class S>
void crba(const TreeModel& model, TreeDataT<S>& data, S* M, int ld);

// (S) Inverse dynamics τ = M a + C(q, v) v + g(q) (Pinocchio's rnea, armature included) from
// the velocities and accelerations of forward_motion(v, a), with gravity; `a` is the same joint
// acceleration (nullptr: 0), for the armature term. τ has nv entries.
template <class S>
void rnea(const TreeModel& model, TreeDataT<S>& data, const S* a, S* tau);

// (S) Gravitational potential energy −Σ m_i gᵀ c_i. Needs forward_kinematics.
template <class S>
S potential_energy(const TreeModel& model, const TreeDataT<S>& data);

// Analytic first derivatives of rnea in Pinocchio's tangent (every joint type: q_k moves joint
// k along its local twist, v and a held; a quaternion tree's chain rule to nonmin's coordinates
// is TreeProgram::quat_dynamics): dtau_dq(:, k) = ∂τ/∂q_k and dtau_dv(:, k) = ∂τ/∂v_k (nv × nv
// each, column-major), at the velocity v and acceleration a; the armature term M_a a has no q and no v
// dependence. Needs forward_kinematics (with inertias); overwrites ov, oa, of, Ic, Bc, oh, cw, cy.
// Derivation (docs/theory.md, "Analytic derivatives of RNEA"): moving q_k moves the subtree of
// joint k rigidly with the twist ξ = J_k, so δJ_j = ξ × J_j, δI_i = ξ×* I_i − I_i ξ×,
// δν_i = ξ × (ν_i − ν_p), δα_i = ξ × (α_i − α_p) − (ξ × ν_p) × (ν_i − ν_p) (p = k's parent, α
// with the gravity offset); with the composite inertia Ic_j, momentum Hc_j = Σ I_i ν_i,
// K_j = Σ (ν_i×* I_i − I_i ν_i×) and subtree force F_j over i ⪰ j, and η = ξ × ν_p:
//   ∂τ_j/∂q_k = −J_jᵀ [Ic_j (ξ × α_p − η × ν_p) + η ×* Hc_j + K_j η]        (j ⪰ k)
//   ∂τ_j/∂q_k = J_jᵀ (ξ ×* F_k) + (the j = k bracket with J_j)                 (j ≺ k)
//   ∂τ_j/∂v_k = J_jᵀ [K_m ξ + ξ ×* Hc_m − Ic_m (ξ × (ν_p + ν_k))],  m = j if j ⪰ k, else k
// (δα_i = ξ × ν_i − ξ × ν_p − ξ × ν_k along v_k; for a 1-dof joint ξ × ν_k = ξ × ν_p).
void rnea_derivatives(const TreeModel& model, TreeData& data, const double* v, const double* a,
                      double* dtau_dq, double* dtau_dv);

// A frame's world placement, and its world-aligned kinematics (LOCAL_WORLD_ALIGNED in
// Pinocchio): origin velocity, angular velocity, classical acceleration of the origin and
// angular acceleration, from forward_motion.
template <class S>
struct FrameKinematicsT {
    SE3T<S> oMf;
    Vec3T<S> v = Vec3T<S>::Zero(), w = Vec3T<S>::Zero(), a = Vec3T<S>::Zero(), alpha = Vec3T<S>::Zero();
};
using FrameKinematics = FrameKinematicsT<double>;
// (S)
template <class S>
SE3T<S> frame_placement(const TreeModel& model, const TreeDataT<S>& data, const Frame& frame);
// (S)
template <class S>
void frame_kinematics(const TreeModel& model, const TreeDataT<S>& data, const Frame& frame,
                      bool motion, FrameKinematicsT<S>& out);

// (S) row[0:nv] += c_linᵀ Jp + c_angᵀ Jω with Jp, Jω the LOCAL_WORLD_ALIGNED Jacobian of the
// point p rigidly attached to `joint` (its linear rows at p, its angular rows): one constraint
// row contributed by one frame. Touches only the columns of the joint's support.
template <class S>
void add_jacobian_row(const TreeModel& model, const TreeDataT<S>& data, int joint, const Vec3T<S>& p,
                      const Vec3T<S>& c_lin, const Vec3T<S>& c_ang, S* row);

// Christoffel-consistent Coriolis matrix C_v (nv × nv, row-major, leading dimension ld) at the
// velocities of forward_motion: C_v v are rnea's velocity terms and Ṁ_v − 2 C_v is skew. With
// body inertias I_i and velocities ν_i in world axes (J_i the body Jacobian),
//   C_v = Σ_i J_iᵀ (I_i J̇_i + B_i J_i),  B_i = ½ (ν_i×* I_i − I_i ν_i× + (I_i ν_i)×̄*),
// where (f)×̄* ν = ν ×* f; gathered over composite subtrees like crba (J̇_k = ν_j × J_k for a
// column k of joint j). Needs forward_kinematics (with inertias) and forward_motion.
void coriolis(const TreeModel& model, TreeData& data, double* C, int ld);

// row[0:nv] += d/dt (c_linᵀ Jp + c_angᵀ Jω) (the time derivative of add_jacobian_row's row) for
// the point p moving with velocity pdot and coefficient rates cdot_lin, cdot_ang. Needs
// forward_motion (the body velocities).
void add_jacobian_dot_row(const TreeModel& model, const TreeData& data, int joint, const Vec3& p,
                          const Vec3& pdot, const Vec3& c_lin, const Vec3& c_ang,
                          const Vec3& cdot_lin, const Vec3& cdot_ang, double* row);

// The full 6 × nv LOCAL_WORLD_ALIGNED Jacobian of a frame (rows: linear, angular; row-major
// with leading dimension ld). Needs forward_kinematics.
void frame_jacobian(const TreeModel& model, const TreeData& data, const Frame& frame, double* J6,
                    int ld);

}  // namespace nonmin::rbd
