// The simulation loop of the engine, generic over nonmin::Program (the model) and driven by
// nonmin::Solver (the projection dynamics). Specified by the Python driver
// (nonmin/sim/_simulate.py, _integrators.py, _stabilization.py), which stays the reference:
// every decision below (step clipping, error control, output sampling, the projection's
// Gauss–Newton cutoff rules, the drift-aware rank tolerance) is the driver's, in the same order,
// so the two agree to round-off.
//
// One accepted step (no events on this path):
//   1. the integrator advances y = (q, qd) with qdd = Solver::forward (corrected eq. (ddq_sim))
//      under the drift-aware rank tolerance (drift_rank_rtol) and the stabilization's bias
//      (γ, or γ + 2α(A qd + φ_t) + β²φ with Baumgarte);
//   2. the stabilization projects the step end (mass-metric Gauss–Newton on φ, then the velocity
//      correction; eq. of nonmin.core.position_correction);
//   3. the samples of the step are recorded: the step end, or the requested output times from
//      the method's continuous extension (DOPRI5's own; the quintic Hermite interpolant of the
//      projected step ends for the fixed-step methods), projected.
//
// Everything is allocated once in make_loop() from the program's sizes; a step allocates
// nothing (the sample buffers grow geometrically and are reused after each take).
#pragma once
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include "nonmin/svd.hpp"

#include "../program.hpp"
#include "../solver.hpp"
#include "../types.hpp"

namespace nonmin::sim {

// Constants of nonmin/sim/_stabilization.py and _simulate.py (same names, same values).
constexpr double DEFAULT_RTOL = 1e-10;                  // nonmin.core.linalg.DEFAULT_RTOL
constexpr double ROUNDOFF_FLOOR = 4.0 * std::numeric_limits<double>::epsilon();
constexpr double POSITION_CUT_RTOL = 1e-2;
constexpr double SINGULAR_CUT_RTOL = 1e-4;
constexpr double CHORD_RATE = 0.1;
constexpr double SAMPLE_VELOCITY_RTOL = SINGULAR_CUT_RTOL;
constexpr double DRIFT_RTOL_CAP = 1e-2;                  // drift_rank_rtol's upper bound

// rk8: DOP853's 8th-order stages and weights with a fixed step (no error estimate, no projected
// error points; nonmin.sim.RK8)
enum class Method : int { rk4 = 0, dopri5 = 1, midpoint = 2, dop853 = 3, rk8 = 4 };
enum class Stabilization : int { none = 0, baumgarte = 1, projection = 2 };

// nonmin.sim.Projection's parameters.
struct ProjectionOptions {
    double tol = 0.0;
    int max_iter = 10;
    bool velocity = true;
    bool euclidean = false;      // metric="euclidean"
    double velocity_rtol = -1.0;  // ≤ 0: None
    // energy=True with its level (NaN: off): q̇ scaled onto T + V = energy_level
    double energy_level = std::numeric_limits<double>::quiet_NaN();
};

// _stabilization.ENERGY_MAX_CHANGE
constexpr double ENERGY_MAX_CHANGE = 1e-2;

struct Options {
    Method method = Method::rk4;
    double dt = 1e-3;  // fixed step (rk4, midpoint, rk8)
    // dopri5
    double rtol = 1e-8, atol = 1e-10;
    double h_max = std::numeric_limits<double>::infinity();
    double h_min_factor = 1e-14;
    double h0 = 0.0;  // first step (≤ 0: Hairer's heuristic)
    // midpoint
    double xtol = 1e-13;
    int max_iter = 50;
    int max_halvings = 12;
    // stabilization
    Stabilization stab = Stabilization::projection;
    double alpha = 10.0, beta = 10.0;  // Baumgarte gains
    ProjectionOptions projection;
    bool project_initial = true;
    ProjectionOptions initial_projection;  // used when stab != projection
    // rank policy
    double rank_rtol = -1.0;  // ≤ 0: None (the core default)
    double drift_factor = 1.0;
    double spd_rtol = 1e-13;
    double sym_rtol = 1e-9;
    // run
    double t1 = 1.0;
    // fixed steps: the origin of the grid t_grid + k·dt that the steps return to after a placed
    // step (SingularPassages.align; the run's t_span start); NaN: no grid
    double t_grid = std::numeric_limits<double>::quiet_NaN();
    long long max_steps = 10000000;
    bool passages = true;  // singularity-aware step placement (the integrator's `passages`)
    // adaptive methods: samples inside a step from a partial step of the method (else from
    // the continuous extension; next to a singular passage always the extension)
    bool partial_samples = true;
};

// Singularity-aware step placement (nonmin.sim._integrators.SingularPassages): the indicator
// σ_min(DA) at the last projected step ends, the predicted singular instant, and the scratch of
// the indicator (sim_integrators.cpp: singular_indicator, passage_observe, passage_place).
struct Passages {
    double frac[3] = {0.25, 0.75, 0.0};  // the method's passage fractions (sorted)
    int n_frac = 2;
    double ts[3] = {0, 0, 0}, ss[3] = {0, 0, 0};  // history, oldest first
    int count = 0;
    bool have_star = false;
    double t_star = 0.0;
    double sigma = std::numeric_limits<double>::infinity();  // the last indicator observed
    // the indicator's rate |dσ/dt| between the last two observations on one time line (kept
    // across a passage, unlike the history): passage_stages
    double last_t = 0.0, ss_last = 0.0, rate = 0.0;
    bool have_last = false;
    bool widen = false;  // fixed-step methods: the passage step is ≥ PASSAGE_SIGMA wide
    // indicator scratch, sized from m_all and n at make_loop
    Mat B, G, C;                 // equilibrated live rows (k × n), Gram (k × k), its Cholesky
    Vec x, y, v, w;              // iteration vectors (k); v: the vector kept between calls
    int v_len = -1;              // length of v (−1: none kept)
    Vec tri;  // up to PASSAGE_DENSE_ROWS live rows: the tridiagonal form of G and scratch (4 mr)
    std::vector<int> live, order, first, col_ptr, col_rows;
};

// A controller evaluated by the loop: u(t, q, qd) at every evaluation of the dynamics, and
// update() after every accepted step (nonmin.control.Controller's __call__ and update).
class Controller {
  public:
    virtual ~Controller() = default;
    // The loop's evaluation that control() may read (the terms at (t, q, qd) of the call, the
    // active rows of A gathered in `A`'s first m rows, `rows` their stacked indices).
    virtual void attach(const Terms& T, const Mat& A, int m, const std::vector<int>& rows) {
        (void)T, (void)A, (void)m, (void)rows;
    }
    virtual Status control(double t, const double* q, const double* qd, const std::uint8_t* active,
                           double* u) = 0;
    // What control() reads from the loop's evaluation beyond M, h, f_p, B, A, γ (Need bits: e.g.
    // NEED_GRAVITY, so that f_g comes from the same pass instead of an evaluation of its own).
    virtual unsigned need() const { return 0u; }
    // Whether u depends on (t, q, qd) only (not on what update() records): then F at the
    // projected step end, evaluated for the sample, is also the next step's first stage.
    virtual bool stateless() const { return false; }
    virtual Status update(double t, const double* q, const double* qd, const std::uint8_t* active) {
        (void)t, (void)q, (void)qd, (void)active;
        return Status::ok;
    }
    // A fresh controller with the same law and no history, for another loop (the batch: one per
    // thread and run); null when the controller cannot be copied (then runs are not batched).
    virtual std::unique_ptr<Controller> clone() const { return nullptr; }
};

// The controller of an active set, for a loop whose event layer changes the active set (the
// batch keeps one compiled controller per active set): set_active() asks it, and keeps the
// current controller when it returns null.
class ControllerSelect {
  public:
    virtual ~ControllerSelect() = default;
    virtual Controller* select(const std::uint8_t* active) = 0;
};

// The guards watched during the steps (events and unilateral contact): check() is given the
// evaluation at the projected step end and says whether a guard crossed (or an impact is due);
// then the step is not accepted, and the event layer takes it (locates the crossing, applies
// the transition) from the step start. Until the guards are compiled values, the Python
// driver's own guard code is called back (nonmin.sim._simulate).
class Watch {
  public:
    virtual ~Watch() = default;
    virtual Status check(double t, const double* q, const double* qd, const double* f_c, bool& fired) = 0;
};

// A unilateral-contact guard evaluated in the loop (the general driver's "impact" and "release"
// watches, _simulate._guard_value): impact — the gap φ of an inactive unilateral constraint
// (its first row), watched for a downward crossing or for staying below zero; release — the
// normal force λ = ((DA)⁺D)ᵀ f_c of an active one (its first active row; range_basis of the
// active A at the run's rank tolerance), watched for a downward crossing. `g` is the value at
// the last accepted step end.
struct ContactGuard {
    bool release = false;
    int constraint = 0;  // index in Program::constraints()
    int row = 0;         // release: the constraint's first row among the active rows
    double g = 0.0;
    int fric = -1;       // ≥ 0: a friction guard of Loop::fric[fric] (sim_friction.cpp): sticking,
                         // μ λ_n − |λ_t|; slipping, s·v_t (both fire on a crossing or below zero)
};

// A point contact with Coulomb friction (sim_friction.cpp): its unilateral normal constraint,
// its tangential (sticking) constraint — active while the contact sticks —, the coefficient,
// and the slip direction while it slips (±1; 0: sticking or open).
// A planar contact's tangential constraint has one row (slip direction s = ±1); a spatial one
// two (slip = 1 while slipping, the friction force opposite to the slip velocity's direction:
// the exact isotropic cone; dir: that direction at the last event, the guard's reference).
struct FrictionContact {
    int normal = 0, tangent = 0;
    double mu = 0.0;
    int slip = 0;
    double dir[2] = {0.0, 0.0};
    int dim = 1;  // rows of the tangential constraint (1 or 2; set by set_friction)
};

// Recorded samples (the arrays of nonmin.sim.Trajectory), row-major, appended in order.
struct Samples {
    int n = 0, k = 0, c = 0;
    std::vector<double> t, q, qd, qdd, f_c, u, cond, mu, energy, phi_norm, vel_norm;
    std::vector<double> fr_work;  // cumulative work of the friction forces (J; sim_friction.cpp)
    std::vector<double> work;     // cumulative work of controllers and applied forces (J; work_at)
    std::vector<std::int64_t> rank;
    std::vector<std::uint8_t> active;
    std::size_t size() const { return t.size(); }
    void clear();
};

// Why a call of run() returned.
enum class Outcome : int {
    done = 0,      // reached t1, or the step budget of the call
    handover = 1,  // a numerical failure (kernel status, non-finite qdd, step underflow, no
                   // convergence, max_steps): the state is the last accepted one; the Python
                   // driver continues from it and raises the typed error exactly as it would
    callback = 2,  // a Python callback raised: its exception is kept by the binding
    event = 3,     // a watched guard crossed in the step: the step was not accepted, the state
                   // is its start (the event layer takes that step)
    transition = 4,  // contact guards crossed: the engine located the event and applied it
                     // (sim/events.hpp); the state is after it, Loop::events says what happened
};

// One evaluation of the dynamics at a state (what a sample records).
struct Point {
    double t = 0.0;
    Vec q, qd, qdd, f_c, u;
    int rank = 0;
    double mu = 0.0, cond = 1.0, energy = 0.0, phi_norm = 0.0, vel_norm = 0.0;
    double fr_power = 0.0;  // power of the slipping contacts' friction forces, Σ F e·v_t (W)
    double power = 0.0;     // power of controllers and applied forces, q̇ᵀ(B u + f_passive + f_c) (W)
    double work = std::numeric_limits<double>::quiet_NaN();  // W here when a partial step gave it exactly
};

// One transition applied by the engine's event layer (the fields of nonmin.sim.EventRecord).
struct EventInfo {
    double t = 0.0;
    std::string name, text;
    Vec q_before, qd_before, q_after, qd_after;
    std::vector<std::uint8_t> active_before, active_after;
};

// The loop: model, solver, options, the active set (fixed on this path), the integration
// state and every buffer. Plain data; the algorithms are the free functions below.
struct Loop {
    const Program* prog = nullptr;
    Controller* ctrl = nullptr;
    ControllerSelect* ctrl_select = nullptr;  // (the batch) the controller after an active-set change
    Watch* watch = nullptr;
    Options opt;
    std::unique_ptr<Workspace> ws;
    Solver solver;
    Terms T;
    int n = 0, k = 0, c = 0, m_all = 0;
    int spare_m = -1;  // the solver's row count when make_loop finished (~Loop: the spare)

    // active set and its rows
    std::vector<std::uint8_t> active;  // one entry per constraint
    std::vector<int> rows;             // stacked rows of the active constraints (m of them)
    std::vector<std::uint8_t> hol;     // per active row: has a position level
    int m = 0, m_hol = 0;
    bool any_active = false;

    // gathered terms of the active rows
    Mat Ac, Ah, Alin;  // (m_all × n): active rows, position-level rows, last linearization
    // The rows Ac and Ah were last gathered for in full: while `rows` is the same, evaluate()
    // copies only the program's row pattern (Program::a_pattern; the other entries are 0).
    std::vector<int> gathered;
    // That pattern for the gathered rows (RowPattern's compressed rows; empty: unknown): of
    // Ac's m rows (pc_*) and of Ah's m_hol rows (ph_*, also Alin's), as the Solver takes them.
    std::vector<int> pc_start, pc_cols, ph_start, ph_cols;
    // Counts the full gatherings; Alin holds rows copied in full at gathering alin_gen (later
    // copies of the same rows take the pattern's entries only)
    unsigned long long gather_gen = 0, alin_gen = ~0ull;
    // The (t, q) at which Ac, Ah and φ (phi, phih) were last gathered (ev_ok; at gathering
    // ev_gen of the same rows): evaluate() at that very (t, q) does not gather them again, and a
    // program whose terms come on request (ev_strip: Program::constraint_terms_on_request, the
    // planar programs) is not asked for A and φ again (the numba loop's `same`; e.g.
    // the point right after a projection, whose velocity correction left q as it was). Without
    // a controller or friction (whose evaluations read the program's terms themselves).
    bool ev_ok = false, ev_strip = false;
    double ev_t = 0.0;
    unsigned long long ev_gen = 0;
    Vec ev_q;
    Vec gam, phi, vel, phih, bias, floor_, rnorm;
    Vec g, u, qdd, fc, zero_n, aq, dq;
    Mat Mq, L;  // the projection's metric (n × n), Cholesky factor of M̄
    // A constant M (Program::constant_mass) is evaluated once: T.M keeps it, later evaluations
    // skip NEED_M (m_held); m_known: the solver's Known bits for it (0: not valid, the solver
    // checks and reports); mq: what Mq holds (0 nothing yet, 1 the identity, 2 the constant M).
    bool m_held = false;
    unsigned m_known = 0;
    int mq = 0;
    // The Solver holds the velocity correction's factorization (its generation vgen; A at
    // (vt, vq), metric Mq, rank tolerance vrtol): a dynamics solve at the same (t, q) with M = Mq
    // and that tolerance has the same A and reuses it (Solver::again). vlq: that factorization
    // is a certified LQ of every row (rank m): the rank tolerance decided nothing but the
    // certificate, which holds at any smaller tolerance, so a solve at a tolerance ≤ vrtol
    // reuses it too (bitwise the fresh result; the sample's velocity step is at
    // SAMPLE_VELOCITY_RTOL, the dynamics at the drift-aware tolerance). lq_full: the last
    // correction()'s factorization was one.
    bool vheld = false, vlq = false, lq_full = false;
    unsigned long long vgen = 0;
    double vt = 0.0, vrtol = 0.0;
    Vec vq;
    // The position correction's last linearization (Solver generation pgen, rank tolerance
    // prtol; pfull: a certified LQ of all m rows, which are every active row) serves the
    // velocity correction at the corrected q through Solver::near (refined to that q's A,
    // exact to round-off, no factorization), and then the dynamics solves at that (t, q)
    // (nheld: A at (nt, vq) is the last near() call's, rank tolerance ≤ prtol).
    // plq: that factorization was a certified LQ of full rank (velocity_again's condition).
    bool pfull = false, plq = false, nheld = false;
    unsigned long long pgen = 0;
    double prtol = 0.0;

    // integration state
    double t = 0.0;
    Vec y, f;          // (2n): state, F(t, y) when have_f
    bool have_f = false;
    double h = 0.0;    // dopri5: proposed next step
    long long n_steps = 0, n_rhs = 0, n_rejected = 0;
    std::vector<double> t_out;
    bool every = true;
    std::size_t out_i = 0;
    std::string message;  // why the last run() handed over

    // step buffers
    Vec y0, f0, y1, yq1, ys, yp, fp1, tmp2n, k1, k2, k3, k4, kn, ev;
    Mat K;  // (7 × 2n) dopri5 stages
    Vec d_ydiff, d_bspl, d_r3, d_r4;  // dopri5 continuous extension
    // dop853 (sized only for it): the 12 stages of a step, F(t + h, y1) (row 12) and the three
    // stages of the continuous extension (rows 13–15); its 7 coefficient rows (F8); the
    // third-order error estimate e3; what of the accepted step is evaluated already
    Mat K8, F8;
    Vec e3;
    bool d8_fsal = false, d8_dense = false;
    double d8_t0 = 0.0, d8_h = 0.0;
    std::vector<Vec> half;            // midpoint halving levels
    Point p1, ps;

    // diagnostics: cond(M̄) from the singular values of L
    Svd svd;

    // contact guards (fixed active set: the release SVD has the active rows' size)
    std::vector<ContactGuard> guards;
    std::vector<double> guard_new;
    // release guards already pulling at the step start (run start or after a transition: no
    // downward crossing to see) and still clearly pulling at its end: released at the start
    std::vector<std::uint8_t> guard_pull;
    std::vector<std::uint8_t> one_mask;
    Mat DA;
    Vec lam_c, lam_tmp;
    Svd svd_a;

    Samples rec;
    Passages pas;
    bool stage_proj = false;  // RK4: the step being taken may project its stage states (passage_stages decides)

    // Coulomb friction (sim_friction.cpp): the contacts, the evaluation mask (the active set
    // plus the tangential rows of slipping contacts), the normal forces of the slipping ones,
    // scratch, and Painlevé's inconsistency when it was met (contact index, time, denominator)
    std::vector<FrictionContact> fric;
    std::vector<std::uint8_t> eval_mask;
    std::vector<int> fr_J, fr_rown;
    std::vector<double> fr_N;
    Vec fr_g, fr_zero, fr_N0, fr_W, fr_tmp;
    Mat fr_rq, fr_rf;
    Point fr_p;
    double fr_vthresh = 1e-6;  // |v_t| at or below which a closing contact may stick
    int painleve = -1;
    double painleve_t = 0.0, painleve_den = 0.0;
    // the friction forces' work (sim_friction.cpp, friction_work_*): the power of the last
    // evaluation; the cumulative work at (t, y) and F = (q̇, q̈) and the power there (fw_have0:
    // known); the step being recorded (Simpson's rule on [fw_t0, fw_t0 + fw_h] with the power at
    // its start, middle and end: samples inside it read the integral of that quadratic)
    double fr_power = 0.0;
    double fw = 0.0, fw_P0 = 0.0;
    bool fw_have0 = false;
    bool fw_step = false;
    double fw_t0 = 0.0, fw_h = 0.0, fw_W0 = 0.0, fw_Pm = 0.0, fw_P1 = 0.0;
    Vec fw_f0, fw_f1, fw_ym;
    Point fw_p;

    // the work of controllers and applied forces, W = ∫ q̇ᵀ(B u + f_passive + f_c) dt, as a
    // quadrature state of the integrator (no evaluation of its own): every rhs() leaves its power
    // in wk_P (work_power), each method combines its
    // stage powers with its own weights b into wk_dW (the increment of its last advance over
    // [t, t + h]); wk_f is the power of L.f, wk_K the stages' (dopri5: 7, dop853: 13). wk: W at
    // (L.t, L.y); the step being recorded: W0 at t0, W1 at t0 + h, the powers P0, P1 there
    // (samples inside it read the cubic Hermite interpolant; work_at)
    double wk_P = 0.0, wk_f = 0.0, wk_dW = 0.0, wk = 0.0;
    bool wk_fc = false;  // the constraint forces work (a rheonomic or nonholonomic constraint)
    double wk_K[16] = {};
    bool wk_on = false;
    double wk_t0 = 0.0, wk_h = 0.0, wk_W0 = 0.0, wk_W1 = 0.0, wk_P0 = 0.0, wk_P1 = 0.0;

    // the engine's event layer (sim/events.hpp, sim_events.cpp): what the last transition did
    std::vector<EventInfo> events;
    std::shared_ptr<struct EventScratch> evs;

    explicit Loop(int m_max, int n_) : solver(m_max, n_) {}
    explicit Loop(Solver&& s) : solver(std::move(s)) {}
    // hands the solver and the large matrices to the next make_loop of the same sizes
    // (sim_loop.cpp: the spare workspace)
    ~Loop();
    Loop(const Loop&) = delete;
    Loop& operator=(const Loop&) = delete;
};

// Build a loop for `prog` (which must outlive it) with the active mask (one entry per
// constraint), the options, the output times (empty with `every`: one sample per step) and an
// optional controller (must outlive the loop). Allocates everything.
std::unique_ptr<Loop> make_loop(const Program& prog, const std::uint8_t* active, const Options& opt,
                                const std::vector<double>& t_out, bool every, Controller* ctrl);

// Watch these contact guards during the steps (after make_loop; values at the start given).
void set_guards(Loop& L, const std::vector<ContactGuard>& guards);

// Initial projection (when asked), the first evaluation and its sample, at (t0, q0, qd0).
Outcome start(Loop& L, double t0, const double* q0, const double* qd0);

// Continue from a state reached elsewhere (after an event): no projection, no sample; F(t, y) is
// evaluated afresh; `h` is the proposed step of adaptive methods; the counters continue.
void resume(Loop& L, double t, const double* y, double h, long long n_steps, std::size_t out_i);
// The singular-passage history of a resumed run: the indicator at the k earlier step ends
// (ts[i], ys[i*2n .. (i+1)*2n)) under the current active set, then at the current state — what
// the uninterrupted run had observed there (call after start()).
void passage_seed(Loop& L, const double* ts, const double* ys, int k);

// Advance by at most `max_steps` accepted steps (stops at t1).
Outcome run(Loop& L, long long max_steps);

// The pieces, exposed for tests and for the event layer.
Status evaluate(Loop& L, double t, const double* q, const double* qd, unsigned need);
double drift_rank_rtol(Loop& L);
// W (the work of controllers and applied forces) at time t of the step being recorded
double work_at(const Loop& L, double t);
// the power q̇ᵀ(M q̈ − h) − (friction power) of the evaluation just made (L.T at (t, q, q̇))
double work_power(const Loop& L, const double* qd, const double* qdd);
Status rhs(Loop& L, double t, const double* y, double* out);
Status point(Loop& L, double t, const double* q, const double* qd, Point& p, bool diagnostics);
Status project(Loop& L, double t, double* y, const ProjectionOptions& po);

// _integrators.singular_indicator over the first m rows of A (m × n, row stride n): the estimate
// of σ_min(DA) (0 when the Gram matrix is not positive definite, +inf when m = 0); the warm-start
// vector is kept in L.pas.
double singular_indicator(Loop& L, const Mat& A, int m);

// The smallest eigenvalue of the symmetric k × k matrix X (row-major; its lower triangle is
// read and X destroyed): Householder tridiagonalization, then Newton's method on the Sturm
// pivots from 0 (bisection where it cannot proceed); within ~k eps ‖X‖ of the exact value. d, e:
// scratch of k and 3k entries. The indicator's dense path (k ≤ 32 live rows); bound for tests.
double sym_min_eigenvalue(double* X, int k, double* d, double* e);

// Size the scratch of the indicator and set the method's fractions (make_loop).
void passage_setup(Loop& L);

// SingularPassages.observe / reset / place.
void passage_observe(Loop& L, double t, const Mat& A, int m);
void passage_reset(Loop& L);
double passage_place(const Loop& L, double t, double h);
// Whether the RK4 step of size h from t (f = F(t, y), 2n) projects its stage states: the
// predicted instant is inside it, or nearer than a few steps or than a fraction of the motion's
// time scale ‖q̇‖/‖q̈‖ (sim_integrators.cpp; docs/theory.md, singular passages).
bool passage_stages(const Loop& L, double t, double h, const double* f);
// Whether the step of size h from t holds the predicted singular instant (adaptive methods
// then sample it from the continuous extension)
bool passage_holds(const Loop& L, double t, double h);
// SingularPassages.noise: PASSAGE_NOISE·eps/σ at the last step end (0 without one).
double passage_noise(const Loop& L);

// hermite_quintic of _integrators.py into out (2n): y(t0 + s) from both ends of a step.
void hermite_quintic(int n, const double* y0, const double* f0, const double* y1, const double* f1,
                     double h, double s, double* out);

}  // namespace nonmin::sim
