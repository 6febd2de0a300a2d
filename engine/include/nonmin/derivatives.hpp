// Derivatives of the projection dynamics at one state (nonmin.linear; docs/linear.md): q̈, f_c
// and ∂q̈/∂q, ∂q̈/∂q̇, ∂q̈/∂f (and those of f_c), the kernel's solve differentiated analytically
// at the rank it used. With G = (DA)⁺ (D the row equilibration), Ae = D A, Z an orthonormal
// basis of N(A), S = Zᵀ M Z, w = −G D γ, q̈ = w + Z S⁻¹ Zᵀ (g − M w), f_c = M q̈ − g, the
// equilibrated multipliers λe = Gᵀ f_c and the least-squares residual ρ = Dγ − Ae G Dγ:
//
//   Q δq̈ = −G (δAe q̈ + D δγ) − G Gᵀ δAeᵀ ρ                        (= δw + δP q̈, Q G = G)
//   P δq̈ = Z S⁻¹ Zᵀ (−δ(M q̈ − g) + δAeᵀ λe − M Q δq̈)              (−Zᵀ δP f_c = Zᵀ δAeᵀ λe)
//   δf_c = δ(M q̈ − g) + M δq̈,
//
// where δ(·) holds q̈, λe, ρ and D fixed. So only three products of the model terms are
// differentiated: δ(M a − g), δ(Aᵀ λ) and δ(A a + γ) at a = q̈ (Program::residual_tangents:
// for robots one RNEA and the frame accelerations on multi-direction duals, never dM or dA —
// the route of Pinocchio's derivatives of the constrained dynamics), for all 2n directions of
// (q, q̇) at once; the kernel's part is then a few dense products over the 2n columns.
//
// The rank decision is the core's (rule of docs/theory.md: vanished rows, unit rows, singular
// values ≤ rtol σ_max dropped): the certified LQ of the equilibrated rows when it proves that
// the rule keeps every row (DA = L Q: G = Qᵀ L⁻¹, Z the LQ's remaining orthonormal rows; the
// core's shortcut, linalg.hpp), else the engine's SVD (svd.hpp) of the equilibrated rows.
#pragma once
#include <memory>
#include <vector>

#include <Eigen/Cholesky>

#include "linalg.hpp"
#include "program.hpp"
#include "svd.hpp"

namespace nonmin {

struct DerivativeOutputs {
    Vec qdd, fc;            // n
    Mat dqdd_dq, dqdd_dqd;  // n × n (column j: along e_j)
    Mat dqdd_df;            // n × n
    Mat dfc_dq, dfc_dqd, dfc_df;
    Mat dqdd_du_t, dfc_du_t;  // k × n: (∂q̈/∂u)ᵀ, (∂f_c/∂u)ᵀ (∂/∂f · B(q))
    int rank = 0;
};

// Preallocated scratch for one program and thread (matrices keep their storage between calls).
struct DerivativeScratch {
    explicit DerivativeScratch(const Program& p);
    Terms val, tan;
    std::unique_ptr<Workspace> ws;
    Vec dq, dqd;              // n
    Mat DQ, DV;               // 2n × n: the seeds (e_j, 0) then (0, e_j)
    Mat Rdyn, Rlam, Rcon;     // 2n × n, 2n × 2n (two λ), 2n × m_all: residual tangents
    Mat lam;                  // 2 × m_all: D λe and D ρ on the active rows
    std::vector<int> rows;    // active rows
    Mat Ae, G, Gt, Z, Zt, ZtM, MG, Sm, C, T1, AQ, MAQ, RHS, DQDD, DFC, ZS, ZSB;  // (2n-direction ones: one row each)
    Vec d, ge, g, Gge, w1, w2;
    Eigen::LLT<Mat> llt;
    Svd svd;
    linalg::LQWork lq;      // the certified LQ of D A (full rank proved: no SVD)
    Mat Bq, E;              // m × (n + 1): [D A | D γ]; n × n: the LQ's orthogonal factor
    Vec cv;
    DerivativeOutputs out;  // the bindings' outputs (no allocation per call)
};
// q̈, f_c and their derivatives at (t, q, qd) with applied force f (n; nullptr: 0) and actuator
// inputs u (k; nullptr: 0, f += B(q) u with u held fixed). Status::not_positive_definite when
// Zᵀ M Z fails Cholesky; not_differentiable when the program has no evaluate_tangent.
Status forward_derivatives(const Program& p, DerivativeScratch& s, double t, const double* q, const double* qd,
                           const double* f, const double* u, const std::uint8_t* active, double rtol,
                           DerivativeOutputs& out);

}  // namespace nonmin
