// The core layer's linear algebra: the rank tolerance policy of docs/theory.md ("Rank tolerance
// policy") on raw row-major buffers, and the SPD factorization with its pivot test. Free
// functions over caller-owned scratch (no allocation); the Solver (solver.hpp) strings them
// together. Specified by nonmin.core.linalg (range_basis, cholesky).
#pragma once
#include <cstdint>

namespace nonmin::linalg {

// nonmin.core.DEFAULT_RTOL, SPD_RTOL and nonmin._validation.SYMMETRY_RTOL.
inline constexpr double DEFAULT_RTOL = 1e-10;
inline constexpr double SPD_RTOL = 1e-13;
inline constexpr double SYMMETRY_RTOL = 1e-9;

// Outcome of cholesky_spd (rule 6).
enum CholStatus : int { CHOL_OK = 0, CHOL_FAIL = 1, CHOL_SMALL_PIVOT = 2 };

// ‖X[i, :n]‖₂ with four interleaved partial sums in a fixed order.
double row_norm(const double* x, int n);

// Rules 1–2 (row equilibration). For A (m × n, row-major, leading dimension lda): rows with
// ‖a_i‖ ≤ rtol · max_i ‖a_i‖ vanished (d_i = 0, row of B zero), the others are scaled to unit
// length (d_i = 1/‖a_i‖). Writes B (m × (n + 1), leading dimension n + 1) = [D A | D b] (b may be
// null: last column zero), d (m) and the row norms (m). Returns the number of live rows. A is
// finite (the caller checks); a row norm that overflows makes every row vanish, as in NumPy.
int equilibrate(const double* A, int m, int n, const double* b, double rtol, double* B, double* d,
                double* norms);

// Rule 3 for few rows: one-sided (Hestenes) Jacobi SVD of the rows of B (m × (n + 1),
// augmented: the rotations act on the last column too). At convergence the rows are mutually
// orthogonal in their first n entries: their norms are the singular values of D A and their
// directions the right singular vectors; the last column holds Uᵀ D b. Rows whose squared norm
// is ≤ eps² ‖B‖_F² are round-off (e.g. the difference of duplicated rows) and not rotated.
// T (m × m, may be null) accumulates the rotation (T ← R T), for warm starts.
void jacobi_rows(double* B, int m, int n, double* T);

// The SVD rule on the rows left by jacobi_rows: σ_i = ‖B[i, :n]‖, kept if σ_i > rtol · σ_max.
// Writes the kept unit rows into V (r × n, leading dimension n), cv_k = (u_kᵀ D b)/σ_k and
// sig (m, the row norms). Returns r.
int keep_rows(const double* B, int m, int n, double rtol, double* V, double* cv, double* sig);

// Rule 6: in-place Cholesky factor of the lower triangle of W (n × n, row-major), right-looking,
// reciprocal pivots into dinv, cw (n) scratch. CHOL_FAIL if a pivot ≤ 0 (stops there),
// CHOL_SMALL_PIVOT if L_jj² ≤ spd_rtol · dmax (continues; *ratio = smallest L_jj²/dmax).
int cholesky_spd(double* W, int n, double spd_rtol, double dmax, double* dinv, double* cw,
                 double* ratio);

// Solve L Lᵀ x = b in place (x = b on entry), L the lower triangle of W with reciprocal pivots
// dinv (as cholesky_spd leaves them).
void cholesky_solve(const double* W, int n, const double* dinv, double* x);

}  // namespace nonmin::linalg
