// Eigen's SVDs of the engine's row-major Mat, instantiated once (engine/src/eigen_svd.cpp) and
// declared extern in every other translation unit: JacobiSVD<Mat>::compute (with its QR
// preconditioners) cost ~9 s of compile time in each of the five files that call it, and
// BDCSVD<Mat> made core_solver.cpp the longest file of the build (issue 17, target 7: the
// build of a fresh clone). Include this header instead of <Eigen/SVD>.
#pragma once
#include <Eigen/SVD>

#include "types.hpp"

extern template class Eigen::JacobiSVD<nonmin::Mat>;
extern template class Eigen::BDCSVD<nonmin::Mat>;
