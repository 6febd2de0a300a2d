// Bindings of the planar Program (nonmin/planar.hpp): a description filled element by element
// by src/nonmin/model/planar/_program.py, and the PlanarProgram built from it once.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <memory>
#include <tuple>

#include "nonmin/planar.hpp"
#include "nonmin/timefn.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

using PointT = std::tuple<int, double, double>;

PlanarPoint point(const PointT& p) { return PlanarPoint{std::get<0>(p), std::get<1>(p), std::get<2>(p)}; }

PlanarPrim prim(PlanarPrimKind kind, int constraint, int offset) {
    PlanarPrim p;
    p.kind = kind;
    p.constraint = constraint;
    p.offset = offset;
    return p;
}

// A Python profile t -> (f, ḟ, f̈) called from the engine (takes the GIL; a raised exception
// stays set as the thread's Python error and the evaluation returns callback_error).
std::function<bool(double, double*)> wrap_profile(nb::callable fn) {
    auto holder = std::make_shared<nb::object>(std::move(fn));
    return [holder](double t, double* f) -> bool {
        nb::gil_scoped_acquire gil;
        try {
            nb::object r = (*holder)(t);
            nb::sequence seq = nb::cast<nb::sequence>(r);
            if (nb::len(seq) != 3) {
                PyErr_SetString(PyExc_ValueError, "a drive profile must return (f, fd, fdd)");
                return false;
            }
            for (int i = 0; i < 3; ++i) f[i] = nb::cast<double>(seq[i]);
            return true;
        } catch (nb::python_error& e) {
            e.restore();
            return false;
        } catch (const std::exception& e) {
            PyErr_SetString(PyExc_TypeError, (std::string("drive profile: ") + e.what()).c_str());
            return false;
        }
    };
}

}  // namespace

void bind_planar(nb::module_& m) {
    nb::class_<PlanarDescription>(m, "PlanarDescription",
                                  "Plain-data description of a planar model (bodies, row primitives, "
                                  "forces, actuators), filled by nonmin.model.planar._program.")
        .def(nb::init<>())
        .def_prop_ro("n", [](const PlanarDescription& d) { return d.n; })
        .def_prop_ro("m_all", [](const PlanarDescription& d) { return d.m_all; })
        .def(
            "set_gravity",
            [](PlanarDescription& d, double gx, double gy) {
                d.gx = gx;
                d.gy = gy;
            },
            nb::arg("gx"), nb::arg("gy"))
        .def("add_body", &PlanarDescription::add_body, nb::arg("mass"), nb::arg("inertia"),
             "Body index; inertia ≤ 0 makes a point mass (coordinates x, y only).")
        .def(
            "add_constraint",
            [](PlanarDescription& d, const std::string& name, int kind, int dim) {
                if (kind < 0 || kind > 3) throw EngineError("constraint kind must be 0..3");
                return d.add_constraint(name, static_cast<ConstraintKind>(kind), dim);
            },
            nb::arg("name"), nb::arg("kind"), nb::arg("dim"))
        .def(
            "add_pin",
            [](PlanarDescription& d, int c, int off, PointT a, PointT b) {
                PlanarPrim p = prim(PlanarPrimKind::pin, c, off);
                p.a = point(a);
                p.b = point(b);
                d.prims.push_back(p);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("a"), nb::arg("b"))
        .def(
            "add_line",
            [](PlanarDescription& d, int c, int off, PointT a, double ux, double uy, PointT b, double roll) {
                PlanarPrim p = prim(PlanarPrimKind::line, c, off);
                p.a = point(a);
                p.b = point(b);
                p.ux = ux;
                p.uy = uy;
                p.roll = roll;
                d.prims.push_back(p);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("a"), nb::arg("ux"), nb::arg("uy"), nb::arg("b"),
            nb::arg("roll") = 0.0)
        .def(
            "add_rod",
            [](PlanarDescription& d, int c, int off, PointT a, PointT b, double length, double sign) {
                PlanarPrim p = prim(PlanarPrimKind::rod, c, off);
                p.a = point(a);
                p.b = point(b);
                p.length = length;
                p.sign = sign;
                d.prims.push_back(p);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("a"), nb::arg("b"), nb::arg("length"),
            nb::arg("sign"))
        .def(
            "add_angle",
            [](PlanarDescription& d, int c, int off, std::vector<int> bodies, std::vector<double> coefs,
               double c0, int driver) {
                PlanarPrim p = prim(PlanarPrimKind::angle, c, off);
                p.angle_bodies = std::move(bodies);
                p.angle_coefs = std::move(coefs);
                p.angle_const = c0;
                p.driver = driver;
                d.prims.push_back(p);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("bodies"), nb::arg("coefs"), nb::arg("const"),
            nb::arg("driver") = -1)
        .def(
            "add_driver",
            [](PlanarDescription& d, double start, double speed) {
                PlanarDriver dr;
                dr.fn = TimeFunction::constant_speed(start, speed);
                d.drivers.push_back(dr);
                return static_cast<int>(d.drivers.size()) - 1;
            },
            nb::arg("start"), nb::arg("speed"), "A constant-speed profile f = start + speed·t.")
        .def(
            "add_driver_callback",
            [](PlanarDescription& d, nb::callable fn) {
                PlanarDriver dr;
                dr.fn.kind = TimeFunction::callback;
                dr.fn.fn = wrap_profile(std::move(fn));
                d.drivers.push_back(dr);
                return static_cast<int>(d.drivers.size()) - 1;
            },
            nb::arg("profile"), "A Python profile t -> (f, fd, fdd) (the program is then not thread safe).")
        .def(
            "add_driver_function",
            [](PlanarDescription& d, const TimeFunction& fn) {
                d.drivers.push_back(PlanarDriver{fn});
                return static_cast<int>(d.drivers.size()) - 1;
            },
            nb::arg("fn"), "A TimeFunction (pieces, expression tape or callback).")
        .def(
            "set_drivers",
            [](PlanarDescription& d, int prim_index, int driver, int driver2) {
                if (prim_index < 0) prim_index += static_cast<int>(d.prims.size());
                if (prim_index < 0 || prim_index >= static_cast<int>(d.prims.size()))
                    throw EngineError("set_drivers: primitive index out of range");
                d.prims[static_cast<std::size_t>(prim_index)].driver = driver;
                d.prims[static_cast<std::size_t>(prim_index)].driver2 = driver2;
            },
            nb::arg("prim"), nb::arg("driver"), nb::arg("driver2") = -1,
            "Attach drivers to a primitive (−1: the last added): it then subtracts f(t).")
        .def(
            "add_coord",
            [](PlanarDescription& d, int c, int off, std::vector<int> coords, std::vector<double> coefs,
               double c0, int driver) {
                PlanarPrim p = prim(PlanarPrimKind::coord, c, off);
                p.coords = std::move(coords);
                p.angle_coefs = std::move(coefs);
                p.angle_const = c0;
                p.driver = driver;
                d.prims.push_back(p);
            },
            nb::arg("constraint"), nb::arg("offset"), nb::arg("coords"), nb::arg("coefs"), nb::arg("const"),
            nb::arg("driver") = -1)
        .def(
            "add_spring",
            [](PlanarDescription& d, PointT a, PointT b, double k, double L0, double c) {
                d.springs.push_back(PlanarSpring{point(a), point(b), k, L0, c});
            },
            nb::arg("a"), nb::arg("b"), nb::arg("stiffness"), nb::arg("rest_length"), nb::arg("damping"))
        .def(
            "add_rotational_spring",
            [](PlanarDescription& d, int ba, int bb, double k, double th0, double c) {
                d.rotational_springs.push_back(PlanarRotationalSpring{ba, bb, k, th0, c});
            },
            nb::arg("body_a"), nb::arg("body_b"), nb::arg("stiffness"), nb::arg("rest_angle"),
            nb::arg("damping"))
        .def(
            "add_torque",
            [](PlanarDescription& d, int ba, int bb) {
                PlanarActuator a;
                a.kind = PlanarActuatorKind::torque;
                a.body_a = ba;
                a.body_b = bb;
                d.actuators.push_back(a);
            },
            nb::arg("body_a"), nb::arg("body_b"))
        .def(
            "add_prismatic_actuator",
            [](PlanarDescription& d, PointT pa, double ux, double uy, PointT pb) {
                PlanarActuator a;
                a.kind = PlanarActuatorKind::prismatic;
                a.a = point(pa);
                a.b = point(pb);
                a.ux = ux;
                a.uy = uy;
                d.actuators.push_back(a);
            },
            nb::arg("a"), nb::arg("ux"), nb::arg("uy"), nb::arg("b"))
        .def(
            "add_force",
            [](PlanarDescription& d, PointT p, double dx, double dy) {
                PlanarActuator a;
                a.kind = PlanarActuatorKind::force;
                a.a = point(p);
                a.ux = dx;
                a.uy = dy;
                d.actuators.push_back(a);
            },
            nb::arg("point"), nb::arg("dx"), nb::arg("dy"));

    nb::class_<PlanarProgram, Program>(m, "PlanarProgram",
                                       "The Program of a planar model (constant M, C = 0).")
        .def(
            "__init__",
            [](PlanarProgram* self, const PlanarDescription& d) {
                try {
                    new (self) PlanarProgram(d);
                } catch (const EngineError& e) {
                    raise_error("ModelError", std::string("planar description: ") + e.what());
                }
            },
            nb::arg("description"));
}

}  // namespace nonmin::bindings
