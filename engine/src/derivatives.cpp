// The derivative pipeline of nonmin/derivatives.hpp: model terms on dual numbers (one
// evaluate_tangent per direction e_j of q and of q̇), the kernel's derivative analytically.
#include "nonmin/derivatives.hpp"

#include <Eigen/Cholesky>
#include "nonmin/svd.hpp"

#include <cmath>
#include <vector>

namespace nonmin {

DerivativeScratch::DerivativeScratch(const Program& p)
    : val(p.make_terms()), tan(p.make_terms()), ws(p.make_workspace()), dq(Vec::Zero(p.n())), dqd(Vec::Zero(p.n())) {}

Status forward_derivatives(const Program& p, DerivativeScratch& s, double t, const double* q, const double* qd,
                           const double* f, const double* u, const std::uint8_t* active, double rtol,
                           DerivativeOutputs& out) {
    if (!p.differentiable()) return Status::not_differentiable;
    const int n = p.n(), k = p.k();
    // active rows
    std::vector<int> rows;
    for (std::size_t c = 0; c < p.constraints().size(); ++c)
        if (active[c])
            for (int r = 0; r < p.constraints()[c].dim; ++r) rows.push_back(p.constraints()[c].row + r);
    const int m = static_cast<int>(rows.size());
    Status st = p.evaluate(t, q, qd, active, NEED_M | NEED_H | NEED_B | NEED_A | NEED_GAMMA, s.val, *s.ws);
    if (st != Status::ok) return st;
    const Mat& M = s.val.M;
    Vec uv = Vec::Zero(k);
    if (u != nullptr) uv = CVecMap(u, k);
    Vec g = s.val.h + s.val.f_passive;
    if (f != nullptr) g += CVecMap(f, n);
    if (k > 0) g.noalias() += s.val.B * uv;
    // equilibrated active rows and the rank decision
    Mat Ae(m, n);
    Vec d = Vec::Zero(m), ge(m);
    double big = 0.0;
    for (int i = 0; i < m; ++i) big = std::max(big, s.val.A.row(rows[i]).norm());
    for (int i = 0; i < m; ++i) {
        const double nr = s.val.A.row(rows[i]).norm();
        d[i] = (nr > rtol * big && nr > 0.0) ? 1.0 / nr : 0.0;
        Ae.row(i) = d[i] * s.val.A.row(rows[i]);
        ge[i] = d[i] * s.val.gamma[rows[i]];
    }
    Mat G = Mat::Zero(n, m), Z;
    int r = 0;
    if (m > 0) {
        Eigen::JacobiSVD<Mat> svd(Ae, Eigen::ComputeFullU | Eigen::ComputeFullV);
        const Vec& sv = svd.singularValues();
        const double smax = sv.size() ? sv[0] : 0.0;
        for (int i = 0; i < sv.size(); ++i)
            if (sv[i] > rtol * smax && sv[i] > 0.0) ++r;
        const Mat& V = svd.matrixV();
        const Mat& U = svd.matrixU();
        for (int i = 0; i < r; ++i) G.noalias() += (V.col(i) / sv[i]) * U.col(i).transpose();
        Z = V.rightCols(n - r);
    } else {
        Z = Mat::Identity(n, n);
    }
    const int kz = n - r;
    const Mat MZ = M * Z;
    const Mat Sm = Z.transpose() * MZ;
    Eigen::LLT<Mat> llt(Sm);
    if (kz > 0) {
        if (llt.info() != Eigen::Success) return Status::not_positive_definite;
        const Mat L = llt.matrixL();
        double dmax = 0.0;
        for (int i = 0; i < kz; ++i) dmax = std::max(dmax, Sm(i, i));
        for (int i = 0; i < kz; ++i)
            if (L(i, i) * L(i, i) <= 1e-13 * dmax) return Status::not_positive_definite;
    }
    const Vec Gge = G * ge;
    const Vec w = -Gge;
    const Vec res = ge - Ae * Gge;  // least-squares residual (0 for consistent biases)
    const Vec GtGge = G.transpose() * Gge;
    out.qdd = w;
    if (kz > 0) out.qdd.noalias() += Z * llt.solve(Z.transpose() * (g - M * w));
    out.fc = M * out.qdd - g;
    out.rank = r;
    const Vec& qdd = out.qdd;
    const Vec& fc = out.fc;
    const Vec Gtqdd = G.transpose() * qdd, Gtfc = G.transpose() * fc;
    const Mat P = Z * Z.transpose();
    const Vec Pqdd = P * qdd;  // P f_c = 0 (up to round-off): δP f_c = −P δAeᵀ Gᵀ f_c
    // one direction: the terms' tangents in s.tan -> δq̈, δf_c
    Mat dAe(m, n);
    Vec dge(m), dg(n);
    auto direction = [&](Eigen::Ref<Vec> dqdd, Eigen::Ref<Vec> dfc, bool has_dq) {
        dg = s.tan.h + s.tan.f_passive;
        if (k > 0 && has_dq && u != nullptr) dg.noalias() += s.tan.B * uv;
        Vec a = Vec::Zero(n), dPfc = Vec::Zero(n);
        if (m > 0) {
            for (int i = 0; i < m; ++i) {
                dge[i] = d[i] * s.tan.gamma[rows[i]];
                if (has_dq) dAe.row(i) = d[i] * s.tan.A.row(rows[i]);
            }
            a.noalias() = -G * dge;
            if (has_dq) {
                // δw part of δG: +G δAe G ge − G Gᵀ δAeᵀ res − P δAeᵀ Gᵀ G ge
                a.noalias() += G * (dAe * Gge);
                a.noalias() -= G * (G.transpose() * (dAe.transpose() * res));
                a.noalias() -= P * (dAe.transpose() * GtGge);
                // + δP q̈ = −G δAe P q̈ − P δAeᵀ Gᵀ q̈
                a.noalias() -= G * (dAe * Pqdd);
                a.noalias() -= P * (dAe.transpose() * Gtqdd);
                dPfc.noalias() = -P * (dAe.transpose() * Gtfc);
            }
        }
        const Vec aq = a - P * a;
        Vec rhs = dg - M * aq - dPfc;
        if (has_dq) rhs.noalias() -= s.tan.M * qdd;
        dqdd = aq;
        if (kz > 0) dqdd.noalias() += Z * llt.solve(Z.transpose() * rhs);
        dfc = M * dqdd - dg;
        if (has_dq) dfc.noalias() += s.tan.M * qdd;
    };
    out.dqdd_dq.resize(n, n);
    out.dqdd_dqd.resize(n, n);
    out.dfc_dq.resize(n, n);
    out.dfc_dqd.resize(n, n);
    Vec col_a(n), col_b(n);
    const unsigned need_q = NEED_M | NEED_H | NEED_A | NEED_GAMMA | (k > 0 && u != nullptr ? NEED_B : 0u);
    const unsigned need_v = NEED_H | NEED_GAMMA;
    for (int j = 0; j < n; ++j) {
        s.dq.setZero();
        s.dq[j] = 1.0;
        s.dqd.setZero();
        st = p.evaluate_tangent(t, q, qd, s.dq.data(), s.dqd.data(), active, need_q, s.val, s.tan, *s.ws);
        if (st != Status::ok) return st;
        direction(col_a, col_b, true);
        out.dqdd_dq.col(j) = col_a;
        out.dfc_dq.col(j) = col_b;
    }
    for (int j = 0; j < n; ++j) {
        s.dq.setZero();
        s.dqd.setZero();
        s.dqd[j] = 1.0;
        st = p.evaluate_tangent(t, q, qd, s.dq.data(), s.dqd.data(), active, need_v, s.val, s.tan, *s.ws);
        if (st != Status::ok) return st;
        direction(col_a, col_b, false);
        out.dqdd_dqd.col(j) = col_a;
        out.dfc_dqd.col(j) = col_b;
    }
    // ∂/∂f: δg = e_j, nothing else moves: δq̈ = Z S⁻¹ Zᵀ e_j
    if (kz > 0)
        out.dqdd_df = Z * llt.solve(Z.transpose());
    else
        out.dqdd_df = Mat::Zero(n, n);
    out.dfc_df = M * out.dqdd_df - Mat::Identity(n, n);
    return Status::ok;
}

}  // namespace nonmin
