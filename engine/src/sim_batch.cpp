// Many runs of the simulation loop in one call (nonmin/sim/batch.hpp).
#include "nonmin/sim/batch.hpp"
#include "nonmin/sim/events.hpp"
#include "lanes.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <thread>

namespace nonmin::sim {

namespace {

// The compiled controllers of one loop: a fresh copy of the batch's prototype for each active set
// the run meets (ControllerSelect: asked by set_active() when the event layer changes the set).
struct RunControllers final : ControllerSelect {
    const BatchInput* in = nullptr;
    int program = -1;
    std::vector<std::pair<std::vector<std::uint8_t>, std::unique_ptr<Controller>>> made;

    Controller* select(const std::uint8_t* active) override {
        const std::size_t c = in->ctrl_mask.empty() ? 0 : in->ctrl_mask[0].size();
        for (auto& [mask, ctl] : made)
            if (std::equal(mask.begin(), mask.end(), active)) return ctl.get();
        for (std::size_t j = 0; j < in->ctrl_protos.size(); ++j)
            if (in->ctrl_program[j] == program && std::equal(in->ctrl_mask[j].begin(), in->ctrl_mask[j].end(), active)) {
                std::unique_ptr<Controller> ctl = in->ctrl_protos[j]->clone();
                if (!ctl) return nullptr;
                made.emplace_back(std::vector<std::uint8_t>(active, active + c), std::move(ctl));
                return made.back().second.get();
            }
        return nullptr;  // none compiled for this set: the current one stays (and fails, stale)
    }
};

// The loops of one thread: one per (program, active mask) met, built on first use.
struct ThreadLoops {
    struct Entry {
        int program = -1;
        std::vector<std::uint8_t> mask;
        std::unique_ptr<Loop> loop;
        RunControllers ctrls;
    };
    std::vector<std::unique_ptr<Entry>> entries;

    Entry& get(const BatchInput& in, int p, const std::uint8_t* mask, int c) {
        for (auto& e : entries)
            if (e->program == p && std::equal(e->mask.begin(), e->mask.end(), mask)) return *e;
        auto e = std::make_unique<Entry>();
        e->program = p;
        e->mask.assign(mask, mask + c);
        e->loop = make_loop(*in.programs[static_cast<std::size_t>(p)], mask, in.opt, in.t_out, false, nullptr);
        e->ctrls.in = &in;
        e->ctrls.program = p;
        if (!in.ctrl_protos.empty()) e->loop->ctrl_select = &e->ctrls;
        entries.push_back(std::move(e));
        return *entries.back();
    }
};

template <class T>
void copy_rows(const std::vector<T>& src, std::size_t rows, std::size_t width, T* dst) {
    if (dst && rows) std::memcpy(dst, src.data(), rows * width * sizeof(T));
}

// Sample j of R into row p of the run's block (the recorded arrays only).
void copy_sample(const BatchOutput& out, const Samples& R, std::size_t j, std::size_t row, std::size_t n,
                 std::size_t nu, std::size_t c) {
    auto put = [&](const std::vector<double>& src, std::size_t w, double* dst) {
        if (dst) std::memcpy(dst + row * w, src.data() + j * w, w * sizeof(double));
    };
    put(R.q, n, out.q);
    put(R.qd, n, out.qd);
    put(R.qdd, n, out.qdd);
    put(R.f_c, n, out.f_c);
    put(R.u, nu, out.u);
    put(R.energy, 1, out.energy);
    put(R.phi_norm, 1, out.phi_norm);
    put(R.vel_norm, 1, out.vel_norm);
    put(R.cond, 1, out.cond);
    put(R.mu, 1, out.mu);
    put(R.work, 1, out.work);
    if (out.rank) out.rank[row] = R.rank[j];
    if (out.active && c) std::memcpy(out.active + row * c, R.active.data() + j * c, c);
}

// The run's transitions until it ends: each contact event applied inside run() (Outcome::
// transition) is kept, counted for Zeno as the driver's _zeno_check does, and the loop resumed
// from the state after it (as the driver's next engine call: resume()).
Outcome run_contact(const BatchInput& in, Loop& L, std::vector<EventInfo>* events) {
    std::vector<double> recent;
    Outcome o = run(L, std::numeric_limits<long long>::max());
    while (o == Outcome::transition) {
        for (EventInfo& e : L.events) {
            recent.push_back(e.t);
            if (events) events->push_back(std::move(e));
        }
        L.events.clear();
        const double te = L.t;
        std::size_t drop = 0;
        while (drop < recent.size() && recent[drop] < te - in.zeno_window) ++drop;
        recent.erase(recent.begin(), recent.begin() + static_cast<std::ptrdiff_t>(drop));
        if (static_cast<long long>(recent.size()) > in.zeno_max) {
            L.message = "Zeno accumulation (made again by simulate)";
            return Outcome::handover;
        }
        resume(L, L.t, L.y.data(), L.h, L.n_steps, L.out_i);
        o = run(L, std::numeric_limits<long long>::max());
    }
    return o;
}

// The contact guards of the active set at the run's first point (the driver's watches of
// _watches and their values _guard_value at that point): impact gaps of the inactive unilateral
// constraints, release forces of the active ones.
Status arm_contact(const BatchInput& in, Loop& L, double t0) {
    const auto& cons = L.prog->constraints();
    std::vector<ContactGuard> gs;
    int row_i = 0;
    bool any_release = false, any_gap = false;
    std::vector<std::uint8_t> gap_mask(cons.size(), 0);
    for (std::size_t ic = 0; ic < cons.size(); ++ic) {
        const bool act = L.active[ic] != 0;
        if (cons[ic].kind == ConstraintKind::unilateral) {
            gs.push_back({act, static_cast<int>(ic), act ? row_i : 0, 0.0});
            any_release = any_release || act;
            if (!act) {
                gap_mask[ic] = 1;
                any_gap = true;
            }
        }
        if (act) row_i += cons[ic].dim;
    }
    set_guards(L, gs);
    set_contact_options(L, in.restitution, in.v_thresh);
    if (any_release) release_forces(L, L.p1.f_c.data());  // (L.Ac: A at the first point)
    for (ContactGuard& G : L.guards)
        if (G.release) G.g = L.lam_c[G.row];
    if (any_gap) {
        const int n = L.n;
        const Status s = L.prog->evaluate(t0, L.y.data(), L.y.data() + n, gap_mask.data(), NEED_PHI, L.T, *L.ws);
        if (s != Status::ok) return s;
        for (ContactGuard& G : L.guards)
            if (!G.release) G.g = L.T.phi[cons[static_cast<std::size_t>(G.constraint)].row];
    }
    return Status::ok;
}

void run_one(const BatchInput& in, const BatchOutput& out, int i, ThreadLoops& loops) {
    const Program& p0 = *in.programs[0];
    const std::size_t n = static_cast<std::size_t>(p0.n()), nu = static_cast<std::size_t>(p0.k()),
                      c = p0.constraints().size(), N = in.t_out.size();
    const std::size_t ii = static_cast<std::size_t>(i);
    const std::uint8_t* mask = in.active + ii * c;
    ThreadLoops::Entry& E = loops.get(in, in.program_of[i], mask, static_cast<int>(c));
    Loop& L = *E.loop;
    L.rec.clear();  // keeps the buffers' capacity
    L.n_rhs = 0;
    L.n_rejected = 0;
    L.wk = 0.0;  // W of this run from its start (the loop is reused run after run)
    if (in.contact || !in.ctrl_protos.empty()) {
        // a contact run left the loop in another active set; controllers start afresh per run
        E.ctrls.made.clear();
        L.ctrl = nullptr;
        if (!std::equal(L.active.begin(), L.active.end(), mask)) set_active(L, mask);
        if (!in.ctrl_protos.empty()) {
            L.ctrl = E.ctrls.select(mask);
            if (L.ctrl) L.ctrl->attach(L.T, L.Ac, L.m, L.rows);
        }
        L.events.clear();
    }
    Outcome o;
    if (!in.ctrl_protos.empty() && !L.ctrl) {
        o = Outcome::handover;
        L.message = "no compiled controller for the run's active set";
    } else {
        o = start(L, in.t0, in.q0 + ii * n, in.qd0 + ii * n);
        std::vector<EventInfo>* evs = out.events ? &(*out.events)[ii] : nullptr;
        if (o == Outcome::done && in.contact) {
            const Status s = arm_contact(in, L, in.t0);
            if (s != Status::ok) {
                o = Outcome::handover;
                L.message = "contact guards at the start: kernel status " + std::to_string(static_cast<int>(s));
            } else {
                o = run_contact(in, L, evs);
            }
        } else if (o == Outcome::done) {
            o = run(L, std::numeric_limits<long long>::max());
        }
    }
    const Samples& R = L.rec;
    const std::size_t rs = ii * N;  // first sample row of run i
    std::size_t S = 0;
    if (!in.contact) {  // one sample per output time, in order
        S = std::min(R.size(), N);
        copy_rows(R.q, S, n, out.q ? out.q + rs * n : nullptr);
        copy_rows(R.qd, S, n, out.qd ? out.qd + rs * n : nullptr);
        copy_rows(R.qdd, S, n, out.qdd ? out.qdd + rs * n : nullptr);
        copy_rows(R.f_c, S, n, out.f_c ? out.f_c + rs * n : nullptr);
        copy_rows(R.u, S, nu, out.u ? out.u + rs * nu : nullptr);
        copy_rows(R.energy, S, 1, out.energy ? out.energy + rs : nullptr);
        copy_rows(R.phi_norm, S, 1, out.phi_norm ? out.phi_norm + rs : nullptr);
        copy_rows(R.vel_norm, S, 1, out.vel_norm ? out.vel_norm + rs : nullptr);
        copy_rows(R.cond, S, 1, out.cond ? out.cond + rs : nullptr);
        copy_rows(R.mu, S, 1, out.mu ? out.mu + rs : nullptr);
        copy_rows(R.work, S, 1, out.work ? out.work + rs : nullptr);
        copy_rows(R.rank, S, 1, out.rank ? out.rank + rs : nullptr);
        if (out.active && c) std::memcpy(out.active + rs * c, R.active.data(), S * c);
    } else {  // samples at events too: each output time gets the last sample at that time
        BatchOutput o1 = out;
        auto shift = [&](auto*& p, std::size_t w) {
            if (p) p += rs * w;
        };
        shift(o1.q, n), shift(o1.qd, n), shift(o1.qdd, n), shift(o1.f_c, n), shift(o1.u, nu);
        shift(o1.energy, 1), shift(o1.phi_norm, 1), shift(o1.vel_norm, 1), shift(o1.cond, 1), shift(o1.mu, 1), shift(o1.work, 1);
        shift(o1.rank, 1), shift(o1.active, c);
        std::size_t p = 0;
        for (std::size_t j = 0; j < R.size(); ++j) {
            while (p < N && in.t_out[p] < R.t[j]) ++p;
            for (std::size_t r = p; r < N && in.t_out[r] == R.t[j]; ++r) {
                copy_sample(o1, R, j, r, n, nu, c);
                S = r + 1;
            }
        }
    }
    out.outcome[i] = static_cast<std::int32_t>(o);
    out.samples[i] = static_cast<std::int64_t>(S);
    out.n_steps[i] = L.n_steps;
    out.n_rhs[i] = L.n_rhs;
    out.n_rejected[i] = L.n_rejected;
    out.t_end[i] = L.t;
    for (std::size_t j = 0; j < 2 * n; ++j) out.y_end[ii * 2 * n + j] = L.y[static_cast<Eigen::Index>(j)];
    if (o != Outcome::done && out.messages) (*out.messages)[ii] = L.message;
}

}  // namespace

int simulate_batch(const BatchInput& in, const BatchOutput& out) {
    if (in.k <= 0) return 0;
    bool safe = true;
    for (const Program* p : in.programs) safe = safe && p->thread_safe();
    int nt = in.threads > 0 ? in.threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    nt = std::min(nt, in.k);
    if (!safe) nt = 1;
    std::atomic<int> next{0};
    // lock-step lanes (lanes.hpp) for fixed-step RK4 without contact or controllers: each thread
    // runs W runs at a time, one per fiber, each with its own loops (the scalar loop, unchanged)
    const char* le = std::getenv("NONMIN_LANES");
    const bool lanes_on = lanes::available() && !(le && le[0] == '0') && in.opt.method == Method::rk4 &&
                          !in.contact && in.ctrl_protos.empty();
    auto worker = [&]() {
        if (lanes_on) {
            const int W = lanes::width();
            std::vector<ThreadLoops> loops(static_cast<std::size_t>(W));
            lanes::run_fibers(W, [&](int f) {
                for (int i = next.fetch_add(1); i < in.k; i = next.fetch_add(1))
                    run_one(in, out, i, loops[static_cast<std::size_t>(f)]);
            });
            return;
        }
        ThreadLoops loops;
        for (int i = next.fetch_add(1); i < in.k; i = next.fetch_add(1)) run_one(in, out, i, loops);
    };
    if (nt == 1) {
        worker();
    } else {
        std::vector<std::thread> pool;
        pool.reserve(static_cast<std::size_t>(nt));
        for (int t = 0; t < nt; ++t) pool.emplace_back(worker);
        for (std::thread& th : pool) th.join();
    }
    int bad = 0;
    for (int i = 0; i < in.k; ++i) bad += out.outcome[i] != static_cast<std::int32_t>(Outcome::done);
    return bad;
}

}  // namespace nonmin::sim
