// Lock-step lanes for the batched engine (issue 20, target 1; benchmarks/SWEEP.md).
//
// The runs of a batch thread each run in a fiber of their own (a stack and a saved register
// set: the scalar loop of sim_loop.cpp, unchanged, exactly as simulate() runs it). When a run
// reaches a kernel that has a lane form (first: the certified LQ of the rank decision,
// linalg::lq_certified), it parks its call and the thread switches to the next run; once every
// run of the group is parked (or finished), the parked calls of one shape are evaluated W at a
// time in the lanes of a SIMD register (W = 4 doubles under AVX2, chosen at run time, else 2
// with SSE2), each lane's result written to its run's scratch, and the runs resume.
//
// A lane's arithmetic is its scalar run's (the same operations in the same order; +, −, ×, ÷
// and sqrt are correctly rounded in every lane, no FMA: the engine is built without -mfma and
// the lane code only enables AVX2), so every run stays bitwise equal to simulate(). A
// data-dependent decision inside the kernel that differs between the lanes (a structural zero
// in one lane only, a row skipped as redundant, an unproved certificate) abandons the lane
// evaluation: each parked call is then made by the scalar kernel, as in simulate(). Nothing
// else of a run depends on its neighbours: runs at different places of their loops (another
// step, a failed run, a projection with more iterations) only meet at the next kernel call.
//
// Switches: NONMIN_LANES=0 in the environment turns the lanes off (the scalar batch), =2 takes
// the SSE2 lanes (W = 2) on an AVX2 machine;
// NONMIN_LANES_SCALAR_EVERY=K makes every K-th group of parked calls scalar (tests: runs served
// now by lanes, now alone, stay bitwise equal). Only on x86-64 (elsewhere: the scalar batch).
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>

namespace nonmin::lanes {

// Whether this build and CPU have lanes (x86-64; the width is 4 with AVX2, else 2).
bool available();
int width();

// Counters of the lanes of this process (tests, benchmarks): kernel calls served in lanes,
// served alone (a single parked call, or NONMIN_LANES_SCALAR_EVERY), and lane evaluations
// abandoned because the lanes' decisions differed.
struct Stats {
    std::atomic<long long> lane_calls{0}, lane_groups{0}, scalar_calls{0}, diverged{0};
};
Stats& stats();

// Runs body(fiber) in `fibers` fibers on this thread (fibers = width(): one call per lane) until each returns, serving their parked
// kernel calls in lanes. body must not throw past its end (its exceptions are caught, the first
// rethrown here after every fiber ended).
void run_fibers(int fibers, const std::function<void(int)>& body);

// Inside a fiber of run_fibers on this thread.
bool in_fiber();

// Groups of fibers running in this process (run_fibers). The kernels with a lane form ask
// maybe_in_fiber() on every call: outside a batch with lanes (every simulate()) that is one
// relaxed load, not the call and thread-local lookup of in_fiber().
inline std::atomic<int> groups_live{0};
inline bool maybe_in_fiber() { return groups_live.load(std::memory_order_relaxed) != 0 && in_fiber(); }

}  // namespace nonmin::lanes

namespace nonmin::linalg {
struct LQWork;
// lq_certified's call from a fiber: parked, served in lanes or alone (sim_lanes.cpp).
int lq_certified_parked(const double* B, int m, int n, double rtol, LQWork& w, double* cv, bool skip_redundant,
                        bool inverse);
// The scalar kernel (core_lq.cpp), and its lane forms over W calls: each call's B (m × (n + 1)),
// its rank tolerance, scratch and cv; returns LQ_DIVERGED (nothing of the calls' outputs is meaningful then)
// when the lanes' decisions differ, else the common result, every lane's outputs written.
int lq_certified_scalar(const double* B, int m, int n, double rtol, LQWork& w, double* cv, bool skip_redundant,
                        bool inverse);
inline constexpr int LQ_DIVERGED = -1;
// (rtol: each lane's; the margin and the certificate are decided per lane)
// E, x (null: not asked): with a result of rank r and n − r ≤ r, also lq_rows_min_norm(w, r, n,
// r, n − r, E, cv, x) per lane (*z set true), as lq_certified_z.
int lq_certified_lanes4(const double* const* B, int m, int n, const double* rtol, LQWork* const* w,
                        double* const* cv, bool skip_redundant, bool inverse, double* const* E = nullptr,
                        double* const* x = nullptr, bool* z = nullptr);
int lq_certified_lanes2(const double* const* B, int m, int n, const double* rtol, LQWork* const* w,
                        double* const* cv, bool skip_redundant, bool inverse, double* const* E = nullptr,
                        double* const* x = nullptr, bool* z = nullptr);
// lq_certified_z's parked and scalar forms
int lq_certified_z_parked(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                          bool* z);
int lq_certified_z_scalar(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                          bool* z);
}  // namespace nonmin::linalg
