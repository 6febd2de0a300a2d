// Bindings of the spatial Program (nonmin/spatial.hpp): a description filled by
// src/nonmin/model/spatial/_program.py from the model's row plan, and the SpatialProgram.
#include <nanobind/nanobind.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <array>
#include <utility>

#include "nonmin/spatial.hpp"
#include "nonmin/timefn.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

std::vector<SpatialTerm> terms(const std::vector<std::pair<int, double>>& x) {
    std::vector<SpatialTerm> out;
    for (const auto& [k, c] : x) out.push_back(SpatialTerm{k, c});
    return out;
}

}  // namespace

void bind_spatial(nb::module_& m) {
    nb::class_<SpatialDescription>(m, "SpatialDescription",
                                   "Plain-data description of a spatial quaternion model (bodies, "
                                   "attachments, rows φ = X·Y, springs, actuators).")
        .def(nb::init<>())
        .def_prop_ro("m_all", [](const SpatialDescription& d) { return d.m_all; })
        .def(
            "set_gravity", [](SpatialDescription& d, std::array<double, 3> g) { d.gravity = g; }, nb::arg("g"))
        .def(
            "add_body",
            [](SpatialDescription& d, double mass, std::array<double, 9> inertia) {
                d.bodies.push_back(SpatialBody{mass, inertia});
                return static_cast<int>(d.bodies.size()) - 1;
            },
            nb::arg("mass"), nb::arg("inertia"), "inertia: body-frame 3 × 3 about the COM, row-major.")
        .def(
            "add_attachment",
            [](SpatialDescription& d, int body, bool point, CArr1 Q, std::array<double, 3> value) {
                if (Q.shape(0) != 48) raise_error("ShapeError", "Q must have 48 entries (3, 4, 4)");
                SpatialAttachment a;
                a.body = body;
                a.point = point;
                std::copy(Q.data(), Q.data() + 48, a.Q.begin());
                a.value = value;
                d.attachments.push_back(a);
                return static_cast<int>(d.attachments.size()) - 1;
            },
            nb::arg("body"), nb::arg("point"), nb::arg("Q"), nb::arg("value"),
            "A world-frame attachment: body point / vector with point tensor Q(s) (flattened), or "
            "the constant `value` on the ground (body −1).")
        .def(
            "add_constraint",
            [](SpatialDescription& d, const std::string& name, int kind, int dim) {
                if (kind < 0 || kind > 3) throw EngineError("constraint kind must be 0..3");
                return d.add_constraint(name, static_cast<ConstraintKind>(kind), dim);
            },
            nb::arg("name"), nb::arg("kind"), nb::arg("dim"))
        .def(
            "add_norm_row",
            [](SpatialDescription& d, int c, int off, int body) {
                SpatialRow r;
                r.constraint = c;
                r.offset = off;
                r.norm_body = body;
                if (body < 0) raise_error("ModelError", "norm row: body index must be ≥ 0");
                d.rows.push_back(r);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("body"))
        .def(
            "add_dot_row",
            [](SpatialDescription& d, int c, int off, std::vector<std::pair<int, double>> x,
               std::vector<std::pair<int, double>> y) {
                SpatialRow r;
                r.constraint = c;
                r.offset = off;
                r.x = terms(x);
                r.y = terms(y);
                d.rows.push_back(r);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("x"), nb::arg("y"),
            "A row φ = X·Y with X = Σ coef·x_k over (attachment, coef) pairs, Y likewise.")
        .def(
            "add_driver",
            [](SpatialDescription& d, const TimeFunction& fn) {
                d.drivers.push_back(fn);
                return static_cast<int>(d.drivers.size()) - 1;
            },
            nb::arg("fn"), "A prescribed motion (TimeFunction); returns its index.")
        .def(
            "set_row_driver",
            [](SpatialDescription& d, int driver, double square) {
                if (d.rows.empty()) throw EngineError("set_row_driver: no row yet");
                d.rows.back().driver = driver;
                d.rows.back().square = square;
            },
            nb::arg("driver"), nb::arg("square") = 0.0,
            "The last added row subtracts g(t) = f(t) (square = 0) or square·f(t)².")
        .def(
            "add_angle_row",
            [](SpatialDescription& d, int c, int off, std::vector<std::pair<int, double>> x,
               std::vector<std::pair<int, double>> y, std::vector<std::pair<int, double>> x2,
               std::vector<std::pair<int, double>> y2, int driver) {
                SpatialRow r;
                r.constraint = c;
                r.offset = off;
                r.x = terms(x);
                r.y = terms(y);
                r.x2 = terms(x2);
                r.y2 = terms(y2);
                r.angle = true;
                r.driver = driver;
                d.rows.push_back(r);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("x"), nb::arg("y"), nb::arg("x2"), nb::arg("y2"),
            nb::arg("driver"), "An angle-driver row φ = sin(θ − f): P1 = X·Y = cos θ, P2 = X2·Y2 = sin θ.")
        .def(
            "add_spring",
            [](SpatialDescription& d, int a, int b, double k, double L0, double c) {
                d.springs.push_back(SpatialSpring{a, b, k, L0, c});
            },
            nb::arg("a"), nb::arg("b"), nb::arg("stiffness"), nb::arg("rest_length"), nb::arg("damping"))
        .def(
            "add_rotation_actuator",
            [](SpatialDescription& d, int axis, int body_a, int body_b) {
                SpatialActuator a;
                a.kind = SpatialActuatorKind::rotation;
                a.axis = axis;
                a.body_a = body_a;
                a.body_b = body_b;
                d.actuators.push_back(a);
            },
            nb::arg("axis"), nb::arg("body_a"), nb::arg("body_b"))
        .def(
            "add_translation_actuator",
            [](SpatialDescription& d, int axis, int pa, int pb) {
                SpatialActuator a;
                a.kind = SpatialActuatorKind::translation;
                a.axis = axis;
                a.pa = pa;
                a.pb = pb;
                d.actuators.push_back(a);
            },
            nb::arg("axis"), nb::arg("pa"), nb::arg("pb"));

    nb::class_<SpatialProgram, Program>(m, "SpatialProgram", "The Program of a spatial quaternion model.")
        .def(
            "__init__",
            [](SpatialProgram* self, const SpatialDescription& d) {
                try {
                    new (self) SpatialProgram(d);
                } catch (const EngineError& e) {
                    raise_error("ModelError", std::string("spatial description: ") + e.what());
                }
            },
            nb::arg("description"));
}

}  // namespace nonmin::bindings
