// The core layer's linear algebra: the rank tolerance policy of docs/theory.md ("Rank tolerance
// policy") on raw row-major buffers, and the SPD factorization with its pivot test. Free
// functions over caller-owned scratch (no allocation); the Solver (solver.hpp) strings them
// together. Specified by nonmin.core.linalg (range_basis, cholesky).
#pragma once
#include <cstdint>
#include <vector>

namespace nonmin::linalg {

// nonmin.core.DEFAULT_RTOL, SPD_RTOL and nonmin._validation.SYMMETRY_RTOL.
inline constexpr double DEFAULT_RTOL = 1e-10;
inline constexpr double SPD_RTOL = 1e-13;
inline constexpr double SYMMETRY_RTOL = 1e-9;

// Outcome of cholesky_spd (rule 6).
enum CholStatus : int { CHOL_OK = 0, CHOL_FAIL = 1, CHOL_SMALL_PIVOT = 2 };

// Sums of squares outside [ROW_NORM_SMALL, ROW_NORM_BIG] are recomputed scaled by row_norm
// (nonmin.core.linalg.row_norms: the plain formula over- or underflows near 1e±308).
inline constexpr double ROW_NORM_BIG = 1e300;
inline constexpr double ROW_NORM_SMALL = 1e-290;

// ‖x[:n]‖₂: four interleaved partial sums in a fixed order; a sum of squares outside
// [ROW_NORM_SMALL, ROW_NORM_BIG] is recomputed as s‖x/s‖ with s = max|x_k| (so a row above
// ~1e154 keeps a finite norm; NaN stays NaN, an infinite entry gives a non-finite norm).
double row_norm(const double* x, int n);

// Rules 1–2 (row equilibration). For A (m × n, row-major, leading dimension lda): rows with
// ‖a_i‖ ≤ rtol · max_i ‖a_i‖ vanished (d_i = 0, row of B zero), the others are scaled to unit
// length (d_i = 1/‖a_i‖). Writes B (m × (n + 1), leading dimension n + 1) = [D A | D b] (b may be
// null: last column zero), d (m) and the row norms (m). Returns the number of live rows. A is
// finite (the caller checks); norms by row_norm (no overflow), as nonmin.core.linalg.row_norms.
int equilibrate(const double* A, int m, int n, const double* b, double rtol, double* B, double* d,
                double* norms);

// row_norm over the entries cols[0 … e−1] (sorted) of x, the others 0: bitwise row_norm(x, n)
// (each entry goes to the partial sum row_norm gives it; adding a zero square changes no sum).
double row_norm_pattern(const double* x, int n, const int* cols, int e);

// equilibrate for an A whose row i is 0 outside the columns cols[start[i]] … cols[start[i+1]−1]
// (a RowPattern of A's m rows, program.hpp): reads only those entries, writes the same B, d and
// norms bitwise. b_zero: B is all zero on entry (the caller keeps it so between calls), so only the
// pattern's entries and the last column are written instead of every row in full.
int equilibrate_pattern(const double* A, int m, int n, const int* start, const int* cols,
                        const double* b, double rtol, double* B, double* d, double* norms,
                        bool b_zero = false);

// Rule 3 for few rows: one-sided (Hestenes) Jacobi SVD of the rows of B (m × (n + 1),
// augmented: the rotations act on the last column too). At convergence the rows are mutually
// orthogonal in their first n entries: their norms are the singular values of D A and their
// directions the right singular vectors; the last column holds Uᵀ D b. Rows whose squared norm
// is ≤ eps² ‖B‖_F² are round-off (e.g. the difference of duplicated rows) and not rotated.
// T (m × m, may be null) accumulates the rotation (T ← R T), for warm starts.
void jacobi_rows(double* B, int m, int n, double* T);

// The cyclic one-sided Jacobi behind jacobi_rows and the engine's SVD (svd.cpp), on the k rows
// of X (leading dimension ld): a pair whose first len entries are not orthogonal to
// |x·y| ≤ tol ‖x‖‖y‖ is rotated over its first rot ≥ len entries (the rest ride along, e.g. an
// augmented right-hand side). Rows of squared norm ≤ eps² ‖X[:, :len]‖_F² are round-off and not
// rotated. T (k × k, may be null) accumulates the rotations (T ← R T). At most 60 sweeps.
void jacobi_orthogonalize(double* X, int k, int ld, int len, int rot, double tol, double* T);

// The SVD rule on the rows left by jacobi_rows: σ_i = ‖B[i, :n]‖, kept if σ_i > rtol · σ_max.
// Writes the kept unit rows into V (r × n, leading dimension n), cv_k = (u_kᵀ D b)/σ_k and
// sig (m, the row norms). Returns r.
int keep_rows(const double* B, int m, int n, double rtol, double* V, double* cv, double* sig);

// Rule 6: in-place Cholesky factor of the lower triangle of W (n × n, row-major), right-looking,
// reciprocal pivots into dinv, cw (n) scratch. CHOL_FAIL if a pivot ≤ 0 (stops there),
// CHOL_SMALL_PIVOT if L_jj² ≤ spd_rtol · dmax (continues; *ratio = smallest L_jj²/dmax).
int cholesky_spd(double* W, int n, double spd_rtol, double dmax, double* dinv, double* cw,
                 double* ratio);

// Eigenvalues of the symmetric k × k X (row-major, destroyed) into ev (k), by cyclic Jacobi
// rotations to round-off (off-diagonal mass ≤ eps² of the total).
void sym_eigenvalues(double* X, int k, double* ev);

// Solve L Lᵀ x = b in place (x = b on entry), L the lower triangle of W with reciprocal pivots
// dinv (as cholesky_spd leaves them).
void cholesky_solve(const double* W, int n, const double* dinv, double* x);

// ---------------------------------------------------------------------------- certified LQ
// The shortcut of rule 3 (docs/theory.md, "Compiled backend shortcut"): when every row is live
// and m ≤ n, D A = L Q by Householder reflections from the right (Q with orthonormal rows). If
// the factorization *proves* that the SVD rule keeps all m rows, Q spans R(Aᵀ), the rank is m
// and (DA)⁺ D b = Qᵀ L⁻¹ D b: the SVD's projector and minimum-norm solution at a fraction of its
// cost. Every product skips exact zero terms only (A is sparse in absolute coordinates), so the
// results are those of the dense loops.

// What an lq_* call proved: nothing (the SVD decides), full rank with the dense L⁻¹ in Li (few
// rows), full rank with L over its row profile in Li (many rows).
enum LQResult : int { LQ_NONE = 0, LQ_INVERSE = 1, LQ_PROFILE = 2 };

// Up to this many rows: dense L⁻¹ and the Frobenius certificate ‖L‖_F ‖L⁻¹‖_F · margin · rtol
// < 1 (margin QR_MARGIN for rtol ≤ QR_MARGIN_RTOL, else 1); above: lq_sparse.
inline constexpr int DENSE_INVERSE_MAX_ROWS = 32;
inline constexpr double QR_MARGIN = 10.0;
inline constexpr double QR_MARGIN_RTOL = 1e-6;
// The profile certificate: Cholesky of L Lᵀ − τI, τ = (CERT_SLACK · max(rtol, CERT_FLOOR))² ‖L Lᵀ‖∞.
inline constexpr double CERT_FLOOR = 1e-5;
inline constexpr double CERT_SLACK = 1.01;
// Rank-revealing rows (docs/theory.md, rule 3): a row whose residual ρ after the reflectors of the
// rows kept before it is ≤ REDUNDANT_CANDIDATE and ≤ redundant_row_tol(m, n) · (1 + ‖c‖₁), c the
// row's combination of the kept rows (c L = its L part), is skipped: the round-off of an exactly
// dependent unit row, whose Householder backward error per row is ≤ γ̃_{mn} ≈ m n u (Higham
// Thm 19.4, taken as m n eps) for it and for each kept row it combines. The certificate then
// also bounds the skipped rows' residuals (eF = √Σρ²: margin · eF < rtol · σ_max's lower bound)
// and proves σ_min(L₁₁) > rt · σ_max + eF.
inline double redundant_row_tol(int m, int n) {
    return static_cast<double>(m) * static_cast<double>(n) * 2.220446049250313e-16;
}
inline constexpr double REDUNDANT_CANDIDATE = 1e-8;
// A skipped row's bias must be the same combination of the kept rows' biases to this relative
// accuracy (else the SVD's least-squares solution of the inconsistent system is taken).
inline constexpr double REDUNDANT_BIAS_RTOL = 1e-10;
// The certified LQ is tried from this many live rows on. (The numba kernels used 4: there the
// Jacobi SVD of 1–3 rows was as cheap; in C++ the LQ of a few rows costs a fraction of it.)
inline constexpr int QR_MIN_ROWS = 1;

// Scratch of the certified LQ for up to m_max rows and n columns (allocated once).
struct LQWork {
    int m_max = 0, n = 0;
    std::vector<double> Wq;     // m × n: the rows being reduced; L in its lower part
    std::vector<double> Hv;     // m × n: reflector j's vector at its columns
    std::vector<double> beta;   // m: reflector j's 2/‖v‖²
    std::vector<double> rp;     // m: 1/L_aa, L's reciprocal pivots (lq_certified)
    std::vector<double> Li;     // m × m: L⁻¹ (LQ_INVERSE) or L over its profile (LQ_PROFILE)
    std::vector<double> G;      // m × m: the factor of L Lᵀ − τI (profile certificate)
    std::vector<double> key;    // m: row sort keys (lq_sparse)
    std::vector<int> Hx;        // m × (n + 1): [count, columns…] of reflector j (pivot first)
    std::vector<int> Lf;        // m: first column of L's row i (profile)
    std::vector<int> Ro;        // m: the row of B of factor row a (lq_sparse: by first column)
    std::vector<int> Pc;        // n: pivot columns in order, then the others
    std::vector<int> Lr;        // n: last row that may be nonzero in column k (scratch)
    std::vector<int> Rl;        // m × (n + 1): [count, columns…] where row i may be nonzero
    std::vector<int> order;     // m: the row sort (lq_sparse keeps it for the next call)
    int order_m = -1;           // rows of the order kept in `order` (−1: none)
    std::vector<std::uint8_t> In;  // m × n: membership marks of Rl (zero between calls)
    std::vector<double> Wz;     // m × n: lq_sparse's work matrix (zero between calls)
    std::vector<int> Ap;        // m × (n + 1): the row pattern of A (lq_sparse's input)
    std::vector<int> Kr;        // m: the work-matrix row of factor row a (rows kept, in order)
    std::vector<double> Cs;     // m: a candidate row's combination of the kept rows (scratch)
    int rank = 0;               // factor rows kept (m when no row was skipped)
    int skipped = 0;            // rows skipped as redundant (residual ≤ redundant_row_tol)
    double skip_f2 = 0.0;       // Σ of their squared residual norms (eF²)
    double skip_n2 = 0.0;       // Σ of their squared norms (‖x_s‖², 1 each up to round-off)

    LQWork() = default;
    LQWork(int m_max, int n);
};

// The row pattern of A (m × n, leading dimension lda): Ap[i] = [count, columns with a nonzero
// entry (NaN counts)…] (Ap: m × (n + 1)).
void row_pattern(const double* A, int m, int n, int lda, int* Ap);
// The same from a known pattern (start, cols as equilibrate_pattern) of the rows rows[0 … m−1]
// of A: a superset of the nonzeros, which lq_sparse filters by value (the same result).
void row_pattern_known(const int* start, const int* cols, const int* rows, int m, int n, int* Ap);

// Few rows (m ≤ DENSE_INVERSE_MAX_ROWS, every row of B = [D A | D b] live; m ≤ n unless
// skip_redundant): reflector j pivots on column j. With skip_redundant, rows at round-off distance
// from the span of the rows kept before them are skipped (w.rank rows kept, w.Ro[a] the row of
// B of factor row a); without, w.rank = m. On LQ_INVERSE: cv = L⁻¹ (D b)[Ro] (w.rank), the
// reflectors in w, L in the rows of w.Wq (factor row a: columns 0 … a). inverse: L⁻¹ in w.Li
// (dense, m³/6) and cv its product with (D b)[Ro]; without, the certificate is first tried with
// a bound on ‖L⁻¹‖_F from one substitution (core_lq.cpp; the exact norm only when the bound does
// not prove it: the same decision), w.Li is not written and cv comes from lq_lower_subst.
int lq_certified(const double* B, int m, int n, double rtol, LQWork& w, double* cv,
                 bool skip_redundant = false, bool inverse = true);

// The rank decision's dense step in one call: lq_certified(B, m, n, rtol, w, cv, true, false)
// and, when it returns LQ_INVERSE with r = w.rank and n − r ≤ r, lq_rows_min_norm(w, r, n, r,
// n − r, E, cv, x) (*z = true; else *z = false, E and x untouched). Bitwise the two calls; in a
// batch's lanes (engine/src/lanes.hpp) one parked call.
int lq_certified_z(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                   bool* z);

// cv ← L⁻¹ cv by forward substitution with the L that lq_certified left in w.Wq (m rows) and
// its reciprocal pivots w.rp.
void lq_lower_subst(const LQWork& w, int m, double* cv);

// Many rows: rows taken in the order of their first nonzero column (w.Ro), reflector j pivots on
// row j's first column not pivoted yet, row column lists track fill-in; B is read over w.Ap
// (row_pattern of A, set by the caller). Rows at round-off distance from the span of the rows
// kept before them are skipped (w.rank rows kept; w.Ro[a] the row of B of factor row a).
// Certificate: Cholesky of L Lᵀ − τI over L's row profile, with the skipped rows' bound.
// On LQ_PROFILE: cv = L⁻¹ (D b)[Ro] (w.rank).
int lq_sparse(const double* B, int m, int n, double rtol, LQWork& w, double* cv);

// Rows first … first + count − 1 of the orthogonal H_{m−1} ⋯ H_0 into E (count × n): rows
// 0 … m − 1 are Q (a basis of R(Aᵀ)), rows m … n − 1 an orthonormal basis Z of N(A).
void lq_rows(const LQWork& w, int m, int n, int first, int count, double* E);

// cv ← L⁻¹ cv over L's row profile (as lq_sparse left it: LQ_PROFILE).
void lq_profile_solve(const LQWork& w, int m, double* cv);

// x = −Qᵀ cv (= −(DA)⁺ D b for cv = L⁻¹ D b), through the reflectors.
void lq_min_norm(const LQWork& w, int m, int n, const double* cv, double* x);

// lq_rows(w, m, n, first, count, E) and lq_min_norm(w, m, n, cv, x) in one sweep over the
// reflectors (the same operations on each vector: results bitwise those of the two calls).
void lq_rows_min_norm(const LQWork& w, int m, int n, int first, int count, double* E,
                      const double* cv, double* x);

}  // namespace nonmin::linalg
