// The certified LQ factorization of the row-equilibrated constraint matrix (linalg.hpp): the
// shortcut of the rank rule that needs no SVD when full rank is proved.
#include <algorithm>
#include <cmath>

#include "nonmin/linalg.hpp"
#include "lanes.hpp"

#pragma GCC diagnostic ignored "-Wpsabi"  // the lanes' vectors: inlined into their target functions

#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace nonmin::linalg {

LQWork::LQWork(int m_max_, int n_) : m_max(m_max_), n(n_) {
    const std::size_t m = static_cast<std::size_t>(std::max(m_max_, 1));
    const std::size_t nn = static_cast<std::size_t>(n_);
    Wq.assign(m * nn, 0.0);
    Hv.assign(m * nn, 0.0);
    beta.assign(m, 0.0);
    rp.assign(m, 0.0);
    Li.assign(m * m, 0.0);
    key.assign(m, 0.0);
    Hx.assign(m * (nn + 1), 0);
    Lf.assign(m, 0);
    Ro.assign(m, 0);
    Pc.assign(nn, 0);
    Lr.assign(nn, 0);
    order.assign(m, 0);
    Kr.assign(m, 0);
    Cs.assign(m, 0.0);
    if (m_max_ > DENSE_INVERSE_MAX_ROWS) {  // lq_sparse's scratch (many rows only)
        G.assign(m * m, 0.0);
        Rl.assign(m * (nn + 1), 0);
        In.assign(m * nn, 0);
        Wz.assign(m * nn, 0.0);
        Ap.assign(m * (nn + 1), 0);
    }
}

void row_pattern(const double* A, int m, int n, int lda, int* Ap) {
    for (int i = 0; i < m; ++i) {
        int* P = Ap + static_cast<long>(i) * (n + 1);
        const double* Ai = A + static_cast<long>(i) * lda;
        int c = 0;
        for (int k = 0; k < n; ++k)
            if (Ai[k] != 0.0) P[1 + c++] = k;
        P[0] = c;
    }
}

void row_pattern_known(const int* start, const int* cols, const int* rows, int m, int n, int* Ap) {
    for (int i = 0; i < m; ++i) {
        int* P = Ap + static_cast<long>(i) * (n + 1);
        const int r = rows[i];
        const int e = start[r + 1] - start[r];
        P[0] = e;
        for (int t = 0; t < e; ++t) P[1 + t] = cols[start[r] + t];
    }
}

// cv ← L⁻¹ cv by forward substitution over L's row profile (Li holds L, row i from Lf[i]).
void lq_profile_solve(const LQWork& w, int m, double* cv) {
    const int ld = w.m_max;
    for (int i = 0; i < m; ++i) {
        double s = cv[i];
        const double* Li = w.Li.data() + static_cast<long>(i) * ld;
        for (int k = w.Lf[i]; k < i; ++k) s -= Li[k] * cv[k];
        cv[i] = s / Li[i];
    }
}

void lq_lower_subst(const LQWork& w, int m, double* cv) {
    const int n = w.n;
    const double* Wq = w.Wq.data();
    for (int i = 0; i < m; ++i) {
        const double* Wi = Wq + static_cast<long>(i) * n;
        double s = cv[i];
        for (int k = 0; k < i; ++k) s -= Wi[k] * cv[k];
        cv[i] = s * w.rp[i];
    }
}

namespace {

// Row X (its entries at the reflector's cnt columns Hc, increasing) times the reflector
// I − β v vᵀ; returns whether the row changed. TestZero = false skips the test d = 0 (a row the
// reflector does not touch: X − 0·v, the same values; for the dense path, where that branch is
// mispredicted). The callers pass the reflector's storage as locals (see reflect).
template <bool TestZero>
inline bool reflect_row_at(double* X, const int* Hc, const double* v, int cnt, double bj) {
    double d = 0.0;
    for (int t = 0; t < cnt; ++t) d += X[Hc[t]] * v[Hc[t]];
    if constexpr (TestZero) {
        if (d == 0.0) return false;
    }
    d *= bj;
    for (int t = 0; t < cnt; ++t) X[Hc[t]] -= d * v[Hc[t]];
    return true;
}

// Row i of X (leading dimension n) times reflector j (its columns Hx[j], its vector Hv[j]).
inline bool reflect_row(double* X, const LQWork& w, int j, double bj) {
    const int n = w.n;
    const int* H = w.Hx.data() + static_cast<long>(j) * (n + 1);
    return reflect_row_at<true>(X, H + 1, w.Hv.data() + static_cast<long>(j) * n, H[0], bj);
}

// Add a reflector's cnt columns Hc to a row's column list R ([count, columns…]) and its byte
// marks (lq_sparse).
inline void merge_columns(int* R, std::uint8_t* mark, const int* Hc, int cnt) {
    int rc = R[0];
    for (int t = 0; t < cnt; ++t) {
        const int k = Hc[t];
        if (!mark[k]) {
            mark[k] = 1;
            R[1 + rc++] = k;
        }
    }
    R[0] = rc;
}

// Finish reflector j (pivot p, x0 its entry, s the sum of squares over its columns) of row `row`
// of the work matrix X (Wq or Wz) and apply it to rows row+1 … imax. Returns false for an
// all-zero row. (The reflector's columns, vector and the column lists' storage are held in
// locals: the column lists' byte marks could alias w's members, which the compiler otherwise
// reloads for every row.)
bool reflect(double* X, LQWork& w, int j, int row, int p, double x0, double s, int imax, bool track) {
    const int n = w.n;
    int* H = w.Hx.data() + static_cast<long>(j) * (n + 1);
    double* v = w.Hv.data() + static_cast<long>(j) * n;
    const int cnt = H[0];
    if (s == 0.0) return false;
    const double nrm = std::sqrt(s);
    const double alpha = x0 >= 0.0 ? -nrm : nrm;
    const double v0 = x0 - alpha;
    v[p] = v0;
    const double bj = 2.0 / (s - x0 * x0 + v0 * v0);
    w.beta[j] = bj;
    double* Xj = X + static_cast<long>(row) * n;
    Xj[p] = alpha;
    for (int t = 2; t <= cnt; ++t) Xj[H[t]] = 0.0;
    const int* Hc = H + 1;
    if (track) {
        int* Rl = w.Rl.data();
        std::uint8_t* In = w.In.data();
        for (int i = row + 1; i <= imax; ++i)
            if (reflect_row_at<true>(X + static_cast<long>(i) * n, Hc, v, cnt, bj))
                merge_columns(Rl + static_cast<long>(i) * (n + 1), In + static_cast<long>(i) * n, Hc, cnt);
    } else {
        for (int i = row + 1; i <= imax; ++i) reflect_row_at<false>(X + static_cast<long>(i) * n, Hc, v, cnt, bj);
    }
    for (int t = 1; t <= cnt; ++t)  // those rows may now be nonzero in all its columns
        if (imax > w.Lr[H[t]]) w.Lr[H[t]] = imax;
    return true;
}

// Pc: the reflectors' pivot columns in order, then the other columns (Lr is scratch); W is
// LQWork or the lanes' workspace (the same integer bookkeeping).
template <class W>
void pivot_order(W& w, int m, int n) {
    for (int i = 0; i < m; ++i) {
        const int p = w.Hx[static_cast<long>(i) * (n + 1) + 1];
        w.Pc[i] = p;
        w.Lr[p] = -2;
    }
    int c = m;
    for (int k = 0; k < n; ++k)
        if (w.Lr[k] != -2) w.Pc[c++] = k;
}


// The skipped rows' part of the certificate (docs/theory.md, rule 3). With X = D A in the
// basis of the reflectors, X = [L₁₁ 0; L₂₁ E] (kept rows, then the skipped ones); the rows of E
// are the skipped rows' residuals against every kept row, each ≤ its residual ρ against the
// rows kept before it, so ‖E‖₂ ≤ eF = √Σρ². Weyl: σ_{r+1}(X) ≤ eF and σ_r(X) ≥ σ_min(L₁₁) − eF;
// σ_max(X) ≥ max_a ‖L_a‖ (a kept row) and σ_max(X)² ≤ ‖L₁₁‖² + ‖[L₂₁ E]‖_F² = ‖L₁₁‖² + Σ‖x_s‖².
// True when margin · eF < rtol · max_a ‖L_a‖ (row2max = max_a ‖L_a‖²): then σ_{r+1}(X) is
// below the SVD rule's cut by the certificate's margin; the caller proves
// σ_min(L₁₁) > rt · σ_max(X) + eF.
// Whether work row j of X (residual sum of squares s after the r reflectors so far) is redundant
// to round-off in [D A | D b]: s ≤ (tol · (1 + ‖c‖₁))² with c L = its entries at the pivot
// columns (L: the kept rows, factor row a at work row Kr[a]), and its bias consistent with that
// combination, |b_j − Σ c_a b_a| ≤ REDUNDANT_BIAS_RTOL · (|b_j| + Σ|c_a b_a|) (an inconsistent
// bias gets the SVD's least-squares solution instead). Only for s ≤ REDUNDANT_CANDIDATE².
// The bias of work row i is B[Ro[i]·(n + 1) + n].
bool redundant_row(const double* X, LQWork& w, int r, int j, const double* B, double s, double tol) {
    if (!(s <= REDUNDANT_CANDIDATE * REDUNDANT_CANDIDATE)) return false;
    const int n = w.n;
    const long ldb = n + 1;
    const double* x = X + static_cast<long>(j) * n;
    double* c = w.Cs.data();
    double c1 = 0.0;
    for (int b = r - 1; b >= 0; --b) {  // back substitution over L's columns
        const int pb = w.Hx[static_cast<long>(b) * (n + 1) + 1];
        double t = x[pb];
        for (int a = b + 1; a < r; ++a) t -= c[a] * X[static_cast<long>(w.Kr[a]) * n + pb];
        c[b] = t / X[static_cast<long>(w.Kr[b]) * n + pb];
        c1 += std::fabs(c[b]);
    }
    const double d = tol * (1.0 + c1);
    if (!(s <= d * d)) return false;
    const double bj = B[w.Ro[j] * ldb + n];
    double bc = 0.0, bs = std::fabs(bj);
    for (int a = 0; a < r; ++a) {
        const double t = c[a] * B[w.Ro[w.Kr[a]] * ldb + n];
        bc += t;
        bs += std::fabs(t);
    }
    return std::fabs(bj - bc) <= REDUNDANT_BIAS_RTOL * bs;
}

bool skipped_rows_small(const LQWork& w, double rtol, double margin, double row2max) {
    return margin * std::sqrt(w.skip_f2) < rtol * std::sqrt(row2max);
}

// The profile certificate of lq_sparse: Cholesky of T − τI, T = L Lᵀ, over L's row profile.
int certify_profile(const double* B, int m, int n, double rtol, LQWork& w, double* cv) {
    const int ld = w.m_max;
    double* Li = w.Li.data();
    double* G = w.G.data();
    const double* Wz = w.Wz.data();
    for (int i = 0; i < m; ++i)  // L (columns in the pivot order Pc) over its row profile
        for (int c = w.Lf[i]; c <= i; ++c)
            Li[i * ld + c] = Wz[static_cast<long>(w.Kr[i]) * n + w.Pc[c]];
    for (int i = 0; i < m; ++i) cv[i] = 0.0;
    for (int i = 0; i < m; ++i) {  // T = L Lᵀ over the profile, |T| row sums
        const int fi = w.Lf[i];
        const double* Lii = Li + static_cast<long>(i) * ld;
        double* Gi = G + static_cast<long>(i) * ld;
        double ci = 0.0;  // cv[i]: 0 until row i (later rows add to it), so summed here in order
        for (int j = fi; j < i; ++j) {
            const double* Lj = Li + static_cast<long>(j) * ld;
            double s = 0.0;
            for (int k = std::max(fi, w.Lf[j]); k <= j; ++k) s += Lii[k] * Lj[k];
            Gi[j] = s;
            const double a = std::fabs(s);
            ci += a;
            cv[j] += a;
        }
        double s = 0.0;
        for (int k = fi; k <= i; ++k) s += Lii[k] * Lii[k];
        Gi[i] = s;
        cv[i] = ci + std::fabs(s);
    }
    double tnorm = 0.0;
    for (int i = 0; i < m; ++i) tnorm = std::max(tnorm, cv[i]);
    const double rt = CERT_SLACK * std::max(rtol, CERT_FLOOR);
    double tau = rt * rt * tnorm;
    if (w.skipped > 0) {  // the skipped rows: σ_min(L₁₁) > rt · σ_max(X) + eF
        double row2max = 0.0;
        for (int i = 0; i < m; ++i) row2max = std::max(row2max, G[static_cast<long>(i) * ld + i]);
        if (!skipped_rows_small(w, rtol, CERT_SLACK, row2max)) return LQ_NONE;
        const double sq = rt * std::sqrt(tnorm + w.skip_n2) + std::sqrt(w.skip_f2);
        tau = sq * sq;
    }
    for (int i = 0; i < m; ++i) {  // Cholesky of T − τI, row by row over the profile
        const int fi = w.Lf[i];
        double* Gi = G + static_cast<long>(i) * ld;
        for (int j = fi; j < i; ++j) {
            const double* Gj = G + static_cast<long>(j) * ld;
            double s = Gi[j];
            for (int k = std::max(fi, w.Lf[j]); k < j; ++k) s -= Gi[k] * Gj[k];
            Gi[j] = s / Gj[j];
        }
        double s = Gi[i] - tau;
        for (int k = fi; k < i; ++k) s -= Gi[k] * Gi[k];
        if (!(s > 0.0)) return LQ_NONE;
        Gi[i] = std::sqrt(s);
    }
    for (int i = 0; i < m; ++i) cv[i] = B[static_cast<long>(w.Ro[i]) * (n + 1) + n];
    lq_profile_solve(w, m, cv);
    w.rank = m;
    return LQ_PROFILE;
}

}  // namespace

namespace {

// The lanes' decisions (lanes.hpp): one bool for a scalar run. For W runs in lock step, lane 0's
// value, and in `acc` (the mask type, zero at the start) the lanes that differ from lane 0: the
// evaluation goes on with lane 0's decisions (indices stay valid) and is abandoned at its end
// when diverged(acc).
#define NONMIN_INLINE __attribute__((always_inline)) inline
NONMIN_INLINE bool decide(bool b, bool&) { return b; }
template <class M>
NONMIN_INLINE bool decide(const M& mask, M& acc) {
    acc |= mask ^ (M{} + mask[0]);
    return mask[0] != 0;
}
NONMIN_INLINE bool diverged(bool) { return false; }
template <class M>
NONMIN_INLINE bool diverged(const M& acc) {
    bool any = false;
    for (int l = 1; l < static_cast<int>(sizeof(M) / sizeof(acc[0])); ++l) any = any || acc[l] != 0;
    return any;
}
NONMIN_INLINE double vsqrt(double x) { return std::sqrt(x); }
NONMIN_INLINE double vabs(double x) { return std::fabs(x); }
NONMIN_INLINE double vmax(double a, double b) { return std::max(a, b); }
template <class S, std::size_t... I>
NONMIN_INLINE S vsqrt_(const S& x, std::index_sequence<I...>) {
    return S{std::sqrt(x[I])...};
}
template <class S>
NONMIN_INLINE S vsqrt(const S& x) {  // std::sqrt per lane (correctly rounded: the same result)
    return vsqrt_(x, std::make_index_sequence<sizeof(S) / sizeof(double)>{});
}
// lane l of the result: p[l][e] (the lanes built in registers, not through memory)
template <class S, std::size_t... I>
NONMIN_INLINE S gather_(const double* const* p, long e, std::index_sequence<I...>) {
    return S{p[I][e]...};
}
template <class S>
NONMIN_INLINE S gather(const double* const* p, long e) {
    return gather_<S>(p, e, std::make_index_sequence<sizeof(S) / sizeof(double)>{});
}
template <class S, std::size_t... I>
NONMIN_INLINE S load_(const double* a, std::index_sequence<I...>) {
    return S{a[I]...};
}
template <class S>
NONMIN_INLINE S load(const double* a) {  // lane l: a[l]
    return load_<S>(a, std::make_index_sequence<sizeof(S) / sizeof(double)>{});
}
template <class S>
NONMIN_INLINE S vmax(const S& a, const S& b) {
    return a < b ? b : a;  // std::max(a, b) per lane
}
template <class S>
NONMIN_INLINE S vabs(const S& x) {  // std::fabs per lane: the sign bit cleared
    using I = decltype(x < x);
    return (S)((I)x & 0x7fffffffffffffffLL);
}
template <class S>
NONMIN_INLINE S bc(double x) {  // x in every lane
    return S{} + x;
}
template <class S>
constexpr bool is_lane = !std::is_same_v<S, double>;

// Storage for the lanes' vectors at their alignment (the default allocator aligns to 16 bytes
// where AVX is not enabled, and the AVX code loads 32-byte vectors with aligned moves).
template <class T>
struct AlignedAlloc {
    using value_type = T;
    AlignedAlloc() = default;
    template <class U>
    AlignedAlloc(const AlignedAlloc<U>&) {}
    T* allocate(std::size_t k) {
        return static_cast<T*>(::operator new(k * sizeof(T), std::align_val_t(sizeof(T) < 32 ? 16 : 32)));
    }
    void deallocate(T* p, std::size_t) { ::operator delete(p, std::align_val_t(sizeof(T) < 32 ? 16 : 32)); }
    bool operator==(const AlignedAlloc&) const { return true; }
    bool operator!=(const AlignedAlloc&) const { return false; }
};
template <class T>
using AVec = std::vector<T, AlignedAlloc<T>>;

// The certified LQ's work arrays on the scalar S (LQWork for double; LaneLQ for W lanes).
template <class S>
struct LaneLQ {
    int m_max = 0, n = 0;
    AVec<S> Wq, Hv, beta, rp, Li, Cs;
    std::vector<int> Hx, Ro, Pc, Lr, Kr;
    int rank = 0, skipped = 0;
    void size(int m_max_, int n_) {
        if (m_max == m_max_ && n == n_) return;
        m_max = m_max_;
        n = n_;
        const std::size_t m = static_cast<std::size_t>(std::max(m_max_, 1)), nn = static_cast<std::size_t>(n_);
        Wq.assign(m * nn, S{});
        Hv.assign(m * nn, S{});
        beta.assign(m, S{});
        rp.assign(m, S{});
        Li.assign(m * m, S{});
        Cs.assign(m, S{});
        Hx.assign(m * (nn + 1), 0);
        Ro.assign(m, 0);
        Pc.assign(nn, 0);
        Lr.assign(nn, 0);
        Kr.assign(m, 0);
    }
};

// lq_rows_min_norm on the scalar S (double: the kernel; W lanes: each lane's operations its
// scalar call's, a row the reflector does not touch (d = 0) kept as it is, lane by lane).
template <class S, class Wk>
NONMIN_INLINE void lq_rows_min_norm_t(const Wk& w, int m, int n, int first, int count, S* E, const S* cv, S* x) {
    for (int i = 0; i < count; ++i) {
        S* Ei = E + static_cast<long>(i) * n;
        for (int k = 0; k < n; ++k) Ei[k] = S{};
        Ei[w.Pc[first + i]] = bc<S>(1.0);
    }
    for (int i = 0; i < n; ++i) x[i] = S{};
    for (int i = 0; i < m; ++i) x[w.Pc[i]] = cv[i];
    for (int j = m - 1; j >= 0; --j) {  // independent chains side by side (lq_rows, lq_min_norm)
        const S bj = w.beta[j];
        const int* H = w.Hx.data() + static_cast<long>(j) * (n + 1);
        const S* v = w.Hv.data() + static_cast<long>(j) * n;
        const int cnt = H[0];
        for (int i = 0; i < count; ++i) {  // reflect_row
            S* X = E + static_cast<long>(i) * n;
            S d = S{};
            for (int t = 1; t <= cnt; ++t) d += X[H[t]] * v[H[t]];
            if constexpr (is_lane<S>) {
                const auto keep = d == 0.0;
                const S db = d * bj;
                for (int t = 1; t <= cnt; ++t) {
                    const S nx = X[H[t]] - db * v[H[t]];
                    X[H[t]] = keep ? X[H[t]] : nx;
                }
            } else {
                if (d == 0.0) continue;
                d *= bj;
                for (int t = 1; t <= cnt; ++t) X[H[t]] -= d * v[H[t]];
            }
        }
        S d = S{};
        for (int t = 1; t <= cnt; ++t) d += v[H[t]] * x[H[t]];
        d *= bj;
        for (int t = 1; t <= cnt; ++t) x[H[t]] -= d * v[H[t]];
    }
    for (int i = 0; i < n; ++i) x[i] = -x[i];
}

// lq_certified (linalg.hpp) on the scalar S: S = double is the engine's kernel; S = W doubles
// evaluates W calls of one shape in lock step, every lane's operations those of its scalar call
// (lanes.hpp), and returns LQ_DIVERGED where their decisions differ or where the scalar kernel
// leaves the common path (a row skipped or a residual candidate for it, a certificate not proved
// by the bound, L⁻¹ asked for): those calls are made by the scalar kernel.
template <class S, class Wk>
NONMIN_INLINE int lq_certified_t(const S* B, int m, int n, S rtol, Wk& w, S* cv, bool skip_redundant, bool inverse) {
    constexpr bool lane = is_lane<S>;
    std::conditional_t<lane, decltype(S{} < S{}), bool> div{};  // (lanes: those off lane 0's decisions)
    if constexpr (lane) {
        if (inverse) return LQ_DIVERGED;
    }
    const int ld = w.m_max;
    S* Wq = w.Wq.data();
    for (int k = 0; k < n; ++k) {
        w.Pc[k] = 0;  // 1 once pivoted
        w.Lr[k] = -1;
    }
    for (int i = 0; i < m; ++i) {
        w.Ro[i] = i;
        const S* Bi = B + static_cast<long>(i) * (n + 1);
        S* Wi = Wq + static_cast<long>(i) * n;
        for (int k = 0; k < n; ++k) {
            const S x = Bi[k];
            Wi[k] = x;
            const int last = w.Lr[k];
            w.Lr[k] = decide(x != 0.0, div) ? i : last;  // (a select, not a branch: the pattern is irregular)
        }
    }
    // a row whose residual is at round-off level is skipped (skip_redundant; else never)
    const double tol = redundant_row_tol(m, n);
    w.skipped = 0;
    if constexpr (!lane) {
        w.skip_f2 = 0.0;
        w.skip_n2 = 0.0;
    }
    int r = 0;  // reflectors so far: reflector r pivots on column r
    for (int j = 0; j < m; ++j) {
        const int p = r;
        S* Wj = Wq + static_cast<long>(j) * n;
        S s = S{};
        if (p < n) {
            S* v = w.Hv.data() + static_cast<long>(r) * n;
            int* H = w.Hx.data() + static_cast<long>(r) * (n + 1);
            const S x0 = Wj[p];
            s = x0 * x0;
            v[p] = x0;
            H[1] = p;
            int cnt = 1;
            int imax = w.Lr[p];
            for (int k = p + 1; k < n; ++k) {  // (columns after r are not pivoted yet)
                const S x = Wj[k];
                v[k] = x;
                if (decide(x != 0.0, div)) {
                    s += x * x;
                    H[1 + cnt++] = k;
                    if (w.Lr[k] > imax) imax = w.Lr[k];
                }
            }
            H[0] = cnt;
            if constexpr (lane) {
                // a candidate for a redundant row, or an all-zero row: the scalar kernel's
                if ((skip_redundant && decide(s <= REDUNDANT_CANDIDATE * REDUNDANT_CANDIDATE, div)) ||
                    decide(s == 0.0, div))
                    return LQ_DIVERGED;
                w.Pc[p] = 1;
                // reflect(): reflector r of work row j, applied to rows j+1 … imax
                const S nrm = vsqrt(s);
                const S alpha = x0 >= 0.0 ? -nrm : nrm;
                const S v0 = x0 - alpha;
                v[p] = v0;
                const S bj = 2.0 / (s - x0 * x0 + v0 * v0);
                w.beta[r] = bj;
                Wj[p] = alpha;
                for (int t = 2; t <= cnt; ++t) Wj[H[t]] = S{};
                for (int i = j + 1; i <= imax; ++i) {  // reflect_row_at<false>
                    S* X = Wq + static_cast<long>(i) * n;
                    S d = S{};
                    for (int t = 1; t <= cnt; ++t) d += X[H[t]] * v[H[t]];
                    d *= bj;
                    for (int t = 1; t <= cnt; ++t) X[H[t]] -= d * v[H[t]];
                }
                for (int t = 1; t <= cnt; ++t)
                    if (imax > w.Lr[H[t]]) w.Lr[H[t]] = imax;
                w.Kr[r++] = j;
                continue;
            } else {
                if (!skip_redundant || !redundant_row(Wq, w, r, j, B, s, tol)) {
                    w.Pc[p] = 1;
                    if (!reflect(Wq, w, r, j, p, x0, s, imax, false)) return LQ_NONE;
                    w.Kr[r++] = j;
                    continue;
                }
            }
        } else if constexpr (lane) {
            return LQ_DIVERGED;
        } else if (!skip_redundant || !redundant_row(Wq, w, r, j, B, 0.0, tol)) {
            return LQ_NONE;
        }
        if constexpr (!lane) {
            ++w.skipped;  // every column pivoted (s = 0), or a residual at round-off level
            w.skip_f2 += s;
            const double* Bj = B + static_cast<long>(j) * (n + 1);
            for (int k = 0; k < n; ++k) w.skip_n2 += Bj[k] * Bj[k];
        }
    }
    for (int a = 0; a < r; ++a) {  // the kept rows' L entries (columns 0 … a) to rows 0 … r − 1
        const int src = w.Kr[a];
        w.Ro[a] = src;
        if (src != a)
            for (int k = 0; k <= a; ++k) Wq[a * n + k] = Wq[static_cast<long>(src) * n + k];
    }
    m = r;
    pivot_order(w, m, n);  // Pc: the reflectors' pivot columns in order, then the others
    S fl = S{}, row2max = S{};  // ‖L‖_F², max_a ‖L_a‖²
    for (int i = 0; i < m; ++i) {
        S ri = S{};
        for (int k = 0; k <= i; ++k) {
            const S x2 = Wq[i * n + k] * Wq[i * n + k];
            fl += x2;
            ri += x2;
        }
        row2max = vmax(row2max, ri);
    }
    // reciprocal pivots: independent divisions, off the substitutions' dependency chains
    for (int i = 0; i < m; ++i) w.rp[i] = 1.0 / Wq[i * n + i];
    const S margin = [&]() __attribute__((always_inline)) {
        if constexpr (lane)
            return S(rtol <= QR_MARGIN_RTOL ? bc<S>(QR_MARGIN) : bc<S>(1.0));  // per lane, its rtol's
        else
            return rtol <= QR_MARGIN_RTOL ? QR_MARGIN : 1.0;
    }();
    if constexpr (!lane) {
        if (w.skipped > 0 && !skipped_rows_small(w, rtol, margin, row2max)) return LQ_NONE;
    }
    // The certificate with f2 ≥ ‖L⁻¹‖_F²: without skipped rows ‖L‖_F ‖L⁻¹‖_F · margin · rtol < 1;
    // with them σ_min(L₁₁) ≥ 1/‖L⁻¹‖_F > margin · rtol · √(‖L‖_F² + Σ‖x_s‖²) + eF
    auto certifies = [&](const S& f2) __attribute__((always_inline)) {
        if constexpr (lane) {
            return decide(vsqrt(fl) * vsqrt(f2) * margin * rtol < 1.0, div);
        } else {
            if (w.skipped == 0) return std::sqrt(fl) * std::sqrt(f2) * margin * rtol < 1.0;
            const double bound = margin * rtol * std::sqrt(fl + w.skip_n2) + std::sqrt(w.skip_f2);
            return bound * std::sqrt(f2) < 1.0;
        }
    };
    bool proved = false;
    if (!inverse) {
        // ‖L⁻¹‖_F² ≤ ‖C⁻¹ 1‖₂², C = L's comparison matrix (|L_ii| on the diagonal, −|L_ik|
        // below): |L⁻¹| ≤ C⁻¹ entrywise (Higham, Thm 8.12) and C⁻¹ ≥ 0, so each row's sum of
        // squares is at most its sum squared. One substitution (m²/2) instead of L⁻¹ (m³/6); the
        // exact norm below only when the bound does not prove the rank (near a singular
        // configuration): the decision is the exact test's. (1 + 1e-12: the bound's round-off.)
        S* x = w.Cs.data();
        S fb = S{};
        for (int i = 0; i < m; ++i) {
            const S* Wi = Wq + static_cast<long>(i) * n;
            S s = bc<S>(1.0);
            for (int k = 0; k < i; ++k) s += vabs(Wi[k]) * x[k];
            x[i] = s * vabs(w.rp[i]);
            fb += x[i] * x[i];
        }
        proved = certifies(fb * (1.0 + 1e-12));
    }
    if constexpr (lane) {
        if (diverged(div) || !proved) return LQ_DIVERGED;  // (inverse: returned above)
    } else {
        double* Li = w.Li.data();
        if (!proved) {
            // L⁻¹ row by row: row i = (e_i − Σ_{k<i} L_ik · row k) / L_ii (zero L_ik skipped)
            double f0 = 0.0, f1 = 0.0;
            for (int i = 0; i < m; ++i) {
                double* Ri = Li + static_cast<long>(i) * ld;
                for (int c = 0; c < i; ++c) Ri[c] = 0.0;
                Ri[i] = 1.0;
                for (int k = 0; k < i; ++k) {
                    const double a = Wq[i * n + k];
                    if (a != 0.0) {
                        const double* Rk = Li + static_cast<long>(k) * ld;
                        for (int c = 0; c <= k; ++c) Ri[c] -= a * Rk[c];
                    }
                }
                const double r = w.rp[i];
                for (int c = 0; c <= i; ++c) Ri[c] *= r;
                const int i2 = (i + 1) - (i + 1) % 2;  // ‖L⁻¹‖_F²: two interleaved partial sums
                for (int c = 0; c < i2; c += 2) {
                    f0 += Ri[c] * Ri[c];
                    f1 += Ri[c + 1] * Ri[c + 1];
                }
                if (i2 <= i) f0 += Ri[i] * Ri[i];
            }
            if (!certifies(f0 + f1)) return LQ_NONE;
        }
        if (inverse) {
            for (int i = 0; i < m; ++i) {  // cv = L⁻¹ (D b)[Ro]
                const double* Ri = Li + static_cast<long>(i) * ld;
                double s = 0.0;
                for (int k = 0; k <= i; ++k) s += Ri[k] * B[static_cast<long>(w.Ro[k]) * (n + 1) + n];
                cv[i] = s;
            }
            w.rank = m;
            return LQ_INVERSE;
        }
    }
    // cv = L⁻¹ (D b)[Ro] by substitution (lq_lower_subst)
    for (int i = 0; i < m; ++i) cv[i] = B[static_cast<long>(w.Ro[i]) * (n + 1) + n];
    for (int i = 0; i < m; ++i) {
        const S* Wi = Wq + static_cast<long>(i) * n;
        S s = cv[i];
        for (int k = 0; k < i; ++k) s -= Wi[k] * cv[k];
        cv[i] = s * w.rp[i];
    }
    w.rank = m;
    return LQ_INVERSE;
}

}  // namespace

int lq_certified(const double* B, int m, int n, double rtol, LQWork& w, double* cv, bool skip_redundant,
                 bool inverse) {
    if (lanes::maybe_in_fiber()) return lq_certified_parked(B, m, n, rtol, w, cv, skip_redundant, inverse);
    return lq_certified_scalar(B, m, n, rtol, w, cv, skip_redundant, inverse);
}

int lq_certified_scalar(const double* B, int m, int n, double rtol, LQWork& w, double* cv, bool skip_redundant,
                        bool inverse) {
    return lq_certified_t<double>(B, m, n, rtol, w, cv, skip_redundant, inverse);
}

int lq_certified_z_scalar(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                          bool* z) {
    const int res = lq_certified_scalar(B, m, n, rtol, w, cv, true, false);
    *z = res == LQ_INVERSE && n - w.rank <= w.rank;
    if (*z) lq_rows_min_norm(w, w.rank, n, w.rank, n - w.rank, E, cv, x);
    return res;
}

int lq_certified_z(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                   bool* z) {
    if (lanes::maybe_in_fiber()) return lq_certified_z_parked(B, m, n, rtol, w, cv, E, x, z);
    return lq_certified_z_scalar(B, m, n, rtol, w, cv, E, x, z);
}

namespace {

// W calls in the lanes of S: gathered, evaluated by lq_certified_t<S>, each lane's outputs (the
// entries its scalar call writes) scattered to its scratch and cv.
template <int W, class S>
__attribute__((always_inline)) inline int lq_lanes(const double* const* B, int m, int n, const double* rtol,
                                                   LQWork* const* w, double* const* cv, bool skip_redundant,
                                                   bool inverse, double* const* E, double* const* x, bool* z) {
    struct Scratch {
        LaneLQ<S> L;
        AVec<S> Bl, cl, E;
    };
    thread_local Scratch tls;
    Scratch& X = tls;  // (one look-up of the thread's scratch)
    LaneLQ<S>& L = X.L;
    AVec<S>& Bl = X.Bl;
    AVec<S>& cl = X.cl;
    L.size(w[0]->m_max, n);
    const int ld = n + 1;
    if (static_cast<int>(Bl.size()) < m * ld) Bl.resize(static_cast<std::size_t>(m * ld));
    if (static_cast<int>(cl.size()) < m) cl.resize(static_cast<std::size_t>(m));
    for (int e = 0; e < m * ld; ++e) Bl[static_cast<std::size_t>(e)] = gather<S>(B, e);
    const S rl = load<S>(rtol);
    const int res = lq_certified_t<S>(Bl.data(), m, n, rl, L, cl.data(), skip_redundant, inverse);
    if (res != LQ_INVERSE) return LQ_DIVERGED;
    const int r = L.rank;
    const int k = n - r;
    const bool zdo = E != nullptr && k <= r;  // the null-space basis and w in the same lanes
    if (z) *z = zdo;
    if (zdo) {
        if (static_cast<int>(X.E.size()) < k * n + n) X.E.resize(static_cast<std::size_t>(k * n + n));
        lq_rows_min_norm_t<S>(L, r, n, r, k, X.E.data(), cl.data(), X.E.data() + k * n);
    }
    for (int l = 0; l < W; ++l) {
        LQWork& o = *w[l];
        for (int j = 0; j < r; ++j) {  // reflector j's [count, columns…]
            const int* H = L.Hx.data() + static_cast<long>(j) * (n + 1);
            std::copy(H, H + 1 + H[0], o.Hx.data() + static_cast<long>(j) * (n + 1));
        }
        std::copy(L.Ro.begin(), L.Ro.begin() + m, o.Ro.begin());
        std::copy(L.Kr.begin(), L.Kr.begin() + r, o.Kr.begin());
        std::copy(L.Pc.begin(), L.Pc.begin() + n, o.Pc.begin());
        std::copy(L.Lr.begin(), L.Lr.begin() + n, o.Lr.begin());
        for (int e = 0; e < m * n; ++e) o.Wq[static_cast<std::size_t>(e)] = L.Wq[static_cast<std::size_t>(e)][l];
        for (int j = 0; j < r; ++j) {  // reflector j's vector: columns j … n − 1 written
            const S* v = L.Hv.data() + static_cast<long>(j) * n;
            double* vo = o.Hv.data() + static_cast<long>(j) * n;
            for (int k = j; k < n; ++k) vo[k] = v[k][l];
            o.beta[static_cast<std::size_t>(j)] = L.beta[static_cast<std::size_t>(j)][l];
            o.rp[static_cast<std::size_t>(j)] = L.rp[static_cast<std::size_t>(j)][l];
            o.Cs[static_cast<std::size_t>(j)] = L.Cs[static_cast<std::size_t>(j)][l];
            cv[l][j] = cl[static_cast<std::size_t>(j)][l];
        }
        if (zdo) {
            for (int e = 0; e < k * n; ++e) E[l][e] = X.E[static_cast<std::size_t>(e)][l];
            for (int j = 0; j < n; ++j) x[l][j] = X.E[static_cast<std::size_t>(k * n + j)][l];
        }
        o.rank = r;
        o.skipped = 0;
        o.skip_f2 = 0.0;
        o.skip_n2 = 0.0;
    }
    return LQ_INVERSE;
}

typedef double lane4 __attribute__((vector_size(32)));
typedef double lane2 __attribute__((vector_size(16)));

}  // namespace

__attribute__((target("avx2"))) int lq_certified_lanes4(const double* const* B, int m, int n, const double* rtol,
                                                         LQWork* const* w, double* const* cv, bool skip_redundant,
                                                         bool inverse, double* const* E, double* const* x, bool* z) {
    return lq_lanes<4, lane4>(B, m, n, rtol, w, cv, skip_redundant, inverse, E, x, z);
}

int lq_certified_lanes2(const double* const* B, int m, int n, const double* rtol, LQWork* const* w, double* const* cv,
                        bool skip_redundant, bool inverse, double* const* E, double* const* x, bool* z) {
    return lq_lanes<2, lane2>(B, m, n, rtol, w, cv, skip_redundant, inverse, E, x, z);
}

int lq_sparse(const double* B, int m, int n, double rtol, LQWork& w, double* cv) {
    const long ldp = n + 1;
    for (int i = 0; i < m; ++i) {  // rows by their first nonzero column (a stable sort)
        int f = n - 1;
        const int* P = w.Ap.data() + i * ldp;
        for (int t = 0; t < P[0]; ++t)
            if (B[i * ldp + P[1 + t]] != 0.0) {
                f = P[1 + t];
                break;
            }
        w.key[i] = static_cast<double>(f) * m + i;
    }
    // The keys are distinct, so the sorted order is unique: insertion sort from the last call's
    // order (the rows' first columns rarely change: O(m)), std::sort when it moves too much
    bool sorted = false;
    if (w.order_m == m) {
        long moves = 0;
        const long budget = 4L * m;
        for (int a = 1; a < m && moves <= budget; ++a) {
            const int r = w.order[a];
            const double kr = w.key[r];
            int b = a;
            while (b > 0 && w.key[w.order[b - 1]] > kr) {
                w.order[b] = w.order[b - 1];
                --b;
                ++moves;
            }
            w.order[b] = r;
        }
        sorted = moves <= budget;
    }
    if (!sorted) {
        for (int i = 0; i < m; ++i) w.order[i] = i;
        std::sort(w.order.begin(), w.order.begin() + m,
                  [&](int a, int b) { return w.key[a] < w.key[b]; });
        w.order_m = m;
    }
    for (int k = 0; k < n; ++k) {
        w.Pc[k] = 0;
        w.Lr[k] = -1;
    }
    double* Wz = w.Wz.data();
    {  // (w's storage in locals: the byte marks' stores could alias w's members)
        std::uint8_t* In = w.In.data();
        int* Lr = w.Lr.data();
        int* Rl = w.Rl.data();
        const int* Ap = w.Ap.data();
        for (int i = 0; i < m; ++i) {  // the rows in that order, with their column lists
            const int src = w.order[i];
            w.Ro[i] = src;
            const int* P = Ap + src * ldp;
            int* R = Rl + i * ldp;
            const int e = P[0];
            int c = 0;
            for (int t = 0; t < e; ++t) {
                const int k = P[1 + t];
                const double x = B[src * ldp + k];
                if (x != 0.0) {
                    Wz[static_cast<long>(i) * n + k] = x;
                    In[static_cast<long>(i) * n + k] = 1;
                    R[1 + c++] = k;
                    Lr[k] = i;
                }
            }
            R[0] = c;
        }
    }
    int res = LQ_NONE;
    bool ok = true;
    const double tol = redundant_row_tol(m, n);  // a residual at round-off level: skipped
    w.skipped = 0;
    w.skip_f2 = 0.0;
    w.skip_n2 = 0.0;
    int r = 0;  // reflectors so far (factor rows kept)
    for (int j = 0; j < m; ++j) {  // j: the work row
        const int* R = w.Rl.data() + j * ldp;
        double* Wj = Wz + static_cast<long>(j) * n;
        double* v = w.Hv.data() + static_cast<long>(r) * n;
        int* H = w.Hx.data() + r * ldp;
        const int c = R[0];
        // the unpivoted nonzero columns, increasing (one pass, insertion into H[1…]): the
        // pivot is the first of them, H[1]
        int cnt = 0;
        for (int t = 0; t < c; ++t) {
            const int k = R[1 + t];
            if (w.Pc[k] == 0 && Wj[k] != 0.0) {
                int a = 1 + cnt;
                while (a > 1 && H[a - 1] > k) {
                    H[a] = H[a - 1];
                    --a;
                }
                H[a] = k;
                ++cnt;
            }
        }
        const int p = cnt > 0 ? H[1] : -1;
        double s = 0.0;
        if (p >= 0) {
            const double x0 = Wj[p];
            for (int t = 1; t <= cnt; ++t) v[H[t]] = Wj[H[t]];
            w.Pc[p] = 1;
            s = x0 * x0;
            int imax = w.Lr[p];
            for (int t = 2; t <= cnt; ++t) {
                const double x = v[H[t]];
                s += x * x;
                if (w.Lr[H[t]] > imax) imax = w.Lr[H[t]];
            }
            H[0] = cnt;
            if (!redundant_row(Wz, w, r, j, B, s, tol)) {
                if (!reflect(Wz, w, r, j, p, x0, s, imax, true)) {
                    ok = false;
                    break;
                }
                w.Kr[r++] = j;
                continue;
            }
            w.Pc[p] = 0;
        } else if (!redundant_row(Wz, w, r, j, B, 0.0, tol)) {  // (no residual: the bias decides)
            ok = false;
            break;
        }
        ++w.skipped;  // no residual left, or one at round-off level: a redundant row
        w.skip_f2 += s;
        const int src = w.Ro[j];
        const int* P = w.Ap.data() + src * ldp;
        for (int t = 0; t < P[0]; ++t) {
            const double x = B[src * ldp + P[1 + t]];
            w.skip_n2 += x * x;
        }
    }
    if (ok && r > 0) {
        for (int a = 0; a < r; ++a) w.Ro[a] = w.Ro[w.Kr[a]];  // (Kr[a] ≥ a: in place)
        pivot_order(w, r, n);
        for (int c = 0; c < n; ++c) w.Lr[w.Pc[c]] = c;  // a column's position in that order
        for (int a = 0; a < r; ++a) {  // L's row profile: its first nonzero column
            int f = a;
            const int i = w.Kr[a];
            const int* R = w.Rl.data() + i * ldp;
            for (int t = 0; t < R[0]; ++t) {
                const int k = R[1 + t];
                if (w.Lr[k] < f && Wz[static_cast<long>(i) * n + k] != 0.0) f = w.Lr[k];
            }
            w.Lf[a] = f;
        }
        res = certify_profile(B, r, n, rtol, w, cv);
    }
    {
        std::uint8_t* In = w.In.data();
        const int* Rl = w.Rl.data();
        for (int i = 0; i < m; ++i) {  // Wz and In back to zero
            const int* R = Rl + i * ldp;
            const int e = R[0];
            for (int t = 0; t < e; ++t) {
                Wz[static_cast<long>(i) * n + R[1 + t]] = 0.0;
                In[static_cast<long>(i) * n + R[1 + t]] = 0;
            }
        }
    }
    return res;
}

void lq_rows(const LQWork& w, int m, int n, int first, int count, double* E) {
    for (int i = 0; i < count; ++i) {
        double* Ei = E + static_cast<long>(i) * n;
        for (int k = 0; k < n; ++k) Ei[k] = 0.0;
        Ei[w.Pc[first + i]] = 1.0;
    }
    for (int j = m - 1; j >= 0; --j)
        for (int i = 0; i < count; ++i) reflect_row(E + static_cast<long>(i) * n, w, j, w.beta[j]);
}

void lq_rows_min_norm(const LQWork& w, int m, int n, int first, int count, double* E,
                      const double* cv, double* x) {
    lq_rows_min_norm_t<double>(w, m, n, first, count, E, cv, x);
}

void lq_min_norm(const LQWork& w, int m, int n, const double* cv, double* x) {
    for (int i = 0; i < n; ++i) x[i] = 0.0;
    for (int i = 0; i < m; ++i) x[w.Pc[i]] = cv[i];
    for (int j = m - 1; j >= 0; --j) {
        const int* H = w.Hx.data() + static_cast<long>(j) * (n + 1);
        const double* v = w.Hv.data() + static_cast<long>(j) * n;
        double d = 0.0;
        for (int t = 1; t <= H[0]; ++t) d += v[H[t]] * x[H[t]];
        d *= w.beta[j];
        for (int t = 1; t <= H[0]; ++t) x[H[t]] -= d * v[H[t]];
    }
    for (int i = 0; i < n; ++i) x[i] = -x[i];
}

}  // namespace nonmin::linalg
