// The core layer's contract with the loop: the rank-revealing projection-dynamics solve.
// Implemented in engine/src (core layer); specified by the NumPy kernels of nonmin.core
// (linalg.py: the rank policy on the row-equilibrated A; dynamics.py: qdd, f_c, μ, M̄), with
// which it agrees to round-off. One Solver per thread: it owns preallocated scratch for
// constraint matrices of up to m_max rows and n columns; no allocation inside a call.
#pragma once
#include <memory>

#include "types.hpp"

namespace nonmin {

// Bits of SolveOptions::known: what the caller has established, so the checks are skipped
// (results bitwise unchanged). KNOWN_M_VALID: M finite and symmetric within sym_rtol;
// KNOWN_M_DIAGONAL (with KNOWN_M_VALID): M diagonal.
enum Known : unsigned { KNOWN_M_VALID = 1u, KNOWN_M_DIAGONAL = 2u };

struct SolveOptions {
    double rtol = 1e-10;      // DEFAULT_RTOL: relative singular-value cutoff on D A
    double spd_rtol = 1e-13;  // SPD_RTOL: M̄ Cholesky pivot test
    double mu = 0.0;          // virtual mass; ≤ 0 means the optimal tr(PMP)/(n − r)
    double sym_rtol = 1e-9;   // SYMMETRY_RTOL: max|M − Mᵀ| ≤ sym_rtol · max|M|
    unsigned known = 0;       // Known bits (0: check everything)
    // The row pattern of A's m rows when known (program.hpp's RowPattern restricted to them:
    // row i's columns a_cols[a_start[i]] … a_cols[a_start[i+1] − 1], every other entry 0): the
    // checks, row norms and the sparse LQ's profile read only those entries (results bitwise
    // unchanged). Null: A is scanned.
    const int* a_start = nullptr;
    const int* a_cols = nullptr;
};

struct SolveInfo {
    Status status = Status::ok;
    int rank = 0;     // numerical rank of A used
    double mu = 0.0;  // virtual mass used
    double pivot_ratio = 0.0;  // smallest L_jj² / max M̄_jj when the SPD test failed on a pivot
    bool chol_failed = false;  // not_positive_definite because a pivot was ≤ 0
    int method = 0;            // rank decision: 0 SVD (Jacobi sweeps / svd.hpp), 1 certified LQ with
                               // L⁻¹ (few rows), 2 certified LQ over L's profile (many rows)
    bool null_space_form = false;  // q̈ through Z and S = Z M Zᵀ (k = n − r ≤ r)
};

class Solver {
  public:
    Solver(int m_max, int n);
    ~Solver();
    Solver(Solver&&) noexcept;
    Solver& operator=(Solver&&) noexcept;

    int n() const;
    int m_max() const;

    // Forward dynamics (eq. ddq_sim, corrected sign): for the total applied force g = f + h,
    // qdd = M̄⁻¹ [P g + (μI − PM) w], w = −A⁺ γ, with A (m × n, row-major, m ≤ m_max) and γ.
    // f_c = M qdd − g when f_c is not null. M is n × n row-major.
    SolveInfo forward(const double* M, const double* g, const double* A, int m, const double* gamma,
                      const SolveOptions& opt, double* qdd, double* f_c);

    // Everything nonmin.core.solve_dynamics returns: qdd and f_c as forward, the null-space
    // projector P (n × n) and the lower Cholesky factor L of M̄ (n × n, zero above the diagonal).
    // Any output pointer may be null (not computed).
    SolveInfo solve(const double* M, const double* g, const double* A, int m, const double* gamma,
                    const SolveOptions& opt, double* qdd, double* f_c, double* P, double* L);

    // Solve again with the factorization of the last forward/solve call, which must have
    // succeeded (held()): the same A, M, rank tolerance and μ option (the caller guarantees it),
    // new g and γ (m entries, m of that call). Costs O(m² + mn + n²) instead of a factorization.
    // Certified LQ: bitwise the result of a fresh call; SVD paths: the same to round-off (Σ⁻¹Uᵀ
    // of the kept rows applied to D γ instead of rotating it with B). Status bad_shape when
    // nothing is held. qdd, f_c as forward.
    SolveInfo again(const double* M, const double* g, const double* gamma, double* qdd, double* f_c);
    // Solve at a constraint matrix A (m × n, m the held call's m) close to the A_h of the held
    // factorization, without factorizing A: the held factorization must be a certified LQ of
    // every row (rank m) in the null-space form, taken at a rank tolerance ≥ opt.rtol, and
    // opt.known must state M (KNOWN_M_VALID). Its factors give A_h⁺ and an orthonormal basis
    // Z_h of N(A_h); with A = A_h + E, each pass z ← z − A_h⁺(A z) turns the basis' residual
    // from O(‖E‖) into O(‖E‖²/σ_min) (then Gram–Schmidt), and likewise w ← w − A_h⁺(A w + γ)
    // the minimum-norm solution of A w = −γ; passes continue until the equilibrated residuals
    // are at round-off (64 eps), at most NEAR_PASSES. With Z and w exact for A, the null-space
    // form q̈ = w + Zᵀ S⁻¹ Z (g − M w), S = Z M Zᵀ, μ = tr S / k gives the fresh call's result
    // to round-off (not bitwise) at the cost of a few products with A and the held factors. The
    // rank is the held one: A must be the held A moved by a projection's correction (the
    // caller's concern). `same`: A is bitwise the A of the last near() call, which succeeded
    // on the factorization still held (its Z, S and factor are reused; only w is new).
    // The held factorization stays held for again(); cond_mbar() then reports the near A's.
    // Status ok, or bad_shape when declined (nothing suitable held, passes not at round-off:
    // factorize A instead), or the SPD status of S. qdd, f_c as forward.
    SolveInfo near(const double* M, const double* g, const double* A, int m, const double* gamma,
                   const SolveOptions& opt, bool same, double* qdd, double* f_c);
    // Whether a factorization is held (the last forward/solve succeeded; any other call drops it).
    bool held() const;
    // Counts the calls that factorize (forward, solve, range_basis, min_norm; not again): a
    // caller that keeps a factorization for later checks that no other call came in between.
    unsigned long long generation() const;
    // cond(M̄) of the held factorization in the null-space form: M̄ acts as μ on R(Aᵀ) and as
    // S = Z M Zᵀ on N(A), so cond = max(μ, λ_max(S)) / min(μ, λ_min(S)) (k × k eigenvalues, no
    // n × n M̄); equals (σ_max(L)/σ_min(L))² of M̄'s Cholesky factor L to round-off. NaN when
    // nothing is held or the form is the range form (then mbar_factor).
    double cond_mbar();
    // The held range form's Cholesky factor L of M̄ (n × n, zero above the diagonal) into L;
    // false (nothing written) in the null-space form or when nothing is held.
    bool mbar_factor(double* L) const;

    // The rank policy alone: r and an orthonormal basis of R(Aᵀ) in the rows of V (r × n,
    // V has room for min(m, n) rows), so that P = I − VᵀV (nonmin.core.range_basis).
    int range_basis(const double* A, int m, double rtol, double* V);

    // Minimum-norm solution x = (DA)⁺ D b of A x = b under the same rank policy (n-vector x).
    SolveInfo min_norm(const double* A, int m, const double* b, double rtol, double* x);

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace nonmin
