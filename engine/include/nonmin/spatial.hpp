// The spatial multibody model in absolute coordinates with unit quaternions as a Program
// (model layer). Formulas: src/nonmin/model/spatial/_model.py and _quaternion.py.
//
// Body i owns q_i = (x, y, z, e0, e1, e2, e3): the centre of mass and the quaternion ε (scalar
// first). Per body, block-diagonal:
//
//   M = blockdiag(m I₃, 4 Gᵀ J G),   C q̇ = (0, 8 G(ε̇)ᵀ J G(ε) ε̇),   f_g = (m g, 0),   V = −m gᵀ r,
//
// with G(ε) = [−e, e0 I − ẽ]. World-frame attachments x_k(q) — a body point r + R(ε) s, a body
// vector R(ε) s, or a constant (on the ground) — are quadratic in ε: R(ε) s = [εᵀ Q_a(s) ε]_a
// with the constant point tensor Q(s) (3 × 4 × 4, given by the description), so
// ∂x/∂ε = 2 Q(s) ε and the acceleration bias is 2 [ε̇ᵀ Q_a(s) ε̇]_a exactly.
//
// Constraints: a norm row per body, φ = ½(εᵀε − 1), A = [0, εᵀ], γ = ε̇ᵀε̇, and joint rows
// φ = X·Y with X = Σ_k cx_k x_k, Y = Σ_k cy_k x_k (coincident points, perpendicular vectors,
// vector ⊥ offset, ...: the decomposition of spatial/_model.py's _RowPlan), so that
// A = Σ_k (cx_k Y + cy_k X)ᵀ ∂x_k/∂q, A q̇ = Ẋ·Y + X·Ẏ and γ = Ȧ q̇ = 2 Ẋ·Ẏ + X·Ÿ₀ + Y·Ẍ₀
// (Ẍ₀ = Σ cx_k 2[ε̇ᵀ Q_a ε̇]_a). Point-to-point spring-dampers and joint actuators (torque about
// / force along a joint axis) complete it.
//
// Drivers (rheonomic rows): a row with a driver subtracts g(t) = f(t) (square = 0) or
// g = square·f(t)² (a prescribed distance: φ = |d|²/(2L) − f²/(2L)), f a TimeFunction:
// φ −= g, A q̇ + φ_t −= ġ, γ −= g̈ (A unchanged). An angle row (a driven revolute angle θ) has
// two products P1 = X·Y = cos θ and P2 = X2·Y2 = sin θ and φ = sin(θ − f) = c P2 − s P1
// (c, s = cos f, sin f): A = c A2 − s A1, A q̇ + φ_t = c Ṗ2 − s Ṗ1 − ḟ S with S = s P2 + c P1,
// γ = c γ2 − s γ1 − 2ḟ (s Ṗ2 + c Ṗ1) − f̈ S − ḟ² (c P2 − s P1).
#pragma once
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "dual.hpp"
#include "dual_terms.hpp"
#include "program.hpp"
#include "timefn.hpp"

namespace nonmin {

struct SpatialBody {
    double mass = 1.0;
    std::array<double, 9> inertia{};  // body-frame inertia about the COM, row-major 3 × 3
};

// A world-frame attachment: body point r + R s (point = true), body vector R s, or, on the
// ground (body −1), the constant `value`.
struct SpatialAttachment {
    int body = -1;
    bool point = false;
    std::array<double, 48> Q{};  // point tensor Q(s)[a][j][k], row-major (3, 4, 4)
    std::array<double, 3> value{};
};

struct SpatialTerm {
    int attachment = 0;
    double coef = 1.0;
};

// One constraint row: a norm row of body `norm_body` (≥ 0), or φ = X·Y (norm_body = −1).
struct SpatialRow {
    int constraint = 0, offset = 0;
    int norm_body = -1;
    std::vector<SpatialTerm> x, y;
    int driver = -1;      // index into SpatialDescription::drivers, −1: none
    double square = 0.0;  // 0: g = f; else g = square·f²
    bool angle = false;   // an angle row: P1 from (x, y), P2 from (x2, y2)
    std::vector<SpatialTerm> x2, y2;
};

struct SpatialSpring {
    int a = 0, b = 0;  // point attachments
    double stiffness = 0.0, rest_length = 0.0, damping = 0.0;
};

enum class SpatialActuatorKind : int { rotation = 0, translation = 1 };

// rotation: torque u about the world axis (vector attachment `axis` on body a) on body b, −u
// on a (generalized force 2 E(ε)ᵀ axis per body). translation: the gradient of the slide
// axis·(p_b − p_a) (point attachments pa, pb).
struct SpatialActuator {
    SpatialActuatorKind kind = SpatialActuatorKind::rotation;
    int axis = 0, pa = -1, pb = -1;
    int body_a = -1, body_b = -1;
};

struct SpatialDescription {
    std::vector<SpatialBody> bodies;
    std::array<double, 3> gravity{0.0, 0.0, -9.81};
    std::vector<SpatialAttachment> attachments;
    std::vector<ConstraintInfo> constraints;
    std::vector<SpatialRow> rows;
    std::vector<SpatialSpring> springs;
    std::vector<SpatialActuator> actuators;
    std::vector<TimeFunction> drivers;
    int m_all = 0;

    int add_constraint(const std::string& name, ConstraintKind kind, int dim);
};

// The scratch of one evaluation on the scalar S (double; Dual and DualW for the derivatives).
template <class S>
struct SpatialScratch {
    // per attachment: value, velocity, acceleration bias (3 each) and Q ε (3 × 4)
    std::vector<S> val, vel, acc, Qe;
    std::vector<S> col;  // one column of B
    std::vector<double> treg;  // registers of the drivers' expression tapes
};

struct SpatialWorkspace : Workspace, SpatialScratch<double> {
    // evaluate_tangent's and residual_tangents' dual scratch (made at first use)
    std::unique_ptr<SpatialScratch<Dual>> dual;
    std::vector<Dual> dq, dqd;
    TermsOf<Dual> dterms;
    std::unique_ptr<SpatialScratch<DualW>> wide;
    DualResidualScratch<DUAL_WIDTH> wres;
};

class SpatialProgram final : public Program {
  public:
    explicit SpatialProgram(SpatialDescription desc);  // validates; throws EngineError

    Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                    unsigned need, Terms& out, Workspace& ws) const override;
    Status evaluate_tangent(double t, const double* q, const double* qd, const double* dq, const double* dqd,
                            const std::uint8_t* active, unsigned need, Terms& out, Terms& tangent,
                            Workspace& ws) const override;
    Status residual_tangents(const ResidualQuery& rq, Workspace& ws) const override;
    bool differentiable() const override { return true; }
    std::unique_ptr<Workspace> make_workspace() const override;

    bool thread_safe() const override { return thread_safe_; }

  private:
    template <class S>
    Status eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need, TermsOf<S>& out,
                SpatialScratch<S>& w) const;
    template <class S>
    void size_scratch(SpatialScratch<S>& w) const {
        const std::size_t K = d_.attachments.size();
        w.val.assign(3 * K, S(0.0));
        w.vel.assign(3 * K, S(0.0));
        w.acc.assign(3 * K, S(0.0));
        w.Qe.assign(12 * K, S(0.0));
        w.col.assign(static_cast<std::size_t>(n_), S(0.0));
        w.treg.assign(static_cast<std::size_t>(tape_size_) + 1, 0.0);
    }

    SpatialDescription d_;
    std::vector<std::vector<int>> rows_of_;  // rows of each constraint
    bool thread_safe_ = true;
    int tape_size_ = 0;
};

}  // namespace nonmin
