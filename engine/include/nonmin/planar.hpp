// The planar multibody model in absolute coordinates as a Program (model layer).
//
// Body i owns (x_i, y_i, θ_i) (rigid body, centre of mass at its origin) or (x_i, y_i) (point
// mass). A body-fixed point with local coordinates s is at p = r + R(θ) s, with Jacobian
// [I, (R s)^⊥], velocity ṗ = ṙ + θ̇ (R s)^⊥ and acceleration p̈ = r̈ + θ̈ (R s)^⊥ − θ̇² R s
// (v^⊥ = (−v_y, v_x)). M = diag(m, m, I) per body is constant, C = 0, h = f_g.
//
// Every joint of nonmin.model.planar is decomposed by the Python side into row primitives
// (src/nonmin/model/planar/_program.py), whose formulas are those of planar/_elements.py:
//
//   pin    2 rows  φ = p_a − p_b                          (revolute; first two rows of a weld)
//   line   1 row   φ = n·(p_b − p_a), n = R_a u^⊥          (point-on-line; prismatic's 2nd row)
//                  + ρ (θ_b − θ_a) when roll ρ ≠ 0 (the tangential row of a frictional contact
//                  of radius ρ: its velocity is the slip velocity; Ȧ gains nothing)
//   rod    1 row   φ = σ (dᵀd − L²)/(2L), d = p_b − p_a     (σ = −1: rope, gap = −φ)
//   angle  1 row   φ = Σ c_j θ_j − c0 − f(t)               (weld, prismatic, gear, angle driver)
//   coord  1 row   φ = Σ c_j q_j − c0 − f(t)               (coordinate driver: any coordinate)
//
// Drivers (rheonomic rows) subtract a prescribed f(t) (a TimeFunction): a pin with drivers is
// φ = p_a − p_b − (f_x(t), f_y(t)) (a point on a path), a line row φ = n·(p_b − p_a) − f(t) (a
// prescribed slide or offset), a rod with a driver φ = (dᵀd − f(t)²)/(2 L) with the constant
// reference length L (a prescribed distance).
//
// plus translational and rotational spring-dampers and the input matrix B (torques, prismatic
// joint forces, point forces). The description is plain data, built once; the Program
// evaluates it with no allocation (scratch in PlanarWorkspace).
#pragma once
#include <functional>
#include <string>
#include <vector>

#include "dual.hpp"
#include "dual_terms.hpp"
#include "program.hpp"
#include "timefn.hpp"

namespace nonmin {

// A body-fixed point: body index (−1: the ground, where local = global coordinates).
struct PlanarPoint {
    int body = -1;
    double sx = 0.0;
    double sy = 0.0;
};

struct PlanarBody {
    double mass = 1.0;
    double inertia = 0.0;  // ≤ 0: a point mass (coordinates x, y only)
    int ix = 0, iy = 0, ith = -1;  // its coordinates (set by PlanarDescription::add_body)
};

enum class PlanarPrimKind : int { pin = 0, line = 1, rod = 2, angle = 3, coord = 4 };

struct PlanarPrim {
    PlanarPrimKind kind = PlanarPrimKind::pin;
    int constraint = 0;  // index into constraints
    int offset = 0;      // first row within the constraint
    PlanarPoint a, b;
    double ux = 0.0, uy = 0.0;          // line: unit axis on body a
    double roll = 0.0;                  // line: + roll (θ_b − θ_a) (a rolling contact's tangent row)
    double length = 1.0, sign = 1.0;    // rod
    std::vector<int> angle_bodies;      // angle: bodies (−1 ground) with their coefficients
    std::vector<double> angle_coefs;    // angle and coord: coefficients
    std::vector<int> coords;            // coord: coordinate indices
    double angle_const = 0.0;           // angle, coord: c0
    int driver = -1;                    // index into drivers, −1 none (pin: the x row)
    int driver2 = -1;                   // pin: the y row's driver
};

// A prescribed motion t -> (f, ḟ, f̈) (nonmin/timefn.hpp).
struct PlanarDriver {
    TimeFunction fn;
};

struct PlanarSpring {
    PlanarPoint a, b;
    double stiffness = 0.0, rest_length = 0.0, damping = 0.0;
};

struct PlanarRotationalSpring {
    int body_a = -1, body_b = -1;
    double stiffness = 0.0, rest_angle = 0.0, damping = 0.0;
};

enum class PlanarActuatorKind : int { torque = 0, prismatic = 1, force = 2 };

// One column of B. torque: +1 on θ_b, −1 on θ_a. prismatic: force along u = R_a axis on body
// b at p_b and the reaction on body a at the same global point. force: along a fixed global
// direction at point a.
struct PlanarActuator {
    PlanarActuatorKind kind = PlanarActuatorKind::torque;
    int body_a = -1, body_b = -1;  // torque
    PlanarPoint a, b;              // prismatic (a, b) / force (a)
    double ux = 0.0, uy = 0.0;     // prismatic axis on body a / force direction
};

struct PlanarDescription {
    std::vector<PlanarBody> bodies;
    double gx = 0.0, gy = -9.81;
    std::vector<ConstraintInfo> constraints;  // rows assigned in declaration order
    std::vector<PlanarPrim> prims;
    std::vector<PlanarDriver> drivers;
    std::vector<PlanarSpring> springs;
    std::vector<PlanarRotationalSpring> rotational_springs;
    std::vector<PlanarActuator> actuators;
    int n = 0;      // coordinates so far
    int m_all = 0;  // rows so far

    int add_body(double mass, double inertia);
    int add_constraint(const std::string& name, ConstraintKind kind, int dim);
};

struct PlanarWorkspace : Workspace {
    std::vector<double> c, s;  // cos θ, sin θ per body
    std::vector<double> treg;  // registers of the drivers' expression tapes
    // evaluate_tangent's dual scratch (sized at its first use)
    std::vector<Dual> dq, dqd, dc, ds;
    TermsOf<Dual> dterms;
    // residual_tangents' scratch (DUAL_WIDTH directions per pass)
    DualResidualScratch<DUAL_WIDTH> wide;
    std::vector<DualW> wc, wsn;
};

class PlanarProgram final : public Program {
  public:
    // Validates the description (indices, row coverage of every constraint); throws EngineError.
    explicit PlanarProgram(PlanarDescription desc);

    Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active,
                    unsigned need, Terms& out, Workspace& ws) const override;
    Status evaluate_tangent(double t, const double* q, const double* qd, const double* dq, const double* dqd,
                            const std::uint8_t* active, unsigned need, Terms& out, Terms& tangent,
                            Workspace& ws) const override;
    bool differentiable() const override { return true; }
    Status residual_tangents(const ResidualQuery& rq, Workspace& ws) const override;
    std::unique_ptr<Workspace> make_workspace() const override;
    bool constant_mass() const override { return true; }
    bool constraint_terms_on_request() const override { return true; }
    bool thread_safe() const override { return thread_safe_; }

    const PlanarDescription& description() const { return d_; }
    const Vec& mass_diagonal() const { return mdiag_; }
    const Vec& gravity_force() const { return fg_; }

  private:
    // The evaluation on the scalar S (double: evaluate; Dual: evaluate_tangent); cs, sn: the
    // cos θ, sin θ scratch per body; treg: the drivers' registers (functions of t, in double).
    template <class S>
    Status eval(double t, const S* q, const S* qd, const std::uint8_t* active, unsigned need,
                TermsOf<S>& out, S* cs, S* sn, double* treg) const;

    PlanarDescription d_;
    Vec mdiag_;  // diagonal of M
    Vec fg_;     // gravity force (constant)
    std::vector<std::vector<int>> prims_of_;  // primitives of each constraint
    bool thread_safe_ = true;
    int tape_size_ = 0;  // largest expression-tape scratch of the drivers
};

}  // namespace nonmin
