// The engine's SVD (see nonmin/svd.hpp): one-sided Jacobi on the rows of a work copy X, the
// same rotations accumulated in T. Tall or square A (or a full V): X = Aᵀ (its rows are A's
// columns), so A T ᵀ has orthogonal columns: V = Tᵀ, U's columns the normalized rows of X. Wide A:
// X = A, so T A has orthogonal rows: U = Tᵀ, V's columns the normalized rows of X.
#include "nonmin/svd.hpp"

#include "nonmin/linalg.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nonmin {

namespace {

constexpr double EPS = std::numeric_limits<double>::epsilon();

double dot(const double* x, const double* y, int len) {
    double s0 = 0.0, s1 = 0.0;
    const int l2 = len - len % 2;
    for (int k = 0; k < l2; k += 2) {
        s0 += x[k] * y[k];
        s1 += x[k + 1] * y[k + 1];
    }
    if (len % 2) s0 += x[len - 1] * y[len - 1];
    return s0 + s1;
}

// Cyclic one-sided Jacobi on the k rows of X (k × len): pairs are rotated until every pair is
// orthogonal to |x·y| ≤ √len ε ‖x‖‖y‖ (LAPACK dgesvj's test); linalg::jacobi_orthogonalize.
void orthogonalize(double* X, int k, int len, double* T) {
    linalg::jacobi_orthogonalize(X, k, len, len, len, EPS * std::sqrt(static_cast<double>(std::max(len, 1))), T);
}

}  // namespace

Svd& Svd::compute(const Eigen::Ref<const Mat>& A, int options) {
    options_ = options;
    const int m = static_cast<int>(A.rows()), n = static_cast<int>(A.cols());
    const int p = std::min(m, n);
    const bool want_u = options & (Eigen::ComputeThinU | Eigen::ComputeFullU);
    const bool want_v = options & (Eigen::ComputeThinV | Eigen::ComputeFullV);
    const bool full_u = options & Eigen::ComputeFullU, full_v = options & Eigen::ComputeFullV;
    if (full_u && m > n) throw EngineError("Svd: a full U of a tall matrix is not implemented");
    const bool by_cols = m >= n || full_v;  // X = Aᵀ (else X = A)
    const int k = by_cols ? n : m, len = by_cols ? m : n;
    s_.resize(p);
    U_.resize(want_u ? m : 0, want_u ? (full_u ? m : p) : 0);
    V_.resize(want_v ? n : 0, want_v ? (full_v ? n : p) : 0);
    double scale = 0.0;  // (max |a_ij|: X = A / scale, no overflow in the squares)
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < n; ++j) scale = std::max(scale, std::fabs(A(i, j)));
    if (!std::isfinite(scale) || std::isnan(A.sum())) {
        s_.setConstant(std::numeric_limits<double>::quiet_NaN());
        U_.setZero();
        V_.setZero();
        return *this;
    }
    if (scale == 0.0) scale = 1.0;
    const double inv = 1.0 / scale;
    X_.resize(static_cast<std::size_t>(k) * len);
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < n; ++j) X_[by_cols ? j * len + i : i * len + j] = A(i, j) * inv;
    const bool with_t = by_cols ? want_v : want_u;
    if (with_t) {
        T_.assign(static_cast<std::size_t>(k) * k, 0.0);
        for (int i = 0; i < k; ++i) T_[static_cast<std::size_t>(i) * k + i] = 1.0;
    }
    orthogonalize(X_.data(), k, len, with_t ? T_.data() : nullptr);
    nrm_.resize(k);
    ord_.resize(k);
    for (int i = 0; i < k; ++i) {
        nrm_[i] = std::sqrt(dot(&X_[static_cast<std::size_t>(i) * len], &X_[static_cast<std::size_t>(i) * len], len));
        ord_[i] = i;
    }
    for (int i = 1; i < k; ++i) {  // decreasing, ties in index order (insertion: no allocation)
        const int o = ord_[i];
        int j = i;
        for (; j > 0 && nrm_[ord_[j - 1]] < nrm_[o]; --j) ord_[j] = ord_[j - 1];
        ord_[j] = o;
    }
    for (int a = 0; a < p; ++a) s_[a] = nrm_[ord_[a]] * scale;
    // the rows of X, normalized, are the columns of U (by_cols) or V; the rows of T those of V or U
    Mat& W = by_cols ? U_ : V_;
    if (by_cols ? want_u : want_v)
        for (int a = 0; a < W.cols(); ++a) {
            const int i = ord_[a];
            const double* Xi = &X_[static_cast<std::size_t>(i) * len];
            const double r = nrm_[i] > 0.0 ? 1.0 / nrm_[i] : 0.0;
            for (int c = 0; c < len; ++c) W(c, a) = Xi[c] * r;
        }
    if (with_t) {
        Mat& Q = by_cols ? V_ : U_;
        for (int a = 0; a < Q.cols(); ++a) {
            const double* Ti = &T_[static_cast<std::size_t>(ord_[a]) * k];
            for (int c = 0; c < k; ++c) Q(c, a) = Ti[c];
        }
    }
    return *this;
}

}  // namespace nonmin
