// Bindings of the compiled controllers (nonmin/sim/control.hpp): SimControl (Regulator, the
// Tracker's computed torque, ForceControl over either), the time signals they evaluate
// (SimTimeSignal: the engine's TimeFunctions, which SimPiecewisePolynomial builds from PPoly's
// layout; SimPySignal, a Python function called back) and the SimController base
// SimLoop takes.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/pair.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <memory>

#include <string>
#include <utility>
#include <vector>

#include "nonmin/program.hpp"
#include "nonmin/sim/control.hpp"
#include "register.hpp"

namespace nb = nanobind;

namespace nonmin::bindings {

namespace {

using CArr1 = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using CArr2 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using CArr3 = nb::ndarray<const double, nb::ndim<3>, nb::c_contig, nb::device::cpu>;

[[noreturn]] void raise_input(const std::string& msg) {
    nb::object type = nb::module_::import_("nonmin.errors").attr("InputError");
    PyErr_SetString(type.ptr(), msg.c_str());
    throw nb::python_error();
}

// A Python function of time: fn(t) -> float64 array of shape (3, dim) (value and two derivatives,
// `triple`) or (dim,). Any exception or a wrong result is a failure status: the loop hands over
// and the Python controller, calling the same function, raises what it raises.
class PySignal final : public sim::Signal {
  public:
    PySignal(nb::object fn, int dim, bool triple) : fn_(std::move(fn)), dim_(dim), triple_(triple) {}
    ~PySignal() override {
        nb::gil_scoped_acquire gil;
        fn_.reset();
    }
    int dim() const override { return dim_; }
    Status eval(double t, double* x, double* v, double* a) override {
        nb::gil_scoped_acquire gil;
        try {
            nb::object r = fn_(t);
            auto arr = nb::cast<nb::ndarray<const double, nb::c_contig, nb::device::cpu>>(r);
            const std::size_t want = static_cast<std::size_t>(dim_) * (triple_ ? 3 : 1);
            if (arr.size() != want) return Status::bad_shape;
            const double* p = arr.data();
            for (int i = 0; i < dim_; ++i) {
                x[i] = p[i];
                if (v) v[i] = triple_ ? p[dim_ + i] : 0.0;
                if (a) a[i] = triple_ ? p[2 * dim_ + i] : 0.0;
            }
        } catch (nb::python_error&) {
            return Status::not_finite;  // (discarded: the Python controller raises it again)
        } catch (nb::cast_error&) {
            return Status::bad_shape;
        }
        return Status::ok;
    }

  private:
    nb::object fn_;
    int dim_;
    bool triple_;
};

// A Python controller called back: fn(t, q, qd, active: bytes, u_out) writes u (what a compiled
// controller evaluates for an active set it was not compiled for). An exception is left set on
// the thread (SimLoop raises it: callback_error).
class PyFallback final : public sim::Controller {
  public:
    PyFallback(nb::object fn, int n, int k, int c) : fn_(std::move(fn)), n_(n), k_(k), c_(c) {}
    ~PyFallback() override {
        nb::gil_scoped_acquire gil;
        fn_.reset();
    }
    Status control(double t, const double* q, const double* qd, const std::uint8_t* active, double* u) override {
        nb::gil_scoped_acquire gil;
        try {
            std::vector<double> qv(q, q + n_), qdv(qd, qd + n_);
            nb::bytes mask(reinterpret_cast<const char*>(active), static_cast<std::size_t>(c_));
            nb::object r = fn_(t, nb::cast(qv), nb::cast(qdv), mask);
            auto v = nb::cast<std::vector<double>>(r);
            if (static_cast<int>(v.size()) != k_) return Status::bad_shape;
            for (int j = 0; j < k_; ++j) u[j] = v[static_cast<std::size_t>(j)];
        } catch (nb::python_error& e) {
            e.restore();
            return Status::callback_error;
        } catch (nb::cast_error&) {
            return Status::bad_shape;
        }
        return Status::ok;
    }

  private:
    nb::object fn_;
    int n_, k_, c_;
};

// The controller with the Python objects it borrows kept alive.
struct SimControl final : sim::Projected {
    SimControl(const Program& prog, sim::ControlSpec spec) : sim::Projected(prog, std::move(spec)) {}
    std::vector<nb::object> keep;
    std::unique_ptr<PyFallback> fallback;
};

}  // namespace

void bind_control(nb::module_& m) {
    nb::class_<sim::Controller>(m, "SimController", "A controller the engine's loop evaluates (compiled).");
    nb::class_<sim::Signal>(m, "SimSignal", "A function of time the compiled controllers evaluate.")
        .def_prop_ro("dim", &sim::Signal::dim)
        .def(
            "__call__",
            [](sim::Signal& s, double t) {
                const int d = s.dim();
                std::vector<double> x(static_cast<std::size_t>(3 * d));
                Status st;
                {
                    nb::gil_scoped_release release;
                    st = s.eval(t, x.data(), x.data() + d, x.data() + 2 * d);
                }
                if (st != Status::ok) raise_input("the signal could not be evaluated at t = " + std::to_string(t));
                return x;
            },
            nb::arg("t"), "(value, first derivative, second derivative) at t, concatenated.");
    nb::class_<sim::TimeSignal, sim::Signal>(
        m, "SimTimeSignal",
        "A vector of TimeFunctions (pieces or tapes), one per component; hold: outside [lo, hi] "
        "(strictly) the end values with zero derivatives.")
        .def(
            "__init__",
            [](sim::TimeSignal* self, std::vector<TimeFunction> f, bool hold, double lo, double hi) {
                try {
                    new (self) sim::TimeSignal(std::move(f), hold, lo, hi);
                } catch (const EngineError& e) {
                    raise_input(e.what());
                }
            },
            nb::arg("functions"), nb::arg("hold") = false, nb::arg("lo") = 0.0, nb::arg("hi") = 0.0);
    m.def(
        "SimPiecewisePolynomial",
        [](CArr1 x, CArr3 c, bool hold) {
            std::vector<double> xv(x.data(), x.data() + x.shape(0));
            std::vector<double> cv(c.data(), c.data() + c.size());
            if (c.shape(1) + 1 != x.shape(0))
                raise_input("SimPiecewisePolynomial: c must have shape (order, len(x) - 1, dim)");
            try {
                return sim::TimeSignal::from_ppoly(xv, cv, static_cast<int>(c.shape(0)), static_cast<int>(c.shape(2)),
                                                   hold);
            } catch (const EngineError& e) {
                raise_input(e.what());
            }
        },
        nb::arg("x"), nb::arg("c"), nb::arg("hold"),
        "scipy.interpolate.PPoly's layout as a SimTimeSignal: breakpoints x (p + 1,), coefficients c "
        "(order, p, dim); hold: constant outside [x_0, x_p] with zero derivatives, else the end pieces "
        "extend.");
    nb::class_<PySignal, sim::Signal>(m, "SimPySignal",
                                      "A Python function t -> array (3, dim) (triple) or (dim,), called back.")
        .def(nb::init<nb::object, int, bool>(), nb::arg("fn"), nb::arg("dim"), nb::arg("triple"));

    m.def("sim_passivity_supported", &sim::passivity_supported, nb::arg("program"),
          "Whether the Tracker's passivity law compiles for this program (C and Ȧ in the engine: a "
          "constant mass matrix or a rigid-body tree).");
    nb::class_<SimControl, sim::Controller>(
        m, "SimControl", nb::dynamic_attr(),
        "nonmin.control's Regulator (σ = 0), Tracker (computed torque, passivity) and ForceControl over either, "
        "compiled for one active set of the loop.")
        .def(
            "__init__",
            [](SimControl* self, const Program& prog, int law, CArr1 q_star, CArr2 Kp, CArr2 Kd,
               const std::vector<std::array<int, 4>>& qblocks, CArr1 u_min, CArr1 u_max, double rtol,
               bool raise_infeasible, bool project_target, bool reject, bool mass_metric,
               const std::vector<int>& fixed, nb::object reference,
               const std::vector<std::pair<int, nb::object>>& forces, nb::object other_active_set, double lambda, bool own_terms, double sigma,
               nb::object xi0) {
                auto vec = [](CArr1 a) { return Vec(CVecMap(a.data(), static_cast<Eigen::Index>(a.shape(0)))); };
                auto mat = [](CArr2 a) {
                    return Mat(CMatMap(a.data(), static_cast<Eigen::Index>(a.shape(0)),
                                       static_cast<Eigen::Index>(a.shape(1))));
                };
                if (law < 0 || law > 2)
                    raise_input("SimControl: law must be 0 (regulator), 1 (computed torque) or 2 (passivity)");
                sim::ControlSpec s;
                s.law = static_cast<sim::Law>(law);
                s.q_star = vec(q_star);
                s.Kp = mat(Kp);
                s.Kd = mat(Kd);
                s.qblocks = qblocks;
                s.u_min = vec(u_min);
                s.u_max = vec(u_max);
                s.rtol = rtol;
                s.raise_infeasible = raise_infeasible;
                s.project_target = project_target;
                s.reject = reject;
                s.mass_metric = mass_metric;
                s.fixed = fixed;
                s.lambda = lambda;
                s.own_terms = own_terms;
                s.sigma = sigma;
                if (!xi0.is_none()) s.xi0 = vec(nb::cast<CArr1>(xi0));
                std::vector<nb::object> keep;
                if (!reference.is_none()) {
                    s.reference = nb::cast<sim::Signal*>(reference);
                    keep.push_back(reference);
                }
                for (const auto& [con, sig] : forces) {
                    s.forces.emplace_back(con, nb::cast<sim::Signal*>(sig));
                    keep.push_back(sig);
                }
                std::unique_ptr<PyFallback> fb;
                if (!other_active_set.is_none()) {
                    fb = std::make_unique<PyFallback>(other_active_set, prog.n(), prog.k(),
                                                      static_cast<int>(prog.constraints().size()));
                    s.other_active_set = fb.get();
                }
                try {
                    new (self) SimControl(prog, std::move(s));
                } catch (const EngineError& e) {
                    raise_input(e.what());
                }
                self->keep = std::move(keep);
                self->fallback = std::move(fb);
            },
            nb::arg("program"), nb::arg("law"), nb::arg("q_star"), nb::arg("Kp"), nb::arg("Kd"),
            nb::arg("quaternion_blocks"), nb::arg("u_min"), nb::arg("u_max"), nb::arg("rtol"),
            nb::arg("raise_infeasible"), nb::arg("project_target"), nb::arg("reject"), nb::arg("mass_metric"),
            nb::arg("fixed"), nb::arg("reference").none(), nb::arg("forces"),
            nb::arg("other_active_set").none() = nb::none(), nb::arg("lambda_") = 1.0, nb::arg("own_terms") = false, nb::arg("sigma") = 0.0,
            nb::arg("xi0").none() = nb::none())
        .def(
            "probe",
            [](SimControl& c, const Program& prog, double t, CArr1 q, CArr1 qd, const std::vector<int>& active) {
                const int n = prog.n();
                if (q.shape(0) != static_cast<std::size_t>(n) || qd.shape(0) != static_cast<std::size_t>(n) ||
                    active.size() != prog.constraints().size())
                    raise_input("SimControl.probe: q, qd need n entries and active one per constraint");
                std::vector<std::uint8_t> mask(active.begin(), active.end());
                std::vector<double> u(static_cast<std::size_t>(prog.k()));
                const Status st = c.probe(t, q.data(), qd.data(), mask.data(), u.data());
                if (st != Status::ok) raise_input("SimControl.probe: the compiled law failed (status " +
                                                  std::to_string(static_cast<int>(st)) + ")");
                nb::dict d;
                d["u"] = u;
                d["lyapunov"] = c.lyapunov();
                d["target"] = std::vector<double>(c.target().data(), c.target().data() + n);
                return d;
            },
            nb::arg("program"), nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("active"),
            "One law evaluation at (t, q, qd) with the active mask (0/1 per constraint), outside the loop: "
            "{'u', 'lyapunov', 'target'} (ControlInfo's u, lyapunov and target; for the tests).")
        .def_prop_ro("lyapunov", &SimControl::lyapunov, "W of the last law evaluation (NaN: the law has none).")
        .def_prop_ro("stats", [](const SimControl& r) {
            nb::dict d;
            d["steps"] = r.steps;
            d["infeasible_steps"] = r.infeasible_steps;
            d["saturated_steps"] = r.saturated_steps;
            d["saturated"] = std::vector<bool>(r.saturated.begin(), r.saturated.end());
            d["min_sigma_pb"] = r.min_sigma_pb;
            d["max_abs_u"] = r.max_abs_u;
            d["fast_actuations"] = r.fast_actuations;
            d["svd_actuations"] = r.svd_actuations;
            return d;
        });
}

}  // namespace nonmin::bindings
