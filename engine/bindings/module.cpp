// The extension module nonmin._engine: one registration function per engine layer.
// Each engine/bindings/<layer>.cpp defines its `bind_<layer>(nb::module_&)` and is listed here.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>

#include <Eigen/Core>

#include "register.hpp"

namespace nb = nanobind;

NB_MODULE(_engine, m) {
    m.doc() = "nonmin's ahead-of-time compiled engine (C++17). Private: use the public API.";
    // Model sources cache their compiled Program in module-level dicts (one per model), which
    // are still alive when the interpreter tears the extension down; nanobind would report
    // them as leaks at every exit.
    nb::set_leak_warnings(false);
    m.def(
        "build_info",
        []() {
            nb::dict d;
            d["version"] = NONMIN_VERSION;
            d["compiler"] = __VERSION__;
            d["cplusplus"] = static_cast<long>(__cplusplus);
            d["eigen"] = std::to_string(EIGEN_WORLD_VERSION) + "." +
                         std::to_string(EIGEN_MAJOR_VERSION) + "." +
                         std::to_string(EIGEN_MINOR_VERSION);
#ifdef NDEBUG
            d["optimized"] = true;
#else
            d["optimized"] = false;
#endif
            return d;
        },
        "Build information of the compiled engine (version, compiler, Eigen).");
    nonmin::bindings::register_all(m);
}
