// Derivatives of the projection dynamics at one state (nonmin.linear; docs/linear.md): q̈, f_c
// and ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂f (and those of f_c) with the model terms differentiated in forward
// mode (Program::evaluate_tangent, dual.hpp) and the kernel's solve differentiated analytically
// at the rank it used. With G = (DA)⁺ (D the row equilibration), Ae = D A, Z an orthonormal
// basis of N(A), S = Zᵀ M Z, w = −G D γ, q̈ = w + Z S⁻¹ Zᵀ (g − M w), f_c = M q̈ − g:
//
//   δP x = −G δAe P x − P δAeᵀ Gᵀ x
//   δw   = G δAe G Dγ − G Gᵀ δAeᵀ (I − Ae G) Dγ − P δAeᵀ Gᵀ G Dγ − G D δγ
//   Q δq̈ = Q (δw + δP q̈),   P δq̈ = Z S⁻¹ Zᵀ (δg − δM q̈ − M Q δq̈ − δP f_c)
//   δf_c = δM q̈ + M δq̈ − δg.
//
// The rank decision is the core's (rule of docs/theory.md: vanished rows, unit rows, singular
// values ≤ rtol σ_max dropped), made here with Eigen's JacobiSVD of the equilibrated rows.
#pragma once
#include <memory>

#include "program.hpp"

namespace nonmin {

struct DerivativeOutputs {
    Vec qdd, fc;            // n
    Mat dqdd_dq, dqdd_dqd;  // n × n (column j: along e_j)
    Mat dqdd_df;            // n × n
    Mat dfc_dq, dfc_dqd, dfc_df;
    int rank = 0;
};

// Preallocated scratch for one program and thread.
struct DerivativeScratch {
    explicit DerivativeScratch(const Program& p);
    Terms val, tan;
    std::unique_ptr<Workspace> ws;
    Vec dq, dqd;
};

// q̈, f_c and their derivatives at (t, q, qd) with applied force f (n; nullptr: 0) and actuator
// inputs u (k; nullptr: 0, f += B(q) u with u held fixed). Status::not_positive_definite when
// Zᵀ M Z fails Cholesky; not_differentiable when the program has no evaluate_tangent.
Status forward_derivatives(const Program& p, DerivativeScratch& s, double t, const double* q, const double* qd,
                           const double* f, const double* u, const std::uint8_t* active, double rtol,
                           DerivativeOutputs& out);

}  // namespace nonmin
