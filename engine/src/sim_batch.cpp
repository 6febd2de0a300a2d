// Many runs of the simulation loop in one call (nonmin/sim/batch.hpp).
#include "nonmin/sim/batch.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <thread>

namespace nonmin::sim {

namespace {

// The loops of one thread: one per (program, active mask) met, built on first use.
struct ThreadLoops {
    struct Entry {
        int program = -1;
        std::vector<std::uint8_t> mask;
        std::unique_ptr<Loop> loop;
    };
    std::vector<Entry> entries;

    Loop& get(const BatchInput& in, int p, const std::uint8_t* mask, int c) {
        for (Entry& e : entries)
            if (e.program == p && std::equal(e.mask.begin(), e.mask.end(), mask)) return *e.loop;
        Entry e;
        e.program = p;
        e.mask.assign(mask, mask + c);
        e.loop = make_loop(*in.programs[static_cast<std::size_t>(p)], mask, in.opt, in.t_out, false, nullptr);
        entries.push_back(std::move(e));
        return *entries.back().loop;
    }
};

template <class T>
void copy_rows(const std::vector<T>& src, std::size_t rows, std::size_t width, T* dst) {
    if (dst && rows) std::memcpy(dst, src.data(), rows * width * sizeof(T));
}

void run_one(const BatchInput& in, const BatchOutput& out, int i, ThreadLoops& loops) {
    const Program& p0 = *in.programs[0];
    const std::size_t n = static_cast<std::size_t>(p0.n()), nu = static_cast<std::size_t>(p0.k()),
                      c = p0.constraints().size(), N = in.t_out.size();
    const std::size_t ii = static_cast<std::size_t>(i);
    const std::uint8_t* mask = in.active + ii * c;
    Loop& L = loops.get(in, in.program_of[i], mask, static_cast<int>(c));
    L.rec.clear();  // keeps the buffers' capacity
    L.n_rhs = 0;
    L.n_rejected = 0;
    Outcome o = start(L, in.t0, in.q0 + ii * n, in.qd0 + ii * n);
    if (o == Outcome::done) o = run(L, std::numeric_limits<long long>::max());
    const Samples& R = L.rec;
    const std::size_t S = std::min(R.size(), N);
    const std::size_t rs = ii * N;  // first sample row of run i
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
    copy_rows(R.rank, S, 1, out.rank ? out.rank + rs : nullptr);
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
    auto worker = [&]() {
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
