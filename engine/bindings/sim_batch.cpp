// Binding of the batched simulation loop (nonmin/sim/batch.hpp): k runs in one call, GIL
// released, threaded over the runs. Used by nonmin.sim.simulate_batch.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>
#include <nanobind/stl/tuple.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "nonmin/sim/batch.hpp"
#include "../src/lanes.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

using CMask2 = nb::ndarray<const std::uint8_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using CInt1 = nb::ndarray<const std::int32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

template <class T>
nb::ndarray<nb::numpy, T> owned(std::vector<std::size_t> shape, T fill) {
    std::size_t size = 1;
    for (std::size_t s : shape) size *= s;
    T* data = new T[size > 0 ? size : 1];
    std::fill(data, data + (size > 0 ? size : 1), fill);
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
    return nb::ndarray<nb::numpy, T>(data, shape.size(), shape.data(), owner);
}

}  // namespace

void bind_sim_batch(nb::module_& m) {
    m.attr("REC_Q") = static_cast<unsigned>(sim::REC_Q);
    m.attr("REC_QD") = static_cast<unsigned>(sim::REC_QD);
    m.attr("REC_QDD") = static_cast<unsigned>(sim::REC_QDD);
    m.attr("REC_FC") = static_cast<unsigned>(sim::REC_FC);
    m.attr("REC_U") = static_cast<unsigned>(sim::REC_U);
    m.def(
        "simulate_batch",
        [](std::vector<nb::handle> programs, CInt1 program_of, double t0, CArr2 q0, CArr2 qd0, CMask2 active,
           const sim::Options& opt, CArr1 t_out, unsigned record, int threads, bool contact,
           const std::vector<double>& restitution, double v_thresh, int zeno_max, double zeno_window,
           const std::vector<std::tuple<int, std::vector<std::uint8_t>, nb::handle>>& controllers) {
            if (programs.empty()) raise_error("InputError", "simulate_batch: no program");
            sim::BatchInput in;
            for (nb::handle h : programs) in.programs.push_back(&nb::cast<const Program&>(h));
            const Program& p0 = *in.programs[0];
            const std::size_t n = static_cast<std::size_t>(p0.n()), nu = static_cast<std::size_t>(p0.k()),
                              c = p0.constraints().size();
            for (const Program* p : in.programs)
                if (static_cast<std::size_t>(p->n()) != n || static_cast<std::size_t>(p->k()) != nu ||
                    p->constraints().size() != c)
                    raise_error("ShapeError", "simulate_batch: every program must have the same n, k and "
                                              "constraints");
            const std::size_t k = q0.shape(0), N = t_out.shape(0);
            if (qd0.shape(0) != k || program_of.shape(0) != k || active.shape(0) != k)
                raise_error("ShapeError", "simulate_batch: q0, qd0, program_of and active must have one row per run");
            if (q0.shape(1) != n || qd0.shape(1) != n)
                raise_error("ShapeError", "simulate_batch: q0 and qd0 must have " + std::to_string(n) + " columns");
            if (active.shape(1) != c)
                raise_error("ShapeError", "simulate_batch: active must have " + std::to_string(c) + " columns");
            for (std::size_t i = 0; i < k; ++i)
                if (program_of.data()[i] < 0 || static_cast<std::size_t>(program_of.data()[i]) >= programs.size())
                    raise_error("InputError", "simulate_batch: program_of names no program");
            in.k = static_cast<int>(k);
            in.program_of = program_of.data();
            in.t0 = t0;
            in.q0 = q0.data();
            in.qd0 = qd0.data();
            in.active = active.data();
            in.opt = opt;
            in.t_out.assign(t_out.data(), t_out.data() + N);
            in.record = record;
            in.threads = threads;
            in.contact = contact;
            if (contact && restitution.size() != c)
                raise_error("ShapeError", "simulate_batch: restitution must have one value per constraint");
            in.restitution = restitution;
            in.v_thresh = v_thresh;
            in.zeno_max = zeno_max;
            in.zeno_window = zeno_window;
            for (const auto& [prog, mask, ctl] : controllers) {
                if (prog < 0 || static_cast<std::size_t>(prog) >= programs.size() || mask.size() != c)
                    raise_error("InputError", "simulate_batch: a controller names no program or has a bad mask");
                in.ctrl_protos.push_back(nb::cast<const sim::Controller*>(ctl));
                in.ctrl_program.push_back(prog);
                in.ctrl_mask.push_back(mask);
            }

            const double nan = std::numeric_limits<double>::quiet_NaN();
            nb::dict d;
            auto arr3 = [&](unsigned flag, const char* key, std::size_t w, double*& dst) {
                if (!(record & flag)) return;
                auto a = owned<double>({k, N, w}, nan);
                dst = a.data();
                d[key] = a;
            };
            auto arr2 = [&](const char* key, double*& dst) {
                auto a = owned<double>({k, N}, nan);
                dst = a.data();
                d[key] = a;
            };
            sim::BatchOutput out;
            arr3(sim::REC_Q, "q", n, out.q);
            arr3(sim::REC_QD, "qd", n, out.qd);
            arr3(sim::REC_QDD, "qdd", n, out.qdd);
            arr3(sim::REC_FC, "f_c", n, out.f_c);
            arr3(sim::REC_U, "u", nu, out.u);
            arr2("energy", out.energy);
            arr2("phi_norm", out.phi_norm);
            arr2("velocity_residual_norm", out.vel_norm);
            arr2("cond", out.cond);
            arr2("mu", out.mu);
            arr2("work", out.work);
            auto rank = owned<std::int64_t>({k, N}, -1);
            out.rank = rank.data();
            d["rank"] = rank;
            if (contact) {
                auto act = owned<std::uint8_t>({k, N, c}, 0);
                out.active = act.data();
                d["active_mask"] = act;
            }
            std::vector<std::vector<sim::EventInfo>> events(contact ? k : 0);
            if (contact) out.events = &events;
            auto outcome = owned<std::int32_t>({k}, -1);
            auto samples = owned<std::int64_t>({k}, 0);
            auto steps = owned<std::int64_t>({k}, 0), rhs = owned<std::int64_t>({k}, 0),
                 rej = owned<std::int64_t>({k}, 0);
            auto t_end = owned<double>({k}, nan);
            auto y_end = owned<double>({k, 2 * n}, nan);
            out.outcome = outcome.data();
            out.samples = samples.data();
            out.n_steps = steps.data();
            out.n_rhs = rhs.data();
            out.n_rejected = rej.data();
            out.t_end = t_end.data();
            out.y_end = y_end.data();
            std::vector<std::string> messages(k);
            out.messages = &messages;
            int bad;
            {
                nb::gil_scoped_release release;
                bad = sim::simulate_batch(in, out);
            }
            if (PyErr_Occurred()) throw nb::python_error();
            d["outcome"] = outcome;
            d["samples"] = samples;
            d["n_steps"] = steps;
            d["n_rhs"] = rhs;
            d["n_rejected"] = rej;
            d["t_end"] = t_end;
            d["y_end"] = y_end;
            d["messages"] = messages;
            d["failed"] = bad;
            if (contact) {
                nb::list evs;
                for (const auto& run : events) {
                    nb::list l;
                    for (const sim::EventInfo& e : run) {
                        nb::dict ed;
                        ed["t"] = e.t;
                        ed["name"] = e.name;
                        ed["transition"] = e.text;
                        auto vec = [&](const Vec& v) {
                            auto a = owned<double>({n}, 0.0);
                            std::memcpy(a.data(), v.data(), n * sizeof(double));
                            return a;
                        };
                        auto msk = [&](const std::vector<std::uint8_t>& v) {
                            auto a = owned<std::uint8_t>({c}, 0);
                            if (c) std::memcpy(a.data(), v.data(), c);
                            return a;
                        };
                        ed["q_before"] = vec(e.q_before);
                        ed["qd_before"] = vec(e.qd_before);
                        ed["q_after"] = vec(e.q_after);
                        ed["qd_after"] = vec(e.qd_after);
                        ed["active_before"] = msk(e.active_before);
                        ed["active_after"] = msk(e.active_after);
                        l.append(ed);
                    }
                    evs.append(l);
                }
                d["events"] = evs;
            }
            return d;
        },
        nb::arg("programs"), nb::arg("program_of"), nb::arg("t0"), nb::arg("q0"), nb::arg("qd0"),
        nb::arg("active"), nb::arg("options"), nb::arg("t_out"), nb::arg("record"), nb::arg("threads"),
        nb::arg("contact") = false, nb::arg("restitution") = std::vector<double>{}, nb::arg("v_thresh") = 1e-6,
        nb::arg("zeno_max") = 100, nb::arg("zeno_window") = 1e-3,
        nb::arg("controllers") = std::vector<std::tuple<int, std::vector<std::uint8_t>, nb::handle>>{},
        "Run k simulations (run i: programs[program_of[i]], (t0, q0[i], qd0[i]), active mask "
        "active[i]) to options.t1, each recorded at t_out; threads over the runs with the GIL "
        "released. Returns a dict of arrays (k, N, ...) and per-run outcome (SIM_DONE when the "
        "run reached t1), samples, n_steps, n_rhs, n_rejected, t_end, y_end, messages. contact: the "
        "engine's event layer on the unilateral constraints (restitution per constraint, v_thresh, "
        "Zeno limit); then also active_mask (k, N, c) and events (per run, dicts as SimLoop.events). "
        "controllers: (program index, active mask, compiled SimController) prototypes, copied per "
        "thread and run.");
    // the lock-step lanes of the batch (engine/src/lanes.hpp): their width and counters
    m.def("lanes_stats", []() {
        nb::dict d;
        const lanes::Stats& s = lanes::stats();
        d["available"] = lanes::available();
        d["width"] = lanes::width();
        d["lane_calls"] = s.lane_calls.load();
        d["lane_groups"] = s.lane_groups.load();
        d["scalar_calls"] = s.scalar_calls.load();
        d["diverged"] = s.diverged.load();
        return d;
    });
}

}  // namespace nonmin::bindings
