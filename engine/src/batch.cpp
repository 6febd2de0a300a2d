// Model + kernel over a batch of states (nonmin/batch.hpp).
#include "nonmin/batch.hpp"

#include <algorithm>
#include <thread>
#include <vector>

namespace nonmin {

namespace {

// Rows of the active constraints, in row order.
std::vector<int> active_rows(const Program& p, const std::uint8_t* active) {
    std::vector<int> rows;
    for (std::size_t c = 0; c < p.constraints().size(); ++c) {
        if (!active[c]) continue;
        const ConstraintInfo& ci = p.constraints()[c];
        for (int r = 0; r < ci.dim; ++r) rows.push_back(ci.row + r);
    }
    return rows;
}

void run_chunk(const Program& p, int lo, int hi, const double* t, const double* q, const double* qd,
               const std::uint8_t* active, const std::vector<int>& rows, const double* f, int f_stride,
               const SolveOptions& opt, BatchOutputs out, int* failures) {
    const int n = p.n();
    const int m = static_cast<int>(rows.size());
    Terms T = p.make_terms();
    auto ws = p.make_workspace();
    Solver solver(std::max(m, 1), n);
    Mat A(std::max(m, 1), n);
    Vec gamma(std::max(m, 1));
    Vec g(n);
    const unsigned need = NEED_M | NEED_H | NEED_A | NEED_GAMMA;
    int bad = 0;
    for (int i = lo; i < hi; ++i) {
        const std::size_t off = static_cast<std::size_t>(i) * n;
        Status s = p.evaluate(t[i], q + off, qd + off, active, need, T, *ws);
        if (s == Status::ok) {
            for (int r = 0; r < m; ++r) {
                A.row(r) = T.A.row(rows[r]);
                gamma[r] = T.gamma[rows[r]];
            }
            g = T.h + T.f_passive;
            if (f != nullptr) g += CVecMap(f + static_cast<std::size_t>(i) * f_stride, n);
            const SolveInfo info = solver.forward(T.M.data(), g.data(), A.data(), m, gamma.data(), opt,
                                                  out.qdd + off, out.f_c ? out.f_c + off : nullptr);
            s = info.status;
            if (out.rank) out.rank[i] = info.rank;
        }
        out.status[i] = static_cast<int>(s);
        if (s != Status::ok) {
            ++bad;
            if (s == Status::callback_error) {  // a Python error is pending: stop this chunk
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
    const std::vector<int> rows = active_rows(program, active);
    int nt = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    // below ~64 states per thread the start-up of a thread is not amortized
    nt = std::min(nt, std::max(1, N / 64));
    if (!program.thread_safe()) nt = 1;
    if (nt == 1) {
        int bad = 0;
        run_chunk(program, 0, N, t, q, qd, active, rows, f, f_stride, opt, out, &bad);
        return bad;
    }
    std::vector<int> failures(nt, 0);
    std::vector<std::thread> pool;
    pool.reserve(nt);
    for (int k = 0; k < nt; ++k) {
        const int lo = static_cast<int>(static_cast<long long>(N) * k / nt);
        const int hi = static_cast<int>(static_cast<long long>(N) * (k + 1) / nt);
        pool.emplace_back(run_chunk, std::cref(program), lo, hi, t, q, qd, active, std::cref(rows), f,
                          f_stride, std::cref(opt), out, &failures[k]);
    }
    for (std::thread& th : pool) th.join();
    int bad = 0;
    for (int b : failures) bad += b;
    return bad;
}

}  // namespace nonmin
