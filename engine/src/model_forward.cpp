// Forward dynamics from a state: Program evaluation + core solve (see nonmin/forward.hpp).
#include "nonmin/forward.hpp"

#include <cmath>

namespace nonmin {

namespace {

int active_rows(const Program& p, const std::uint8_t* active) {
    int m = 0;
    const auto& cs = p.constraints();
    for (std::size_t i = 0; i < cs.size(); ++i)
        if (active[i]) m += cs[i].dim;
    return m;
}

}  // namespace

ForwardScratch::ForwardScratch(const Program& p, const std::uint8_t* act)
    : terms(p.make_terms()),
      ws(p.make_workspace()),
      solver(std::max(active_rows(p, act), 1), p.n()),
      active(act, act + p.constraints().size()) {
    const auto& cs = p.constraints();
    for (std::size_t i = 0; i < cs.size(); ++i)
        if (active[i])
            for (int r = 0; r < cs[i].dim; ++r) rows.push_back(cs[i].row + r);
    m = static_cast<int>(rows.size());
    for (int r = 0; r < m; ++r)
        if (rows[static_cast<std::size_t>(r)] != r) contiguous = false;
    if (!contiguous) {
        A = Mat::Zero(m, p.n());
        gamma = Vec::Zero(m);
    }
    g = Vec::Zero(p.n());
    const RowPattern& pat = p.a_pattern();
    if (pat.known()) {
        pat_start.push_back(0);
        for (int r : rows) {
            pat_cols.insert(pat_cols.end(), pat.row(r), pat.row(r) + pat.count(r));
            pat_start.push_back(static_cast<int>(pat_cols.size()));
        }
    }
}

SolveInfo forward_dynamics(const Program& p, ForwardScratch& s, double t, const double* q,
                           const double* qd, const double* f, const SolveOptions& opt, double* qdd,
                           double* f_c) {
    SolveInfo info;
    unsigned need = NEED_H | NEED_A | NEED_GAMMA;
    const bool constant = p.constant_mass();
    if (!(constant && s.mass_known)) need |= NEED_M;
    info.status = p.evaluate(t, q, qd, s.active.data(), need, s.terms, *s.ws);
    if (info.status != Status::ok) return info;
    SolveOptions o = opt;
    if (!s.pat_start.empty() && o.a_start == nullptr) {
        o.a_start = s.pat_start.data();
        o.a_cols = s.pat_cols.data();
    }
    if (constant) {
        if (!s.mass_known) {
            // validate the constant M once (finite, symmetric); diagonal M takes the fast path
            const Mat& M = s.terms.M;
            const int n = p.n();
            double scale = 0.0, asym = 0.0;
            bool finite = true, diagonal = true;
            for (int i = 0; i < n; ++i)
                for (int j = 0; j < n; ++j) {
                    const double v = M(i, j);
                    if (!std::isfinite(v)) finite = false;
                    scale = std::max(scale, std::fabs(v));
                    asym = std::max(asym, std::fabs(v - M(j, i)));
                    if (i != j && v != 0.0) diagonal = false;
                }
            if (finite && asym <= opt.sym_rtol * scale) {
                s.known = KNOWN_M_VALID | (diagonal ? KNOWN_M_DIAGONAL : 0u);
                s.mass_known = true;
            }
        }
        o.known |= s.known;
    }
    s.g = s.terms.h + s.terms.f_passive;
    if (f != nullptr) s.g += CVecMap(f, p.n());
    const double* A = s.terms.A.data();
    const double* gamma = s.terms.gamma.data();
    if (!s.contiguous) {
        for (int r = 0; r < s.m; ++r) {
            const int src = s.rows[static_cast<std::size_t>(r)];
            s.A.row(r) = s.terms.A.row(src);
            s.gamma[r] = s.terms.gamma[src];
        }
        A = s.A.data();
        gamma = s.gamma.data();
    }
    return s.solver.forward(s.terms.M.data(), s.g.data(), A, s.m, gamma, o, qdd, f_c);
}

}  // namespace nonmin
