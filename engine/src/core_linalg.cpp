// The rank tolerance policy and the SPD factorization (see linalg.hpp, docs/theory.md).
#include "nonmin/linalg.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace nonmin::linalg {

namespace {
constexpr double EPS = std::numeric_limits<double>::epsilon();
constexpr int MAX_SWEEPS = 60;
}  // namespace

double row_norm(const double* x, int n) {
    const int n4 = n - n % 4;
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    for (int k = 0; k < n4; k += 4) {
        s0 += x[k] * x[k];
        s1 += x[k + 1] * x[k + 1];
        s2 += x[k + 2] * x[k + 2];
        s3 += x[k + 3] * x[k + 3];
    }
    for (int k = n4; k < n; ++k) s0 += x[k] * x[k];
    const double s = (s0 + s1) + (s2 + s3);
    // squares that overflowed (a row above ~1e154) or underflowed (below ~1e-154): recompute on
    // the row divided by its largest entry (nonmin.core.linalg.row_norms, ROW_NORM_BIG/SMALL);
    // inside the range the plain sum is kept, bitwise. NaN stays NaN (not > and not <).
    if (s > 1e300 || s < 1e-290) {
        double scale = 0.0;
        for (int k = 0; k < n; ++k) scale = std::max(scale, std::fabs(x[k]));
        if (!(scale > 0.0)) return scale == 0.0 ? std::sqrt(s) : scale;
        double r = 0.0;
        for (int k = 0; k < n; ++k) {
            const double y = x[k] / scale;
            r += y * y;
        }
        return scale * std::sqrt(r);
    }
    return std::sqrt(s);
}

double row_norm_pattern(const double* x, int n, const int* cols, int e) {
    const int n4 = n - n % 4;
    double sp[4] = {0.0, 0.0, 0.0, 0.0};
    for (int t = 0; t < e; ++t) {
        const int k = cols[t];
        sp[k < n4 ? (k & 3) : 0] += x[k] * x[k];
    }
    const double s = (sp[0] + sp[1]) + (sp[2] + sp[3]);
    if (s > 1e300 || s < 1e-290) return row_norm(x, n);  // the rare scaled recomputation
    return std::sqrt(s);
}

int equilibrate_pattern(const double* A, int m, int n, const int* start, const int* cols,
                        const double* b, double rtol, double* B, double* d, double* norms, bool b_zero) {
    const int ld = n + 1;
    double big = 0.0;
    for (int i = 0; i < m; ++i) {
        const double nrm = row_norm_pattern(A + static_cast<long>(i) * n, n, cols + start[i],
                                            start[i + 1] - start[i]);
        norms[i] = nrm;
        if (nrm > big) big = nrm;
    }
    const double thr = rtol * big;
    int live = 0;
    for (int i = 0; i < m; ++i) {
        double* Bi = B + static_cast<long>(i) * ld;
        const double* Ai = A + static_cast<long>(i) * n;
        if (!b_zero) std::fill(Bi, Bi + ld, 0.0);  // (b_zero: B is all zero already)
        if (norms[i] > thr) {
            const double di = 1.0 / norms[i];
            for (int t = start[i]; t < start[i + 1]; ++t) Bi[cols[t]] = Ai[cols[t]] * di;
            Bi[n] = b ? di * b[i] : 0.0;
            d[i] = di;
            ++live;
        } else {
            Bi[n] = 0.0;
            d[i] = 0.0;
        }
    }
    return live;
}

int equilibrate(const double* A, int m, int n, const double* b, double rtol, double* B, double* d,
                double* norms) {
    const int ld = n + 1;
    double big = 0.0;
    for (int i = 0; i < m; ++i) {
        const double nrm = row_norm(A + static_cast<long>(i) * n, n);
        norms[i] = nrm;
        if (nrm > big) big = nrm;
    }
    const double thr = rtol * big;
    int live = 0;
    for (int i = 0; i < m; ++i) {
        double* Bi = B + static_cast<long>(i) * ld;
        const double* Ai = A + static_cast<long>(i) * n;
        if (norms[i] > thr) {
            const double di = 1.0 / norms[i];
            for (int j = 0; j < n; ++j) Bi[j] = Ai[j] * di;
            Bi[n] = b ? di * b[i] : 0.0;
            d[i] = di;
            ++live;
        } else {
            for (int j = 0; j <= n; ++j) Bi[j] = 0.0;
            d[i] = 0.0;
        }
    }
    return live;
}

void jacobi_orthogonalize(double* X, int k, int ld, int len, int rot, double tol, double* T) {
    double frob2 = 0.0;
    for (int i = 0; i < k; ++i)
        for (int c = 0; c < len; ++c) frob2 += X[static_cast<long>(i) * ld + c] * X[static_cast<long>(i) * ld + c];
    const double noise2 = EPS * EPS * frob2;
    for (int sweep = 0; sweep < MAX_SWEEPS; ++sweep) {
        bool rotated = false;
        for (int i = 0; i < k - 1; ++i) {
            double* Xi = X + static_cast<long>(i) * ld;
            for (int j = i + 1; j < k; ++j) {
                double* Xj = X + static_cast<long>(j) * ld;
                // the three dot products over the first len entries, even and odd terms apart
                double a0 = 0.0, a1 = 0.0, b0 = 0.0, b1 = 0.0, c0 = 0.0, c1 = 0.0;
                const int l2 = len - len % 2;
                for (int c = 0; c < l2; c += 2) {
                    const double x = Xi[c], y = Xj[c], x1 = Xi[c + 1], y1 = Xj[c + 1];
                    a0 += x * x;
                    b0 += y * y;
                    c0 += x * y;
                    a1 += x1 * x1;
                    b1 += y1 * y1;
                    c1 += x1 * y1;
                }
                if (len % 2) {
                    const double x = Xi[len - 1], y = Xj[len - 1];
                    a0 += x * x;
                    b0 += y * y;
                    c0 += x * y;
                }
                const double aa = a0 + a1, bb = b0 + b1, cc = c0 + c1;
                if (aa <= noise2 || bb <= noise2 || std::fabs(cc) <= tol * std::sqrt(aa * bb)) continue;
                rotated = true;
                const double zeta = (bb - aa) / (2.0 * cc);
                double t;
                if (std::fabs(zeta) > 1e150)
                    t = 0.5 / zeta;
                else
                    t = std::copysign(1.0, zeta) / (std::fabs(zeta) + std::sqrt(1.0 + zeta * zeta));
                const double cs = 1.0 / std::sqrt(1.0 + t * t);
                const double sn = cs * t;
                for (int c = 0; c < rot; ++c) {
                    const double x = Xi[c], y = Xj[c];
                    Xi[c] = cs * x - sn * y;
                    Xj[c] = sn * x + cs * y;
                }
                if (T) {
                    double* Ti = T + static_cast<long>(i) * k;
                    double* Tj = T + static_cast<long>(j) * k;
                    for (int c = 0; c < k; ++c) {
                        const double x = Ti[c], y = Tj[c];
                        Ti[c] = cs * x - sn * y;
                        Tj[c] = sn * x + cs * y;
                    }
                }
            }
        }
        if (!rotated) break;
    }
}

void jacobi_rows(double* B, int m, int n, double* T) { jacobi_orthogonalize(B, m, n + 1, n, n + 1, EPS, T); }

int keep_rows(const double* B, int m, int n, double rtol, double* V, double* cv, double* sig) {
    const int ld = n + 1;
    double smax = 0.0;
    for (int i = 0; i < m; ++i) {
        sig[i] = row_norm(B + static_cast<long>(i) * ld, n);
        if (sig[i] > smax) smax = sig[i];
    }
    int r = 0;
    for (int i = 0; i < m; ++i) {
        if (sig[i] > rtol * smax) {
            const double inv = 1.0 / sig[i];
            const double* Bi = B + static_cast<long>(i) * ld;
            double* Vr = V + static_cast<long>(r) * n;
            for (int k = 0; k < n; ++k) Vr[k] = Bi[k] * inv;
            cv[r] = Bi[n] * inv;
            ++r;
        }
    }
    return r;
}

int cholesky_spd(double* W, int n, double spd_rtol, double dmax, double* dinv, double* cw,
                 double* ratio) {
    int st = CHOL_OK;
    double rt = std::numeric_limits<double>::infinity();
    for (int j = 0; j < n; ++j) {
        const double s = W[j * n + j];
        if (!(s > 0.0)) {
            *ratio = rt;
            return CHOL_FAIL;
        }
        const double ljj = std::sqrt(s);
        const double piv = ljj * ljj;
        if (piv <= spd_rtol * dmax) {
            st = CHOL_SMALL_PIVOT;
            if (piv / dmax < rt) rt = piv / dmax;
        }
        W[j * n + j] = ljj;
        const double rj = 1.0 / ljj;
        dinv[j] = rj;
        for (int i = j + 1; i < n; ++i) {
            const double x = W[i * n + j] * rj;
            W[i * n + j] = x;
            cw[i] = x;
        }
        for (int i = j + 1; i < n; ++i) {
            const double a = cw[i];
            double* Wi = W + static_cast<long>(i) * n;
            for (int k = j + 1; k <= i; ++k) Wi[k] -= a * cw[k];
        }
    }
    *ratio = rt;
    return st;
}

void sym_eigenvalues(double* X, int k, double* ev) {
    double total = 0.0;
    for (int i = 0; i < k * k; ++i) total += X[i] * X[i];
    for (int sweep = 0; sweep < MAX_SWEEPS; ++sweep) {
        double off = 0.0;
        for (int p = 0; p < k; ++p)
            for (int q = p + 1; q < k; ++q) off += 2.0 * X[p * k + q] * X[p * k + q];
        if (!(off > EPS * EPS * total)) break;
        for (int p = 0; p < k - 1; ++p)
            for (int q = p + 1; q < k; ++q) {
                const double apq = X[p * k + q];
                if (apq == 0.0) continue;
                const double app = X[p * k + p], aqq = X[q * k + q];
                const double theta = (aqq - app) / (2.0 * apq);
                double t;
                if (std::fabs(theta) > 1e150)
                    t = 0.5 / theta;
                else
                    t = std::copysign(1.0, theta) / (std::fabs(theta) + std::sqrt(1.0 + theta * theta));
                const double c = 1.0 / std::sqrt(1.0 + t * t);
                const double s = t * c;
                for (int r = 0; r < k; ++r) {  // columns p, q
                    const double xp = X[r * k + p], xq = X[r * k + q];
                    X[r * k + p] = c * xp - s * xq;
                    X[r * k + q] = s * xp + c * xq;
                }
                for (int r = 0; r < k; ++r) {  // rows p, q
                    const double xp = X[p * k + r], xq = X[q * k + r];
                    X[p * k + r] = c * xp - s * xq;
                    X[q * k + r] = s * xp + c * xq;
                }
            }
    }
    for (int i = 0; i < k; ++i) ev[i] = X[i * k + i];
}

void cholesky_solve(const double* W, int n, const double* dinv, double* x) {
    for (int k = 0; k < n; ++k) {  // L y = b, column-oriented
        const double y = x[k] * dinv[k];
        x[k] = y;
        for (int i = k + 1; i < n; ++i) x[i] -= W[i * n + k] * y;
    }
    for (int i = n - 1; i >= 0; --i) {  // Lᵀ x = y, rows of L
        const double xi = x[i] * dinv[i];
        x[i] = xi;
        for (int k = 0; k < i; ++k) x[k] -= W[i * n + k] * xi;
    }
}

}  // namespace nonmin::linalg
