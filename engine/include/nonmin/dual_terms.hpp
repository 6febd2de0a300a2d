// Splitting the dual-number terms of a forward-mode evaluation (Program::evaluate_tangent) into
// the values and the directional derivatives, each a plain Terms.
#pragma once
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

}  // namespace nonmin
