// Bindings of TimeFunction (nonmin/timefn.hpp): built by src/nonmin/model/_timefn.py and handed
// to the model descriptions' driver entries (planar, spatial, robots).
#include <nanobind/nanobind.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/function.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <memory>

#include "nonmin/timefn.hpp"
#include "nonmin/types.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nb = nanobind;

namespace nonmin::bindings {

std::function<bool(double, double*)> wrap_time_callback(nb::callable fn) {
    auto holder = std::make_shared<nb::object>(std::move(fn));
    return [holder](double t, double* f) -> bool {
        nb::gil_scoped_acquire gil;
        try {
            nb::object r = (*holder)(t);
            nb::sequence seq = nb::cast<nb::sequence>(r);
            if (nb::len(seq) != 3) {
                PyErr_SetString(PyExc_ValueError, "a time function must return (f, fd, fdd)");
                return false;
            }
            for (int i = 0; i < 3; ++i) f[i] = nb::cast<double>(seq[i]);
            return true;
        } catch (nb::python_error& e) {
            e.restore();
            return false;
        } catch (const std::exception& e) {
            PyErr_SetString(PyExc_TypeError, (std::string("time function: ") + e.what()).c_str());
            return false;
        }
    };
}

namespace {

TimeFunction checked(TimeFunction f) {
    try {
        f.validate("time function");
    } catch (const EngineError& e) {
        raise_error("ModelError", e.what());
    }
    return f;
}

}  // namespace

void bind_timefn(nb::module_& m) {
    nb::class_<TimeFunction>(m, "TimeFunction",
                             "A prescribed motion f(t) (pieces, expression tape or callback) for drivers.")
        .def_static(
            "pieces",
            [](std::vector<double> breaks, std::vector<double> coefs, int degree, bool hold) {
                TimeFunction f;
                f.kind = TimeFunction::pieces;
                f.breaks = std::move(breaks);
                f.coefs = std::move(coefs);
                f.degree = degree;
                f.hold = hold;
                return checked(std::move(f));
            },
            nb::arg("breaks"), nb::arg("coefs"), nb::arg("degree"), nb::arg("hold") = false)
        .def_static(
            "tape",
            [](std::vector<int> op, std::vector<int> a, std::vector<int> b, std::vector<double> c,
               std::array<int, 3> out) {
                TimeFunction f;
                f.kind = TimeFunction::tape;
                f.op = std::move(op);
                f.a = std::move(a);
                f.b = std::move(b);
                f.c = std::move(c);
                f.out = out;
                return checked(std::move(f));
            },
            nb::arg("op"), nb::arg("a"), nb::arg("b"), nb::arg("c"), nb::arg("out"))
        .def_static(
            "callback",
            [](nb::callable fn) {
                TimeFunction f;
                f.kind = TimeFunction::callback;
                f.fn = wrap_time_callback(std::move(fn));
                return f;
            },
            nb::arg("fn"))
        .def_prop_ro("kind", [](const TimeFunction& f) { return f.kind; })
        .def(
            "__call__",
            [](const TimeFunction& f, double t) {
                std::vector<double> scratch(static_cast<std::size_t>(f.scratch_size()) + 1);
                double out[3] = {0.0, 0.0, 0.0};
                const int st = f.eval(t, out, scratch.data());
                if (st == TimeFunction::EVAL_FAILED) throw nb::python_error();
                return nb::make_tuple(out[0], out[1], out[2]);
            },
            nb::arg("t"), "(f, ḟ, f̈) at t (a test hook; drivers evaluate in C++).");
}

}  // namespace nonmin::bindings
