// The core layer's other kernels (dynamics.hpp): M̄, μ, S, R and Γ, C̄, the impact map and the
// mass-metric position correction. Specified by nonmin.core (dynamics.py, projectors.py,
// impact.py). The matrix kernels multiply through one coefficient-based product, mm (they are not
// on the simulation loop's path); the impact map and the correction are one Solver call each.
#include "nonmin/dynamics.hpp"

#include "nonmin/svd.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "nonmin/linalg.hpp"

namespace nonmin {

namespace {
using RowMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using CMap = Eigen::Map<const RowMat>;
using Map = Eigen::Map<RowMat>;
constexpr double TINY = std::numeric_limits<double>::min();
// A B, coefficient-based: every product of the file goes through this one instantiation. Eigen's
// GEMM (blocking and packing kernels, instantiated for each expression's storage orders) took 11
// of the file's 14.6 s of compile CPU; with mm the file takes 3.0 s (issue 17, target 7).
RowMat mm(const Eigen::Ref<const RowMat>& A, const Eigen::Ref<const RowMat>& B) {
    RowMat C(A.rows(), B.cols());
    C.noalias() = A.lazyProduct(B);
    return C;
}
}  // namespace

void constraint_inertia(const double* M, const double* P, double mu, int n, double* Mbar) {
    CMap Mm(M, n, n), Pm(P, n, n);
    Map out(Mbar, n, n);
    RowMat PMP = mm(mm(Pm, Mm), Pm);
    out = PMP + mu * (RowMat::Identity(n, n) - Pm);
}

double optimal_virtual_mass(const double* M, const double* P, int n) {
    CMap Mm(M, n, n), Pm(P, n, n);
    const double rank = n - std::nearbyint(Pm.trace());  // np.rint: half to even
    const RowMat PMP = mm(mm(Pm, Mm), Pm);
    const double dof = n - rank;
    const double mu = dof > 0 ? PMP.trace() / std::max(dof, 1.0) : Mm.trace() / n;
    return mu > 0.0 ? mu : 1.0;
}

Status constraint_force_projector(const double* M, const double* P, double mu, int n, double* S,
                                  double* work) {
    CMap Mm(M, n, n), Pm(P, n, n);
    Map W(work, n, n);
    W = mm(mm(Pm, Mm), Pm) + mu * (RowMat::Identity(n, n) - Pm);  // M̄
    double dmax = -std::numeric_limits<double>::infinity();
    for (int i = 0; i < n; ++i) dmax = std::max(dmax, W(i, i));
    double* dinv = work + static_cast<long>(n) * n;
    double* cw = dinv + n;
    double ratio = 0.0;
    if (linalg::cholesky_spd(work, n, linalg::SPD_RTOL, dmax, dinv, cw, &ratio) != linalg::CHOL_OK)
        return Status::not_positive_definite;
    Map X(cw + n, n, n);  // X = M̄⁻¹ P, column by column
    double* col = cw + n + static_cast<long>(n) * n;
    for (int j = 0; j < n; ++j) {
        for (int i = 0; i < n; ++i) col[i] = Pm(i, j);
        linalg::cholesky_solve(work, n, dinv, col);
        for (int i = 0; i < n; ++i) X(i, j) = col[i];
    }
    Map Sm(S, n, n);
    Sm = RowMat::Identity(n, n) - mm(Mm, X);
    return Status::ok;
}

void actuation_projectors(const double* B, const double* P, int n, int k, double rtol,
                          double* R, double* Gamma, int* rank_pb, int* dof) {
    CMap Bm(B, n, k), Pm(P, n, n);
    *dof = static_cast<int>(std::nearbyint(Pm.trace()));
    Map Rm(R, n, n), G(Gamma, k, n);
    if (k == 0) {
        *rank_pb = 0;
        Rm.setZero();
        return;
    }
    const RowMat PB = mm(Pm, Bm);
    Svd svd(PB, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const auto& s = svd.singularValues();
    double bscale = 0.0;  // largest column norm of B: the actuators' own scale
    for (int j = 0; j < k; ++j) bscale = std::max(bscale, Bm.col(j).squaredNorm());
    bscale = std::sqrt(bscale);
    const double ref = std::max(std::max(s.size() ? s(0) : 0.0, bscale), TINY);
    int r = 0;
    Eigen::VectorXd inv = Eigen::VectorXd::Zero(s.size());
    for (Eigen::Index a = 0; a < s.size(); ++a)
        if (s(a) > rtol * ref) {
            inv(a) = 1.0 / s(a);
            ++r;
        }
    *rank_pb = r;
    G = mm(svd.matrixV() * inv.asDiagonal(), svd.matrixU().transpose());
    Rm = mm(Bm, G);
}

void coriolis_bar(Solver& s, const double* M, const double* C, const double* A,
                  const double* Adot, int m, double mu, double rtol, double* Cbar) {
    const int n = s.n();
    CMap Mm(M, n, n), Cm(C, n, n);
    Map out(Cbar, n, n);
    RowMat V(std::max(m, 1), n);
    const int r = s.range_basis(A, m, rtol, V.data());
    const RowMat P = RowMat::Identity(n, n) - mm(V.topRows(r).transpose(), V.topRows(r));
    RowMat Lam = RowMat::Zero(n, n);
    if (m > 0 && r > 0) {  // Λ = −A⁺Ȧ, A⁺ of A itself truncated to the rank of the policy
        CMap Am(A, m, n), Ad(Adot, m, n);
        Svd svd(Am, Eigen::ComputeThinU | Eigen::ComputeThinV);
        const auto& sv = svd.singularValues();
        Eigen::VectorXd inv = Eigen::VectorXd::Zero(sv.size());
        for (int a = 0; a < std::min<int>(r, static_cast<int>(sv.size())); ++a)
            inv(a) = sv(a) > 0.0 ? 1.0 / sv(a) : 1.0;  // (as nonmin.core.pseudo_inverse)
        Lam = -mm(mm(svd.matrixV() * inv.asDiagonal(), svd.matrixU().transpose()), Ad);
    }
    const RowMat LP = mm(Lam, P);
    out = mm(mm(P, Cm), P) + mm(mm(P, Mm), LP + LP.transpose()) - mu * LP;
}

SolveInfo impact_map(Solver& s, const double* M, const double* A, int m, const double* qd_minus,
                     double restitution, double mu, double rtol, double* qd_plus, double* work) {
    const int n = s.n();
    for (int i = 0; i < n; ++i) {  // g = M q̇⁻
        double t = 0.0;
        for (int j = 0; j < n; ++j) t += M[static_cast<long>(i) * n + j] * qd_minus[j];
        work[i] = t;
    }
    SolveOptions opt;
    opt.mu = mu;
    opt.rtol = rtol;
    opt.known = KNOWN_M_VALID;  // (validated by the caller)
    static thread_local std::vector<double> zero;
    zero.assign(std::max(m, 1), 0.0);
    const SolveInfo info = s.forward(M, work, A, m, zero.data(), opt, qd_plus, nullptr);
    if (info.status != Status::ok) return info;
    const double e1 = 1.0 + restitution;
    for (int i = 0; i < n; ++i) qd_plus[i] = qd_minus[i] + e1 * (qd_plus[i] - qd_minus[i]);
    return info;
}

SolveInfo position_correction(Solver& s, const double* M, const double* A, int m,
                              const double* phi, double mu, double rtol, double* dq,
                              double* work) {
    const int n = s.n();
    for (int i = 0; i < n; ++i) work[i] = 0.0;
    SolveOptions opt;
    opt.mu = mu;
    opt.rtol = rtol;
    opt.known = KNOWN_M_VALID;
    return s.forward(M, work, A, m, phi, opt, dq, nullptr);
}

}  // namespace nonmin
