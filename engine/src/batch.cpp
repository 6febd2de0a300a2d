// Model + kernel over a batch of states (nonmin/batch.hpp).
#include "nonmin/batch.hpp"

#include "nonmin/forward.hpp"

#include <algorithm>
#include <thread>
#include <vector>

namespace nonmin {

namespace {

void run_chunk(const Program& p, int lo, int hi, const double* t, const double* q, const double* qd,
               const std::uint8_t* active, const double* f, int f_stride, const SolveOptions& opt,
               BatchOutputs out, int* failures) {
    const int n = p.n();
    ForwardScratch s(p, active);
    int bad = 0;
    for (int i = lo; i < hi; ++i) {
        const std::size_t off = static_cast<std::size_t>(i) * n;
        const double* fi = f != nullptr ? f + static_cast<std::size_t>(i) * f_stride : nullptr;
        const SolveInfo info = forward_dynamics(p, s, t[i], q + off, qd + off, fi, opt, out.qdd + off,
                                                out.f_c ? out.f_c + off : nullptr);
        if (out.rank) out.rank[i] = info.rank;
        out.status[i] = static_cast<int>(info.status);
        if (info.status != Status::ok) {
            ++bad;
            if (info.status == Status::callback_error) {  // a Python error is pending: stop this chunk
                for (int j = i + 1; j < hi; ++j) out.status[j] = static_cast<int>(Status::callback_error);
                bad += hi - i - 1;
                break;
            }
        }
    }
    *failures = bad;
}

}  // namespace

int forward_batch(const Program& program, int N, const double* t, const double* q, const double* qd,
                  const std::uint8_t* active, const double* f, int f_stride, const SolveOptions& opt,
                  int threads, BatchOutputs out) {
    if (N <= 0) return 0;
    int nt = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    // below ~64 states per thread the start-up of a thread is not amortized
    nt = std::min(nt, std::max(1, N / 64));
    if (!program.thread_safe()) nt = 1;
    if (nt == 1) {
        int bad = 0;
        run_chunk(program, 0, N, t, q, qd, active, f, f_stride, opt, out, &bad);
        return bad;
    }
    std::vector<int> failures(nt, 0);
    std::vector<std::thread> pool;
    pool.reserve(nt);
    for (int k = 0; k < nt; ++k) {
        const int lo = static_cast<int>(static_cast<long long>(N) * k / nt);
        const int hi = static_cast<int>(static_cast<long long>(N) * (k + 1) / nt);
        pool.emplace_back(run_chunk, std::cref(program), lo, hi, t, q, qd, active, f, f_stride,
                          std::cref(opt), out, &failures[k]);
    }
    for (std::thread& th : pool) th.join();
    int bad = 0;
    for (int b : failures) bad += b;
    return bad;
}

}  // namespace nonmin
