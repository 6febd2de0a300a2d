// The engine's SVD of a dense row-major Mat: one-sided (Hestenes) Jacobi, implemented once in
// engine/src/svd.cpp. It replaced Eigen's JacobiSVD<Mat> (two-sided Jacobi behind
// column-pivoting QR preconditioners) and BDCSVD<Mat>, whose one explicit instantiation alone
// took 58 s of the build's ~300 s of compile CPU and made every unit that saw their class
// definitions slower (issue 17, target 7: the build of a fresh clone; measurements in svd.cpp).
// One-sided Jacobi is accurate to high relative accuracy on each singular value, so the rank
// decisions (σ_i > rtol σ_max) of its callers see the same or better values.
//
// The interface is the part of Eigen's that the engine used: the same option flags
// (Eigen::ComputeThinU, ComputeFullU, ComputeThinV, ComputeFullV), singular values sorted in
// decreasing order, matrixU() (m × p, p = min(m, n); m × m with ComputeFullU when m ≤ n) and
// matrixV() (n × p; n × n with ComputeFullV). Singular vectors of a zero singular value are
// zero columns where they are not defined by the rotations (a finite placeholder: every caller
// multiplies them by zero). A non-finite input gives NaN singular values and zero vectors.
#pragma once
#include <vector>

#include "types.hpp"

namespace nonmin {

class Svd {
public:
    Svd() = default;
    // (sizes are a hint only, as Eigen's preallocating constructor; buffers grow on first use)
    Svd(Eigen::Index /*rows*/, Eigen::Index /*cols*/, int options = 0) : options_(options) {}
    Svd(const Eigen::Ref<const Mat>& A, int options) { compute(A, options); }

    Svd& compute(const Eigen::Ref<const Mat>& A, int options);
    Svd& compute(const Eigen::Ref<const Mat>& A) { return compute(A, options_); }

    const Vec& singularValues() const { return s_; }
    const Mat& matrixU() const { return U_; }
    const Mat& matrixV() const { return V_; }

private:
    int options_ = 0;
    Vec s_;
    Mat U_, V_;
    std::vector<double> X_, T_, nrm_;
    std::vector<int> ord_;
};

}  // namespace nonmin
