// The projection-dynamics solve (solver.hpp): input checks, the rank policy (linalg.hpp), M̄,
// its Cholesky factorization, q̈ and f_c. Specified by nonmin.core.dynamics._solve_dynamics_numpy.
#include "nonmin/svd.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "nonmin/linalg.hpp"
#include "nonmin/solver.hpp"

namespace nonmin {

namespace {
constexpr double TINY = std::numeric_limits<double>::min();
// Above this many rows the rank is decided by the engine's SVD (svd.hpp: one-sided Jacobi on the
// columns, O(n² m) per sweep) instead of the row sweeps of jacobi_rows (O(m² n) per sweep).
constexpr int JACOBI_MAX_ROWS = 32;
}  // namespace

struct Solver::Impl {
    int m_max, n;
    std::vector<double> B, d, sig, V, cv, Kt, Tt, Et, Ft, G, Ls, W, wv, u, g, dinv, cw;
    Mat big;                 // large-m SVD input (m_max × n)
    Svd svd;  // large-m SVD (thin U, full V: the null-space basis)
    linalg::LQWork lq;       // certified LQ scratch
    int lqmode = linalg::LQ_NONE;  // what the last rank decision used
    bool zmode = false;            // null-space form: Z (rows of Kt, k = n − r ≤ r) spans N(A)
    bool w_done = false;           // wv holds w of the last rank decision (lq_rows_min_norm)
    int m_live = 0;                // rows of B the rank decision used (the live rows of A)
    // The factorization of the last successful forward/solve call, for again(): its A had m
    // rows (scales d, live rows compacted), rank r, M diagonal or not, μ; the SVD paths keep
    // Σ⁻¹Uᵀ of the kept rows in Ui (r × m_live), the certified LQ its L (lq.Wq or lq.Li); the range
    // form keeps M̄'s Cholesky factor (W, dinv), the null-space form Z (Kt), S (G) and its
    // factor (Ls).
    bool held = false;
    unsigned long long gen = 0;  // factorizations begun (Solver::generation)
    int h_m = 0, h_r = 0;
    bool h_diag = false;
    double h_mu = 0.0;
    std::vector<double> Ui, Tj, db;
    std::vector<int> lrows;  // the live rows (a known pattern's rows after compaction)
    bool b_zero = true;      // B is all zero (a known pattern's entries are zeroed after use)
    double h_rtol = 0.0;     // the held call's rank tolerance
    // near(): the refined basis Z of the last near call's A (rows of Zn), S = Z M Zᵀ (Gn), its
    // factor (Lsn) and μ; near_ok: they are that A's, refined from the factorization still held;
    // near_last: the last solve was near() (cond_mbar reads Gn)
    std::vector<double> Zn, Gn, Lsn, nres, nx;
    bool near_ok = false, near_last = false;
    int near_k = 0;
    double near_mu = 0.0;

    Impl(int m_max_, int n_)
        : m_max(m_max_), n(n_) {
        const long mn = static_cast<long>(m_max) * n;
        B.assign(static_cast<long>(m_max) * (n + 1), 0.0);
        d.assign(m_max, 0.0);
        sig.assign(m_max, 0.0);
        V.assign(mn, 0.0);
        cv.assign(std::max(m_max, n) + 1, 0.0);
        Kt.assign(mn, 0.0);
        Tt.assign(mn, 0.0);
        Et.assign(mn, 0.0);
        Ft.assign(mn, 0.0);
        G.assign(static_cast<long>(m_max) * m_max, 0.0);
        Ls.assign(static_cast<long>(m_max) * m_max, 0.0);
        W.assign(static_cast<long>(n) * n, 0.0);
        wv.assign(n, 0.0);
        u.assign(n, 0.0);
        g.assign(n, 0.0);
        dinv.assign(n, 0.0);
        cw.assign(n, 0.0);
        if (m_max > JACOBI_MAX_ROWS) {
            big = Mat::Zero(m_max, n);
            svd = Svd(m_max, n, Eigen::ComputeThinU | Eigen::ComputeFullV);
        }
        if (m_max >= linalg::QR_MIN_ROWS) lq = linalg::LQWork(m_max, n);
        Ui.assign(static_cast<long>(m_max) * m_max, 0.0);
        const long mj = std::min(m_max, JACOBI_MAX_ROWS);
        Tj.assign(mj * mj, 0.0);
        db.assign(m_max + 1, 0.0);
        lrows.assign(m_max, 0);
        Zn.assign(mn, 0.0);
        Gn.assign(static_cast<long>(m_max) * m_max, 0.0);
        Lsn.assign(static_cast<long>(m_max) * m_max, 0.0);
        nres.assign(m_max + 1, 0.0);
        nx.assign(n, 0.0);
    }

    double smax_of(int m) const {  // max_i sig[i] (keep_rows' σ_max)
        double smax = 0.0;
        for (int i = 0; i < m; ++i)
            if (sig[i] > smax) smax = sig[i];
        return smax;
    }

    // Rule 3: the rank r of D A (B holds [D A | D b], live rows of A: `live`; B is overwritten,
    // its live rows first: a vanished row is a zero row of D A, which changes neither the SVD's
    // nonzero singular values and vectors nor the LQ's certificate).
    // Certified LQ (lqmode ≠ LQ_NONE): cv = L⁻¹ D b and Q (rows of V) or Z (rows of Kt, zmode);
    // rows the LQ skipped as redundant (residual at round-off level, certified below the cut) are
    // left out like vanished rows: r = lq.rank kept rows, lq.Ro[a] the live row of factor row a.
    // SVD: the kept right singular vectors V (r × n), cv_k = (u_kᵀ D b)/σ_k, and with many rows
    // and few degrees of freedom (zmode) the other right singular vectors in the rows of Kt.
    // with_w: in the null-space form of the certified LQ, also w = −(DA)⁺ D b into wv (the same
    // sweep over the reflectors as Z; w_done tells min_norm_w).
    int rank_decision(int m, int live, double rtol, const int* pst = nullptr, const int* pco = nullptr,
                      bool with_w = false) {
        lqmode = linalg::LQ_NONE;
        zmode = false;
        w_done = false;
        held = false;
        ++gen;
        if (pst) {  // the live rows, for the known pattern
            int c = 0;
            for (int i = 0; i < m; ++i)
                if (d[i] != 0.0) lrows[c++] = i;
        }
        if (live < m) {  // vanished rows are zero rows of D A: keep the live rows only (in order)
            const int ld = n + 1;
            int c = 0;
            for (int i = 0; i < m; ++i)
                if (d[i] != 0.0) {
                    if (c != i)
                        for (int k = 0; k <= n; ++k) B[c * ld + k] = B[i * ld + k];
                    ++c;
                }
            m = live;
        }
        m_live = m;
        if (m == 0) return 0;
        if (linalg::QR_MIN_ROWS <= m) {  // (m > n: at least m − n rows are skipped)
            bool zw = false;  // Z and w made with the dense factorization (lq_certified_z)
            if (m > linalg::DENSE_INVERSE_MAX_ROWS) {
                if (pst)
                    linalg::row_pattern_known(pst, pco, lrows.data(), m, n, lq.Ap.data());
                else
                    linalg::row_pattern(B.data(), m, n, n + 1, lq.Ap.data());
                lqmode = linalg::lq_sparse(B.data(), m, n, rtol, lq, cv.data());
            } else if (with_w) {  // (with Z and w when n − r ≤ r: one call, lanes in a batch)
                lqmode = linalg::lq_certified_z(B.data(), m, n, rtol, lq, cv.data(), Kt.data(), wv.data(), &zw);
            } else {
                lqmode = linalg::lq_certified(B.data(), m, n, rtol, lq, cv.data(), true, false);
            }
            if (lqmode != linalg::LQ_NONE) {
                const int r = lq.rank;
                zmode = n - r <= r;  // few degrees of freedom: the null-space basis Z
                if (zmode && with_w) {
                    if (!zw) linalg::lq_rows_min_norm(lq, r, n, r, n - r, Kt.data(), cv.data(), wv.data());
                    w_done = true;
                } else if (zmode)
                    linalg::lq_rows(lq, r, n, r, n - r, Kt.data());
                else
                    linalg::lq_rows(lq, r, n, 0, r, V.data());
                return r;
            }
        }
        if (m <= JACOBI_MAX_ROWS) {  // (T accumulates the rotations: Σ⁻¹Uᵀ for again())
            double* T = Tj.data();
            for (int i = 0; i < m; ++i)
                for (int c = 0; c < m; ++c) T[i * m + c] = i == c ? 1.0 : 0.0;
            linalg::jacobi_rows(B.data(), m, n, T);
            const int r = linalg::keep_rows(B.data(), m, n, rtol, V.data(), cv.data(), sig.data());
            const double cut = rtol * smax_of(m);
            int a = 0;
            for (int i = 0; i < m && a < r; ++i) {  // the kept rows, in keep_rows' order
                if (!(sig[i] > cut)) continue;
                const double inv = 1.0 / sig[i];
                for (int c = 0; c < m; ++c) Ui[a * m + c] = T[i * m + c] * inv;
                ++a;
            }
            return r;
        }
        const int ld = n + 1;
        auto Bm = big.topRows(m);
        for (int i = 0; i < m; ++i)
            for (int k = 0; k < n; ++k) Bm(i, k) = B[i * ld + k];
        svd.compute(Bm, Eigen::ComputeThinU | Eigen::ComputeFullV);
        const auto& s = svd.singularValues();
        const auto& U = svd.matrixU();
        const auto& Vs = svd.matrixV();
        const int p = static_cast<int>(s.size());
        const double smax = p > 0 ? s(0) : 0.0;
        int r = 0;
        for (int a = 0; a < p; ++a)
            if (s(a) > rtol * smax) ++r;
        for (int a = 0; a < r; ++a) {
            const double inv = 1.0 / s(a);
            for (int k = 0; k < n; ++k) V[a * n + k] = Vs(k, a);
            double t = 0.0;
            for (int c = 0; c < m; ++c) t += U(c, a) * B[c * ld + n];
            cv[a] = t * inv;
            for (int c = 0; c < m; ++c) Ui[a * m + c] = U(c, a) * inv;
        }
        zmode = n - r <= r;
        if (zmode)
            for (int a = 0; a < n - r; ++a)
                for (int k = 0; k < n; ++k) Kt[a * n + k] = Vs(k, r + a);
        return r;
    }

    // The null-space form's factorization: S = Z M Zᵀ (k × k, in G), μ, the Cholesky factor of S
    // (Ls) with the SPD test of the n × n M̄ = diag(μI, S) in the basis [Q; Z] (pivots of S
    // against max_i M̄_ii). Returns a linalg::CholStatus.
    // (Z, S, Lf: the basis read and the outputs, Kt, G and Ls when null)
    int null_factor(const double* M, bool diag, int k, double mu_in, double* mu_out,
                    double spd_rtol, double* ratio, const double* Z = nullptr, double* S = nullptr,
                    double* Lf = nullptr) {
        if (!Z) Z = Kt.data();
        if (!S) S = G.data();
        if (!Lf) Lf = Ls.data();
        double* ZM = Et.data();
        for (int a = 0; a < k; ++a) {  // ZM = Z M
            const double* Za = Z + static_cast<long>(a) * n;
            double* Ya = ZM + static_cast<long>(a) * n;
            if (diag) {
                for (int j = 0; j < n; ++j) Ya[j] = 0.0 + Za[j] * M[j * n + j];
                continue;
            }
            for (int j = 0; j < n; ++j) Ya[j] = 0.0;
            for (int i = 0; i < n; ++i) {
                const double c = Za[i];
                const double* Mi = M + static_cast<long>(i) * n;
                for (int j = 0; j < n; ++j) Ya[j] += c * Mi[j];
            }
        }
        double trs = 0.0;
        for (int a = 0; a < k; ++a) {
            for (int c = 0; c < k; ++c) {
                double s = 0.0;
                const double* Ya = ZM + static_cast<long>(a) * n;
                const double* Zc = Z + static_cast<long>(c) * n;
                for (int j = 0; j < n; ++j) s += Ya[j] * Zc[j];
                S[a * k + c] = s;
            }
            trs += S[a * k + a];
        }
        double mu;
        if (mu_in > 0.0) {
            mu = mu_in;
        } else {
            if (k > 0) {
                mu = trs / k;
            } else {  // r = n: tr(M)/n
                mu = 0.0;
                for (int i = 0; i < n; ++i) mu += M[i * n + i];
                mu /= n;
            }
            if (!(mu > 0.0)) mu = 1.0;
        }
        *mu_out = mu;
        // M̄_ii = μ (1 − ‖Z e_i‖²) + (Zᵀ S Z)_ii: the rows of S Z (Tt) and the sums over a
        // (pp, tt) element by element over i, each sum in the order of a one-i-at-a-time loop
        double* SZ = Tt.data();
        double* pp = cw.data();  // (cw, u: scratch until null_finish)
        double* tt = u.data();
        for (int a = 0; a < k; ++a) {
            double* Ya = SZ + static_cast<long>(a) * n;
            for (int i = 0; i < n; ++i) Ya[i] = 0.0;
            for (int c = 0; c < k; ++c) {
                const double sac = S[a * k + c];
                const double* Zc = Z + static_cast<long>(c) * n;
                for (int i = 0; i < n; ++i) Ya[i] += sac * Zc[i];
            }
        }
        for (int i = 0; i < n; ++i) pp[i] = tt[i] = 0.0;
        for (int a = 0; a < k; ++a) {
            const double* Za = Z + static_cast<long>(a) * n;
            const double* Ya = SZ + static_cast<long>(a) * n;
            for (int i = 0; i < n; ++i) {
                pp[i] += Za[i] * Za[i];
                tt[i] += Za[i] * Ya[i];
            }
        }
        double dmax = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < n; ++i) {
            const double dd = mu * (1.0 - pp[i]) + tt[i];
            if (dd > dmax) dmax = dd;
        }
        int st = linalg::CHOL_OK;
        double rt = std::numeric_limits<double>::infinity();
        double* L = Lf;
        for (int j = 0; j < k; ++j) {  // Cholesky of S
            double s = S[j * k + j];
            for (int c = 0; c < j; ++c) s -= L[j * k + c] * L[j * k + c];
            if (!(s > 0.0)) {
                *ratio = rt;
                return linalg::CHOL_FAIL;
            }
            if (s <= spd_rtol * dmax) {
                st = linalg::CHOL_SMALL_PIVOT;
                if (s / dmax < rt) rt = s / dmax;
            }
            const double ljj = std::sqrt(s);
            L[j * k + j] = ljj;
            for (int i = j + 1; i < k; ++i) {
                double t = S[i * k + j];
                for (int c = 0; c < j; ++c) t -= L[i * k + c] * L[j * k + c];
                L[i * k + j] = t / ljj;
            }
        }
        *ratio = rt;
        return st;
    }

    // out = w + Zᵀ S⁻¹ Z u (S = Ls Lsᵀ): the null-space form's q̈ (Z, L: Kt and Ls when null).
    void null_space_qdd(int k, const double* uu, const double* w, double* out, const double* Z = nullptr,
                        const double* L = nullptr) {
        if (!Z) Z = Kt.data();
        if (!L) L = Ls.data();
        double* y = cv.data();
        for (int a = 0; a < k; ++a) {
            double s = 0.0;
            const double* Za = Z + static_cast<long>(a) * n;
            for (int j = 0; j < n; ++j) s += Za[j] * uu[j];
            for (int c = 0; c < a; ++c) s -= L[a * k + c] * y[c];
            y[a] = s / L[a * k + a];
        }
        for (int a = k - 1; a >= 0; --a) {
            double s = y[a];
            for (int c = a + 1; c < k; ++c) s -= L[c * k + a] * y[c];
            y[a] = s / L[a * k + a];
        }
        for (int i = 0; i < n; ++i) out[i] = w[i];
        for (int a = 0; a < k; ++a) {
            const double c = y[a];
            const double* Za = Z + static_cast<long>(a) * n;
            for (int i = 0; i < n; ++i) out[i] += Za[i] * c;
        }
    }

    // q̈ = w + Zᵀ S⁻¹ Z (g − M w) and f_c = M q̈ − g with the factor of S held (Ls).
    void null_finish(const double* M, const double* gin, bool diag, int k, double* qdd, double* fc,
                     const double* Z = nullptr, const double* L = nullptr) {
        for (int i = 0; i < n; ++i) {
            g[i] = gin[i];
            u[i] = gin[i];
        }
        add_m_times(M, diag, wv.data(), -1.0, u.data());  // u = g − M w
        null_space_qdd(k, u.data(), wv.data(), qdd, Z, L);
        if (fc) {
            for (int i = 0; i < n; ++i) cw[i] = 0.0;
            add_m_times(M, diag, qdd, 1.0, cw.data());
            for (int i = 0; i < n; ++i) fc[i] = cw[i] - g[i];
        }
    }

    // Step 6 in the range form with M̄'s factor held (W, dinv): rhs = P(g − M w) + μ w,
    // q̈ = M̄⁻¹ rhs, f_c = M q̈ − g.
    void range_finish(const double* M, const double* gin, bool diag, int r, double mu, double* qdd,
                      double* fc) {
        for (int i = 0; i < n; ++i) {
            g[i] = gin[i];
            u[i] = gin[i];
        }
        add_m_times(M, diag, wv.data(), -1.0, u.data());  // u = g − M w
        for (int k = 0; k < r; ++k) {  // cv ← V u
            double s = 0.0;
            const double* Vk = V.data() + static_cast<long>(k) * n;
            for (int j = 0; j < n; ++j) s += Vk[j] * u[j];
            cv[k] = s;
        }
        for (int i = 0; i < n; ++i) u[i] += mu * wv[i];
        for (int k = 0; k < r; ++k) {
            const double ck = cv[k];
            const double* Vk = V.data() + static_cast<long>(k) * n;
            for (int i = 0; i < n; ++i) u[i] -= Vk[i] * ck;
        }
        linalg::cholesky_solve(W.data(), n, dinv.data(), u.data());
        for (int i = 0; i < n; ++i) qdd[i] = u[i];
        if (fc) {
            for (int i = 0; i < n; ++i) cw[i] = 0.0;
            add_m_times(M, diag, qdd, 1.0, cw.data());
            for (int i = 0; i < n; ++i) fc[i] = cw[i] - g[i];
        }
    }

    // w = −(DA)⁺ D γ from cv (r entries): −Qᵀ cv through the reflectors (null-space form of the
    // certified LQ), or −Σ_k v_k cv_k.
    void min_norm_w(int r) {
        if (w_done) {  // rank_decision's sweep made it (for this cv; again() computes anew)
            w_done = false;
            return;
        }
        if (zmode && lqmode != linalg::LQ_NONE) {
            linalg::lq_min_norm(lq, r, n, cv.data(), wv.data());
            return;
        }
        for (int j = 0; j < n; ++j) wv[j] = 0.0;
        for (int k = 0; k < r; ++k) {
            const double ck = cv[k];
            const double* Vk = V.data() + static_cast<long>(k) * n;
            for (int j = 0; j < n; ++j) wv[j] -= Vk[j] * ck;
        }
    }

    SolveInfo again(const double* M, const double* gin, const double* gamma, double* qdd, double* fc);
    SolveInfo near(const double* M, const double* gin, const double* A, int m, const double* gamma,
                   const SolveOptions& opt, bool same, double* qdd, double* fc);

    // cv = L⁻¹ b[Ro] over the r rows of the held certified LQ: lq_certified's substitution with
    // its L (LQ_INVERSE) or the solve over L's profile (LQ_PROFILE).
    void lq_lower_solve(const double* b, int r) {
        for (int i = 0; i < r; ++i) cv[i] = b[lq.Ro[i]];
        if (lqmode == linalg::LQ_INVERSE)
            linalg::lq_lower_subst(lq, r, cv.data());
        else
            linalg::lq_profile_solve(lq, r, cv.data());
    }

    // x = A_h⁺ b = (D A_h)⁺ D b through the held certified LQ of every row (near()).
    void near_pinv(const double* b, double* x) {
        const int r = h_r;
        double* db_ = db.data();
        for (int i = 0; i < r; ++i) db_[i] = d[i] * b[i];
        lq_lower_solve(db_, r);
        linalg::lq_min_norm(lq, r, n, cv.data(), x);
        for (int j = 0; j < n; ++j) x[j] = -x[j];
    }

    // Keep the factorization just made for again() (when the solve succeeded).
    void hold(const SolveInfo& info, int m, int r, bool diag) {
        held = info.status == Status::ok;
        h_m = m;
        h_r = r;
        h_diag = diag;
        h_mu = info.mu;
    }

    // M̄ = μI + Zᵀ(S − μI)Z (lower triangle of W) for the L output of the null-space form;
    // returns max_i M̄_ii.
    double mbar_from_s(int k, double mu) {
        const double* Z = Kt.data();
        const double* S = G.data();
        double* Y = Tt.data();
        for (int a = 0; a < k; ++a)  // Y = (S − μI) Z
            for (int j = 0; j < n; ++j) {
                double s = -mu * Z[a * n + j];
                for (int c = 0; c < k; ++c) s += S[a * k + c] * Z[c * n + j];
                Y[a * n + j] = s;
            }
        double dmax = -std::numeric_limits<double>::infinity();
        for (int i = 0; i < n; ++i) {
            for (int j = 0; j <= i; ++j) {
                double s = i == j ? mu : 0.0;
                for (int a = 0; a < k; ++a) s += Z[a * n + i] * Y[a * n + j];
                W[i * n + j] = s;
            }
            if (W[i * n + i] > dmax) dmax = W[i * n + i];
        }
        return dmax;
    }

    // out += sign · M x (M symmetric, row-major; diagonal M without the zero terms).
    void add_m_times(const double* M, bool diag, const double* x, double sign, double* out) const {
        if (diag) {
            for (int i = 0; i < n; ++i) out[i] += sign * (M[i * n + i] * x[i]);
            return;
        }
        for (int j = 0; j < n; ++j) {
            const double c = sign * x[j];
            const double* Mj = M + static_cast<long>(j) * n;
            for (int i = 0; i < n; ++i) out[i] += Mj[i] * c;
        }
    }

    SolveInfo solve(const double* M, const double* gin, const double* A, int m,
                    const double* gamma, const SolveOptions& opt, double* qdd, double* fc,
                    double* P, double* L, double* xmin);

    // Steps 4–6 in the null-space form (k = n − r ≤ r, Z in the rows of Kt, w in wv):
    // q̈ = w + Zᵀ S⁻¹ Z (g − M w), μ = tr S / k; M̄ and its factor only for the L output.
    SolveInfo solve_null(const double* M, const double* gin, bool diag, int k,
                         const SolveOptions& opt, double* qdd, double* fc, double* P, double* L,
                         SolveInfo info) {
        double mu = 0.0, ratio = 0.0;
        const int st = null_factor(M, diag, k, opt.mu, &mu, opt.spd_rtol, &ratio);
        info.mu = mu;
        if (st != linalg::CHOL_OK) {
            info.status = Status::not_positive_definite;
            info.chol_failed = st == linalg::CHOL_FAIL;
            info.pivot_ratio = st == linalg::CHOL_SMALL_PIVOT ? ratio : 0.0;
            return info;
        }
        null_finish(M, gin, diag, k, qdd, fc);
        if (P) {  // P = ZᵀZ
            const double* Z = Kt.data();
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < n; ++j) {
                    double s = 0.0;
                    for (int a = 0; a < k; ++a) s += Z[a * n + i] * Z[a * n + j];
                    P[i * n + j] = s;
                }
        }
        if (L) {
            const double dmax = mbar_from_s(k, mu);
            double rt = 0.0;
            linalg::cholesky_spd(W.data(), n, 0.0, dmax, dinv.data(), cw.data(), &rt);
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < n; ++j) L[i * n + j] = j <= i ? W[i * n + j] : 0.0;
        }
        return info;
    }
};

SolveInfo Solver::Impl::solve(const double* M, const double* gin, const double* A, int m,
                              const double* gamma, const SolveOptions& opt, double* qdd,
                              double* fc, double* P, double* L, double* xmin) {
    SolveInfo info;
    held = false;
    near_ok = near_last = false;
    h_rtol = opt.rtol;
    ++gen;
    if (m < 0 || m > m_max) {
        info.status = Status::bad_shape;
        return info;
    }
    const long nn = static_cast<long>(n) * n;
    // ------------------------------------------------------------------ 1. input checks
    // x·0 is 0 for finite x and NaN otherwise: the per-column sums are 0 iff all are finite.
    const bool m_valid = (opt.known & KNOWN_M_VALID) != 0;
    double* c = cw.data();
    for (int j = 0; j < n; ++j) c[j] = gin ? gin[j] * 0.0 : 0.0;
    if (M && !m_valid)
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) c[j] += M[i * n + j] * 0.0;
    const int* pst = opt.a_start;
    const int* pco = opt.a_cols;
    if (pst && pco) {  // a known pattern: the other entries are 0
        for (int i = 0; i < m; ++i)
            for (int t = pst[i]; t < pst[i + 1]; ++t) c[pco[t]] += A[static_cast<long>(i) * n + pco[t]] * 0.0;
    } else {
        pst = pco = nullptr;
        for (int i = 0; i < m; ++i)
            for (int j = 0; j < n; ++j) c[j] += A[static_cast<long>(i) * n + j] * 0.0;
    }
    bool bad = false;
    for (int j = 0; j < n; ++j) bad |= c[j] != 0.0;
    for (int i = 0; i < m; ++i) bad |= (gamma[i] - gamma[i]) != 0.0;
    if (bad) {
        info.status = Status::not_finite;
        return info;
    }
    bool diag = false;
    if (M) {
        double asym = 0.0, offd = 0.0;
        if (m_valid) {
            offd = (opt.known & KNOWN_M_DIAGONAL) ? 0.0 : 1.0;
        } else {
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < i; ++j) {
                    const double a = M[i * n + j], b = M[j * n + i];
                    const double dd = std::fabs(a - b);
                    if (dd > asym) asym = dd;
                    const double s = std::fabs(a) + std::fabs(b);
                    if (s > offd) offd = s;
                }
        }
        diag = offd == 0.0;
        if (asym > 0.0) {  // the decision of nonmin._validation.symmetric
            double scale = 0.0;
            for (long k = 0; k < nn; ++k) scale = std::max(scale, std::fabs(M[k]));
            if (asym > opt.sym_rtol * std::max(scale, TINY)) {
                info.status = Status::not_symmetric;
                return info;
            }
        }
    }
    // ------------------------------------------------------------------ 2.–3. rank policy
    const int live = pst ? linalg::equilibrate_pattern(A, m, n, pst, pco, gamma, opt.rtol, B.data(), d.data(),
                                                       sig.data(), b_zero)
                         : linalg::equilibrate(A, m, n, gamma, opt.rtol, B.data(), d.data(), sig.data());
    const int r = rank_decision(m, live, opt.rtol, pst, pco, true);
    // B back to zero over the pattern when the rank decision left its rows in place (no vanished
    // row compacted, no Jacobi rotation: the certified LQ and the SVD only read B); else the next
    // pattern call clears B in full
    b_zero = pst && live == m && (lqmode != linalg::LQ_NONE || m > JACOBI_MAX_ROWS);
    if (b_zero) {
        const int ld = n + 1;
        for (int i = 0; i < m; ++i) {
            double* Bi = B.data() + static_cast<long>(i) * ld;
            for (int t = pst[i]; t < pst[i + 1]; ++t) Bi[pco[t]] = 0.0;
            Bi[n] = 0.0;
        }
    }
    info.rank = r;
    info.method = lqmode;
    info.null_space_form = zmode;
    min_norm_w(r);  // w = −(DA)⁺ D γ
    if (xmin) {  // min_norm: x = (DA)⁺ D b
        for (int j = 0; j < n; ++j) xmin[j] = -wv[j];
        return info;
    }
    if (zmode) {
        info = solve_null(M, gin, diag, n - r, opt, qdd, fc, P, L, info);
        hold(info, m, r, diag);
        return info;
    }
    // ------------------------------------------------------------------ 4. PMP, μ, M̄
    // Q = VᵀV; Kt = V M, G = V M Vᵀ, Tt = G V: PMP = M − VᵀKt − KtᵀV + VᵀTt (rank-r updates).
    for (int k = 0; k < r; ++k) {
        const double* Vk = V.data() + static_cast<long>(k) * n;
        double* Kk = Kt.data() + static_cast<long>(k) * n;
        if (diag) {
            for (int j = 0; j < n; ++j) Kk[j] = 0.0 + Vk[j] * M[j * n + j];
            continue;
        }
        for (int j = 0; j < n; ++j) Kk[j] = 0.0;
        for (int i = 0; i < n; ++i) {
            const double a = Vk[i];
            const double* Mi = M + static_cast<long>(i) * n;
            for (int j = 0; j < n; ++j) Kk[j] += a * Mi[j];
        }
    }
    for (int k = 0; k < r; ++k)
        for (int l = 0; l < r; ++l) {
            double s = 0.0;
            const double* Vk = V.data() + static_cast<long>(k) * n;
            const double* Kl = Kt.data() + static_cast<long>(l) * n;
            for (int j = 0; j < n; ++j) s += Vk[j] * Kl[j];
            G[k * r + l] = s;
        }
    for (int l = 0; l < r; ++l) {
        double* Tl = Tt.data() + static_cast<long>(l) * n;
        for (int j = 0; j < n; ++j) Tl[j] = 0.0;
        for (int k = 0; k < r; ++k) {
            const double a = G[l * r + k];
            const double* Vk = V.data() + static_cast<long>(k) * n;
            for (int j = 0; j < n; ++j) Tl[j] += a * Vk[j];
        }
    }
    double tr_pmp = 0.0, tr_m = 0.0;
    for (int i = 0; i < n; ++i) {  // diag(PMP) = diag(M − QM − MQ + QMQ)
        double s = 0.0;
        for (int k = 0; k < r; ++k)
            s += (2.0 * Kt[k * n + i] - Tt[k * n + i]) * V[k * n + i];
        tr_pmp += M[i * n + i] - s;
        tr_m += M[i * n + i];
    }
    double mu;
    if (opt.mu > 0.0) {
        mu = opt.mu;
    } else {
        mu = r < n ? tr_pmp / (n - r) : tr_m / n;
        if (!(mu > 0.0)) mu = 1.0;
    }
    info.mu = mu;
    for (int k = 0; k < r; ++k)
        for (int j = 0; j < n; ++j) {
            Et[k * n + j] = Kt[k * n + j] - mu * V[k * n + j];
            Ft[k * n + j] = Kt[k * n + j] - Tt[k * n + j];
        }
    double dmax = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) {  // M̄ = M − Vᵀ Et − Ftᵀ V (lower triangle, row by row)
        double* Wi = W.data() + static_cast<long>(i) * n;
        for (int j = 0; j <= i; ++j) Wi[j] = M[i * n + j];
        for (int k = 0; k < r; ++k) {
            const double a = V[k * n + i], b = Ft[k * n + i];
            const double* Ek = Et.data() + static_cast<long>(k) * n;
            const double* Vk = V.data() + static_cast<long>(k) * n;
            for (int j = 0; j <= i; ++j) Wi[j] -= a * Ek[j] + b * Vk[j];
        }
        if (Wi[i] > dmax) dmax = Wi[i];
    }
    // ------------------------------------------------------------------ 5. Cholesky (rule 6)
    double ratio = 0.0;
    const int st = linalg::cholesky_spd(W.data(), n, opt.spd_rtol, dmax, dinv.data(), cw.data(),
                                        &ratio);
    if (st != linalg::CHOL_OK) {
        info.status = Status::not_positive_definite;
        info.chol_failed = st == linalg::CHOL_FAIL;
        info.pivot_ratio = st == linalg::CHOL_SMALL_PIVOT ? ratio : 0.0;
        return info;
    }
    // ------------------------------------------------------------------ 6. q̈, f_c
    range_finish(M, gin, diag, r, mu, qdd, fc);
    hold(info, m, r, diag);
    if (P) {
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) {
                double s = 0.0;
                for (int k = 0; k < r; ++k) s += V[k * n + i] * V[k * n + j];
                P[i * n + j] = (i == j ? 1.0 : 0.0) - s;
            }
    }
    if (L) {
        for (int i = 0; i < n; ++i)
            for (int j = 0; j < n; ++j) L[i * n + j] = j <= i ? W[i * n + j] : 0.0;
    }
    return info;
}

SolveInfo Solver::Impl::again(const double* M, const double* gin, const double* gamma, double* qdd,
                              double* fc) {
    SolveInfo info;
    near_last = false;
    if (!held) {
        info.status = Status::bad_shape;
        return info;
    }
    const int r = h_r;
    info.rank = r;
    info.mu = h_mu;
    info.method = lqmode;
    info.null_space_form = zmode;
    bool bad = false;  // (the checks of a fresh call on the new inputs; A and M are the held ones)
    for (int i = 0; i < n; ++i) bad |= gin[i] * 0.0 != 0.0;
    for (int i = 0; i < h_m; ++i) bad |= (gamma[i] - gamma[i]) != 0.0;
    if (bad) {
        info.status = Status::not_finite;
        return info;
    }
    // D γ over the live rows, compacted as the rank decision took them (equilibrate's d_i b_i)
    double* b = db.data();
    int c = 0;
    for (int i = 0; i < h_m; ++i)
        if (d[i] != 0.0) b[c++] = d[i] * gamma[i];
    const int ml = m_live;
    if (lqmode == linalg::LQ_INVERSE || lqmode == linalg::LQ_PROFILE) {  // cv = L⁻¹ (D γ)[Ro]
        lq_lower_solve(b, r);
    } else {  // cv = Σ⁻¹Uᵀ D γ over the kept rows
        for (int a = 0; a < r; ++a) {
            const double* Ua = Ui.data() + static_cast<long>(a) * ml;
            double s = 0.0;
            for (int k = 0; k < ml; ++k) s += Ua[k] * b[k];
            cv[a] = s;
        }
    }
    min_norm_w(r);
    if (zmode)
        null_finish(M, gin, h_diag, n - r, qdd, fc);
    else
        range_finish(M, gin, h_diag, r, h_mu, qdd, fc);
    return info;
}

// Passes of near() at most (each multiplies the residual by about ‖A − A_h‖ ‖A_h⁺‖; two
// suffice for a projection's corrections of ~1e-6): nonmin ≤ 0.1's core solve_near.
constexpr int NEAR_PASSES = 3;

SolveInfo Solver::Impl::near(const double* M, const double* gin, const double* A, int m, const double* gamma,
                             const SolveOptions& opt, bool same, double* qdd, double* fc) {
    SolveInfo info;
    info.status = Status::bad_shape;  // declined
    const bool reuse = same && near_ok;
    near_last = false;
    if (!held || !zmode || lqmode == linalg::LQ_NONE || m != h_m || m_live != m || h_r != m ||
        !(opt.rtol <= h_rtol) || !(opt.known & KNOWN_M_VALID) || !M || m == 0) {
        near_ok = false;
        return info;
    }
    const int k = n - m;
    const bool diag = (opt.known & KNOWN_M_DIAGONAL) != 0;
    const int* pst = opt.a_start;
    const int* pco = opt.a_cols;
    const bool pat = pst && pco;
    auto row_dot = [&](int i, const double* x, double s) {  // s + (A x)_i
        const double* Ai = A + static_cast<long>(i) * n;
        if (pat)
            for (int t = pst[i]; t < pst[i + 1]; ++t) s += Ai[pco[t]] * x[pco[t]];
        else
            for (int j = 0; j < n; ++j) s += Ai[j] * x[j];
        return s;
    };
    const double tol = 64.0 * std::numeric_limits<double>::epsilon();
    double* Z = Zn.data();
    double* res = nres.data();
    double* x = nx.data();
    if (!reuse) {  // the refined basis Z' from Z_h
        near_ok = false;
        for (long t = 0; t < static_cast<long>(k) * n; ++t) Z[t] = Kt[t];
        bool ok = false;
        for (int pass = 0; pass < NEAR_PASSES && !ok; ++pass) {
            for (int a = 0; a < k; ++a) {
                double* za = Z + static_cast<long>(a) * n;
                for (int i = 0; i < m; ++i) res[i] = row_dot(i, za, 0.0);
                near_pinv(res, x);
                for (int j = 0; j < n; ++j) za[j] -= x[j];
            }
            for (int a = 0; a < k; ++a) {  // Gram–Schmidt
                double* za = Z + static_cast<long>(a) * n;
                for (int c = 0; c < a; ++c) {
                    const double* zc = Z + static_cast<long>(c) * n;
                    double dd = 0.0;
                    for (int j = 0; j < n; ++j) dd += zc[j] * za[j];
                    for (int j = 0; j < n; ++j) za[j] -= dd * zc[j];
                }
                double nn = 0.0;
                for (int j = 0; j < n; ++j) nn += za[j] * za[j];
                const double inv = 1.0 / std::sqrt(nn);
                for (int j = 0; j < n; ++j) za[j] *= inv;
            }
            double big = 0.0;
            for (int a = 0; a < k; ++a)
                for (int i = 0; i < m; ++i)
                    big = std::max(big, std::fabs(row_dot(i, Z + static_cast<long>(a) * n, 0.0)) * d[i]);
            ok = big <= tol;  // (NaN: not)
        }
        if (!ok) return info;
    }
    // w: the minimum-norm solution of A w = −γ
    bool bad = false;
    for (int i = 0; i < n; ++i) bad |= gin[i] * 0.0 != 0.0;
    for (int i = 0; i < m; ++i) bad |= (gamma[i] - gamma[i]) != 0.0;
    if (bad) return info;  // (the fresh call reports it)
    double* w = wv.data();
    near_pinv(gamma, w);
    double gs = 0.0;
    for (int j = 0; j < n; ++j) w[j] = -w[j];
    for (int i = 0; i < m; ++i) gs = std::max(gs, std::fabs(gamma[i]) * d[i]);
    bool ok = false;
    for (int pass = 0; pass < NEAR_PASSES; ++pass) {
        double e = 0.0, wmax = 0.0;
        for (int i = 0; i < m; ++i) {
            res[i] = row_dot(i, w, gamma[i]);
            e = std::max(e, std::fabs(res[i]) * d[i]);
        }
        for (int j = 0; j < n; ++j) wmax = std::max(wmax, std::fabs(w[j]));
        if (e <= tol * (gs + wmax)) {
            ok = true;
            break;
        }
        near_pinv(res, x);
        for (int j = 0; j < n; ++j) w[j] -= x[j];
    }
    if (!ok) return info;
    for (int a = 0; a < k; ++a) {  // w ⟂ N(A)
        const double* za = Z + static_cast<long>(a) * n;
        double dd = 0.0;
        for (int j = 0; j < n; ++j) dd += za[j] * w[j];
        for (int j = 0; j < n; ++j) w[j] -= dd * za[j];
    }
    if (!reuse) {
        double mu = 0.0, ratio = 0.0;
        const int st = null_factor(M, diag, k, opt.mu, &mu, opt.spd_rtol, &ratio, Z, Gn.data(), Lsn.data());
        if (st != linalg::CHOL_OK) return info;  // (the fresh call reports it)
        near_mu = mu;
        near_k = k;
        near_ok = true;
    }
    null_finish(M, gin, diag, k, qdd, fc, Z, Lsn.data());
    near_last = true;
    info.status = Status::ok;
    info.rank = m;
    info.mu = near_mu;
    info.method = lqmode;
    info.null_space_form = true;
    return info;
}

Solver::Solver(int m_max, int n) {
    if (m_max < 0 || n < 1) throw EngineError("Solver: need m_max >= 0 and n >= 1");
    impl_ = std::make_unique<Impl>(m_max, n);
}
Solver::~Solver() = default;
Solver::Solver(Solver&&) noexcept = default;
Solver& Solver::operator=(Solver&&) noexcept = default;

int Solver::n() const { return impl_->n; }
int Solver::m_max() const { return impl_->m_max; }

SolveInfo Solver::forward(const double* M, const double* g, const double* A, int m,
                          const double* gamma, const SolveOptions& opt, double* qdd,
                          double* f_c) {
    return impl_->solve(M, g, A, m, gamma, opt, qdd, f_c, nullptr, nullptr, nullptr);
}

SolveInfo Solver::solve(const double* M, const double* g, const double* A, int m,
                        const double* gamma, const SolveOptions& opt, double* qdd, double* f_c,
                        double* P, double* L) {
    return impl_->solve(M, g, A, m, gamma, opt, qdd, f_c, P, L, nullptr);
}

int Solver::range_basis(const double* A, int m, double rtol, double* Vout) {
    Impl& s = *impl_;
    if (m < 0 || m > s.m_max) throw EngineError("Solver::range_basis: m > m_max");
    const int n = s.n;
    const int live = linalg::equilibrate(A, m, n, nullptr, rtol, s.B.data(), s.d.data(),
                                         s.sig.data());
    s.b_zero = false;
    const int r = s.rank_decision(m, live, rtol);
    if (s.zmode && s.lqmode != linalg::LQ_NONE)  // the decision kept Z: form Q
        linalg::lq_rows(s.lq, r, n, 0, r, s.V.data());
    for (long k = 0; k < static_cast<long>(r) * n; ++k) Vout[k] = s.V[k];
    return r;
}

SolveInfo Solver::again(const double* M, const double* g, const double* gamma, double* qdd,
                        double* f_c) {
    return impl_->again(M, g, gamma, qdd, f_c);
}

bool Solver::held() const { return impl_->held; }

SolveInfo Solver::near(const double* M, const double* g, const double* A, int m, const double* gamma,
                       const SolveOptions& opt, bool same, double* qdd, double* f_c) {
    return impl_->near(M, g, A, m, gamma, opt, same, qdd, f_c);
}

unsigned long long Solver::generation() const { return impl_->gen; }

double Solver::cond_mbar() {
    Impl& s = *impl_;
    if (!s.held || !s.zmode) return std::numeric_limits<double>::quiet_NaN();
    const int k = s.near_last ? s.near_k : s.n - s.h_r;
    const double mu = s.near_last ? s.near_mu : s.h_mu;
    const double* G = s.near_last ? s.Gn.data() : s.G.data();  // S of the last solve
    if (k <= 0) return 1.0;
    double lo, hi;
    if (k == 1) {
        lo = hi = G[0];
    } else {  // eigenvalues of the symmetric part of S (k × k) on a copy
        double* X = s.Tt.data();
        for (int a = 0; a < k; ++a)
            for (int c = 0; c < k; ++c) X[a * k + c] = 0.5 * (G[a * k + c] + G[c * k + a]);
        linalg::sym_eigenvalues(X, k, s.cw.data());
        lo = hi = s.cw[0];
        for (int a = 1; a < k; ++a) {
            lo = std::min(lo, s.cw[a]);
            hi = std::max(hi, s.cw[a]);
        }
    }
    return std::max(mu, hi) / std::min(mu, lo);
}

bool Solver::mbar_factor(double* L) const {
    const Impl& s = *impl_;
    if (!s.held || s.zmode) return false;
    const int n = s.n;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) L[i * n + j] = j <= i ? s.W[i * n + j] : 0.0;
    return true;
}

SolveInfo Solver::min_norm(const double* A, int m, const double* b, double rtol, double* x) {
    SolveOptions opt;
    opt.rtol = rtol;
    return impl_->solve(nullptr, nullptr, A, m, b, opt, nullptr, nullptr, nullptr, nullptr, x);
}

}  // namespace nonmin
