// Helpers shared by the model layer's binding files (program.cpp, planar.cpp, tape.cpp,
// spatial.cpp): typed nonmin.errors exceptions, array type aliases and owned NumPy outputs.
#pragma once
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "nonmin/types.hpp"

namespace nonmin::bindings {

namespace nb = nanobind;

using CArr1 = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using CArr2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using CMask = nb::ndarray<const std::uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using NpArr = nb::ndarray<nb::numpy, double>;

// Raise the exception class `cls` of nonmin.errors with `msg`.
[[noreturn]] inline void raise_error(const char* cls, const std::string& msg) {
    nb::object type = nb::module_::import_("nonmin.errors").attr(cls);
    PyErr_SetString(type.ptr(), msg.c_str());
    throw nb::python_error();
}

// Translate a non-ok Status into the typed Python error (a Python error already set by a
// callback is re-raised as it is).
[[noreturn]] inline void raise_status(Status s, const std::string& what) {
    if (PyErr_Occurred()) throw nb::python_error();
    switch (s) {
        case Status::not_finite:
            raise_error("NonFiniteError", what + ": an input or a model output is not finite");
        case Status::not_positive_definite:
            raise_error("NotPositiveDefiniteError", what + ": matrix not positive definite");
        case Status::not_symmetric:
            raise_error("NotSymmetricError", what + ": matrix not symmetric");
        case Status::bad_shape:
            raise_error("ShapeError", what + ": bad shape");
        case Status::not_differentiable:
            raise_error("ModelError", what + ": this model's program has no forward-mode derivatives");
        case Status::callback_error:
            raise_error("SimulationError", what + ": a Python callback failed");
        default:
            raise_error("NonminError", what + ": engine status " + std::to_string(static_cast<int>(s)));
    }
}

// A new C-contiguous float64 NumPy array of the given shape (owned by a capsule), zero-filled,
// or left uninitialized (zero = false) for an output the engine writes in full.
inline NpArr new_array(std::vector<std::size_t> shape, bool zero = true) {
    std::size_t size = 1;
    for (std::size_t s : shape) size *= s;
    double* data = zero ? new double[size > 0 ? size : 1]() : new double[size > 0 ? size : 1];
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<double*>(p); });
    return NpArr(data, shape.size(), shape.data(), owner);
}

}  // namespace nonmin::bindings
