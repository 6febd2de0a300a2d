// The core layer's other kernels (nonmin.core: dynamics.py, projectors.py, impact.py), one
// state each on row-major buffers; the bindings loop them over batches. Those built on the
// projection solve take a Solver (solver.hpp: same rank policy, same M̄ and SPD test); the
// others are direct formulas. Each is specified by its NumPy kernel, with which it agrees to
// round-off (tests/core).
#pragma once
#include "solver.hpp"
#include "types.hpp"

namespace nonmin {

// eq. (Mbar): M̄ = PMP + μ(I − P) (n × n, full).
void constraint_inertia(const double* M, const double* P, double mu, int n, double* Mbar);

// eq. (optimum_mu): μ = tr(PMP)/(n − r) with r = n − round(tr P); tr(M)/n when r = n; 1 when
// not positive.
double optimal_virtual_mass(const double* M, const double* P, int n);

// eq. (S_definition): S = I − M M̄⁻¹ P with M̄ = PMP + μ(I − P); not_positive_definite when M̄
// fails the SPD test (rule 6). work: at least 2n² + 3n doubles.
Status constraint_force_projector(const double* M, const double* P, double mu, int n, double* S,
                                  double* work);

// eqs. (p1_inverse), (Q_definition), ERRATA 4: Γ = (PB)⁺ (k × n), R = BΓ (n × n), with the rank
// of PB decided relative to max(σ_max(PB), largest column norm of B). Returns rank(PB) in
// *rank_pb and n − round(tr P) in *dof; the caller raises when rank_pb < dof.
void actuation_projectors(const double* B, const double* P, int n, int k, double rtol,
                          double* R, double* Gamma, int* rank_pb, int* dof);

// eq. (Cbar2): C̄ = PCP + PM(ΛP + PΛᵀ) − μΛP with P from the rank policy (Solver::range_basis)
// and Λ = −A⁺Ȧ, A⁺ the Moore–Penrose inverse of A truncated to that rank.
void coriolis_bar(Solver& s, const double* M, const double* C, const double* A,
                  const double* Adot, int m, double mu, double rtol, double* Cbar);

// Impact map (ERRATA "Beyond the paper"): q̇⁺ = q̇⁻ + (1 + e)(M̄⁻¹PMq̇⁻ − q̇⁻), i.e. the solve
// with g = M q̇⁻ and γ = 0. mu ≤ 0: the optimal μ. work: n doubles.
SolveInfo impact_map(Solver& s, const double* M, const double* A, int m, const double* qd_minus,
                     double restitution, double mu, double rtol, double* qd_plus, double* work);

// Minimum mass-metric correction onto φ = 0: Δq = Sᵀ(−A⁺φ) = x − P M̄⁻¹ M x, x = −A⁺φ, i.e. the
// solve with g = 0 and γ = φ (nonmin.sim._stabilization._correction). work: 2n doubles.
SolveInfo position_correction(Solver& s, const double* M, const double* A, int m,
                              const double* phi, double mu, double rtol, double* dq,
                              double* work);

}  // namespace nonmin
