// Bindings of the batched model + kernel (nonmin/batch.hpp): forward dynamics of a Program over
// N states in one call, GIL released for thread-safe programs. Used by
// nonmin.model.Model.forward_dynamics.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

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

}  // namespace

void bind_batch(nb::module_& m) {
    m.def(
        "forward_batch",
        [](const Program& p, CArr1 t, CArr2 q, CArr2 qd, CMask active, std::optional<CArr2> f, double rtol,
           double spd_rtol, double sym_rtol, double mu, int threads, bool want_force) {
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
            if (p.thread_safe()) {
                nb::gil_scoped_release release;
                bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), active.data(),
                                    fp, f_stride, opt, threads, out);
            } else {
                bad = forward_batch(p, static_cast<int>(N), t.data(), q.data(), qd.data(), active.data(),
                                    fp, f_stride, opt, 1, out);
            }
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
