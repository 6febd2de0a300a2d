// Registration of the engine's layers in the extension module (see module.cpp).
#pragma once
#include <nanobind/nanobind.h>

namespace nonmin::bindings {

// Each layer's binding file defines one of these; register_all calls them in order.
void register_all(nanobind::module_& m);

void bind_program(nanobind::module_& m);  // program.cpp: Program, Terms, Workspace
void bind_timefn(nanobind::module_& m);   // timefn.cpp: TimeFunction (drivers' prescribed motions)
void bind_planar(nanobind::module_& m);   // planar.cpp: PlanarDescription, PlanarProgram
void bind_core(nanobind::module_& m);     // core.cpp: Solver (single, batched), min_norm
void bind_tape(nanobind::module_& m);     // tape.cpp: TapeProgram (SymPy models)
void bind_spatial(nanobind::module_& m);  // spatial.cpp: SpatialDescription, SpatialProgram
void bind_rbd(nanobind::module_& m);      // rbd.cpp: TreeProgram (robots)
void bind_sim(nanobind::module_& m);      // sim.cpp: SimLoop, SimOptions, PyProgram (needs Program)
void bind_sim_batch(nanobind::module_& m);  // sim_batch.cpp: simulate_batch (k runs of the loop)
void bind_control(nanobind::module_& m);  // control.cpp: SimControl, SimPiecewisePolynomial, SimPySignal
void bind_batch(nanobind::module_& m);    // batch.cpp: forward_batch (model + kernel over N states)
void bind_events(nanobind::module_& m);   // events.cpp: polyhedral_projection (event layer kernel)
void bind_derivatives(nanobind::module_& m);  // derivatives.cpp: term_tangents (forward mode)

}  // namespace nonmin::bindings
