// Bindings of the event layer's kernel (sim/events.hpp): the multiplier-free mass-metric
// projection onto a polyhedron behind nonmin.core.polyhedral_projection (and so behind
// simultaneous impacts), called on validated arrays.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/tuple.h>

#include <string>
#include <vector>

#include "nonmin/sim/events.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

void bind_events(nb::module_& m) {
    m.def(
        "polyhedral_projection",
        [](CArr2 M, CArr1 x0, CArr2 A_eq, CArr1 r_eq, CArr2 A_in, CArr1 r_in, double rtol) {
            const int n = static_cast<int>(M.shape(0));
            const int m_eq = static_cast<int>(A_eq.shape(0)), m_in = static_cast<int>(A_in.shape(0));
            if (M.shape(1) != M.shape(0) || x0.shape(0) != M.shape(0) || (m_eq && A_eq.shape(1) != M.shape(0)) ||
                (m_in && A_in.shape(1) != M.shape(0)) || r_eq.shape(0) != A_eq.shape(0) ||
                r_in.shape(0) != A_in.shape(0))
                raise_error("ShapeError", "polyhedral_projection: inconsistent shapes");
            Solver S(std::max(m_eq + m_in, 1), n);
            SolveOptions so;
            so.rtol = rtol;
            sim::PolyWork w;
            w.reserve(m_eq + m_in, n);
            NpArr x = new_array({static_cast<std::size_t>(n)});
            std::vector<std::uint8_t> at(static_cast<std::size_t>(std::max(m_in, 1)), 0);
            Status st = Status::ok;
            bool found;
            {
                nb::gil_scoped_release release;
                found = sim::polyhedral_projection(S, so, n, M.data(), x0.data(), A_eq.data(), r_eq.data(), m_eq,
                                                   A_in.data(), r_in.data(), m_in, x.data(), at.data(), w, st);
            }
            if (!found && st != Status::ok) raise_status(st, "polyhedral_projection");
            NpArr ab = new_array({static_cast<std::size_t>(m_in)});
            for (int i = 0; i < m_in; ++i) ab.data()[i] = at[static_cast<std::size_t>(i)];
            return nb::make_tuple(found, x, ab);
        },
        nb::arg("M"), nb::arg("x0"), nb::arg("A_eq"), nb::arg("r_eq"), nb::arg("A_in"), nb::arg("r_in"),
        nb::arg("rtol"),
        "argmin ½‖x − x0‖²_M over {A_eq x + r_eq = 0, A_in x + r_in ≥ 0}: (found, x, at_bound as 0/1).");
}

}  // namespace nonmin::bindings
