// A robot (rigid-body tree + frame constraints) as a Program (model layer): what
// nonmin.model.robots.RobotModel compiles to, once, at load time.
//
// Coordinates are RobotModel's: q = Pinocchio's configuration (nq, quaternions (x, y, z, w) kept
// with a unit-norm constraint) and qd = dq/dt. Pinocchio's velocity is v = T(q) qd with T block
// diagonal (identity on scalar/vector joints; free flyer v_lin = R(ε)ᵀ ṗ; quaternion
// ω = 2 G(ε) ε̇ / |ε|²), and by the chain rule (docs/robots.md)
//
//   M = Tᵀ M_v T,   h = −Tᵀ rnea(q, v, Ṫ qd) = −Tᵀ (M_v Ṫ qd + C_v v + g_v),
//   f_p = −Tᵀ (d ⊙ v),   B = Tᵀ S,   A = A_v T,   γ = γ_v + A_v Ṫ qd,
//
// where γ_v + A_v Ṫ qd is obtained in one pass by taking the classical frame accelerations at
// the joint acceleration a = Ṫ qd. Constraint rows (types of robots/_constraints.py), stacked in
// declaration order:
//
//   unit_quaternion  1  φ = ½(εᵀε − 1), A = εᵀ, γ = ε̇ᵀε̇
//   point            3  φ = p_a − p_b
//   weld             6  [p_a − p_b, log3(R_a R_bᵀ)], rotation rows on ω_a − ω_b
//   hinge            5  [p_a − p_b, (R_a u₁)·(R_b k), (R_a u₂)·(R_b k)]
//   planar_point     2  E (p_a − p_b)
//   planar_weld      3  [E (p_a − p_b), n·log3(R_a R_bᵀ)]
//   point_on_plane   1  (R_a k)·(p_b − p_a)     (contact: the same, unilateral)
//   joint_coupling   1  q₁ − r₁ − c₀ − Σ c_k (q₂ − r₂)^k
//   joint_limit      1  gap s (q₁ − r₁) ≥ 0, s = c₀ = ±1 (unilateral): A = s e₁ᵀ, γ = 0
//   joint_driver     1  q₁ − f(t) (rheonomic; f = drivers[iq2], a TimeFunction): A = e₁ᵀ,
//                       A q̇ + φ_t = q̇₁ − ḟ, γ = −f̈
//   path_driver    1–3  e_i·(p_b − p_a) − f_i(t) for each axis i with drv[i] ≥ 0 (f_i = drivers[drv[i]]):
//                       A = e_i·(J_b − J_a), φ_t = −ḟ_i, γ = e_i·(a_b − a_a) − f̈_i
//   distance_driver  1  (dᵀd − f²)/(2L), d = p_b − p_a, f = drivers[drv[0]], L = ref1:
//                       A = dᵀ(J_b − J_a)/L, φ_t = −f ḟ/L, γ = (ḋᵀḋ + dᵀ(a_b − a_a) − ḟ² − f f̈)/L
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "../dual.hpp"
#include "../program.hpp"
#include "../timefn.hpp"
#include "tree.hpp"

namespace nonmin::rbd {

enum class RowType : int {
    unit_quaternion = 0,
    point = 1,
    weld = 2,
    hinge = 3,
    planar_point = 4,
    planar_weld = 5,
    point_on_plane = 6,
    contact = 7,
    joint_coupling = 8,
    joint_limit = 9,
    joint_driver = 10,
    path_driver = 11,
    distance_driver = 12,
};

struct TreeConstraint;
int row_count(RowType t);            // fixed-size types (path_driver: 3, its largest)
int row_count(const TreeConstraint& c);  // this constraint's rows

struct TreeConstraint {
    std::string name;
    RowType type = RowType::point;
    int frame_a = -1, frame_b = -1;  // indices into TreeDescription::frames
    Vec3 axis = Vec3::UnitZ();  // hinge axis / plane normal in frame a; planar: world normal n
    Vec3 u1 = Vec3::UnitX();    // hinge: (u₁, u₂, k) orthonormal in frame a; planar: world E rows
    Vec3 u2 = Vec3::UnitY();
    int iq = -1;   // unit_quaternion: first of its 4 components; joint_coupling/limit: joint 1's index
    int iq2 = -1;  // joint_coupling: joint 2's index (−1: none); joint_driver: index into drivers
    std::array<double, 5> coef{{0.0, 1.0, 0.0, 0.0, 0.0}};
    double ref1 = 0.0, ref2 = 0.0;
    std::array<int, 3> drv{{-1, -1, -1}};  // path/distance drivers: indices into drivers (−1: none)
};

struct TreeDescription {
    TreeModel model;
    std::vector<Frame> frames;
    std::vector<TreeConstraint> constraints;  // row order
    std::vector<int> actuated;                // velocity indices: one column of B each
    Vec damping;                              // nv viscous damping coefficients
    std::vector<TimeFunction> drivers;        // prescribed motions of joint_driver rows
};

// The scratch of one evaluation on the scalar S (double; Dual for evaluate_tangent).
template <class S>
struct TreeScratch {
    using VecS = Eigen::Matrix<S, Eigen::Dynamic, 1>;
    using MatS = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    explicit TreeScratch(const TreeDescription& d);
    TreeDataT<S> data;
    VecS qn, v, a0, tau, fv;
    VecS zv;  // nv zeros (the motion at q̇ = 0 of NEED_GRAVITY)
    MatS Mv;  // nv × nv
    MatS Av;  // m_all × nv (frame rows in velocity space, robots with quaternions)
    std::vector<Mat3T<S>> R;     // per joint: rotation of its quaternion (free flyer, spherical)
    std::vector<Mat34T<S>> Tq;   // per joint: 2 G(ε) / |ε|²
    MatS Y;                      // 7 × nv scratch of the congruence (T_bᵀ M_v rows of one block)
    MatS Lv;                     // 2 × nv: Σ λ_l A_v rows (residuals)
    VecS tq;                     // nq scratch (residuals)
    FrameKinematicsT<S> ka, kb;
    std::vector<double> treg;    // registers of the drivers' expression tapes (functions of t)
    // evaluate()'s kinematics cache (S = double): data's placements, motion subspaces (and the
    // inertias when fk_inertias) are forward_kinematics at fk_q (bit for bit), so an evaluation
    // at the same q skips it. Only evaluate() sets fk_valid; every other writer of data clears it.
    bool fk_valid = false;
    bool fk_inertias = false;
    std::vector<double> fk_q;
};

// The first derivatives of one frame's world kinematics (frame_kinematics) along one
// coordinate direction, at fixed joint acceleration: its origin's displacement dp and rotation
// dth (q directions; zero along q̇), angular velocity dw, origin velocity dv, classical origin
// acceleration da and angular acceleration dal (row_tangents).
struct FrameTangent {
    Vec3 dp = Vec3::Zero(), dth = Vec3::Zero(), dw = Vec3::Zero(), dv = Vec3::Zero(), da = Vec3::Zero(),
         dal = Vec3::Zero();
};

struct TreeWorkspace : Workspace, TreeScratch<double> {
    explicit TreeWorkspace(const TreeDescription& d) : TreeScratch<double>(d) {}
    // evaluate_tangent's scratch: dual copies of the state and of the terms (made at first use)
    std::unique_ptr<TreeScratch<Dual>> dual;
    std::vector<Dual> dq, dqd;
    TermsOf<Dual> dterms;
    // residual_tangents' scratch on DualW (DUAL_WIDTH directions per pass; made at first use)
    std::unique_ptr<TreeScratch<DualW>> wide;
    std::vector<DualW> wq, wqd, wrd, wrl, wrc;
    std::vector<Vec3> xl, xa;  // per joint and lane: world twists of the seeded directions
    Vec dv;                    // nv: one lane's velocity-space direction
    Mat dtq, dtv;              // nv × nv: ∂τ/∂q, ∂τ/∂v of rnea_derivatives (velocity space)
    // row_tangents' scratch (made at first use): ∂(A a + γ)/∂q_k, ∂(A a + γ)/∂q̇_k (row k of
    // dcq, dcv: nv × m_all) and ∂(Aᵀλ_l)/∂q_k (row k of dlq: nv × 2 nv); per frame side and
    // column k the tangents of its kinematics along q_k (tq) and q̇_k (tv); the side's wrench
    // tangents along q_k (dF).
    Mat dcq, dcv, dlq;
    std::vector<FrameTangent> tqa, tva, tqb, tvb;
    std::vector<Force> dF;
    // trees with quaternion joints (the chain rule through v = T(q) q̇, a_v = T a + Ṫ q̇;
    // docs/theory.md, "Quaternion joints"): dca (nv × m_all) row c = ∂(A_v a_v + γ_v)/∂a_v,c
    // (column c of A_v); the q-space tangents Eq, Ev (nq × nq: row k = ∂r_dyn/∂q_k, ∂/∂q̇_k),
    // Cq, Cv (nq × m_all), Lq (nq × 2 nq); Mb rows c = M_v(:, c) for the quaternion blocks'
    // velocity indices; τ_v (tauv) and A_vᵀλ_l (AtL, 2 × nv) at the state; gv: nv scratch.
    Mat dca, Eq, Ev, Cq, Cv, Lq, Mb, AtL;
    Vec tauv, gv;
};

class TreeProgram : public Program {
  public:
    explicit TreeProgram(TreeDescription description);

    Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                    unsigned need, Terms& out, Workspace& ws) const override;
    Status evaluate_tangent(double t, const double* q, const double* qd, const double* dq, const double* dqd,
                            const std::uint8_t* active, unsigned need, Terms& out, Terms& tangent,
                            Workspace& ws) const override;
    bool differentiable() const override { return true; }
    bool gravity_in_pass() const override { return true; }
    // The residuals of ResidualQuery: M a − h − f_p − B u = Tᵀ (rnea(q, v, T a + Ṫ q̇) + d ⊙ v − S u)
    // (one RNEA, no CRBA), A a + γ = the frame accelerations at the joint acceleration T a + Ṫ q̇,
    // Aᵀ λ from the rows. The first residual's tangents from the analytic rnea_derivatives
    // (tree.hpp), the rows' from row_tangents (analytic, when every active row has them:
    // rows_analytic) or else on DualW without the RNEA; trees with quaternions through the
    // chain rule of quat_dynamics / quat_rows, or, when a row is not analytic (contact, point on
    // plane, distance driver), everything in one pass per DUAL_WIDTH directions on DualW.
    Status residual_tangents(const ResidualQuery& rq, Workspace& ws) const override;
    std::unique_ptr<Workspace> make_workspace() const override;

    const TreeDescription& description() const { return d_; }
    bool thread_safe() const override { return thread_safe_; }
    bool has_quaternions() const { return quat_; }

    // ws.qn = q with every quaternion divided by its norm (Status::not_finite if one is zero or
    // q is not finite) and the blocks of T (ws.R, ws.Tq); then the velocity map v = T(q) qd and
    // a0 = Ṫ(q, qd) qd. Used by evaluate(); public for the bindings' kinematics queries.
    template <class S>
    Status normalize(const S* q, TreeScratch<S>& ws) const;
    template <class S>
    void velocity_map(const S* q, const S* qd, TreeScratch<S>& ws) const;

    // The Christoffel Coriolis matrix in q: C = Tᵀ C_v T + Tᵀ M_v Ṫ (n × n, row-major) at
    // (q, qd), and Ȧ = dA/dt along qd (m_all × n; rows of inactive constraints untouched):
    // Ȧ = Ȧ_v T + A_v Ṫ. Not used by the dynamics (h, γ); for controllers that need them
    // (nonmin.control's tracking law). Allocate their temporaries.
    Status coriolis_matrix(const double* q, const double* qd, TreeWorkspace& ws, double* C) const;
    Status jacobian_dot(const double* q, const double* qd, const std::uint8_t* active,
                        TreeWorkspace& ws, double* Adot) const;

  private:
    // The evaluation on the scalar S (double: evaluate; Dual: evaluate_tangent).
    template <class S>
    Status eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need,
                TermsOf<S>& out, TreeScratch<S>& ws) const;
    // aq += av Ṫ(q, qd) (a row nv -> nq).
    void add_Tdot_row(const TreeWorkspace& ws, const double* q, const double* qd, const double* av,
                      double* aq) const;
    // fq = Tᵀ fv (nv -> nq); also a row a_v of A_v to the row a_v T of A.
    template <class S>
    void apply_Tt(const TreeScratch<S>& ws, const S* fv, S* fq) const;
    template <class S>
    void congruence(TreeScratch<S>& ws, S* M) const;  // M = Tᵀ M_v T (symmetrized)
    template <class S>
    void apply_T(const TreeScratch<S>& ws, const double* xq, S* xv) const;  // xv = T xq (nq -> nv)
    // The residuals of rq at (q, qd) on the scalar S: rd (nq), rl (nlam × nq), rc (m_all, active rows).
    // fixed: when not null, the kinematics at q in double (directions that do not move q: the
    // placements, motion subspaces and inertias are copied instead of recomputed on S).
    // seeded: ws.data already holds the kinematics at q with their tangents (seed_kinematics).
    // dynamics false: rd is not computed (the constraint rows only).
    template <class S>
    Status residuals(const ResidualQuery& rq, const S* q, const S* qd, TreeScratch<S>& ws, S* rd, S* rl,
                     S* rc, const TreeData* fixed, bool seeded = false, bool dynamics = true) const;
    // The kinematics at q on DualW for the w directions rq.dq[j0 ..] (programs without
    // quaternions, v = q̇): values from fx (double), lane l's tangent from the world twist of
    // each body along direction l — δ(oMi) = ξ_i × oMi, δJ_c = ξ_i × J_c, δ(oI_i) the motion
    // of its mass points — instead of differentiating the forward kinematics.
    void seed_kinematics(const ResidualQuery& rq, int j0, int w, TreeWorkspace& ws) const;
    // Whether every active constraint has analytic row tangents (row_tangents): point, weld,
    // hinge, planar_point, planar_weld, path_driver and the joint-space rows.
    bool rows_analytic(const std::uint8_t* active) const;
    // The tangents of A a + γ and Aᵀλ_l (rq.r_con, rq.r_lam) along rq's directions from the
    // analytic derivatives of the frames' kinematics (velocity space, then in q: quat_rows; needs
    // rnea_derivatives' forward_motion at (q̇, a) in ws.data, accelerations with the gravity
    // offset). Derivation in docs/theory.md ("Analytic derivatives of the constraint rows").
    void row_tangents(const ResidualQuery& rq, TreeWorkspace& ws) const;
    // The q-space tangents of the dynamics residual, ws.Eq and ws.Ev, from the velocity-space
    // ws.dtq, ws.dtv of rnea_derivatives (trees with quaternion joints; needs rnea_derivatives'
    // data and ws.v, ws.fv = a_v).
    void quat_dynamics(const ResidualQuery& rq, TreeWorkspace& ws) const;
    // ws.Cq, ws.Cv, ws.Lq from the velocity-space dcq, dcv, dca, dlq (quaternion trees).
    void quat_rows(const ResidualQuery& rq, TreeWorkspace& ws) const;
    // One frame's tangents along every coordinate (tq: q_k, tv: q̇_k; zero outside its support).
    void frame_tangents(const Frame& f, const TreeWorkspace& ws, FrameTangent* tq, FrameTangent* tv) const;
    // dlq(k, l nv + ·) += ∂(J_fᵀ F)/∂q_k for the wrench F (world origin) carried by frame f's
    // body, with dF[k] its own change along q_k at fixed body (coefficient changes, moved point).
    void add_wrench_tangents(const Frame& f, const Force& F, const Force* dF, int l, TreeWorkspace& ws) const;

    // T is the identity on runs of coordinates (iq .. iq+len ↔ iv .. iv+len) and a small block
    // on each quaternion joint (quaternion qs..qs+4 ↔ angular velocity a..a+3; free flyer also
    // position iq..iq+3 ↔ body linear velocity iv..iv+3 through Rᵀ).
    struct Run {
        int iq, iv, len;
    };
    struct QuatBlock {
        int joint, qs, a, iq, iv;
        bool free;
        int v0() const { return free ? iv : a; }   // its velocity rows v0 .. v0 + nv
        int q0() const { return free ? iq : qs; }  // its coordinates q0 .. q0 + nq
        int nv() const { return free ? 6 : 3; }
        int nq() const { return free ? 7 : 4; }
    };
    // T_b (nv × nq of a quaternion block) entry (r, c).
    template <class S>
    static S tb(const TreeScratch<S>& ws, const QuatBlock& b, int r, int c);
    // The chain rule's maps of one quaternion block at (q, q̇, a) (block-local rows: the block's
    // velocities v0.., columns: its coordinates q0..): T_b, ∂v/∂q = ∂(T q̇)/∂q, ∂a_v/∂q =
    // ∂(T a + Ṫ q̇)/∂q, ∂a_v/∂q̇ = ∂(Ṫ q̇)/∂q̇, and dTq[m] = ∂T_q/∂ε_m (3 × 4 each).
    struct QuatMaps {
        Eigen::Matrix<double, 6, 7> T, Vq, Aq, Aqd;
        Mat34 dTq[4];
    };
    void quat_maps(const QuatBlock& b, const double* q, const double* qd, const double* a,
                   const TreeWorkspace& ws, QuatMaps& m) const;
    // y_q (the block's nq coordinates) = ∂T_bᵀ/∂q_k · y_v (the block's nv velocities), k = q0 + kl.
    void add_dTt(const QuatBlock& b, const QuatMaps& m, const TreeWorkspace& ws, int kl, const double* yv,
                 double* yq) const;
    std::vector<Run> runs_;
    std::vector<QuatBlock> qblocks_;
    std::vector<int> act_q_;  // per actuator: its coordinate when T is the identity there, else −1
    // Rows, γ and φ of one frame constraint (A rows in velocity space, nv columns).
    template <class S>
    void frame_rows(const TreeConstraint& c, TreeScratch<S>& ws, bool rows, bool gamma, bool phi, S* A,
                    S* g, S* p) const;
    // Rows, γ, φ and φ_t of a path or distance driver at t (A rows in velocity space).
    template <class S>
    Status driver_rows(const TreeConstraint& c, double t, TreeScratch<S>& ws, bool rows, bool gamma, bool phi,
                       S* A, S* g, S* p, double* phit) const;

    TreeDescription d_;
    bool quat_ = false;
    bool thread_safe_ = true;
};

}  // namespace nonmin::rbd
