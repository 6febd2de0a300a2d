// Bindings of the batched model + kernel (nonmin/batch.hpp): forward dynamics of a Program over
// N states in one call, GIL released for thread-safe programs. Used by
// nonmin.model.Model.forward_dynamics.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

#include <list>
#include <optional>
#include <string>
#include <vector>

#include "nonmin/batch.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nonmin::bindings {

namespace {

using IntArr = nb::ndarray<nb::numpy, int>;

// Uninitialized: forward_batch writes every entry (batch.hpp).
IntArr new_int_array(std::size_t N) {
    int* data = new int[N > 0 ? N : 1];
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<int*>(p); });
    std::size_t shape[1] = {N};
    return IntArr(data, 1, shape, owner);
}

// The per-thread scratch of recent forward_batch calls, kept for the next call of the same
// program, active mask and symmetry tolerance (the one option a ForwardScratch's state depends
// on: the constant M's validation). A ForwardScratch of A02 N = 40 is ~10 MB of zeroed buffers:
// making it took 7.7 ms per call (Model.forward_dynamics of one state: 9.3 ms, the kernel 55 µs).
// Each entry holds a strong reference to its Program (so no other Program can take its
// address); entries are taken out while a call runs (a concurrent call on the same program
// makes its own) and put back at the front after it, the least recent ones dropped past
// KEPT. Touched with the GIL held only; emptied at interpreter exit (atexit).
struct KeptScratch {
    nb::object program;
    std::vector<std::uint8_t> active;
    double sym_rtol = 0.0;
    ScratchPool pool;
};
constexpr std::size_t KEPT = 2;  // entries (a scratch of A02 N = 80 is ~40 MB per thread)
std::list<KeptScratch>* kept = nullptr;  // never destroyed by C++ (cleared at exit)

KeptScratch take_kept(nb::handle program, const std::uint8_t* active, std::size_t c, double sym_rtol) {
    if (kept)
        for (auto it = kept->begin(); it != kept->end(); ++it)
            if (it->program.ptr() == program.ptr() && it->sym_rtol == sym_rtol &&
                std::equal(it->active.begin(), it->active.end(), active, active + c)) {
                KeptScratch e = std::move(*it);
                kept->erase(it);
                return e;
            }
    KeptScratch e;
    e.program = nb::borrow(program);
    e.active.assign(active, active + c);
    e.sym_rtol = sym_rtol;
    return e;
}

void put_kept(KeptScratch&& e) {
    if (!kept) return;
    kept->push_front(std::move(e));
    while (kept->size() > KEPT) kept->pop_back();
}

}  // namespace

void bind_batch(nb::module_& m) {
    kept = new std::list<KeptScratch>();
    m.def("_clear_kept_scratch", []() {
        if (kept) kept->clear();
    }, "Drop the kept per-thread scratch of forward_batch (at interpreter exit).");
    nb::module_::import_("atexit").attr("register")(m.attr("_clear_kept_scratch"));
    m.def(
        "forward_batch",
        [](nb::handle program, CArr1 t, CArr2 q, CArr2 qd, CMask active, std::optional<CArr2> f, double rtol,
           double spd_rtol, double sym_rtol, double mu, int threads, bool want_force) {
            const Program& p = nb::cast<const Program&>(program);
            const std::size_t N = t.shape(0);
            const auto n = static_cast<std::size_t>(p.n());
            if (q.shape(0) != N || qd.shape(0) != N)
                raise_error("ShapeError", "t, q and qd must have the same number of states (rows)");
            if (q.shape(1) != n || qd.shape(1) != n)
                raise_error("ShapeError", "q and qd must have " + std::to_string(n) + " columns");
            if (active.shape(0) != p.constraints().size())
                raise_error("ShapeError", "active must have one entry per constraint");
            int f_stride = 0;
            const double* fp = nullptr;
            if (f) {
                if (f->shape(1) != n || (f->shape(0) != N && f->shape(0) != 1))
                    raise_error("ShapeError", "f must have shape (N, n) or (1, n)");
                fp = f->data();
                f_stride = f->shape(0) == 1 ? 0 : static_cast<int>(n);
            }
            NpArr qdd = new_array({N, n}, false);  // written in full by forward_batch
            NpArr fc = want_force ? new_array({N, n}, false) : new_array({0});
            IntArr rank = new_int_array(N);
            IntArr status = new_int_array(N);
            SolveOptions opt;
            opt.rtol = rtol;
            opt.spd_rtol = spd_rtol;
            opt.sym_rtol = sym_rtol;
            opt.mu = mu;
            BatchOutputs out;
            out.qdd = qdd.data();
            out.f_c = want_force ? fc.data() : nullptr;
            out.rank = rank.data();
            out.status = status.data();
            int bad;
            KeptScratch mine = take_kept(program, active.data(), active.shape(0), sym_rtol);
            if (p.thread_safe()) {
                nb::gil_scoped_release release;
                bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), active.data(),
                                    fp, f_stride, opt, threads, out, &mine.pool);
            } else {
                bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), active.data(),
                                    fp, f_stride, opt, 1, out, &mine.pool);
            }
            put_kept(std::move(mine));
            if (PyErr_Occurred()) throw nb::python_error();
            return nb::make_tuple(qdd, fc, rank, status, bad);
        },
        nb::arg("program"), nb::arg("t"), nb::arg("q"), nb::arg("qd"), nb::arg("active"),
        nb::arg("f").none(), nb::arg("rtol"), nb::arg("spd_rtol"), nb::arg("sym_rtol"), nb::arg("mu"),
        nb::arg("threads"), nb::arg("want_force"),
        "Forward dynamics of `program` over N states: (qdd (N, n), f_c (N, n) or (0,), rank (N,), "
        "status (N,), number of failed states). Threads over the batch when the program is "
        "thread safe (GIL released).");
}

}  // namespace nonmin::bindings
