// The engine's event layer for unilateral contact (engine/src/sim_events.cpp), specified by the
// Python driver (nonmin/sim/_simulate.py: the `fired` branch of simulate, _set_impact, _apply's
// release, _guard_value) and the NumPy kernel nonmin.core.polyhedral_projection:
//
//   * the contact guards at a step end (gaps of the inactive unilateral constraints, normal
//     forces of the active ones), all gaps from one evaluation of the program;
//   * the location of a crossing: Brent's method on the partial step of the run's method from
//     the step start, projected (the state the integrator produces there), to EVENT_XTOL;
//   * the transition: one impact over every contact closing at the instant (Newton's law per
//     contact in inequality form, multiplier-free: the mass-metric projection onto a polyhedron,
//     docs/theory.md "Simultaneous impacts"), the Gauss check of the contacts left closed, or a
//     release; then the projection onto the new active set and the samples before and after.
//
// User guards (Python callbacks) are not located here: a step in which one crosses is left to
// the Python driver (Outcome::event), as is a step in which both kinds cross.
#pragma once
#include <cstdint>
#include <vector>

#include "loop.hpp"

namespace nonmin::sim {

constexpr double EVENT_XTOL = 1e-13;     // _simulate.EVENT_XTOL (s)
constexpr double EVENT_RTOL = 1e-15;     // brentq's rtol in the driver
constexpr int EVENT_MAX_ITER = 200;      // brentq's maxiter in the driver
constexpr double RELEASE_RTOL = 1e-10;   // _simulate.RELEASE_RTOL
constexpr double FEASIBILITY_RTOL = 1e-9;  // nonmin.core.impact.FEASIBILITY_RTOL
constexpr int MAX_INEQUALITY_ROWS = 16;    // nonmin.core.impact.MAX_INEQUALITY_ROWS

// Scratch of polyhedral_projection, sized for faces of up to m_max rows in n unknowns.
struct PolyWork {
    Mat A;  // face rows
    Vec r, bias, dx, xf, zero, best, res, scale_eq0;
    std::vector<int> idx;
    std::vector<std::uint32_t> feasible, empty;
    void reserve(int m_max, int n);
};

// x = argmin ½ (x − x0)ᵀ M (x − x0) subject to A_eq x + r_eq = 0 and A_in x + r_in ≥ 0
// (row-major A_eq (m_eq × n), A_in (m_in × n), m_in ≤ MAX_INEQUALITY_ROWS): the feasible face
// projection nearest to x0, each face one Solver::forward with zero force (see
// nonmin.core.polyhedral_projection, the specification). at_bound (m_in): rows at equality at x.
// Returns false (x untouched) when no face is feasible; `status` is the first failed solve.
bool polyhedral_projection(Solver& S, const SolveOptions& so, int n, const double* M, const double* x0,
                           const double* A_eq, const double* r_eq, int m_eq, const double* A_in,
                           const double* r_in, int m_in, double* x, std::uint8_t* at_bound, PolyWork& w,
                           Status& status);

// Watch these contact guards during the steps (after make_loop; values at the start given).
void set_guards(Loop& L, const std::vector<ContactGuard>& guards);

// Newton's restitution of automatic impacts per constraint (declaration order) and the impact
// velocity threshold (simulate's restitution and impact_velocity_threshold); after set_guards.
void set_contact_options(Loop& L, const std::vector<double>& restitution, double v_thresh);

// The contact guards at the projected step end (the point just evaluated, its f_c given): new
// values into L.guard_new; `fired` when one crossed downward or an impact gap stays below zero.
Status contact_guards(Loop& L, double t, const double* q, const double* qd, const double* f_c, bool& fired);

// The guards' values at the run's first point (after start(), which evaluated it into L.p1), in
// place of the values given to set_guards: a run with unilateral constraints starts in the engine.
Status arm_guards(Loop& L);

// What the step that fired looked like (the state of run() at that moment).
struct FiredStep {
    double t_start = 0.0, h = 0.0, t_new = 0.0;
    bool f_start = false;  // L.f is F(t_start, y_start)
    bool have_p1 = false;  // L.p1 is the evaluation at the projected step end
    bool inside = false;   // L.fp1 holds F there (the Hermite interpolant is available)
    double h_next = 0.0;   // the step the method proposes after this one
};

// Locate the earliest crossing in the step (from L.y at t_start), record the requested samples
// up to it and the sample there, apply the transition, project, record the sample after it, and
// leave the loop at the event: L.t, L.y, the active set and the guards are those after it,
// L.events what was applied. On a failure nothing is recorded or changed and the status is
// returned (the Python driver then takes the step).
Status contact_event(Loop& L, const FiredStep& st);

// Provided by sim_loop.cpp for the event layer: the driver's at(s) before its point() — a partial
// step of size s ≥ 0 of the run's method from (t, y) (f: F(t, y) when known), projected by the
// run's stabilization —, a recorded sample, and the DOPRI5 continuous extension of the step.
Status partial_step(Loop& L, double t, const Vec& y, const Vec* f, double s, Vec& out);
void record_sample(Loop& L, const Point& p, double t);
void dense_output(const Loop& L, double t0, double h, double tt, double* out);
Status stabilize(Loop& L, double t, double* y);
Status stabilize_sample(Loop& L, double t, double* y);  // a sample from a continuous extension

// The active set of the loop (rows, position-level rows, controller attachment, guard buffers).
void set_active(Loop& L, const std::uint8_t* active);

// λ = ((DA)⁺ D)ᵀ f_c over the active rows of the point just evaluated, into L.lam_c (m): the
// multiplier-free split of f_c that the release guards read (sim_events.cpp).
void release_forces(Loop& L, const double* f_c);

// ------------------------------------------------------------------------------ friction
// Coulomb friction at point contacts (sim_friction.cpp; docs/theory.md "Coulomb friction").
// A sticking contact has its tangential row active (a bilateral constraint); a slipping one
// has it inactive and carries the force F = −μ s N along that row, with N its normal force
// read from f_c (no multipliers): N = N0 − Σ_j λ_n(S a_tj) μ_j s_j N_j, solved exactly.

// The contacts (slip directions as given), the evaluation mask, the scratch; before start/resume.
void set_friction(Loop& L, const std::vector<FrictionContact>& contacts);
// The evaluation mask: the active set plus the tangential rows of the slipping contacts.
void friction_mask(Loop& L);
// After the dynamics solve at the evaluation just made (qdd, f_c of the applied forces): add the
// slipping contacts' friction forces' response. Painlevé's inconsistency (the normal-force
// relation has no positive solution: a non-P matrix, for one contact 1 + μ s ∂N/∂F ≤ 0) sets
// L.painleve, L.painleve_t, L.message and returns Status::not_finite.
Status friction_forces(Loop& L, double t, const double* qd, double* qdd, double* fc);
// Append the friction guards of the current active set with their values at (L.t, L.y).
Status friction_arm(Loop& L);
// The value of friction guard G at (t, q, qd); sticking guards read L.lam_c (release_forces of
// the point just evaluated there).
Status friction_guard_value(Loop& L, const ContactGuard& G, double t, const double* q, const double* qd,
                            double& g);
// At an event (t, y): the friction modes after it — the contacts whose guard fired (`fired`,
// indices into L.fric), those whose normal opened or closed (against `act_start`) — decided
// (slip by the tangential velocity, else stick when the sticking force lies in the cone, else
// slip opposite to it). `changed`: the contacts whose mode changed or whose guard fired.
Status friction_transition(Loop& L, double t, Vec& y, const std::vector<int>& fired,
                           const std::vector<std::uint8_t>& act_start, std::vector<int>& changed);
// Append the friction guards after an event (L.lam_c: release_forces of the point after it).
Status friction_append_guards(Loop& L, double t, const Vec& y);

// The work of the friction forces, W(t) = ∫ Σ F_j e_j·v_t,j dt (≤ 0: Coulomb friction only
// dissipates), integrated step by step with Simpson's rule on the power at the step's start, at
// the middle of the quintic Hermite interpolant of its (projected) ends, and at its end (one
// evaluation more per step in which a contact slips; the modes are fixed inside a step, so the
// power is smooth there). friction_work_step: the step from (L.t, L.y) to (t1, y1), `p1` the
// evaluation at its end; samples recorded until friction_work_commit read friction_work_at.
Status friction_work_step(Loop& L, double t1, const double* y1, const Point& p1);
double friction_work_at(const Loop& L, double t);
// End of the step (or of the event's partial step): W, F and the power at the new state `p`.
void friction_work_commit(Loop& L, const Point& p);

}  // namespace nonmin::sim
