// Splitting the dual-number terms of a forward-mode evaluation (Program::evaluate_tangent) into
// the values and the directional derivatives, each a plain Terms; the residuals of a
// ResidualQuery (program.hpp) from terms on any scalar, and the chunked multi-direction driver
// of the programs whose evaluation is templated on the scalar.
#pragma once
#include <algorithm>
#include <vector>

#include "dual.hpp"
#include "program.hpp"

namespace nonmin {

namespace detail {
template <class D>
void split_into(const D& src, Eigen::Index size, double* val, double* tan) {
    const auto* s = src.data();
    for (Eigen::Index i = 0; i < size; ++i) {
        val[i] = s[i].v;
        tan[i] = s[i].d;
    }
}
}  // namespace detail

// Copies what `need` asks from the dual terms d into out (values) and tangent (derivatives).
inline void split_dual(const TermsOf<Dual>& d, unsigned need, Terms& out, Terms& tangent) {
    using detail::split_into;
    if (need & NEED_M) split_into(d.M, d.M.size(), out.M.data(), tangent.M.data());
    if (need & NEED_H) {
        split_into(d.h, d.h.size(), out.h.data(), tangent.h.data());
        split_into(d.f_passive, d.f_passive.size(), out.f_passive.data(), tangent.f_passive.data());
    }
    if (need & NEED_B) split_into(d.B, d.B.size(), out.B.data(), tangent.B.data());
    if (need & NEED_A) split_into(d.A, d.A.size(), out.A.data(), tangent.A.data());
    if (need & NEED_GAMMA) split_into(d.gamma, d.gamma.size(), out.gamma.data(), tangent.gamma.data());
    if (need & NEED_PHI) split_into(d.phi, d.phi.size(), out.phi.data(), tangent.phi.data());
    if (need & NEED_VELOCITY)
        split_into(d.velocity, d.velocity.size(), out.velocity.data(), tangent.velocity.data());
    if (need & NEED_ENERGY) {
        out.kinetic = d.kinetic.v;
        tangent.kinetic = d.kinetic.d;
        out.potential = d.potential.v;
        tangent.potential = d.potential.d;
    }
}

// The residuals of rq (program.hpp) from the terms T on the scalar S: rd = M a − h − f_p − B u
// (n), rl = Aᵀ λ_l (nlam × n), rc = A a + γ (m_all; active rows, others 0). Linear in the
// terms, so on the tangent Terms of evaluate_tangent it gives the residuals' tangents.
template <class S>
void residuals_from_terms(const TermsOf<S>& T, const std::vector<ConstraintInfo>& cons, const ResidualQuery& rq,
                          S* rd, S* rl, S* rc) {
    const auto n = static_cast<int>(T.M.rows());
    const auto k = static_cast<int>(T.B.cols());
    const auto m_all = static_cast<int>(T.A.rows());
    for (int i = 0; i < n; ++i) {
        S acc = -(T.h[i] + T.f_passive[i]);
        for (int j = 0; j < n; ++j) acc += T.M(i, j) * rq.a[j];
        if (rq.u != nullptr)
            for (int c = 0; c < k; ++c) acc -= T.B(i, c) * rq.u[c];
        rd[i] = acc;
    }
    for (int i = 0; i < rq.nlam * n; ++i) rl[i] = S(0.0);
    for (int r = 0; r < m_all; ++r) rc[r] = S(0.0);
    for (std::size_t c = 0; c < cons.size(); ++c) {
        if (!rq.active[c]) continue;
        for (int r = cons[c].row; r < cons[c].row + cons[c].dim; ++r) {
            S acc = T.gamma[r];
            for (int j = 0; j < n; ++j) acc += T.A(r, j) * rq.a[j];
            rc[r] = acc;
            for (int l = 0; l < rq.nlam; ++l) {
                const double lam = rq.lam[l * m_all + r];
                if (lam == 0.0) continue;
                for (int j = 0; j < n; ++j) rl[l * n + j] += lam * T.A(r, j);
            }
        }
    }
}

// Scratch of the chunked driver below (sized at first use).
template <int W>
struct DualResidualScratch {
    std::vector<DualN<W>> q, qd, rd, rl, rc;
    TermsOf<DualN<W>> terms;
    void size(int n, int k, int m_all, int nlam) {
        if (static_cast<int>(q.size()) != n || static_cast<int>(terms.A.rows()) != m_all) {
            q.assign(n, DualN<W>());
            qd.assign(n, DualN<W>());
            rd.assign(n, DualN<W>());
            rc.assign(m_all, DualN<W>());
            terms.resize(n, k, m_all);
        }
        if (static_cast<int>(rl.size()) != nlam * n) rl.assign(static_cast<std::size_t>(nlam * n), DualN<W>());
    }
};

// Seeds the state of directions j0 .. j0 + w − 1 (w ≤ W) into duals (unused lanes zero).
template <int W>
void seed_directions(const ResidualQuery& rq, int n, int j0, int w, DualN<W>* q, DualN<W>* qd) {
    for (int i = 0; i < n; ++i) {
        q[i] = DualN<W>(rq.q[i]);
        qd[i] = DualN<W>(rq.qd[i]);
        for (int l = 0; l < w; ++l) {
            q[i].d[l] = rq.dq[(j0 + l) * n + i];
            qd[i].d[l] = rq.dqd[(j0 + l) * n + i];
        }
    }
}

// Writes lane l of x (len entries) to dst + (j0 + l) · stride for the w lanes.
template <int W>
void scatter_lanes(const DualN<W>* x, int len, int j0, int w, std::ptrdiff_t stride, double* dst) {
    for (int l = 0; l < w; ++l) {
        double* o = dst + (j0 + l) * stride;
        for (int i = 0; i < len; ++i) o[i] = x[i].d[l];
    }
}

// Program::residual_tangents for a program whose evaluation is templated on the scalar:
// eval(q, qd, need, terms) evaluates the terms on DualN<W> (W directions per pass).
template <int W, class Eval>
Status chunked_residual_tangents(const Program& p, const ResidualQuery& rq, DualResidualScratch<W>& s,
                                 Eval&& eval) {
    const int n = p.n(), m_all = p.m_all();
    s.size(n, p.k(), m_all, rq.nlam);
    const unsigned need = NEED_M | NEED_H | NEED_A | NEED_GAMMA | (rq.u != nullptr && p.k() > 0 ? NEED_B : 0u);
    for (int j0 = 0; j0 < rq.nd; j0 += W) {
        const int w = std::min(W, rq.nd - j0);
        seed_directions<W>(rq, n, j0, w, s.q.data(), s.qd.data());
        const Status st = eval(s.q.data(), s.qd.data(), need, s.terms);
        if (st != Status::ok) return st;
        residuals_from_terms(s.terms, p.constraints(), rq, s.rd.data(), s.rl.data(), s.rc.data());
        scatter_lanes<W>(s.rd.data(), n, j0, w, n, rq.r_dyn);
        scatter_lanes<W>(s.rl.data(), rq.nlam * n, j0, w, static_cast<std::ptrdiff_t>(rq.nlam) * n, rq.r_lam);
        scatter_lanes<W>(s.rc.data(), m_all, j0, w, m_all, rq.r_con);
    }
    return Status::ok;
}

}  // namespace nonmin
