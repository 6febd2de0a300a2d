// The derivative pipeline of nonmin/derivatives.hpp: the value of the kernel at the state, then
// the tangents of three residuals of the model terms (Program::residual_tangents, all 2n
// directions of (q, q̇) in multi-direction forward mode; or one evaluate_tangent per direction
// for programs without it), then the kernel's derivative as dense products over 2n columns
// (coefficient-based lazy products: at these sizes Eigen's blocked product costs more than it saves).
#include "nonmin/derivatives.hpp"

#include <Eigen/Cholesky>
#include "nonmin/svd.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "nonmin/dual_terms.hpp"

namespace nonmin {

DerivativeScratch::DerivativeScratch(const Program& p)
    : val(p.make_terms()),
      tan(p.make_terms()),
      ws(p.make_workspace()),
      dq(Vec::Zero(p.n())),
      dqd(Vec::Zero(p.n())),
      DQ(Mat::Zero(2 * p.n(), p.n())),
      DV(Mat::Zero(2 * p.n(), p.n())),
      Rdyn(Mat::Zero(2 * p.n(), p.n())),
      Rlam(Mat::Zero(2 * p.n(), 2 * p.n())),
      Rcon(Mat::Zero(2 * p.n(), p.m_all())),
      lam(Mat::Zero(2, p.m_all())),
      lq(p.m_all(), p.n()),
      Bq(Mat::Zero(std::max(p.m_all(), 1), p.n() + 1)),
      E(Mat::Zero(p.n(), p.n())),
      cv(Vec::Zero(std::max(p.m_all(), 1))) {
    const int n = p.n();
    for (int j = 0; j < n; ++j) {
        DQ(j, j) = 1.0;
        DV(n + j, j) = 1.0;
    }
    rows.reserve(static_cast<std::size_t>(p.m_all()));
}

namespace {

inline int kz_of(int n, int r) { return n - r; }

// C (r × c, leading dimension ldc) = alpha · op(A) · B (+ C when acc), all row-major: op(A)(i, l)
// is A[i lda + l], or A[l lda + i] when tA (A stored kk × r); B is kk × c (ldb). Row i of C
// accumulates alpha op(A)(i, l) · B's row l (contiguous, vectorized; zero entries skipped): at
// these sizes (n ≤ ~20, 2n columns) Eigen's coefficient-based lazy products on row-major
// transposed blocks cost ~4× the instructions.
void mul(bool tA, const double* A, int lda, const double* B, int ldb, double* C, int ldc, int r, int kk, int c,
         double alpha, bool acc) {
    for (int i = 0; i < r; ++i) {
        double* __restrict Ci = C + static_cast<std::ptrdiff_t>(i) * ldc;
        if (!acc)
            for (int j = 0; j < c; ++j) Ci[j] = 0.0;
        for (int l = 0; l < kk; ++l) {
            double a = tA ? A[static_cast<std::ptrdiff_t>(l) * lda + i] : A[static_cast<std::ptrdiff_t>(i) * lda + l];
            if (a == 0.0) continue;
            a *= alpha;
            const double* __restrict Bl = B + static_cast<std::ptrdiff_t>(l) * ldb;
            for (int j = 0; j < c; ++j) Ci[j] += a * Bl[j];
        }
    }
}

// The residual tangents one direction at a time from evaluate_tangent (programs without
// residual_tangents: SymPy tapes).
Status residuals_by_direction(const Program& p, DerivativeScratch& s, const ResidualQuery& rq) {
    const int n = p.n(), m_all = p.m_all();
    const unsigned need = NEED_M | NEED_H | NEED_A | NEED_GAMMA | (rq.u != nullptr && p.k() > 0 ? NEED_B : 0u);
    for (int j = 0; j < rq.nd; ++j) {
        const Status st = p.evaluate_tangent(rq.t, rq.q, rq.qd, rq.dq + j * n, rq.dqd + j * n, rq.active, need,
                                             s.val, s.tan, *s.ws);
        if (st != Status::ok) return st;
        residuals_from_terms<double>(s.tan, p.constraints(), rq, rq.r_dyn + j * n,
                                     rq.r_lam + static_cast<std::ptrdiff_t>(j) * rq.nlam * n, rq.r_con + j * m_all);
    }
    return Status::ok;
}

}  // namespace

Status forward_derivatives(const Program& p, DerivativeScratch& s, double t, const double* q, const double* qd,
                           const double* f, const double* u, const std::uint8_t* active, double rtol,
                           DerivativeOutputs& out) {
    if (!p.differentiable()) return Status::not_differentiable;
    const int n = p.n(), k = p.k(), m_all = p.m_all();
    // active rows
    std::vector<int>& rows = s.rows;
    rows.clear();
    for (std::size_t c = 0; c < p.constraints().size(); ++c)
        if (active[c])
            for (int r = 0; r < p.constraints()[c].dim; ++r) rows.push_back(p.constraints()[c].row + r);
    const int m = static_cast<int>(rows.size());
    Status st = p.evaluate(t, q, qd, active, NEED_M | NEED_H | NEED_B | NEED_A | NEED_GAMMA, s.val, *s.ws);
    if (st != Status::ok) return st;
    const Mat& M = s.val.M;
    const bool with_u = k > 0 && u != nullptr;
    Vec& g = s.g;
    g = s.val.h + s.val.f_passive;
    if (f != nullptr) g += CVecMap(f, n);
    if (with_u) g.noalias() += s.val.B * CVecMap(u, k);
    // equilibrated active rows and the rank decision
    Mat& Ae = s.Ae;
    Vec& d = s.d;
    Vec& ge = s.ge;
    Ae.resize(m, n);
    d.setZero(m);
    ge.resize(m);
    double big = 0.0;
    for (int i = 0; i < m; ++i) big = std::max(big, s.val.A.row(rows[i]).norm());
    for (int i = 0; i < m; ++i) {
        const double nr = s.val.A.row(rows[i]).norm();
        d[i] = (nr > rtol * big && nr > 0.0) ? 1.0 / nr : 0.0;
        Ae.row(i) = d[i] * s.val.A.row(rows[i]);
        ge[i] = d[i] * s.val.gamma[rows[i]];
    }
    Mat& G = s.G;
    Mat& Z = s.Z;
    G.setZero(n, m);
    int r = 0;
    bool certified = false;
    if (m > 0 && m <= n && m <= linalg::DENSE_INVERSE_MAX_ROWS) {
        // the certified LQ: every row live and full rank proved (else the SVD decides)
        bool live = true;
        for (int i = 0; i < m; ++i) live = live && d[i] != 0.0;
        if (live) {
            Mat& B = s.Bq;
            for (int i = 0; i < m; ++i) {
                for (int c = 0; c < n; ++c) B(i, c) = Ae(i, c);
                B(i, n) = ge[i];
            }
            if (linalg::lq_certified(B.data(), m, n, rtol, s.lq, s.cv.data()) == linalg::LQ_INVERSE &&
                s.lq.rank == m) {
                r = m;
                certified = true;
                Mat& E = s.E;  // rows 0 … m − 1: Q (D A = L Q), rows m … n − 1: Z
                linalg::lq_rows(s.lq, m, n, 0, n, E.data());
                const double* Li = s.lq.Li.data();  // L⁻¹, row k at k · m_max (lower)
                const int ld = s.lq.m_max;
                for (int k = 0; k < m; ++k)  // G = Qᵀ L⁻¹
                    for (int i = 0; i <= k; ++i) {
                        const double l = Li[k * ld + i];
                        if (l != 0.0) G.col(i) += l * E.row(k).transpose();
                    }
                Z = E.bottomRows(n - m).transpose();
            }
        }
    }
    if (m > 0 && !certified) {
        Svd& svd = s.svd;
        svd.compute(Ae, Eigen::ComputeThinU | Eigen::ComputeFullV);
        const Vec& sv = svd.singularValues();
        const double smax = sv.size() ? sv[0] : 0.0;
        for (int i = 0; i < sv.size(); ++i)
            if (sv[i] > rtol * smax && sv[i] > 0.0) ++r;
        const Mat& V = svd.matrixV();
        const Mat& U = svd.matrixU();
        for (int i = 0; i < r; ++i) G.noalias() += (V.col(i) / sv[i]) * U.col(i).transpose();
        Z = V.rightCols(n - r);
    } else if (m == 0) {
        Z.setIdentity(n, n);
    }
    const int kz = n - r;
    Mat& Zt = s.Zt;  // Zᵀ, Zᵀ M (kz × n), S = Zᵀ M Z
    Mat& ZtM = s.ZtM;
    Zt = Z.transpose();
    ZtM.resize(kz_of(n, r), n);
    s.Sm.resize(kz_of(n, r), kz_of(n, r));
    mul(false, Zt.data(), n, M.data(), n, ZtM.data(), n, kz_of(n, r), n, n, 1.0, false);
    mul(false, ZtM.data(), n, Z.data(), kz_of(n, r), s.Sm.data(), kz_of(n, r), kz_of(n, r), n, kz_of(n, r), 1.0, false);
    Eigen::LLT<Mat>& llt = s.llt;
    llt.compute(s.Sm);
    if (kz > 0) {
        if (llt.info() != Eigen::Success) return Status::not_positive_definite;
        const auto& L = llt.matrixLLT();
        double dmax = 0.0;
        for (int i = 0; i < kz; ++i) dmax = std::max(dmax, s.Sm(i, i));
        for (int i = 0; i < kz; ++i)
            if (L(i, i) * L(i, i) <= 1e-13 * dmax) return Status::not_positive_definite;
    }
    Vec& Gge = s.Gge;
    Gge.noalias() = G * ge;
    out.qdd = -Gge;
    if (kz > 0) {
        s.w1 = g;
        s.w1.noalias() += M * Gge;
        s.w2.noalias() = Z.transpose() * s.w1;
        llt.solveInPlace(s.w2);
        out.qdd.noalias() += Z * s.w2;
    }
    out.fc.noalias() = M * out.qdd;
    out.fc -= g;
    out.rank = r;
    // the fixed multipliers of the residuals: D λe (λe = Gᵀ f_c) and D ρ (ρ = Dγ − Ae G Dγ)
    const int nlam = m > 0 ? 2 : 0;
    s.lam.setZero(2, m_all);
    if (m > 0) {
        Vec& lame = s.w1;
        Vec& rho = s.w2;
        lame.noalias() = G.transpose() * out.fc;
        rho = ge;
        rho.noalias() -= Ae * Gge;
        for (int i = 0; i < m; ++i) {
            s.lam(0, rows[i]) = d[i] * lame[i];
            s.lam(1, rows[i]) = d[i] * rho[i];
        }
    }
    // residual tangents along the 2n directions
    const int nd = 2 * n;
    s.Rdyn.resize(nd, n);
    s.Rlam.resize(nd, nlam * n);
    s.Rcon.setZero(nd, m_all);
    ResidualQuery rq;
    rq.t = t;
    rq.q = q;
    rq.qd = qd;
    rq.a = out.qdd.data();
    rq.u = with_u ? u : nullptr;
    rq.nlam = nlam;
    rq.lam = s.lam.data();
    rq.active = active;
    rq.nd = nd;
    rq.dq = s.DQ.data();
    rq.dqd = s.DV.data();
    rq.r_dyn = s.Rdyn.data();
    rq.r_lam = s.Rlam.data();
    rq.r_con = s.Rcon.data();
    st = p.residual_tangents(rq, *s.ws);
    if (st == Status::not_differentiable) st = residuals_by_direction(p, s, rq);
    if (st != Status::ok) return st;
    // the kernel's derivative over the 2n directions, one row per direction (the residuals'
    // layout): Q δq̈ = −G (C + Gᵀ L1), C = D (δA q̈ + δγ); M Q δq̈ = −(M G) C
    Mat& AQ = s.AQ;    // (Q δq̈)ᵀ: nd × n
    Mat& MAQ = s.MAQ;  // (M Q δq̈)ᵀ
    AQ.resize(nd, n);
    MAQ.resize(nd, n);
    const int ldl = 2 * n;  // Rlam's rows: [δAeᵀ λe | δAeᵀ ρ]
    if (m > 0) {
        Mat& C = s.C;  // Cᵀ: nd × m
        C.resize(nd, m);
        for (int j = 0; j < nd; ++j)
            for (int i = 0; i < m; ++i) C(j, i) = d[i] * s.Rcon(j, rows[i]);
        // + Gᵀ δAeᵀ ρ
        mul(false, s.Rlam.data() + n, ldl, G.data(), m, C.data(), m, nd, n, m, 1.0, true);
        s.Gt = G.transpose();
        s.MG.resize(m, n);  // Gᵀ M = (M G)ᵀ
        mul(false, s.Gt.data(), n, M.data(), n, s.MG.data(), n, m, n, n, 1.0, false);
        mul(false, C.data(), m, s.Gt.data(), n, AQ.data(), n, nd, m, n, -1.0, false);
        mul(false, C.data(), m, s.MG.data(), n, MAQ.data(), n, nd, m, n, -1.0, false);
    } else {
        AQ.setZero();
        MAQ.setZero();
    }
    Mat& DQDD = s.DQDD;  // δq̈ᵀ
    Mat& DFC = s.DFC;    // δf_cᵀ = δ(M q̈ − g)ᵀ + (M δq̈)ᵀ
    DQDD = AQ;
    DFC = s.Rdyn;
    DFC += MAQ;
    if (kz > 0) {
        Mat& T1 = s.T1;  // (−δ(M q̈ − g) + δAeᵀ λe − M Q δq̈)ᵀ (nd × n)
        T1 = -s.Rdyn;
        if (m > 0) T1 += s.Rlam.leftCols(n);
        T1 -= MAQ;
        Mat& RHS = s.RHS;  // (S⁻¹ Zᵀ T1)ᵀ = T1ᵀ Z S⁻¹ (nd × kz)
        RHS.resize(nd, kz);
        mul(false, T1.data(), n, Z.data(), kz, RHS.data(), kz, nd, n, kz, 1.0, false);
        auto RHSt = RHS.transpose();
        llt.solveInPlace(RHSt);
        mul(false, RHS.data(), kz, Zt.data(), n, DQDD.data(), n, nd, kz, n, 1.0, true);
        mul(false, RHS.data(), kz, ZtM.data(), n, DFC.data(), n, nd, kz, n, 1.0, true);
    }
    out.dqdd_dq = DQDD.topRows(n).transpose();  // column k: along e_k
    out.dqdd_dqd = DQDD.bottomRows(n).transpose();
    out.dfc_dq = DFC.topRows(n).transpose();
    out.dfc_dqd = DFC.bottomRows(n).transpose();
    // ∂/∂f: δg = e_j, nothing else moves: δq̈ = Z S⁻¹ Zᵀ e_j, δf_c = M δq̈ − e_j; ∂/∂u = ∂/∂f · B
    const Mat& B = s.val.B;
    out.dqdd_df.resize(n, n);
    out.dfc_df.resize(n, n);
    out.dqdd_du_t.resize(k, n);
    out.dfc_du_t.resize(k, n);
    if (kz > 0) {
        Mat& ZS = s.ZS;  // S⁻¹ Zᵀ (kz × n)
        ZS = Zt;
        llt.solveInPlace(ZS);
        mul(false, Z.data(), kz, ZS.data(), n, out.dqdd_df.data(), n, n, kz, n, 1.0, false);
        mul(true, ZtM.data(), n, ZS.data(), n, out.dfc_df.data(), n, n, kz, n, 1.0, false);
        out.dfc_df.diagonal().array() -= 1.0;
        s.ZSB.resize(kz, k);  // S⁻¹ Zᵀ B
        mul(false, ZS.data(), n, B.data(), k, s.ZSB.data(), k, kz, n, k, 1.0, false);
        mul(true, s.ZSB.data(), k, Zt.data(), n, out.dqdd_du_t.data(), n, k, kz, n, 1.0, false);
        mul(true, s.ZSB.data(), k, ZtM.data(), n, out.dfc_du_t.data(), n, k, kz, n, 1.0, false);
        out.dfc_du_t -= B.transpose();
    } else {
        out.dqdd_df.setZero();
        out.dfc_df = -Mat::Identity(n, n);
        out.dqdd_du_t.setZero();
        out.dfc_du_t = -B.transpose();
    }
    return Status::ok;
}

}  // namespace nonmin
