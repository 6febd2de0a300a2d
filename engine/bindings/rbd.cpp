// Bindings of the rigid-body layer: nonmin._engine.TreeProgram (a Program, see program.cpp),
// built once by nonmin.model.robots._tree from arrays describing the tree, its frames and its
// constraints. Besides Program's evaluate_into / evaluate_batch it has evaluate_arrays (one call
// writing the requested terms into caller-provided arrays, for RobotModel.evaluate) and the
// single algorithms (placements, Jacobians, frame motion, CRBA, RNEA, potential) for the tests
// against Pinocchio and for kinematic queries.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <cstring>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "nonmin/rbd/tree_program.hpp"
#include "nonmin/timefn.hpp"
#include "program_common.hpp"
#include "register.hpp"

namespace nb = nanobind;

namespace nonmin::bindings {
namespace {

using rbd::SE3;
using rbd::TreeProgram;
using rbd::TreeWorkspace;
using rbd::Vec3;
using CArr = nb::ndarray<const double, nb::c_contig, nb::device::cpu>;
using OArr = nb::ndarray<double, nb::c_contig, nb::device::cpu>;
using IArr = nb::ndarray<const std::int64_t, nb::c_contig, nb::device::cpu>;
using U8Arr = nb::ndarray<const std::uint8_t, nb::c_contig, nb::device::cpu>;

[[noreturn]] void model_error(const std::string& msg) { raise_error("ModelError", msg); }
[[noreturn]] void shape_error(const std::string& msg) { raise_error("ShapeError", msg); }

template <class A>
void expect(const A& a, std::size_t n, const char* name) {
    std::size_t c = 1;
    for (std::size_t i = 0; i < a.ndim(); ++i) c *= a.shape(i);
    if (c != n)
        shape_error(std::string(name) + ": expected " + std::to_string(n) + " values, got " +
                    std::to_string(c));
}

SE3 se3_from(const double* H) {  // 4 × 4 row-major homogeneous transform
    SE3 X;
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) X.R(r, c) = H[4 * r + c];
        X.p[r] = H[4 * r + 3];
    }
    return X;
}

void se3_to(const SE3& X, double* H) {
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) H[4 * r + c] = X.R(r, c);
        H[4 * r + 3] = X.p[r];
    }
    H[12] = H[13] = H[14] = 0.0;
    H[15] = 1.0;
}

// Scratch for the single-algorithm queries (not a hot path: allocated per call).
struct Query {
    const TreeProgram& program;
    TreeWorkspace ws;

    Query(const TreeProgram& p, const CArr& q) : program(p), ws(p.description()) {
        expect(q, model().nq, "q");
        if (program.normalize(q.data(), ws) != Status::ok)
            raise_error("NonFiniteError", "q: not finite, or a quaternion is zero");
        rbd::forward_kinematics(model(), ws.data, ws.qn.data());
    }
    const rbd::TreeModel& model() const { return program.description().model; }
    const rbd::Frame& frame(int f) const {
        const auto& fr = program.description().frames;
        if (f < 0 || f >= static_cast<int>(fr.size()))
            raise_error("InputError", "frame index " + std::to_string(f) + " out of range");
        return fr[f];
    }
};

void make_tree(
    TreeProgram* self, int nq, int nv, IArr types, IArr parents, IArr axis_index, CArr axes, IArr iq, IArr iv,
    CArr placements, CArr masses, CArr coms, CArr inertias, CArr gravity, CArr armature,
    IArr frame_joints, CArr frame_placements, std::vector<std::string> c_names, IArr c_types,
    IArr c_frames, CArr c_axes, CArr c_u, IArr c_iq, CArr c_coef, CArr c_ref, IArr actuated,
    CArr damping, std::vector<TimeFunction> drivers, std::optional<IArr> c_drv) {
    const std::size_t nj = types.shape(0);
    expect(parents, nj, "parents");
    expect(axis_index, nj, "axis_index");
    expect(axes, 3 * nj, "axes");
    expect(iq, nj, "iq");
    expect(iv, nj, "iv");
    expect(placements, 16 * nj, "placements");
    expect(masses, nj, "masses");
    expect(coms, 3 * nj, "coms");
    expect(inertias, 9 * nj, "inertias");
    expect(gravity, 3, "gravity");
    expect(armature, static_cast<std::size_t>(nv), "armature");
    const std::size_t nf = frame_joints.shape(0);
    expect(frame_placements, 16 * nf, "frame_placements");
    const std::size_t nc = c_names.size();
    expect(c_types, nc, "c_types");
    expect(c_frames, 2 * nc, "c_frames");
    expect(c_axes, 3 * nc, "c_axes");
    expect(c_u, 6 * nc, "c_u");
    expect(c_iq, 2 * nc, "c_iq");
    expect(c_coef, 5 * nc, "c_coef");
    expect(c_ref, 2 * nc, "c_ref");
    if (c_drv) expect(*c_drv, 3 * nc, "c_drv");
    expect(damping, static_cast<std::size_t>(nv), "damping");

    rbd::TreeDescription d;
    d.model.nq = nq;
    d.model.nv = nv;
    d.model.gravity = Vec3(gravity.data()[0], gravity.data()[1], gravity.data()[2]);
    d.model.armature = Eigen::Map<const Vec>(armature.data(), nv);
    for (std::size_t i = 0; i < nj; ++i) {
        rbd::Joint j;
        const auto t = types.data()[i];
        if (t < 0 || t > 4) model_error("joint " + std::to_string(i) + ": unknown type " + std::to_string(t));
        j.type = static_cast<rbd::JointType>(t);
        j.parent = static_cast<int>(parents.data()[i]);
        j.axis_index = static_cast<int>(axis_index.data()[i]);
        j.axis = Eigen::Map<const Vec3>(axes.data() + 3 * i);
        j.iq = static_cast<int>(iq.data()[i]);
        j.iv = static_cast<int>(iv.data()[i]);
        j.placement = se3_from(placements.data() + 16 * i);
        j.mass = masses.data()[i];
        j.com = Eigen::Map<const Vec3>(coms.data() + 3 * i);
        j.inertia = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(inertias.data() + 9 * i);
        d.model.joints.push_back(j);
    }
    for (std::size_t f = 0; f < nf; ++f)
        d.frames.push_back(rbd::Frame{static_cast<int>(frame_joints.data()[f]),
                                      se3_from(frame_placements.data() + 16 * f)});
    for (std::size_t c = 0; c < nc; ++c) {
        rbd::TreeConstraint tc;
        tc.name = c_names[c];
        const auto t = c_types.data()[c];
        if (t < 0 || t > 12) model_error("constraint '" + tc.name + "': unknown type " + std::to_string(t));
        tc.type = static_cast<rbd::RowType>(t);
        tc.frame_a = static_cast<int>(c_frames.data()[2 * c]);
        tc.frame_b = static_cast<int>(c_frames.data()[2 * c + 1]);
        tc.axis = Eigen::Map<const Vec3>(c_axes.data() + 3 * c);
        tc.u1 = Eigen::Map<const Vec3>(c_u.data() + 6 * c);
        tc.u2 = Eigen::Map<const Vec3>(c_u.data() + 6 * c + 3);
        tc.iq = static_cast<int>(c_iq.data()[2 * c]);
        tc.iq2 = static_cast<int>(c_iq.data()[2 * c + 1]);
        for (int k = 0; k < 5; ++k) tc.coef[k] = c_coef.data()[5 * c + k];
        tc.ref1 = c_ref.data()[2 * c];
        tc.ref2 = c_ref.data()[2 * c + 1];
        if (c_drv)
            for (int k = 0; k < 3; ++k) tc.drv[k] = static_cast<int>(c_drv->data()[3 * c + k]);
        d.constraints.push_back(tc);
    }
    for (std::size_t k = 0; k < actuated.shape(0); ++k) d.actuated.push_back(static_cast<int>(actuated.data()[k]));
    d.damping = Eigen::Map<const Vec>(damping.data(), nv);
    d.drivers = std::move(drivers);
    try {
        new (self) TreeProgram(std::move(d));
    } catch (const EngineError& e) {
        model_error(std::string("robot description: ") + e.what());
    }
}

void copy_out(const double* src, OArr& dst, std::size_t n, const char* name) {
    expect(dst, n, name);
    if (n) std::memcpy(dst.data(), src, n * sizeof(double));
}

}  // namespace

void bind_rbd(nb::module_& m) {
    nb::class_<TreeProgram, Program>(
        m, "TreeProgram",
        "A robot (rigid-body tree + frame constraints) compiled for the engine "
        "(nonmin/rbd/tree_program.hpp), built by nonmin.model.robots._tree.")
        .def("__init__", &make_tree, nb::arg("nq"), nb::arg("nv"), nb::arg("types"),
             nb::arg("parents"), nb::arg("axis_index"), nb::arg("axes"), nb::arg("iq"),
             nb::arg("iv"), nb::arg("placements"), nb::arg("masses"), nb::arg("coms"),
             nb::arg("inertias"), nb::arg("gravity"), nb::arg("armature"),
             nb::arg("frame_joints"), nb::arg("frame_placements"), nb::arg("c_names"),
             nb::arg("c_types"), nb::arg("c_frames"), nb::arg("c_axes"), nb::arg("c_u"),
             nb::arg("c_iq"), nb::arg("c_coef"), nb::arg("c_ref"), nb::arg("actuated"),
             nb::arg("damping"), nb::arg("drivers") = std::vector<TimeFunction>{},
             nb::arg("c_drv") = nb::none())
        .def_prop_ro("nv", [](const TreeProgram& p) { return p.description().model.nv; })
        .def_prop_ro("has_quaternions", &TreeProgram::has_quaternions)
        .def(
            "evaluate_arrays",
            [](const TreeProgram& prog, Terms& T, Workspace& ws, double t, CArr q, CArr qd,
               U8Arr active, unsigned need, OArr M, OArr h, OArr fp, OArr B, OArr A, OArr gamma,
               OArr phi, OArr vel) {
                const std::size_t n = prog.n(), k = prog.k(), m = prog.m_all();
                expect(q, n, "q");
                expect(qd, n, "qd");
                expect(active, prog.constraints().size(), "active");
                if (dynamic_cast<TreeWorkspace*>(&ws) == nullptr || T.M.rows() != prog.n() ||
                    T.A.rows() != prog.m_all() || T.B.cols() != prog.k())
                    raise_error("InputError", "terms and workspace must be made by this program");
                const Status st = prog.evaluate(t, q.data(), qd.data(), active.data(), need, T, ws);
                if (st != Status::ok) return std::make_tuple(static_cast<int>(st), 0.0, 0.0);
                if (need & NEED_M) copy_out(T.M.data(), M, n * n, "M");
                if (need & NEED_H) {
                    copy_out(T.h.data(), h, n, "h");
                    copy_out(T.f_passive.data(), fp, n, "f_passive");
                }
                if (need & NEED_B) copy_out(T.B.data(), B, n * k, "B");
                if (need & NEED_A) copy_out(T.A.data(), A, m * n, "A");
                if (need & NEED_GAMMA) copy_out(T.gamma.data(), gamma, m, "gamma");
                if (need & NEED_PHI) copy_out(T.phi.data(), phi, m, "phi");
                if (need & NEED_VELOCITY) copy_out(T.velocity.data(), vel, m, "velocity");
                return std::make_tuple(0, T.kinetic, T.potential);
            },
            nb::arg("terms"), nb::arg("workspace"), nb::arg("t"), nb::arg("q"), nb::arg("qd"),
            nb::arg("active"), nb::arg("need"), nb::arg("M"), nb::arg("h"), nb::arg("f_passive"),
            nb::arg("B"), nb::arg("A"), nb::arg("gamma"), nb::arg("phi"), nb::arg("velocity"),
            "Evaluate what `need` (NEED_* bits) asks at (t, q, qd) for the active constraints "
            "(uint8 mask) with the given scratch (make_terms(), make_workspace()) and copy the "
            "terms into the given C-contiguous float64 arrays (all m_all rows; inactive rows "
            "unspecified). Returns (status, kinetic, potential); status 0 is ok. Holds the GIL.")
        .def(
            "coriolis_matrix",
            [](const TreeProgram& prog, CArr q, CArr qd) {
                const auto n = static_cast<std::size_t>(prog.n());
                expect(q, n, "q");
                expect(qd, n, "qd");
                TreeWorkspace ws(prog.description());
                auto C = new_array({n, n});
                if (prog.coriolis_matrix(q.data(), qd.data(), ws, C.data()) != Status::ok)
                    raise_error("NonFiniteError", "q and qd must be finite (and quaternions non-zero)");
                return C;
            },
            nb::arg("q"), nb::arg("qd"),
            "Christoffel Coriolis matrix C = TᵀC_vT + TᵀM_vṪ (n, n) in the coordinates q.")
        .def(
            "jacobian_dot",
            [](const TreeProgram& prog, CArr q, CArr qd, U8Arr active) {
                const auto n = static_cast<std::size_t>(prog.n());
                expect(q, n, "q");
                expect(qd, n, "qd");
                expect(active, prog.constraints().size(), "active");
                TreeWorkspace ws(prog.description());
                auto Ad = new_array({static_cast<std::size_t>(prog.m_all()), n});
                if (prog.jacobian_dot(q.data(), qd.data(), active.data(), ws, Ad.data()) != Status::ok)
                    raise_error("NonFiniteError", "q and qd must be finite (and quaternions non-zero)");
                return Ad;
            },
            nb::arg("q"), nb::arg("qd"), nb::arg("active"),
            "Ȧ = dA/dt along qd, (m_all, n); rows of inactive constraints are zero.")
        .def(
            "placements",
            [](const TreeProgram& prog, CArr q) {
                Query Q(prog, q);
                const auto& model = Q.model();
                const auto& frames = prog.description().frames;
                auto oMi = new_array({model.joints.size(), 4, 4});
                auto oMf = new_array({frames.size(), 4, 4});
                for (std::size_t i = 0; i < model.joints.size(); ++i) se3_to(Q.ws.data.oMi[i], oMi.data() + 16 * i);
                for (std::size_t f = 0; f < frames.size(); ++f)
                    se3_to(rbd::frame_placement(model, Q.ws.data, frames[f]), oMf.data() + 16 * f);
                return nb::make_tuple(oMi, oMf);
            },
            nb::arg("q"), "Joint placements (nj, 4, 4) and frame placements (nf, 4, 4) at q.")
        .def(
            "frame_jacobian",
            [](const TreeProgram& prog, CArr q, int f) {
                Query Q(prog, q);
                const int nv = Q.model().nv;
                auto J = new_array({6, static_cast<std::size_t>(nv)});
                rbd::frame_jacobian(Q.model(), Q.ws.data, Q.frame(f), J.data(), nv);
                return J;
            },
            nb::arg("q"), nb::arg("frame"), "LOCAL_WORLD_ALIGNED Jacobian (6, nv) of a frame.")
        .def(
            "frame_motion",
            [](const TreeProgram& prog, CArr q, CArr v, CArr a, int f) {
                Query Q(prog, q);
                expect(v, Q.model().nv, "v");
                expect(a, Q.model().nv, "a");
                rbd::forward_motion(Q.model(), Q.ws.data, v.data(), a.data());
                rbd::FrameKinematics k;
                rbd::frame_kinematics(Q.model(), Q.ws.data, Q.frame(f), true, k);
                auto out = new_array({4, 3});
                for (int r = 0; r < 3; ++r) {
                    out.data()[r] = k.v[r];
                    out.data()[3 + r] = k.w[r];
                    out.data()[6 + r] = k.a[r];
                    out.data()[9 + r] = k.alpha[r];
                }
                return out;
            },
            nb::arg("q"), nb::arg("v"), nb::arg("a"), nb::arg("frame"),
            "World-aligned (v, ω, classical a, α) of a frame's origin, shape (4, 3), for "
            "Pinocchio's velocity v and acceleration a.")
        .def(
            "crba",
            [](const TreeProgram& prog, CArr q) {
                Query Q(prog, q);
                const auto nv = static_cast<std::size_t>(Q.model().nv);
                auto M = new_array({nv, nv});
                rbd::crba(Q.model(), Q.ws.data, M.data(), static_cast<int>(nv));
                return M;
            },
            nb::arg("q"), "Joint-space inertia M_v (nv, nv) at q (armature included).")
        .def(
            "rnea",
            [](const TreeProgram& prog, CArr q, CArr v, CArr a) {
                Query Q(prog, q);
                expect(v, Q.model().nv, "v");
                expect(a, Q.model().nv, "a");
                rbd::forward_motion(Q.model(), Q.ws.data, v.data(), a.data());
                auto tau = new_array({static_cast<std::size_t>(Q.model().nv)});
                rbd::rnea(Q.model(), Q.ws.data, a.data(), tau.data());
                return tau;
            },
            nb::arg("q"), nb::arg("v"), nb::arg("a"),
            "Inverse dynamics τ = M a + C v + g (Pinocchio's rnea, armature included).")
        .def(
            "potential_energy",
            [](const TreeProgram& prog, CArr q) {
                Query Q(prog, q);
                return rbd::potential_energy(Q.model(), Q.ws.data);
            },
            nb::arg("q"), "Gravitational potential energy at q.");
}

}  // namespace nonmin::bindings
