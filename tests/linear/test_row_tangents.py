"""Analytic tangents of the robots' constraint rows (TreeProgram::row_tangents) against the
dual-number evaluation and central differences.

A robot without quaternion joints takes δ(A q̈ + γ) and δ(Aᵀλ) along the 2n directions of
(q, q̇) from the analytic derivatives of its frames' kinematics (engine backend); the NumPy
backend takes every term's tangent from ``evaluate_tangent`` on dual numbers. On a Panda (9
coordinates) with frame-to-frame constraints of every analytic type — point and weld between
two links (shared ancestors; the two fingers, siblings, whose point rows have rank 1), hinge, planar point and planar weld,
a path driver, a polynomial joint coupling, a joint driver — at configurations off the
manifold and velocities off the null space (rank still full), ∂q̈/∂q, ∂q̈/∂q̇, ∂f_c/∂q,
∂f_c/∂q̇ of the two agree to 1e-10 relative, and ∂q̈/∂q, ∂q̈/∂q̇ equal central differences of
the engine's q̈ (step 1e-6) to 1e-7 relative.
"""

import numpy as np
import pytest

from nonmin.linear import dynamics_derivatives

pin = pytest.importorskip("pinocchio")


def _panda(constraints):
    from pathlib import Path

    from nonmin.model.robots import RobotModel

    urdf = (
        Path(pin.__file__).resolve().parents[4]
        / "share" / "example-robot-data" / "robots" / "panda_description" / "urdf" / "panda.urdf"
    )  # fmt: skip
    if not urdf.exists():
        pytest.skip("example-robot-data is not installed")
    return RobotModel.from_urdf(urdf, constraints=constraints, joint_limits="ignore")


def _placement(rng):
    from scipy.spatial.transform import Rotation

    X = np.eye(4)
    X[:3, :3] = Rotation.from_rotvec(rng.standard_normal(3)).as_matrix()
    X[:3, 3] = 0.1 * rng.standard_normal(3)
    return X


def _cases():
    from nonmin.model.robots import FrameConstraint, JointCoupling, JointDriver, PathDriver

    rng = np.random.default_rng(5)
    fc = FrameConstraint
    return {
        "point_link_to_link": [fc.point("c", "panda_link7", "panda_link2",
                                        placement_a=_placement(rng), placement_b=_placement(rng))],
        "weld_link_to_link": [fc.weld("c", "panda_leftfinger", "panda_link2",
                                      placement_a=_placement(rng), placement_b=_placement(rng))],
        "point_fingers": [fc.point("c", "panda_leftfinger", "panda_rightfinger",
                                   placement_a=_placement(rng), placement_b=_placement(rng))],
        "hinge_world": [fc.hinge("c", "panda_link6", axis=(0.3, -0.5, 0.8),
                                 placement_a=_placement(rng), placement_b=_placement(rng))],
        "hinge_link_to_link": [fc.hinge("c", "panda_hand", "panda_link3", axis=(0.0, 0.6, 0.8),
                                        placement_a=_placement(rng), placement_b=_placement(rng))],
        "planar": [fc.planar_point("c", "panda_link5", normal=(0.2, 1.0, 0.1),
                                   placement_a=_placement(rng)),
                   fc.planar_weld("d", "panda_hand", "panda_link1", normal=(0.0, 0.0, 1.0),
                                  placement_a=_placement(rng), placement_b=_placement(rng))],
        "drivers": [PathDriver("p", "panda_hand", x=0.3, z=0.5, point=(0.05, 0.0, 0.1)),
                    JointCoupling("k", "panda_finger_joint1", "panda_joint2",
                                  polycoef=(0.01, 0.3, -0.2, 0.1, 0.05), reference2=0.1),
                    JointDriver("j", "panda_joint4", -1.5)],
    }  # fmt: skip


CASES = _cases()


@pytest.mark.parametrize("case", sorted(CASES))
def test_row_tangents_match_dual_numbers_and_differences(case):
    model = _panda(CASES[case])
    rng = np.random.default_rng(17)
    q0 = np.array([0.1, -0.5, 0.2, -2.0, 0.1, 1.6, 0.8, 0.02, 0.03])
    for _ in range(2):
        q = q0 + 0.2 * rng.standard_normal(model.n)
        qd = rng.standard_normal(model.n)
        f = rng.standard_normal(model.n)
        ours = dynamics_derivatives(model, q, qd, f=f)
        dual = dynamics_derivatives(model, q, qd, f=f, backend="numpy")
        assert ours.rank == dual.rank
        for key in ("dqdd_dq", "dqdd_dqd", "dfc_dq", "dfc_dqd", "dqdd_df"):
            a, b = getattr(ours, key), getattr(dual, key)
            assert np.abs(a - b).max() <= 1e-10 * max(1.0, float(np.abs(b).max())), key
        h = 1e-6
        for key, dx in (("dqdd_dq", True), ("dqdd_dqd", False)):
            fd = np.empty((model.n, model.n))
            for k in range(model.n):
                e = np.zeros(model.n)
                e[k] = h
                if dx:
                    p = dynamics_derivatives(model, q + e, qd, f=f).qdd
                    m = dynamics_derivatives(model, q - e, qd, f=f).qdd
                else:
                    p = dynamics_derivatives(model, q, qd + e, f=f).qdd
                    m = dynamics_derivatives(model, q, qd - e, f=f).qdd
                fd[:, k] = (p - m) / (2 * h)
            got = getattr(ours, key)
            assert np.abs(got - fd).max() <= 1e-7 * max(1.0, float(np.abs(fd).max())), key


def test_out_reuses_the_result_in_place():
    """``out=``: the earlier result's arrays are overwritten in place (same objects, the values
    of a fresh call at the new state); a result of another size or of the NumPy backend is
    refused with InputError."""
    import nonmin
    from nonmin.model.robots import FrameConstraint

    model = _panda([FrameConstraint.point("c", "panda_hand")])
    rng = np.random.default_rng(2)
    q0 = np.array([0.1, -0.5, 0.2, -2.0, 0.1, 1.6, 0.8, 0.02, 0.03])
    first = dynamics_derivatives(model, q0, rng.standard_normal(9))
    arrays = [first.qdd, first.dqdd_dq, first.dfc_df, first.dqdd_du]
    q, qd, f = q0 + 0.1 * rng.standard_normal(9), rng.standard_normal(9), rng.standard_normal(9)
    again = dynamics_derivatives(model, q, qd, f=f, out=first)
    fresh = dynamics_derivatives(model, q, qd, f=f)
    assert again is first
    assert all(a is b for a, b in zip(arrays, [again.qdd, again.dqdd_dq, again.dfc_df, again.dqdd_du]))
    for key in ("qdd", "f_c", "dqdd_dq", "dqdd_dqd", "dqdd_df", "dqdd_du", "dfc_dq", "dfc_dqd", "dfc_du"):
        assert np.array_equal(getattr(again, key), getattr(fresh, key)), key
    assert again.rank == fresh.rank == 3
    with pytest.raises(nonmin.errors.InputError, match="out must"):
        dynamics_derivatives(model, q, qd, out=dynamics_derivatives(model, q, qd, backend="numpy"))
    from nonmin.model.robots import example_robot_closure

    other, state = example_robot_closure("ur5", "point")  # n = 6
    with pytest.raises(nonmin.errors.InputError, match="out must"):
        dynamics_derivatives(other, state.q, out=first)
