// Bindings of the simulation layer (nonmin/sim/loop.hpp): the loop (SimLoop), its options, and
// the escape hatches into Python — PyProgram (any nonmin Model evaluated through a Python
// callback) and the Python controller — which hold the GIL only inside the callback.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "nonmin/program.hpp"
#include "nonmin/sim/control.hpp"
#include "nonmin/sim/loop.hpp"
#include "nonmin/sim/events.hpp"
#include "register.hpp"

namespace nb = nanobind;

namespace nonmin::bindings {

namespace {

using CArr1 = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using CMask = nb::ndarray<const std::uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using NpArr = nb::ndarray<nb::numpy, double>;

[[noreturn]] void raise_typed(const char* cls, const std::string& msg) {
    nb::object type = nb::module_::import_("nonmin.errors").attr(cls);
    PyErr_SetString(type.ptr(), msg.c_str());
    throw nb::python_error();
}

// A NumPy view of engine memory, valid while the memory lives (only handed to callbacks, which
// write into it; rv_policy::reference: no copy).
nb::object view(double* data, std::size_t r, std::size_t c, int ndim) {
    std::size_t shape[2] = {r, c};
    return nb::cast(NpArr(data, static_cast<std::size_t>(ndim), shape, nb::handle()), nb::rv_policy::reference);
}

// An owned copy of `len` values as a NumPy array of the given shape.
template <class T>
nb::ndarray<nb::numpy, T> copy_array(const T* src, std::vector<std::size_t> shape) {
    std::size_t size = 1;
    for (std::size_t s : shape) size *= s;
    T* data = new T[size > 0 ? size : 1];
    if (size) std::memcpy(data, src, size * sizeof(T));
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
    return nb::ndarray<nb::numpy, T>(data, shape.size(), shape.data(), owner);
}

// A Python exception raised inside a callback, kept until the engine returns to Python.
struct ErrorSlot {
    std::unique_ptr<nb::python_error> err;
    void keep(nb::python_error& e) {
        if (!err) err = std::make_unique<nb::python_error>(std::move(e));
    }
    bool rethrow_if_any() {  // (GIL held)
        if (!err) return false;
        nb::python_error e = std::move(*err);
        err.reset();
        throw e;
    }
};

}  // namespace

// Any Python nonmin Model as a Program: evaluate() calls `callback(t, q, qd, active, need, M, h,
// f_passive, B, A, gamma, phi, velocity) -> potential energy` (nonmin.sim._engine's adapter of
// Model.evaluate / mass_matrix / constraint_terms / potential_energy), which writes the terms
// into the views it is given. q and qd are fresh arrays (the model may keep them).
class PyProgram final : public Program {
  public:
    PyProgram(int n, int k, const std::vector<std::tuple<std::string, int, int, int>>& constraints,
              nb::object callback)
        : callback_(std::move(callback)) {
        n_ = n;
        k_ = k;
        int rows = 0;
        for (const auto& [name, kind, row, dim] : constraints) {
            if (row != rows || dim < 1 || kind < 0 || kind > 3)
                throw EngineError("PyProgram: constraints must be (name, kind 0..3, first row, rows ≥ 1) "
                                  "in stacked row order");
            constraints_.push_back({name, static_cast<ConstraintKind>(kind), row, dim});
            rows += dim;
        }
        m_all_ = rows;
    }
    ~PyProgram() override {
        nb::gil_scoped_acquire gil;
        errors.err.reset();
        callback_.reset();
    }

    Status evaluate(double t, const double* q, const double* qd, const std::uint8_t* active, unsigned need,
                    Terms& out, Workspace&) const override {
        nb::gil_scoped_acquire gil;
        if (need & NEED_ENERGY) need |= NEED_M;
        try {
            const auto n = static_cast<std::size_t>(n_), m = static_cast<std::size_t>(m_all_),
                       k = static_cast<std::size_t>(k_);
            auto qa = copy_array(q, {n});
            auto qda = copy_array(qd, {n});
            nb::bytes mask(reinterpret_cast<const char*>(active), constraints_.size());
            nb::object pot = callback_(t, qa, qda, mask, need, view(out.M.data(), n, n, 2),
                                       view(out.h.data(), n, 1, 1), view(out.f_passive.data(), n, 1, 1),
                                       view(out.B.data(), n, k, 2), view(out.A.data(), m, n, 2),
                                       view(out.gamma.data(), m, 1, 1), view(out.phi.data(), m, 1, 1),
                                       view(out.velocity.data(), m, 1, 1));
            if (need & NEED_ENERGY) {
                out.potential = nb::cast<double>(pot);
                double e = 0.0;
                for (int i = 0; i < n_; ++i) {
                    double s = 0.0;
                    for (int j = 0; j < n_; ++j) s += qd[j] * out.M(j, i);
                    e += s * qd[i];
                }
                out.kinetic = 0.5 * e;  // ½ (qdᵀ M) qd, as the Python driver
            }
        } catch (nb::python_error& e) {
            errors.keep(e);
            return Status::callback_error;
        } catch (const std::exception& e) {
            PyErr_SetString(PyExc_RuntimeError, e.what());
            nb::python_error pe;
            errors.keep(pe);
            return Status::callback_error;
        }
        return Status::ok;
    }

    bool thread_safe() const override { return false; }

    mutable ErrorSlot errors;

  private:
    nb::object callback_;
};

namespace {

// A Python controller: control(t, q, qd, active, u_out) writes u; update(t, q, qd, active).
class PyController final : public sim::Controller {
  public:
    PyController(nb::object control, nb::object update, int k)
        : control_(std::move(control)), update_(std::move(update)), k_(k) {}
    ~PyController() override {
        nb::gil_scoped_acquire gil;
        errors.err.reset();
        control_.reset();
        update_.reset();
    }
    Status control(double t, const double* q, const double* qd, const std::uint8_t* active,
                   double* u) override {
        return call([&](std::size_t n) {
            control_(t, copy_array(q, {n}), copy_array(qd, {n}), mask(active),
                     view(u, static_cast<std::size_t>(k_), 1, 1));
        });
    }
    Status update(double t, const double* q, const double* qd, const std::uint8_t* active) override {
        if (update_.is_none()) return Status::ok;
        return call([&](std::size_t n) { update_(t, copy_array(q, {n}), copy_array(qd, {n}), mask(active)); });
    }
    int n = 0, c = 0;
    ErrorSlot errors;

  private:
    nb::bytes mask(const std::uint8_t* active) const {
        return nb::bytes(reinterpret_cast<const char*>(active), static_cast<std::size_t>(c));
    }
    template <class F>
    Status call(F&& f) {
        nb::gil_scoped_acquire gil;
        try {
            f(static_cast<std::size_t>(n));
        } catch (nb::python_error& e) {
            errors.keep(e);
            return Status::callback_error;
        }
        return Status::ok;
    }
    nb::object control_, update_;
    int k_;
};

// The guards of the Python driver: check(t, q, qd, f_c) -> bool (a guard crossed in the step).
class PyWatch final : public sim::Watch {
  public:
    explicit PyWatch(nb::object check) : check_(std::move(check)) {}
    ~PyWatch() override {
        nb::gil_scoped_acquire gil;
        errors.err.reset();
        check_.reset();
    }
    Status check(double t, const double* q, const double* qd, const double* f_c, bool& fired) override {
        nb::gil_scoped_acquire gil;
        try {
            fired = nb::cast<bool>(check_(t, copy_array(q, {n}), copy_array(qd, {n}), copy_array(f_c, {n})));
        } catch (nb::python_error& e) {
            errors.keep(e);
            return Status::callback_error;
        }
        return Status::ok;
    }
    std::size_t n = 0;
    ErrorSlot errors;

  private:
    nb::object check_;
};

// The loop with what it borrows kept alive.
struct SimLoop {
    nb::object program_ref, compiled_ref;
    const Program* program = nullptr;
    std::unique_ptr<PyController> controller;
    std::unique_ptr<PyWatch> watch;
    std::unique_ptr<sim::Loop> loop;

    void rethrow() {
        if (auto* pp = dynamic_cast<const PyProgram*>(program)) pp->errors.rethrow_if_any();
        if (controller) controller->errors.rethrow_if_any();
        if (watch) watch->errors.rethrow_if_any();
        // a program's own callback (a planar drive profile, bindings/planar.cpp) leaves its
        // exception set on the thread: raise it (raise_typed would call Python with it pending,
        // which CPython reports as a SystemError)
        if (PyErr_Occurred()) throw nb::python_error();
        raise_typed("SimulationError", "a callback of the engine failed without a Python exception");
    }
    int finish(sim::Outcome o) {
        if (o == sim::Outcome::callback) rethrow();
        return static_cast<int>(o);
    }
};

}  // namespace

void bind_sim(nb::module_& m) {
    nb::class_<PyProgram, Program>(m, "PyProgram",
                                   "Any Python model as a Program, evaluated through a Python callback "
                                   "(the engine's escape hatch; the GIL is taken only in the callback).")
        .def(nb::init<int, int, const std::vector<std::tuple<std::string, int, int, int>>&, nb::object>(),
             nb::arg("n"), nb::arg("k"), nb::arg("constraints"), nb::arg("callback"),
             "constraints: (name, kind, first row, rows) in row order; callback(t, q, qd, active: bytes, "
             "need, M, h, f_passive, B, A, gamma, phi, velocity) writes the terms asked by `need` into "
             "the views and returns the potential energy (when NEED_ENERGY).");

    nb::enum_<sim::Method>(m, "SimMethod")
        .value("rk4", sim::Method::rk4)
        .value("dopri5", sim::Method::dopri5)
        .value("midpoint", sim::Method::midpoint)
        .value("dop853", sim::Method::dop853)
        .value("rk8", sim::Method::rk8);
    nb::enum_<sim::Stabilization>(m, "SimStabilization")
        .value("none", sim::Stabilization::none)
        .value("baumgarte", sim::Stabilization::baumgarte)
        .value("projection", sim::Stabilization::projection);

    nb::class_<sim::ProjectionOptions>(m, "SimProjection", "nonmin.sim.Projection's parameters.")
        .def(nb::init<>())
        .def_rw("tol", &sim::ProjectionOptions::tol)
        .def_rw("max_iter", &sim::ProjectionOptions::max_iter)
        .def_rw("velocity", &sim::ProjectionOptions::velocity)
        .def_rw("euclidean", &sim::ProjectionOptions::euclidean)
        .def_rw("velocity_rtol", &sim::ProjectionOptions::velocity_rtol)
        .def_rw("energy_level", &sim::ProjectionOptions::energy_level);

    nb::class_<sim::Options>(m, "SimOptions", "Settings of one run of the engine's loop.")
        .def(nb::init<>())
        .def_rw("method", &sim::Options::method)
        .def_rw("dt", &sim::Options::dt)
        .def_rw("rtol", &sim::Options::rtol)
        .def_rw("atol", &sim::Options::atol)
        .def_rw("h_max", &sim::Options::h_max)
        .def_rw("h_min_factor", &sim::Options::h_min_factor)
        .def_rw("h0", &sim::Options::h0)
        .def_rw("xtol", &sim::Options::xtol)
        .def_rw("max_iter", &sim::Options::max_iter)
        .def_rw("max_halvings", &sim::Options::max_halvings)
        .def_rw("stabilization", &sim::Options::stab)
        .def_rw("alpha", &sim::Options::alpha)
        .def_rw("beta", &sim::Options::beta)
        .def_rw("projection", &sim::Options::projection)
        .def_rw("project_initial", &sim::Options::project_initial)
        .def_rw("initial_projection", &sim::Options::initial_projection)
        .def_rw("rank_rtol", &sim::Options::rank_rtol)
        .def_rw("drift_factor", &sim::Options::drift_factor)
        .def_rw("spd_rtol", &sim::Options::spd_rtol)
        .def_rw("sym_rtol", &sim::Options::sym_rtol)
        .def_rw("t1", &sim::Options::t1)
        .def_rw("t_grid", &sim::Options::t_grid)
        .def_rw("max_steps", &sim::Options::max_steps)
        .def_rw("passages", &sim::Options::passages)
        .def_rw("partial_samples", &sim::Options::partial_samples);

    m.attr("SIM_DONE") = static_cast<int>(sim::Outcome::done);
    m.attr("SIM_HANDOVER") = static_cast<int>(sim::Outcome::handover);
    m.def(
        "sym_min_eigenvalue",
        [](nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu> G) {
            const auto k = G.shape(0);
            if (k == 0 || G.shape(1) != k) raise_typed("ShapeError", "G must be a nonempty square matrix");
            std::vector<double> X(G.data(), G.data() + k * k), d(k), e(3 * k);
            return sim::sym_min_eigenvalue(X.data(), static_cast<int>(k), d.data(), e.data());
        },
        nb::arg("G"),
        "The passage indicator's smallest eigenvalue of a symmetric matrix (its lower triangle; "
        "tests compare it with numpy.linalg.eigvalsh).");
    m.attr("SIM_EVENT") = static_cast<int>(sim::Outcome::event);
    m.attr("SIM_TRANSITION") = static_cast<int>(sim::Outcome::transition);

    nb::class_<SimLoop>(m, "SimLoop", "The engine's simulation loop over one Program and one active set.")
        .def(
            "__init__",
            [](SimLoop* self, nb::handle program, CMask active, const sim::Options& opt, CArr1 t_out, bool every,
               nb::object control, nb::object update, nb::object watch,
               const std::vector<std::tuple<bool, int, int, double>>& guards, nb::object compiled) {
                new (self) SimLoop();
                const Program& prog = nb::cast<const Program&>(program);
                if (active.shape(0) != prog.constraints().size())
                    raise_typed("ShapeError", "active must be a mask of shape (" +
                                                  std::to_string(prog.constraints().size()) + ",), got (" +
                                                  std::to_string(active.shape(0)) + ",)");
                self->program_ref = nb::borrow(program);
                self->program = &prog;
                if (!control.is_none()) {
                    self->controller = std::make_unique<PyController>(control, update, prog.k());
                    self->controller->n = prog.n();
                    self->controller->c = static_cast<int>(prog.constraints().size());
                }
                sim::Controller* ctrl = self->controller.get();
                if (!compiled.is_none()) {
                    if (ctrl) raise_typed("InputError", "SimLoop: a Python and a compiled controller");
                    self->compiled_ref = compiled;
                    ctrl = nb::cast<sim::Controller*>(compiled);  // bindings/control.cpp
                }
                std::vector<double> tv(t_out.data(), t_out.data() + t_out.shape(0));
                self->loop = sim::make_loop(prog, active.data(), opt, tv, every, ctrl);
                if (!guards.empty()) {
                    std::vector<sim::ContactGuard> gs;
                    for (const auto& [release, con, row, g] : guards) {
                        if (con < 0 || con >= static_cast<int>(prog.constraints().size()) || row < 0 ||
                            (release && row >= self->loop->m))
                            raise_typed("InputError", "SimLoop: a contact guard names no constraint or row");
                        gs.push_back({release, con, row, g});
                    }
                    sim::set_guards(*self->loop, gs);
                }
                if (!watch.is_none()) {
                    self->watch = std::make_unique<PyWatch>(watch);
                    self->watch->n = static_cast<std::size_t>(prog.n());
                    self->loop->watch = self->watch.get();
                }
            },
            nb::arg("program"), nb::arg("active"), nb::arg("options"), nb::arg("t_out"), nb::arg("every"),
            nb::arg("control").none() = nb::none(), nb::arg("update").none() = nb::none(),
            nb::arg("watch").none() = nb::none(),
            nb::arg("guards") = std::vector<std::tuple<bool, int, int, double>>{},
            nb::arg("compiled").none() = nb::none())
        .def(
            "resume",
            [](SimLoop& s, double t, CArr1 y, double h, long long n_steps, std::size_t out_i) {
                if (y.shape(0) != static_cast<std::size_t>(2 * s.loop->n))
                    raise_typed("ShapeError", "y must have shape (" + std::to_string(2 * s.loop->n) + ",)");
                sim::resume(*s.loop, t, y.data(), h, n_steps, out_i);
            },
            nb::arg("t"), nb::arg("y"), nb::arg("h"), nb::arg("n_steps"), nb::arg("out_i"),
            "Continue from a state reached by the event layer (no projection, no sample).")
        .def(
            "start",
            [](SimLoop& s, double t0, CArr1 q0, CArr1 qd0) {
                const auto n = static_cast<std::size_t>(s.loop->n);
                if (q0.shape(0) != n || qd0.shape(0) != n)
                    raise_typed("ShapeError", "q0 and qd0 must have shape (" + std::to_string(n) + ",)");
                sim::Outcome o;
                {
                    nb::gil_scoped_release release;
                    o = sim::start(*s.loop, t0, q0.data(), qd0.data());
                }
                return s.finish(o);
            },
            nb::arg("t0"), nb::arg("q0"), nb::arg("qd0"),
            "Initial projection, evaluation and sample; returns SIM_DONE or SIM_HANDOVER.")
        .def(
            "seed_passages",
            [](SimLoop& s, CArr1 ts, CArr1 ys) {
                const auto k = ts.shape(0);
                if (ys.shape(0) != k * static_cast<std::size_t>(2 * s.loop->n))
                    raise_typed("ShapeError", "ys must hold 2n values per time of ts");
                sim::passage_seed(*s.loop, ts.data(), ys.data(), static_cast<int>(k));
            },
            nb::arg("ts"), nb::arg("ys"),
            "The singular-passage history of a resumed run (earlier step ends, flattened (q, qd)).")
        .def(
            "run",
            [](SimLoop& s, long long max_steps) {
                sim::Outcome o;
                {
                    nb::gil_scoped_release release;
                    o = sim::run(*s.loop, max_steps);
                }
                return s.finish(o);
            },
            nb::arg("max_steps"),
            "Advance by at most max_steps accepted steps (GIL released); SIM_DONE or SIM_HANDOVER "
            "(the state is then the last accepted one).")
        .def(
            "take",
            [](SimLoop& s) {
                sim::Samples& R = s.loop->rec;
                const std::size_t N = R.size(), n = static_cast<std::size_t>(R.n),
                                  k = static_cast<std::size_t>(R.k), c = static_cast<std::size_t>(R.c);
                nb::dict d;
                d["t"] = copy_array(R.t.data(), {N});
                d["q"] = copy_array(R.q.data(), {N, n});
                d["qd"] = copy_array(R.qd.data(), {N, n});
                d["qdd"] = copy_array(R.qdd.data(), {N, n});
                d["f_c"] = copy_array(R.f_c.data(), {N, n});
                d["u"] = copy_array(R.u.data(), {N, k});
                d["active_mask"] = copy_array(R.active.data(), {N, c});
                d["rank"] = copy_array(R.rank.data(), {N});
                d["cond"] = copy_array(R.cond.data(), {N});
                d["mu"] = copy_array(R.mu.data(), {N});
                d["energy"] = copy_array(R.energy.data(), {N});
                d["phi_norm"] = copy_array(R.phi_norm.data(), {N});
                d["velocity_residual_norm"] = copy_array(R.vel_norm.data(), {N});
                if (!s.loop->fric.empty()) d["friction_work"] = copy_array(R.fr_work.data(), {N});
                d["work"] = copy_array(R.work.data(), {N});
                R.clear();
                return d;
            },
            "The samples recorded since the last take (arrays of nonmin.sim.Trajectory), cleared.")
        .def_prop_ro(
            "guard_values",
            [](const SimLoop& s) {
                std::vector<double> v;
                for (const sim::ContactGuard& g : s.loop->guards) v.push_back(g.g);
                return v;
            },
            "The contact guards' values at the last accepted step end.")
        .def(
            "set_contact",
            [](SimLoop& s, const std::vector<double>& restitution, double v_thresh) {
                if (restitution.size() != s.program->constraints().size())
                    raise_typed("ShapeError", "restitution must have one value per constraint");
                sim::set_contact_options(*s.loop, restitution, v_thresh);
            },
            nb::arg("restitution"), nb::arg("v_thresh"),
            "Newton's e of automatic impacts per constraint and the impact velocity threshold.")
        .def(
            "set_friction",
            [](SimLoop& s, const std::vector<std::tuple<int, int, double, int, double, double>>& contacts) {
                std::vector<sim::FrictionContact> fc;
                const int c = static_cast<int>(s.program->constraints().size());
                for (const auto& [normal, tangent, mu, slip, d0, d1] : contacts) {
                    if (normal < 0 || normal >= c || tangent < 0 || tangent >= c)
                        raise_typed("InputError", "friction contact: constraint index out of range");
                    if (!(mu >= 0.0) || slip < -1 || slip > 1)
                        raise_typed("InputError", "friction contact: mu must be >= 0 and slip in {-1, 0, 1}");
                    sim::FrictionContact f;
                    f.normal = normal;
                    f.tangent = tangent;
                    f.mu = mu;
                    f.slip = slip;
                    f.dir[0] = d0;
                    f.dir[1] = d1;
                    fc.push_back(f);
                }
                sim::set_friction(*s.loop, fc);
            },
            nb::arg("contacts"),
            "Coulomb friction contacts (normal index, tangent index, mu, slip, direction d0, d1); before "
            "start/resume.")
        .def_prop_rw(
            "work",
            [](const SimLoop& s) { return s.loop->wk; },
            [](SimLoop& s, double w) { s.loop->wk = w; },
            "The work of controllers and applied forces (J) up to the current state (the "
            "integrator's own quadrature of q̇ᵀ(B u + f_passive + f_c)); set it before "
            "start/resume to continue a run's total.")
        .def_prop_rw(
            "friction_work",
            [](const SimLoop& s) { return s.loop->fw; },
            [](SimLoop& s, double w) { s.loop->fw = w; },
            "The friction forces' work (J) accumulated up to the current state; set it before "
            "start/resume to continue a run's total.")
        .def(
            "arm_friction",
            [](SimLoop& s) {
                if (sim::friction_arm(*s.loop) != Status::ok) return false;
                return true;
            },
            "Append the friction guards at the current state (after start/resume); False when its "
            "evaluation failed (message, painleve say why).")
        .def(
            "arm_guards",
            [](SimLoop& s) {
                const Status st = sim::arm_guards(*s.loop);
                if (st != Status::ok) s.loop->message = "kernel status " + std::to_string(static_cast<int>(st));
                return st == Status::ok;
            },
            "The contact guards' values at the first point (after start), in place of those given; "
            "False when their evaluation failed (message says why).")
        .def_prop_ro(
            "friction_slip",
            [](const SimLoop& s) {
                std::vector<std::tuple<int, double, double>> v;
                for (const sim::FrictionContact& f : s.loop->fric) v.emplace_back(f.slip, f.dir[0], f.dir[1]);
                return v;
            },
            "(slip, d0, d1) of each friction contact (slip 0: sticking or open; d: the slip direction of "
            "a two-row contact).")
        .def_prop_ro(
            "painleve",
            [](const SimLoop& s) -> nb::object {
                if (s.loop->painleve < 0) return nb::none();
                return nb::make_tuple(s.loop->painleve, s.loop->painleve_t, s.loop->painleve_den);
            },
            "(friction contact index, t, denominator) of Painlevé's inconsistency when it was met, else None.")
        .def_prop_ro(
            "events",
            [](const SimLoop& s) {
                nb::list out;
                const auto n = static_cast<std::size_t>(s.loop->n), c = static_cast<std::size_t>(s.loop->c);
                for (const sim::EventInfo& e : s.loop->events) {
                    nb::dict d;
                    d["t"] = e.t;
                    d["name"] = e.name;
                    d["transition"] = e.text;
                    d["q_before"] = copy_array(e.q_before.data(), {n});
                    d["qd_before"] = copy_array(e.qd_before.data(), {n});
                    d["q_after"] = copy_array(e.q_after.data(), {n});
                    d["qd_after"] = copy_array(e.qd_after.data(), {n});
                    d["active_before"] = copy_array(e.active_before.data(), {c});
                    d["active_after"] = copy_array(e.active_after.data(), {c});
                    out.append(d);
                }
                return out;
            },
            "The transitions the engine's event layer applied in the last run() (SIM_TRANSITION).")
        .def_prop_ro("t", [](const SimLoop& s) { return s.loop->t; })
        .def_prop_ro(
            "y",
            [](const SimLoop& s) { return copy_array(s.loop->y.data(), {static_cast<std::size_t>(2 * s.loop->n)}); },
            nb::rv_policy::move)
        .def_prop_ro("h", [](const SimLoop& s) { return s.loop->h; })
        .def_prop_ro("n_steps", [](const SimLoop& s) { return s.loop->n_steps; })
        .def_prop_ro("n_rhs", [](const SimLoop& s) { return s.loop->n_rhs; })
        .def_prop_ro("n_rejected", [](const SimLoop& s) { return s.loop->n_rejected; })
        .def_prop_ro("out_i", [](const SimLoop& s) { return s.loop->out_i; })
        .def_prop_ro("message", [](const SimLoop& s) { return s.loop->message; });
}

}  // namespace nonmin::bindings
