"""Example robots built from the files shipped in ``nonmin/data/robots``.

Each function returns ``(model, state)``: a :class:`RobotModel` and a consistent
:class:`~nonmin.model.State` (assembled with :func:`nonmin.model.assemble`).
"""

from __future__ import annotations

import numpy as np

from .._assembly import assemble
from .._protocol import State
from ._constraints import WORLD, FrameConstraint
from ._data import data_path
from ._pinocchio import RobotModel

__all__ = [
    "example_robot_closure",
    "fourbar",
    "fourbar_mjcf",
    "pinocchio_frame_constraint",
    "pinocchio_point_constraint",
    "serial_arm",
    "two_arm_grasp",
    "ur5_point_closure",
]

FOURBAR_CLOSURES = ("point", "planar_point", "hinge", "weld", "planar_weld")


def serial_arm() -> tuple[RobotModel, State]:
    """4-dof arm (``arm4.urdf``) with a unilateral end-effector contact ``"ee_contact"``.

    The contact (ground plane ``z = 0``) is inactive by default; the returned state has the
    end effector touching the ground (``gap = 0``) at rest, so activating ``"ee_contact"`` is
    consistent.
    """
    model = RobotModel.from_urdf(
        data_path("arm4.urdf"), constraints=[FrameConstraint.contact("ee_contact", "ee")]
    )
    state = assemble(
        model, [0.3, 0.6, 0.9, 0.4], active={"ee_contact"}, fixed=["yaw", "wrist"]
    ).replace(active=model.default_active)
    return model, state


def fourbar(closure: str = "planar_point") -> tuple[RobotModel, State]:
    """Planar four-bar (``fourbar.urdf``) closed by a constraint named ``"closure"``.

    Parameters
    ----------
    closure : {"point", "planar_point", "hinge", "weld", "planar_weld"}
        ``planar_point`` (2 rows) is the minimal closure; ``point`` (3 rows) and ``hinge``
        (5 rows) are redundant for a planar loop (rank 2), which Pinocchio's KKT solver cannot
        handle without regularization; ``weld``/``planar_weld`` lock the loop (rank 3).
    """
    from ...errors import InputError

    if closure not in FOURBAR_CLOSURES:
        raise InputError(f"closure must be one of {FOURBAR_CLOSURES}, got {closure!r}")
    make = getattr(FrameConstraint, closure)
    kw = {"normal": (0.0, 1.0, 0.0)} if closure.startswith("planar") else {}
    if closure == "hinge":
        kw = {"axis": (0.0, 1.0, 0.0)}
    con = make("closure", "coupler_tip", "rocker_tip", **kw)
    model = RobotModel.from_urdf(data_path("fourbar.urdf"), constraints=[con], actuated=["crank"])
    guess = [-1.2, 0.9, -1.9]
    if closure in ("weld", "planar_weld"):
        # a weld also fixes the relative angle: assemble with a point closure, then weld there
        pt = model.replace(robot_constraints=(FrameConstraint.planar_point("closure", "coupler_tip",
                                                                           "rocker_tip"),))
        q = assemble(pt, guess, fixed=["crank"]).q
        H = np.linalg.inv(pt.frame_placement(q, "coupler_tip")) @ pt.frame_placement(q, "rocker_tip")
        Hb = np.eye(4)
        Hb[:3, :3] = H[:3, :3].T
        con = make("closure", "coupler_tip", "rocker_tip", placement_b=Hb, **kw)
        model = model.replace(robot_constraints=(con,))
        return model, model.state(q)
    return model, assemble(model, guess, fixed=["crank"])


def fourbar_mjcf() -> tuple[RobotModel, State]:
    """The MJCF four-bar (``fourbar.xml``) with its equalities closure/lock/gear/brake.

    Defined closed in MuJoCo's reference configuration ``qpos0 = 0``, returned at rest there.
    """
    model = RobotModel.from_mjcf(data_path("fourbar.xml"), actuated=["crank"])
    return model, model.state(np.zeros(model.n))


def two_arm_grasp() -> tuple[RobotModel, State]:
    """Two 4-dof arms holding a free-floating box (``two_arms.urdf``).

    ``"grasp_left"`` welds the left end effector to the box's left face frame, and
    ``"grasp_right"`` pins the right end effector to the right face (3D point); 9 rows on
    14 velocity components (+ the box's unit-quaternion row). Coordinates: the box's 7
    (position, quaternion ``x, y, z, w``) followed by the 8 arm joints.
    """
    Hb = np.eye(4)
    Hb[:3, :3] = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # ee x-axis along −y_box
    cons = [
        FrameConstraint.weld("grasp_left", "left_ee", "box_left", placement_b=Hb),
        FrameConstraint.point("grasp_right", "right_ee", "box_right"),
    ]
    model = RobotModel.from_urdf(data_path("two_arms.urdf"), constraints=cons)
    q = model.neutral_configuration()
    arm = [0.0, -1.1, 2.876, -1.776]  # end effectors horizontal, 0.2 m apart, facing each other
    for side in ("left", "right"):
        for j, val in zip(("yaw", "shoulder", "elbow", "wrist"), arm):
            q[model.coordinate_names.index(f"{side}_{j}")] = val
    # box pose that satisfies the left weld exactly: oM_box = oM_ee · Hb⁻¹ · T(0, 0.1, 0)⁻¹
    to_face = np.eye(4)
    to_face[1, 3] = 0.1
    oMbox = model.frame_placement(q, "left_ee") @ np.linalg.inv(Hb) @ np.linalg.inv(to_face)
    box = model.coordinate_names.index("box.x")
    q[box : box + 3] = oMbox[:3, 3]
    q[box + 3 : box + 7] = _rot_to_quat(oMbox[:3, :3])
    return model, assemble(model, q)


#: Configuration at which :func:`ur5_point_closure` pins the tool frame (and its assembly guess).
UR5_Q_GUESS = (0.2, -1.0, 1.3, -0.6, 0.9, 0.4)


def ur5_point_closure() -> tuple[RobotModel, State]:
    """UR5 (example-robot-data) whose tool frame ``"ee_link"`` is pinned to the world (3 rows).

    The point is where ``ee_link`` is at :data:`UR5_Q_GUESS`; the model has a 3-row
    :meth:`FrameConstraint.point` ``"closure"`` (joint limits ignored) and the returned state is
    assembled from that configuration (at rest). Used by the derivative tests against
    Pinocchio and by ``benchmarks/derivative_bench.py``; :func:`pinocchio_point_constraint`
    builds Pinocchio's form of the same closure.

    Raises
    ------
    MissingDependencyError
        When Pinocchio or example-robot-data (extra ``test``) is not installed.
    """
    return example_robot_closure("ur5", "point")


#: example-robot-data arms of :func:`example_robot_closure`: (URDF under robots/, tool frame,
#: configuration where the tool is held).
EXAMPLE_ARMS = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "ee_link", UR5_Q_GUESS),
    "panda": (
        "panda_description/urdf/panda.urdf",
        "panda_hand",
        (0.1, -0.5, 0.2, -2.0, 0.1, 1.6, 0.8, 0.02, 0.03),
    ),
}


def example_robot_closure(arm: str = "panda", closure: str = "point") -> tuple[RobotModel, State]:
    """An example-robot-data arm whose tool frame is held in the world: a 3-row ``"point"``
    or a 6-row ``"weld"`` constraint named ``"closure"`` (joint limits ignored), assembled at
    rest where the tool is at the arm's guess configuration (:data:`EXAMPLE_ARMS`).

    ``example_robot_closure("ur5", "point")`` is :func:`ur5_point_closure`. The Panda has 9
    coordinates (7 arm joints and 2 finger slides, which the closure leaves free). Used by the
    derivative tests against Pinocchio and ``benchmarks/derivative_bench.py``;
    :func:`pinocchio_frame_constraint` builds Pinocchio's form of the closure.

    Raises
    ------
    InputError
        Unknown arm or closure.
    MissingDependencyError
        When Pinocchio or example-robot-data (extra ``test``) is not installed.
    """
    from pathlib import Path

    from ...errors import InputError, MissingDependencyError

    if arm not in EXAMPLE_ARMS:
        raise InputError(f"arm must be one of {sorted(EXAMPLE_ARMS)}, got {arm!r}")
    if closure not in ("point", "weld"):
        raise InputError(f"closure must be 'point' or 'weld', got {closure!r}")
    try:
        import pinocchio as pin
    except ImportError:
        raise MissingDependencyError(
            "example_robot_closure needs Pinocchio: pip install 'nonmin[pin]'"
        ) from None
    rel, frame, guess = EXAMPLE_ARMS[arm]
    urdf = Path(pin.__file__).resolve().parents[4] / "share" / "example-robot-data" / "robots" / rel
    if not urdf.exists():
        raise MissingDependencyError(
            f"example_robot_closure needs example-robot-data ({urdf} is missing): "
            "pip install example-robot-data"
        )
    q_guess = np.array(guess)
    free = RobotModel.from_urdf(urdf, joint_limits="ignore")
    oMe = free.frame_placement(q_guess, frame)
    con = getattr(FrameConstraint, closure)("closure", frame, placement_b=oMe)
    model = RobotModel.from_urdf(urdf, constraints=[con], joint_limits="ignore")
    return model, assemble(model, q_guess)


def pinocchio_frame_constraint(model: RobotModel, name: str = "closure") -> object:
    """Pinocchio's ``RigidConstraintModel`` of a point (``CONTACT_3D``) or weld
    (``CONTACT_6D``) constraint of ``model`` that holds a frame in the world (LOCAL).

    The rows differ from nonmin's (a weld's rotation rows), the constrained accelerations and
    their derivatives do not (the same constraint set at full rank).

    Raises
    ------
    InputError
        When ``name`` is not a point or weld constraint of a frame to the world.
    """
    import pinocchio as pin

    from ...errors import InputError

    cons = {c.name: c for c in model.robot_constraints}
    con = cons.get(name)
    if (
        not isinstance(con, FrameConstraint)
        or con.type not in ("point", "weld")
        or con.frame_b != WORLD
    ):
        raise InputError(
            "name must be a point or weld constraint of a frame to the world in "
            f"{sorted(cons)}, got {name!r}"
        )
    pm = model.pinocchio_model
    fr = pm.frames[pm.getFrameId(con.frame_a)]
    kind = pin.ContactType.CONTACT_3D if con.type == "point" else pin.ContactType.CONTACT_6D
    return pin.RigidConstraintModel(
        kind,
        pm,
        fr.parentJoint,
        fr.placement * pin.SE3(con.placement_a),
        0,
        pin.SE3(con.placement_b),
        pin.ReferenceFrame.LOCAL,
    )


def pinocchio_point_constraint(model: RobotModel, name: str = "closure") -> object:
    """Pinocchio's ``RigidConstraintModel`` (``CONTACT_3D``, LOCAL) of a 3D point constraint
    of ``model`` that pins a frame to the world (``frame_b`` the world), for Pinocchio's
    ``constraintDynamics`` and its derivatives.

    Raises
    ------
    InputError
        When ``name`` is not a point constraint of a frame to the world.
    """
    import pinocchio as pin

    from ...errors import InputError

    cons = {c.name: c for c in model.robot_constraints}
    con = cons.get(name)
    if not isinstance(con, FrameConstraint) or con.type != "point" or con.frame_b != WORLD:
        raise InputError(
            f"name must be a point constraint of a frame to the world in {sorted(cons)}, got {name!r}"
        )
    pm = model.pinocchio_model
    fr = pm.frames[pm.getFrameId(con.frame_a)]
    return pin.RigidConstraintModel(
        pin.ContactType.CONTACT_3D,
        pm,
        fr.parentJoint,
        fr.placement * pin.SE3(con.placement_a),
        0,
        pin.SE3(con.placement_b),
        pin.ReferenceFrame.LOCAL,
    )


def _rot_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method)."""
    tr = float(np.trace(R))
    i = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        x, y, z = (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)
    elif i == 1:
        x = 0.5 * np.sqrt(1.0 + 2 * R[0, 0] - tr)
        w, y, z = (R[2, 1] - R[1, 2]) / (4 * x), (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x)
    elif i == 2:
        y = 0.5 * np.sqrt(1.0 + 2 * R[1, 1] - tr)
        w, x, z = (R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), (R[1, 2] + R[2, 1]) / (4 * y)
    else:
        z = 0.5 * np.sqrt(1.0 + 2 * R[2, 2] - tr)
        w, x, y = (R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z), (R[1, 2] + R[2, 1]) / (4 * z)
    return np.array([x, y, z, w])
