// Built-in controllers compiled for the loop (nonmin.control): the Regulator, the Tracker's
// computed-torque and passivity laws, and ForceControl over either, with their references as values the engine
// evaluates (TimeSignal: one TimeFunction of nonmin/timefn.hpp per component, the drivers' own
// values) or, as an escape hatch, a Python function called back. The
// Python classes stay the specification (nonmin/control/*.py); every formula below names the one
// it mirrors, in the same order of decisions, so the two agree to round-off.
//
// One law evaluation at (t, q, qd), given the loop's terms (M, h, f_p, B, A, γ of the active set):
//   1. P = I − VᵀV from the rank policy of nonmin.core.range_basis(A, rtol) (Solver::range_basis:
//      the certified LQ or the SVD rule), and Z, an orthonormal basis of N(A) (rows), from a
//      Householder QR of Vᵀ;
//   2. the law's f_∥ ∈ N(A) (regulator: −P(f_g + Kp e + Kd qd); computed torque:
//      P(M(P a + w) − h − f_p), a = q̈* − Kd ė − Kp e, w = −(DA)⁺Dγ; passivity (Slotine–Li):
//      P(M̄ q̈_r + C̄ q̇_r − f_g − f_p − Kd s − Kp e), q̇_r = P(q̇* − λe), s = q̇ − q̇_r, with
//      M̄ = PMP + μQ, Λ = −A⁺Ȧ, Ṗ = ΛP + PΛᵀ, C̄ = PCP + PMṖ − μΛP, only as products with vectors
//      (passivity_supported(): C and Ȧ from the program), and W = ½ sᵀM̄s + ½ eᵀKp e);
//   3. u = (PB)⁺ f_∥ (_common.actuate): with PB = Zᵀ(ZB), u = (ZB)ᵀ((ZB)(ZB)ᵀ)⁻¹ Z f_∥ when the
//      smallest singular value of ZB is certified far above the rank cutoff (then rank(PB) =
//      n − r, feasible, and this is the SVD's truncated pseudo-inverse); otherwise the SVD of PB
//      with the cutoff rtol·max(σ_max, max column norm of B), as the Python code;
//      force control (ForceControl.actuation): the minimum-norm solution of [PB; EB] u =
//      [f_∥; E(c₀ − S f_∥) − λ*]: the same certified LQ on [ZB; EB] u = [Z f_∥; …] (the same
//      singular values), else by SVD;
//   4. u clipped to [u_min, u_max].
// update() records what ControlState.record does (σ(PB) computed once per step there).
// A failure (infeasible actuation with on_infeasible="raise", a reference off the manifold or
// not converging, a non-finite value, a callback that raised) is a status: the loop hands over
// and the Python controller raises the typed error at the same state.
#pragma once
#include <array>
#include <limits>
#include <memory>
#include <vector>

#include "nonmin/svd.hpp"

#include "../linalg.hpp"
#include "../program.hpp"
#include "../solver.hpp"
#include "../timefn.hpp"
#include "loop.hpp"

namespace nonmin::sim {

// A function of time with up to two derivatives: value (dim), first and second derivative.
class Signal {
  public:
    virtual ~Signal() = default;
    virtual int dim() const = 0;
    // v, a may be null (not wanted)
    virtual Status eval(double t, double* x, double* v, double* a) = 0;
};

// A vector of the engine's TimeFunctions (nonmin/timefn.hpp), one per component: the references
// of the compiled controllers are the same values the drivers of every model evaluate. `hold`
// (nonmin.control.Reference.spline): outside [lo, hi] (strictly) the end value with zero
// derivatives; otherwise each function's own rule (the end pieces extend). Pieces or tapes (a
// reference called back is a PySignal); eval() is thread safe.
class TimeSignal final : public Signal {
  public:
    TimeSignal(std::vector<TimeFunction> f, bool hold, double lo, double hi);
    // scipy.interpolate.PPoly's layout: breakpoints x (p + 1, increasing), coefficients
    // c[(j·p + i)·dim + d] of (t − x_i)^(order−1−j) on [x_i, x_{i+1}); hold on [x_0, x_p].
    static TimeSignal from_ppoly(const std::vector<double>& x, const std::vector<double>& c, int order, int dim,
                                 bool hold);
    int dim() const override { return static_cast<int>(f_.size()); }
    Status eval(double t, double* x, double* v, double* a) override;

  private:
    std::vector<TimeFunction> f_;
    bool hold_;
    double lo_, hi_;
    std::size_t scratch_size_ = 0;  // the tapes' registers
};

enum class Law : int { regulator = 0, computed_torque = 1, passivity = 2 };

// Whether the passivity (Slotine–Li) law can be compiled for `prog`: it needs the Christoffel
// Coriolis matrix C and Ȧ, which the engine has for programs with a constant mass matrix (C = 0,
// Ȧ from evaluate_tangent along q̇: planar) and for rigid-body trees (TreeProgram::coriolis_matrix
// and jacobian_dot). The other programs (spatial: a quaternion C of their own; tapes and
// Python functions: C from the model's own expressions) are called back.
bool passivity_supported(const Program& prog);

// The constant part of a compiled controller (validated by the Python classes).
struct ControlSpec {
    Law law = Law::regulator;
    Vec q_star;  // regulator: the target (already projected for the active set when fixed)
    Mat Kp, Kd;
    std::vector<std::array<int, 4>> qblocks;
    Vec u_min, u_max;
    double rtol = -1.0;  // ≤ 0: DEFAULT_RTOL
    bool raise_infeasible = true;
    // the target on the manifold, at every call (tracker; a regulator under rheonomic constraints)
    bool project_target = false;
    bool reject = false;       // target_policy="reject": check instead of project
    bool mass_metric = false;  // metric="mass"
    std::vector<int> fixed;
    Signal* reference = nullptr;  // tracker: (q*, q̇*, q̈*)(t); borrowed
    double lambda = 1.0;          // passivity: the sliding variable's bandwidth λ
    // the controller's model is another model than the loop's with the same layout (n, k, the
    // constraints' names, kinds and dims: a controller built on an equal model, or on a nominal
    // model driving another plant): the law evaluates its own program (the one given to the
    // constructor) at every call instead of reading the loop's terms, as the Python controller
    // evaluates its own model
    bool own_terms = false;
    // regulator: spring e + σ‖e‖η (Regulator.sigma > 0), η = q̇/‖q̇‖, or Pξ₀/‖Pξ₀‖ at rest
    double sigma = 0.0;
    Vec xi0;
    // force control: (constraint index, desired force λ*(t) of its rows); borrowed signals
    std::vector<std::pair<int, Signal*>> forces;
    // evaluated instead of the compiled law when the loop's active set is no longer the one the
    // controller was compiled for (the engine's event layer changed it; until the loop returns,
    // e.g. the sample after an impact): the Python controller called back; borrowed, may be null
    Controller* other_active_set = nullptr;
};

class Projected : public Controller {
  public:
    Projected(const Program& prog, ControlSpec spec);

    void attach(const Terms& T, const Mat& A, int m, const std::vector<int>& rows) override;
    Status control(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) override;
    Status update(double t, const double* q, const double* qd, const std::uint8_t* active) override;
    bool stateless() const override { return true; }  // update() only records
    unsigned need() const override { return s_.own_terms ? 0u : own_need(); }
    std::unique_ptr<Controller> clone() const override { return std::make_unique<Projected>(*prog_, s_); }

    // ControlState.record's counters over the accepted steps seen
    long long steps = 0, infeasible_steps = 0;
    std::vector<long long> saturated_steps;
    std::vector<std::uint8_t> saturated;
    double min_sigma_pb = std::numeric_limits<double>::infinity();
    std::vector<double> max_abs_u;
    long long fast_actuations = 0, svd_actuations = 0;  // which path step 3 took (force control too)

    // One law evaluation at (t, q, qd) with the active mask `active`, outside the loop: the
    // program evaluated here, attached, u into `u` (k). For the per-call tests against the
    // Python controllers (ControlInfo.u, .lyapunov, .target).
    Status probe(double t, const double* q, const double* qd, const std::uint8_t* active, double* u);
    // The Lyapunov value W of the last law evaluation (passivity: ½ sᵀM̄s + ½ eᵀKp e; else NaN)
    double lyapunov() const { return lyapunov_; }
    // The projected reference q* of the last law evaluation (LawOutput.target)
    const Vec& target() const { return qs_; }

  private:
    unsigned own_need() const { return gravity_in_pass_ ? NEED_GRAVITY : 0u; }
    Status law(double t, const double* q, const double* qd, const Terms& T, const Mat& A, double* u);
    Status nullspace(const Mat& A);
    void project(const double* x, double* out);
    void ensure_pb(const Terms& T);
    double reduce_actuation(const Terms& T, Mat& W, double* zf) const;
    Status desired(double t, const double* q);
    Status project_configuration(double t, double* x);
    Status min_norm_true(const Mat& A, int m, const double* b, double* x);  // A⁺ b
    Status actuate(const Terms& T);
    bool certified_min_norm(Mat& W, Mat& Lw, int rows, int k, const double* rhs, double fro, double bscale, double* y,
                            double* u);
    Status actuate_force(double t, const Terms& T, const Mat& A);
    bool force_terms_null(const Terms& T, const double* g, const double* gamma);
    void record();
    double sigma_min_pb();
    Status passivity_force(double t, const double* q, const double* qd, const Terms& T, const Mat& A,
                           const Vec& fg);
    Status pseudo_inverse(const Mat& A);
    void lam_p(const double* v, double* out);    // out = Λ P v = −A⁺ Ȧ P v
    void lam_p_t(const double* v, double* out);  // out = (Λ P)ᵀ v = −P Ȧᵀ A⁺ᵀ v
    void mbar_times(const Terms& T, double mu, const double* v, double* out);  // (PMP + μ(I − P)) v

    const Program* prog_;
    ControlSpec s_;
    std::vector<std::uint8_t> compiled_mask_;  // the active set of the first attach()
    bool stale_ = false;                        // the loop's active set is another one
    int n_, k_;
    double rtol_;
    bool gravity_in_pass_;  // the regulator's f_g from the loop's evaluation (Program::gravity_in_pass)
    std::vector<std::uint8_t> mask_;
    // the loop's evaluation
    const Terms* T_ = nullptr;
    const Mat* A_ = nullptr;
    int m_ = 0;
    std::vector<int> rows_;     // stacked active rows
    std::vector<int> hol_;      // positions (among the active rows) of position-level rows
    std::vector<int> frows_;    // force control: positions of the commanded rows
    std::vector<int> fdim_;     // their signals' dims, in order
    // own evaluations
    std::unique_ptr<Workspace> ws_;
    Solver solver_;
    Terms Tg_, Tu_, Tr_;
    Mat Au_;
    // step 1
    int rank_ = 0;
    std::vector<double> Bq_, dq_, sq_, cq_;  // the certified LQ's input and scratch
    linalg::LQWork lq_;
    bool lq_valid_ = false;  // lq_ holds the certified LQ of D A of the last law evaluation
    linalg::LQWork lqr_;  // the tracker's certified LQ of D A(q*) (velocity and acceleration projections)
    std::vector<double> Br_, dqr_, sqr_, cqr_, Vh_;
    Mat V_, Z_, Hq_;  // V: r × n (P = I − VᵀV), Z: (n − r) × n (rows); Householder scratch
    Vec hv_, hw_;    // Householder scratch
    // step 2
    Vec zero_, fpar_, w_, a_, e_, x_;
    Vec qs_, vs_, as_;  // desired motion at the last time asked (projected)
    struct Memo {
        double t = std::numeric_limits<double>::quiet_NaN();
        unsigned signs = 0;
        Vec q, v, a;
    };
    std::array<Memo, 4> memo_;
    int memo_next_ = 0;
    Mat Ar_;
    Vec br_, dr_, stepr_, xr_, tgt_;
    // step 3
    Mat ZB_, G_, PB_;
    Vec zf_, y_, uraw_, us_;
    bool last_feasible_ = true;
    bool pb_valid_ = false;  // PB_ holds P B of the last law evaluation
    Svd svd_pb_, svd_vals_, svd_a_, svd_g_;
    // force control
    Mat Mbar_L_, E_, Gf_, Atrue_, Wf_, Lf_;
    Vec rhsf_, yf_;
    Mat ZMs_, Ss_;  // Z M and S = Z M Zᵀ's Cholesky factor (force_terms_null)
    Vec xs_, ys_;
    Vec c0_, qtmp_, gtmp_, rhs_, lam_, sf_, pf_;
    // passivity: A⁺ (n × m), Ȧ's active rows (m × n), C (n × n), the tangent evaluation
    int coriolis_ = 0;  // 0: C = 0 (constant M), 1: TreeProgram
    Mat Apinv_, Adot_, Cm_, Adall_;
    Terms Tv_, Tt_;
    Vec pe_, ped_, px_, pqrd_, pqrdd_, psv_, pt1_, pt2_, pt3_, pm_, pm2_;
    double lyapunov_ = std::numeric_limits<double>::quiet_NaN();
    // probe()
    Terms Tp_;
    Mat Ap_;
    // the state of the last law evaluation
    double last_t_ = std::numeric_limits<double>::quiet_NaN();
    Vec last_q_, last_qd_;
};

// Regulator is the Projected controller with the regulator law (kept for the bindings' name).
using Regulator = Projected;

}  // namespace nonmin::sim
