// Lock-step lanes for the batched engine: the fibers and the serving of parked kernel calls
// (lanes.hpp).
#include "lanes.hpp"

#include "nonmin/linalg.hpp"

#include <cstdlib>
#include <exception>
#include <memory>
#include <vector>

#if defined(__x86_64__) && defined(__GNUC__) && defined(__linux__)
#define NONMIN_LANES 1
#else
#define NONMIN_LANES 0
#endif

#if NONMIN_LANES
// switch(from, to): saves the callee-saved registers, MXCSR and the x87 control word on the
// current stack, its stack pointer in *from, and continues on the stack `to` (SysV x86-64).
extern "C" void nonmin_lane_switch(void** from, void* to);
asm(R"(
    .text
    .p2align 4
    .globl nonmin_lane_switch
    .hidden nonmin_lane_switch
    .type nonmin_lane_switch,@function
nonmin_lane_switch:
    pushq %rbp
    pushq %rbx
    pushq %r12
    pushq %r13
    pushq %r14
    pushq %r15
    subq $8, %rsp
    stmxcsr (%rsp)
    fnstcw 4(%rsp)
    movq %rsp, (%rdi)
    movq %rsi, %rsp
    ldmxcsr (%rsp)
    fldcw 4(%rsp)
    addq $8, %rsp
    popq %r15
    popq %r14
    popq %r13
    popq %r12
    popq %rbx
    popq %rbp
    ret
    .size nonmin_lane_switch,.-nonmin_lane_switch
)");
#endif

namespace nonmin::lanes {

namespace {

constexpr std::size_t STACK = std::size_t(1) << 20;  // per fiber (reserved, touched as used)

struct LQCall {
    const double* B;
    int m, n;
    double rtol;
    linalg::LQWork* w;
    double* cv;
    bool skip, inverse;
    double* E;  // lq_certified_z: Z and w (null: lq_certified)
    double* x;
    int result;
    bool z;
};

struct Group;

struct Fiber {
    void* sp = nullptr;
    std::unique_ptr<char[]> stack;
    bool done = false;
    bool parked = false;
    LQCall call{};
    Group* g = nullptr;
    int index = 0;
};

struct Group {
    void* main_sp = nullptr;
    std::vector<Fiber> fibers;
    const std::function<void(int)>* body = nullptr;
    std::exception_ptr error;
    long long served = 0;  // groups of parked calls served (NONMIN_LANES_SCALAR_EVERY)
    long long scalar_every = 0;
    int W = 4;                   // lanes per kernel call (= fibers)
    std::vector<Fiber*> parked;  // serve()'s scratch (no allocation per round)
    std::vector<char> taken;
    std::vector<std::size_t> same;
};

thread_local Fiber* tl_fiber = nullptr;

Stats g_stats;

bool cpu_avx2() {
#if NONMIN_LANES
    static const bool yes = __builtin_cpu_supports("avx2");
    return yes;
#else
    return false;
#endif
}

#if NONMIN_LANES
void to_main(Fiber& f) {
    tl_fiber = nullptr;
    nonmin_lane_switch(&f.sp, f.g->main_sp);
    tl_fiber = &f;
}

// The running fiber parks its kernel call c and returns to the group, which serves it (in lanes
// or alone); the served call, its result written, once the fiber resumes.
const LQCall& park(const LQCall& c) {
    Fiber& f = *tl_fiber;
    f.call = c;
    f.parked = true;
    to_main(f);
    return f.call;
}

[[noreturn]] void fiber_entry() {
    Fiber& f = *tl_fiber;
    try {
        (*f.g->body)(f.index);
    } catch (...) {
        if (!f.g->error) f.g->error = std::current_exception();
    }
    f.done = true;
    to_main(f);
    std::abort();  // never resumed
}

void init_fiber(Fiber& f) {
    f.stack.reset(new char[STACK]);
    auto top = reinterpret_cast<std::uintptr_t>(f.stack.get() + STACK) & ~std::uintptr_t(15);
    auto* s = reinterpret_cast<std::uint64_t*>(top);
    *--s = 0;                                                  // fiber_entry's return address (none)
    *--s = reinterpret_cast<std::uint64_t>(&fiber_entry);     // nonmin_lane_switch's ret
    for (int r = 0; r < 6; ++r) *--s = 0;                      // rbp rbx r12 r13 r14 r15
    *--s = 0x1F80ull | (0x037Full << 32);                      // MXCSR, x87 control word
    f.sp = s;
}

// Serve the parked calls: those of one shape W at a time in lanes, the rest alone.
void serve(Group& g) {
    std::vector<Fiber*>& parked = g.parked;
    parked.clear();
    for (Fiber& f : g.fibers)
        if (f.parked) parked.push_back(&f);
    if (parked.empty()) return;
    const bool scalar_now = g.scalar_every > 0 && (++g.served % g.scalar_every) == 0;
    const int W = g.W;
    std::vector<char>& taken = g.taken;
    taken.assign(parked.size(), 0);
    for (std::size_t a = 0; a < parked.size(); ++a) {
        if (taken[a]) continue;
        LQCall& c0 = parked[a]->call;
        std::vector<std::size_t>& same = g.same;
        same.assign(1, a);
        if (!scalar_now && !c0.inverse)
            for (std::size_t b = a + 1; b < parked.size() && static_cast<int>(same.size()) < W; ++b) {
                const LQCall& c = parked[b]->call;
                if (!taken[b] && c.m == c0.m && c.n == c0.n && c.skip == c0.skip && (c.E != nullptr) == (c0.E != nullptr) &&
                    c.inverse == c0.inverse && c.w->m_max == c0.w->m_max)
                    same.push_back(b);
            }
        for (std::size_t b : same) taken[b] = 1;
        int res = linalg::LQ_DIVERGED;
        bool zres = false;
        if (same.size() >= 2 && c0.m <= linalg::DENSE_INVERSE_MAX_ROWS) {
            // lanes without a call of their own repeat the first call into spare scratch
            thread_local linalg::LQWork spare;
            thread_local std::vector<double> spare_cv;
            if (spare.m_max != c0.w->m_max || spare.n != c0.n) spare = linalg::LQWork(c0.w->m_max, c0.n);
            const std::size_t sz = static_cast<std::size_t>(c0.m + c0.n * (c0.n + 2) + 1);
            if (spare_cv.size() < sz) spare_cv.resize(sz);
            const double* Bs[4];
            double rts[4];
            linalg::LQWork* ws[4];
            double *cvs[4], *Es[4], *xs[4];
            for (int l = 0; l < W; ++l) {
                const bool own = l < static_cast<int>(same.size());
                const LQCall& c = own ? parked[same[static_cast<std::size_t>(l)]]->call : c0;
                Bs[l] = c.B;
                rts[l] = c.rtol;
                ws[l] = own ? c.w : &spare;
                cvs[l] = own ? c.cv : spare_cv.data();
                Es[l] = own ? c.E : spare_cv.data() + c0.m;
                xs[l] = own ? c.x : spare_cv.data() + c0.m + c0.n * (c0.n + 1);
            }
            const bool zc = c0.E != nullptr;
            res = W == 4 ? linalg::lq_certified_lanes4(Bs, c0.m, c0.n, rts, ws, cvs, c0.skip, c0.inverse,
                                                       zc ? Es : nullptr, zc ? xs : nullptr, &zres)
                         : linalg::lq_certified_lanes2(Bs, c0.m, c0.n, rts, ws, cvs, c0.skip, c0.inverse,
                                                       zc ? Es : nullptr, zc ? xs : nullptr, &zres);
            if (res == linalg::LQ_DIVERGED) {
                g_stats.diverged.fetch_add(1, std::memory_order_relaxed);
            } else {
                g_stats.lane_groups.fetch_add(1, std::memory_order_relaxed);
                g_stats.lane_calls.fetch_add(static_cast<long long>(same.size()), std::memory_order_relaxed);
            }
        }
        for (std::size_t b : same) {
            LQCall& c = parked[b]->call;
            if (res == linalg::LQ_DIVERGED) {
                c.result = c.E ? linalg::lq_certified_z_scalar(c.B, c.m, c.n, c.rtol, *c.w, c.cv, c.E, c.x, &c.z)
                               : linalg::lq_certified_scalar(c.B, c.m, c.n, c.rtol, *c.w, c.cv, c.skip, c.inverse);
                g_stats.scalar_calls.fetch_add(1, std::memory_order_relaxed);
            } else {
                c.result = res;
                c.z = zres;
            }
            parked[b]->parked = false;
        }
    }
}
#endif

}  // namespace

bool available() {
#if NONMIN_LANES
    return true;
#else
    return false;
#endif
}

int width() {
    const char* e = std::getenv("NONMIN_LANES");  // "2": the SSE2 lanes on an AVX2 machine (tests)
    return cpu_avx2() && !(e && e[0] == '2') ? 4 : 2;
}

Stats& stats() { return g_stats; }

bool in_fiber() { return tl_fiber != nullptr; }

void run_fibers(int fibers, const std::function<void(int)>& body) {
#if NONMIN_LANES
    struct Live {  // groups_live counts this group while it runs (maybe_in_fiber)
        Live() { groups_live.fetch_add(1, std::memory_order_relaxed); }
        ~Live() { groups_live.fetch_sub(1, std::memory_order_relaxed); }
    } live_group;
    Group g;
    g.body = &body;
    if (const char* e = std::getenv("NONMIN_LANES_SCALAR_EVERY")) g.scalar_every = std::atoll(e);
    g.W = fibers == 4 ? 4 : 2;
    g.fibers.resize(static_cast<std::size_t>(fibers));
    for (int i = 0; i < fibers; ++i) {
        Fiber& f = g.fibers[static_cast<std::size_t>(i)];
        f.g = &g;
        f.index = i;
        init_fiber(f);
    }
    while (true) {
        bool live = false;
        for (Fiber& f : g.fibers) {  // each run until it parks a call or ends
            if (f.done) continue;
            live = true;
            if (f.parked) continue;
            tl_fiber = &f;
            nonmin_lane_switch(&g.main_sp, f.sp);
            tl_fiber = nullptr;
        }
        if (!live) break;
        serve(g);
    }
    if (g.error) std::rethrow_exception(g.error);
#else
    for (int i = 0; i < fibers; ++i) body(i);
#endif
}

}  // namespace nonmin::lanes

namespace nonmin::linalg {

int lq_certified_parked(const double* B, int m, int n, double rtol, LQWork& w, double* cv, bool skip_redundant,
                        bool inverse) {
#if NONMIN_LANES
    return lanes::park({B, m, n, rtol, &w, cv, skip_redundant, inverse, nullptr, nullptr, 0, false}).result;
#else
    return lq_certified_scalar(B, m, n, rtol, w, cv, skip_redundant, inverse);
#endif
}

int lq_certified_z_parked(const double* B, int m, int n, double rtol, LQWork& w, double* cv, double* E, double* x,
                          bool* z) {
#if NONMIN_LANES
    const lanes::LQCall& c = lanes::park({B, m, n, rtol, &w, cv, true, false, E, x, 0, false});
    *z = c.z;
    return c.result;
#else
    return lq_certified_z_scalar(B, m, n, rtol, w, cv, E, x, z);
#endif
}

}  // namespace nonmin::linalg
