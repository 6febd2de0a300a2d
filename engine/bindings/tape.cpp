// Bindings of the expression-tape Program (nonmin/tape.hpp), built by
// src/nonmin/model/symbolic/_tape.py from SymPy expressions.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <tuple>

#include "nonmin/tape.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

using IArr = nb::ndarray<const std::int32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

std::vector<int> ints(const IArr& x) { return std::vector<int>(x.data(), x.data() + x.shape(0)); }

}  // namespace

void bind_tape(nb::module_& m) {
    nb::class_<TapeProgram, Program>(m, "TapeProgram",
                                     "A model compiled to an expression tape (straight-line code).")
        .def(
            "__init__",
            [](TapeProgram* self, int n, int k, std::vector<std::tuple<std::string, int, int>> constraints,
               IArr op, IArr a, IArr b, CArr1 c, IArr out_target, IArr out_index, IArr out_reg,
               std::vector<double> params) {
                TapeDescription d;
                d.n = n;
                d.k = k;
                d.n_params = static_cast<int>(params.size());
                int row = 0;
                for (const auto& [name, kind, dim] : constraints) {
                    if (kind < 0 || kind > 3) raise_error("ModelError", "tape: constraint kind must be 0..3");
                    d.constraints.push_back(ConstraintInfo{name, static_cast<ConstraintKind>(kind), row, dim});
                    row += dim;
                }
                d.op = ints(op);
                d.a = ints(a);
                d.b = ints(b);
                d.c.assign(c.data(), c.data() + c.shape(0));
                d.out_target = ints(out_target);
                d.out_index = ints(out_index);
                d.out_reg = ints(out_reg);
                try {
                    new (self) TapeProgram(std::move(d), std::move(params));
                } catch (const EngineError& e) {
                    raise_error("ModelError", std::string("expression tape: ") + e.what());
                }
            },
            nb::arg("n"), nb::arg("k"), nb::arg("constraints"), nb::arg("op"), nb::arg("a"), nb::arg("b"),
            nb::arg("c"), nb::arg("out_target"), nb::arg("out_index"), nb::arg("out_reg"), nb::arg("params"))
        .def_prop_ro("size", &TapeProgram::size, "Number of instructions.")
        .def_prop_ro("n_inputs", &TapeProgram::n_inputs, "Input registers: t, q, qd, parameters.");
}

}  // namespace nonmin::bindings
