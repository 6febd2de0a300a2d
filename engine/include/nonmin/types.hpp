// Common types of the engine: dense row-major matrices (NumPy's layout, so arrays pass without
// copies), vectors, status codes and the engine's exception.
#pragma once
#include <Eigen/Core>

#include <cstdint>
#include <stdexcept>
#include <string>

namespace nonmin {

using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using Vec = Eigen::VectorXd;
using MatMap = Eigen::Map<Mat>;
using CMatMap = Eigen::Map<const Mat>;
using VecMap = Eigen::Map<Vec>;
using CVecMap = Eigen::Map<const Vec>;

// Outcome of one kernel call or one step. Nonzero codes are translated to the typed Python
// errors by the bindings (nonmin.errors), never returned silently as NaN.
enum class Status : int {
    ok = 0,
    not_finite = 1,          // an input (or a model output) is NaN or infinite
    not_positive_definite = 2,  // M̄ fails the SPD test (SPD_RTOL), see core/linalg.py
    not_symmetric = 3,       // M fails the symmetry test (SYMMETRY_RTOL)
    bad_shape = 4,
    callback_error = 5,      // a Python callback raised (its exception is kept by the binding)
    not_differentiable = 6,  // the program has no forward-mode evaluation (Program::evaluate_tangent)
};

// Thrown inside the engine for errors that cannot be a status (programming errors, bad model
// descriptions); the bindings turn it into nonmin.errors.ModelError / InputError.
struct EngineError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

}  // namespace nonmin
