// The list of the engine's layers: add one line per binding file (engine/bindings/<layer>.cpp).
#include "register.hpp"

namespace nonmin::bindings {

void register_all(nanobind::module_& m) {
    bind_program(m);
    bind_timefn(m);
    bind_planar(m);
    bind_core(m);
    bind_batch(m);
    bind_tape(m);
    bind_spatial(m);
    bind_rbd(m);
    bind_sim(m);
    bind_sim_batch(m);
    bind_events(m);
    bind_derivatives(m);
    bind_control(m);
}

}  // namespace nonmin::bindings
