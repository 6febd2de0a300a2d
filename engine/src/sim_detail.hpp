// Private to the engine's simulation loop: what sim_loop.cpp (the driver) uses of
// sim_integrators.cpp (the integrators). Not installed, not part of the engine's interface.
#pragma once
#include "nonmin/sim/loop.hpp"

namespace nonmin::sim::detail {

// _integrators._clip: the step h from t, ending exactly at t_bound when within 1e-9 h of it.
double clip(double t, double h, double t_bound);

// Whether the method chooses its steps (DOPRI5, DOP853).
bool adaptive(const Loop& L);

// A raw step of size h of the fixed-step method from (t, y) (f: F(t, y) when known) into out.
Status fixed_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out);

// DormandPrince5.advance: one raw step of size h from (t, y) (f: F(t, y) when known) into out
// (the event layer's partial steps; L.K is overwritten).
Status dp_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out);

// DormandPrince5.step from (L.t, L.y): the accepted step size in h_acc, the new time in t_new;
// L.y1 the raw end, L.yq1 the projected one, L.K the stages, the continuous extension set up.
Status dp_step(Loop& L, double& h_acc, double& t_new);

// The continuous extension of the last accepted DOPRI5 step at tt into out (2n).
void dp_dense(const Loop& L, double t0, double h, double tt, double* out);

// DOP853.step from (L.t, L.y), as dp_step (stages in L.K8; the continuous extension is set up
// on demand by d8_dense_setup, which evaluates F(t + h, y1) and three more stages).
Status d8_step(Loop& L, double& h_acc, double& t_new);
Status d8_dense_setup(Loop& L);
// The continuous extension (order 7) of the last accepted DOP853 step at tt into out (2n).
void d8_dense(const Loop& L, double tt, double* out);
// DOP853.advance: one raw step (the event layer's partial steps; L.K8 is overwritten).
Status d8_advance(Loop& L, double t, const Vec& y, const Vec* f, double h, Vec& out);

}  // namespace nonmin::sim::detail
