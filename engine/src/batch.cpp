// Model + kernel over a batch of states (nonmin/batch.hpp).
#include "nonmin/batch.hpp"

#include "nonmin/forward.hpp"

#include <algorithm>
#include <atomic>
#include <memory>
#include <thread>
#include <vector>

namespace nonmin {

namespace {

struct BatchJob {
    const Program& p;
    const double* t;
    const double* q;
    const double* qd;
    const std::uint8_t* active;
    const double* f;
    int f_stride;
    const SolveOptions& opt;
    BatchOutputs out;
};

// States lo … hi − 1 marked as failed with status st (their outputs read 0).
void mark_failed(const BatchOutputs& out, int n, int lo, int hi, Status st) {
    for (int j = lo; j < hi; ++j) {
        const std::size_t oj = static_cast<std::size_t>(j) * n;
        std::fill(out.qdd + oj, out.qdd + oj + n, 0.0);
        if (out.f_c) std::fill(out.f_c + oj, out.f_c + oj + n, 0.0);
        if (out.rank) out.rank[j] = 0;
        out.status[j] = static_cast<int>(st);
    }
}

// States lo … hi − 1 with one thread's scratch; returns the states whose status is not ok, and
// sets *stop after a callback error (a Python error is pending: the states after it in this
// range are marked as failed by it, and no other range is started).
int run_range(const BatchJob& job, ForwardScratch& s, int lo, int hi, bool* stop) {
    const int n = job.p.n();
    const BatchOutputs& out = job.out;
    int bad = 0;
    for (int i = lo; i < hi; ++i) {
        const std::size_t off = static_cast<std::size_t>(i) * n;
        const double* fi = job.f != nullptr ? job.f + static_cast<std::size_t>(i) * job.f_stride : nullptr;
        const SolveInfo info = forward_dynamics(job.p, s, job.t[i], job.q + off, job.qd + off, fi, job.opt,
                                                out.qdd + off, out.f_c ? out.f_c + off : nullptr);
        if (out.rank) out.rank[i] = info.rank;
        out.status[i] = static_cast<int>(info.status);
        if (info.status != Status::ok) {
            // the outputs may be uninitialized memory (batch.hpp): a failed state reads 0
            std::fill(out.qdd + off, out.qdd + off + n, 0.0);
            if (out.f_c) std::fill(out.f_c + off, out.f_c + off + n, 0.0);
            ++bad;
            if (info.status == Status::callback_error) {
                mark_failed(out, n, i + 1, hi, Status::callback_error);
                bad += hi - i - 1;
                *stop = true;
                break;
            }
        }
    }
    return bad;
}

}  // namespace

int forward_batch(const Program& program, int N, const double* t, const double* q, const double* qd,
                  const std::uint8_t* active, const double* f, int f_stride, const SolveOptions& opt,
                  int threads, BatchOutputs out, ScratchPool* pool) {
    if (N <= 0) return 0;
    const BatchJob job{program, t, q, qd, active, f, f_stride, opt, out};
    int nt = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    // below ~64 states per thread the start-up of a thread is not amortized
    nt = std::min(nt, std::max(1, N / 64));
    if (!program.thread_safe()) nt = 1;
    ScratchPool local;
    if (pool == nullptr) pool = &local;
    if (pool->size() < static_cast<std::size_t>(nt)) pool->resize(static_cast<std::size_t>(nt));
    // worker j's scratch, made by that worker on first use (its pages touched by it)
    auto scratch = [&](int j) -> ForwardScratch& {
        std::unique_ptr<ForwardScratch>& s = (*pool)[static_cast<std::size_t>(j)];
        if (!s) s = std::make_unique<ForwardScratch>(program, active);
        return *s;
    };
    if (nt == 1) {
        bool stop = false;
        return run_range(job, scratch(0), 0, N, &stop);
    }
    // Threads take chunks of consecutive states from a shared counter (about 64 chunks per
    // thread): a thread slowed by other work on its core takes fewer chunks instead of holding
    // up the whole call with a fixed share. The calling thread is one of the nt workers. Each
    // state's result does not depend on the thread or the order (batch.hpp).
    const int chunk = std::clamp(N / (64 * nt), 8, 512);
    std::atomic<int> next{0};
    std::atomic<int> failures{0};
    std::atomic<bool> stopped{false};
    auto worker = [&](int j) {
        ForwardScratch& s = scratch(j);
        int bad = 0;
        for (;;) {
            if (stopped.load(std::memory_order_relaxed)) break;
            const int lo = next.fetch_add(chunk, std::memory_order_relaxed);
            if (lo >= N) break;
            bool stop = false;
            bad += run_range(job, s, lo, std::min(N, lo + chunk), &stop);
            if (stop) stopped.store(true, std::memory_order_relaxed);
        }
        failures.fetch_add(bad, std::memory_order_relaxed);
    };
    std::vector<std::thread> team;
    team.reserve(static_cast<std::size_t>(nt - 1));
    for (int k = 1; k < nt; ++k) team.emplace_back(worker, k);
    worker(0);
    for (std::thread& th : team) th.join();
    int bad = failures.load();
    if (stopped.load()) {  // after a callback error: the states no thread started failed by it
        const int first = std::min(next.load(), N);
        mark_failed(out, program.n(), first, N, Status::callback_error);
        bad += N - first;
    }
    return bad;
}

}  // namespace nonmin
