"""Reactions by name: the force and torque each constraint exerts on the bodies it joins.

The projection dynamics give the generalized constraint force ``f_c = −S (f + h − M Ω q̇)``
(eq. (fc_R), the oblique projector S; no multipliers are solved for). Since ``f_c ∈ R(Aᵀ)``,
it splits over the rows of the active constraints as ``f_c = Aᵀ λ``; the minimum-norm split
``λ = (Aᵀ)⁺ f_c`` is the only one when the rows are independent. With redundant rows
(``rank A < m``) every ``λ + z``, ``z ∈ N(Aᵀ)``, gives the same ``f_c`` and the same motion:
the physics does not decide those components (a preload of an over-constrained closure).
A linear function ``L λ`` of the multipliers — a force or torque component of one
constraint — is *determined* exactly when ``L z = 0`` for every ``z ∈ N(Aᵀ)``; this module
reports, for every component, whether it is (``determined`` masks), and returns the
minimum-norm value, which for an undetermined component is one admissible choice among many.

Wrenches. Every constraint joins two bodies ``a`` and ``b`` (either may be the ground). The
wrench on a body is read from the constraint's own part ``A_Iᵀ λ_I`` of f_c:

* planar (coordinates ``(x, y, θ)`` per body): the body's columns hold the world force F and
  the torque about the centre of mass; reported as ``F`` in the body frame (``Rᵀ F``) and the
  torque about the constraint's attachment point ``s`` on that body, ``τ − (R s) × F``;
* spatial (``(r, ε)`` per body): ``F = f_r``, the torque about the centre of mass in the body
  frame ``½ G(ε) f_ε`` (``ω' = 2 G ε̇``; the part of ``f_ε`` along ε is the norm row's), then
  moved to the attachment point: ``τ' − s × Rᵀ F``;
* robots (frame constraints): rows are world-aligned (Jacobian differences of the two
  constraint frames), so ``λ`` itself is the force on frame a (and its moment for weld, hinge
  and planar_weld rows); reported in each constraint frame's axes about its origin;
* the ground (no coordinates) gets the opposite of the other body's wrench, in world axes
  about its attachment point (action and reaction: every joint here is invariant under a
  common rigid motion of the two bodies, so the two wrenches balance).

Constraints of other models (functions, SymPy) and constraints that act on joint coordinates
(robot couplings, joint limits, joint drivers, quaternion norms) are reported as multipliers and
generalized forces only (``force_a`` etc. empty): for a joint driver or limit (``A = ±eᵢᵀ``) the
multiplier is the joint torque (force). A planar gear with a moving carrier reports the wrenches
on its two gears (the carrier's share is in ``generalized``).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.linalg import range_basis, resolve_rtol
from ..errors import InputError, ShapeError
from ..model._protocol import Model

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

__all__ = ["DETERMINED_RTOL", "Reaction", "impulses", "reactions"]

#: A component is undetermined when its change along the left null space of A is larger than
#: ``DETERMINED_RTOL`` times the size of the map from the multipliers to it.
DETERMINED_RTOL = 1e-8


@dataclass(frozen=True, eq=False)
class Reaction:
    """What one constraint exerts on the two bodies it joins, at one state or per sample.

    Leading dimensions ``...`` are those of the states (none for one state, ``(N,)`` for a
    trajectory). Components of an inactive constraint are zero (and determined).

    Attributes
    ----------
    name : str
        Constraint name.
    kind : {"planar", "spatial", "frame", "generalized"}
        How the wrench was read (module docstring); ``"generalized"``: no wrench (only
        ``multipliers`` and ``generalized``).
    body_a, body_b : str
        The bodies (frames for robots) the constraint joins; ``""`` when not applicable.
    point_a, point_b : ndarray, shape (d,)
        Where the torque is taken: the attachment point in the body's frame (world
        coordinates on the ground; the constraint frame's origin for robots).
    frame : str
        ``"body"``: each force/torque is in the axes of its own body (world axes on the ground).
    force_a, force_b : ndarray, shape (..., d)
        Force on body a / b (d = 2 planar, 3 spatial; 0 for ``"generalized"``).
    torque_a, torque_b : ndarray, shape (..., t)
        Torque on body a / b about its point (t = 1 planar, 3 spatial).
    determined_a, determined_b : ndarray of bool, shape (..., d + t)
        Whether each component ``[force..., torque...]`` is decided by the dynamics.
    multipliers : ndarray, shape (..., dim)
        ``λ_I`` of the constraint's rows in the minimum-norm split ``λ = (Aᵀ)⁺ f_c``.
    multipliers_determined : ndarray of bool, shape (..., dim)
    generalized : ndarray, shape (..., n)
        The constraint's part ``A_Iᵀ λ_I`` of f_c (the parts of all constraints sum to f_c).
    active : ndarray of bool, shape (...)
    """

    name: str
    kind: str
    body_a: str
    body_b: str
    point_a: FloatArray
    point_b: FloatArray
    frame: str
    force_a: FloatArray
    torque_a: FloatArray
    force_b: FloatArray
    torque_b: FloatArray
    determined_a: BoolArray
    determined_b: BoolArray
    multipliers: FloatArray
    multipliers_determined: BoolArray
    generalized: FloatArray
    active: BoolArray

    @property
    def determined(self) -> BoolArray:
        """True where every component of both wrenches is determined, shape (...)."""
        return np.asarray(np.all(self.determined_a, axis=-1) & np.all(self.determined_b, axis=-1))

    def plot(self, t: ArrayLike | None = None, **kwargs: Any) -> Any:
        """Plot the wrench components against ``t`` (see :func:`nonmin.viz.plot_reaction`)."""
        from ..viz import plot_reaction  # type: ignore[attr-defined]

        return plot_reaction(self, t, **kwargs)

    def to_arrays(self, prefix: str) -> dict[str, FloatArray]:
        """The per-sample arrays under ``prefix + field`` (for files)."""
        return {prefix + f: np.asarray(getattr(self, f)) for f in _SERIES}

    def metadata(self) -> dict[str, Any]:
        """The static description (JSON-serializable)."""
        return {
            "name": self.name,
            "kind": self.kind,
            "body_a": self.body_a,
            "body_b": self.body_b,
            "point_a": np.asarray(self.point_a).tolist(),
            "point_b": np.asarray(self.point_b).tolist(),
            "frame": self.frame,
        }

    @classmethod
    def from_arrays(cls, meta: dict[str, Any], arrays: dict[str, Any]) -> Reaction:
        """Inverse of :meth:`metadata` + :meth:`to_arrays`."""
        return cls(
            name=str(meta["name"]),
            kind=str(meta["kind"]),
            body_a=str(meta["body_a"]),
            body_b=str(meta["body_b"]),
            point_a=np.asarray(meta["point_a"], dtype=float),
            point_b=np.asarray(meta["point_b"], dtype=float),
            frame=str(meta["frame"]),
            **{f: np.asarray(arrays[f]) for f in _SERIES},
        )


_SERIES = (
    "force_a",
    "torque_a",
    "force_b",
    "torque_b",
    "determined_a",
    "determined_b",
    "multipliers",
    "multipliers_determined",
    "generalized",
    "active",
)


# ---------------------------------------------------------------------------- per source
@dataclass
class _Side:
    """Linear map from a constraint's generalized force (or its multipliers) to one body's
    wrench ``[force (d); torque (t)]``: ``wrench = W @ g`` with g = the body's columns of
    ``A_Iᵀ λ_I`` (``on_multipliers=False``) or ``g = λ_I`` (True)."""

    body: str
    point: FloatArray
    W: FloatArray
    cols: NDArray[np.intp] | None  # the body's columns (None: W acts on λ_I)


def _cross2(a: FloatArray, f: FloatArray) -> float:
    return float(a[0] * f[1] - a[1] * f[0])


def _planar_sides(model: Any, name: str, q: FloatArray) -> tuple[str, list[_Side]]:
    from ..model.planar._elements import GROUND, Point

    joint = next(j for j in model.joints if j.name == name)
    pts: list[tuple[str, FloatArray]] = []
    a = getattr(joint, "a", None)
    b = getattr(joint, "b", None)
    bodies = list(joint.bodies)[:2]
    if isinstance(a, Point) and isinstance(b, Point):
        pts = [(a.body, np.array(a.local)), (b.body, np.array(b.local))]
    elif isinstance(a, Point):  # a point on a, nothing on b
        pts = [(a.body, np.array(a.local)), (bodies[-1], np.zeros(2))]
    else:
        bodies = [*bodies, GROUND][:2] if len(bodies) < 2 else bodies
        pts = [(bodies[0], np.zeros(2)), (bodies[1], np.zeros(2))]
    sides: list[_Side] = []
    for body, s in pts:
        if body == GROUND:
            sides.append(_Side(GROUND, s, np.zeros((3, 0)), None))
            continue
        ix, iy, ith = model._index[body]
        if ith < 0:  # point mass: force only, no moment at its own location
            W = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
            sides.append(_Side(body, np.zeros(2), W, np.array([ix, iy])))
            continue
        c, sn = np.cos(q[ith]), np.sin(q[ith])
        Rt = np.array([[c, sn], [-sn, c]])
        rs = np.array([c * s[0] - sn * s[1], sn * s[0] + c * s[1]])
        W = np.zeros((3, 3))
        W[:2, :2] = Rt
        W[2] = [rs[1], -rs[0], 1.0]  # τ_p = τ − (R s) × F
        sides.append(_Side(body, s, W, np.array([ix, iy, ith])))
    return "planar", sides


def _planar_ground(model: Any, q: FloatArray, other: _Side, ground_point: FloatArray) -> FloatArray:
    """W of the ground: minus the other body's world wrench about the ground's point."""
    ix, iy, ith = model._index[other.body]
    r = np.array([q[ix], q[iy]])
    d = r - ground_point
    W = np.zeros((3, len(other.cols)))  # type: ignore[arg-type]
    W[0, 0] = W[1, 1] = -1.0
    W[2, 0], W[2, 1] = d[1], -d[0]  # −(τ + d × F)
    if ith >= 0:
        W[2, 2] = -1.0
    return W


def _spatial_sides(model: Any, name: str, q: FloatArray) -> tuple[str, list[_Side]]:
    from ..model.spatial._model import GROUND
    from ..model.spatial._quaternion import G_matrix, rotation_matrix

    j = model.joint(name)
    sides: list[_Side] = []
    for body, s in (
        (j.body_a, np.asarray(j.point_a, float)),
        (j.body_b, np.asarray(j.point_b, float)),
    ):
        i = model.body_index(body)
        if i < 0:
            sides.append(_Side(GROUND, s, np.zeros((6, 0)), None))
            continue
        o = 7 * i
        e = q[o + 3 : o + 7] / np.linalg.norm(q[o + 3 : o + 7])
        Rt = rotation_matrix(e).T
        sx = np.array([[0.0, -s[2], s[1]], [s[2], 0.0, -s[0]], [-s[1], s[0], 0.0]])
        W = np.zeros((6, 7))
        W[:3, :3] = Rt
        W[3:, :3] = -sx @ Rt
        W[3:, 3:] = 0.5 * G_matrix(e)
        sides.append(_Side(body, s, W, np.arange(o, o + 7)))
    return "spatial", sides


def _spatial_ground(
    model: Any, q: FloatArray, other: _Side, ground_point: FloatArray
) -> FloatArray:
    from ..model.spatial._quaternion import E_matrix

    i = model.body_index(other.body)
    o = 7 * i
    e = q[o + 3 : o + 7] / np.linalg.norm(q[o + 3 : o + 7])
    d = q[o : o + 3] - ground_point
    dx = np.array([[0.0, -d[2], d[1]], [d[2], 0.0, -d[0]], [-d[1], d[0], 0.0]])
    W = np.zeros((6, 7))
    W[:3, :3] = -np.eye(3)
    W[3:, :3] = -dx
    W[3:, 3:] = -0.5 * E_matrix(e)
    return W


def _frame_sides(model: Any, name: str, q: FloatArray) -> tuple[str, list[_Side]] | None:
    from ..model.robots._constraints import (
        DistanceDriver,
        FrameConstraint,
        PathDriver,
        complete_basis,
    )

    c = next((c for c in model.robot_constraints if c.name == name), None)
    if not isinstance(c, FrameConstraint | PathDriver | DistanceDriver):
        return None
    Ha = model.frame_placement(q, f"{name}:a")
    Hb = model.frame_placement(q, f"{name}:b")
    Ra, Rb = Ha[:3, :3], Hb[:3, :3]
    m = c.dim
    F = np.zeros((3, m))  # world force on a = F λ
    T = np.zeros((3, m))  # world moment on a about its origin = T λ
    if isinstance(c, PathDriver | DistanceDriver):  # rows of p_b − p_a: λ is the force on b
        if isinstance(c, PathDriver):
            F[list(c.axes), range(m)] = -1.0
        else:
            F[:, 0] = -(Hb[:3, 3] - Ha[:3, 3]) / c.reference
        Wa = np.vstack([Ra.T @ F, np.zeros((3, m))])
        Wb = np.vstack([Rb.T @ -F, np.zeros((3, m))])
        return "frame", [_Side(c.frame_a, np.zeros(3), Wa, None), _Side(c.frame_b, np.zeros(3), Wb, None)]
    if c.type in ("point", "weld", "hinge"):
        F[:, :3] = np.eye(3)
    if c.type == "weld":
        T[:, 3:6] = np.eye(3)
    if c.type == "hinge":
        u1, u2 = complete_basis(c.axis)
        y = Rb @ c.axis
        T[:, 3] = np.cross(Ra @ u1, y)
        T[:, 4] = np.cross(Ra @ u2, y)
    if c.type in ("planar_point", "planar_weld"):
        u1, u2 = complete_basis(c.axis)
        F[:, 0], F[:, 1] = u1, u2
        if c.type == "planar_weld":
            T[:, 2] = c.axis
    Tb = -T
    if c.type in ("point_on_plane", "contact"):
        nrm = Ra @ c.axis
        d = Hb[:3, 3] - Ha[:3, 3]
        F[:, 0] = -nrm  # on a, applied at p_b
        T[:, 0] = np.cross(d, -nrm)  # about a's origin
        Tb = np.zeros((3, m))
    Wa = np.vstack([Ra.T @ F, Ra.T @ T])
    Wb = np.vstack([Rb.T @ -F, Rb.T @ Tb])
    return "frame", [
        _Side(c.frame_a, np.zeros(3), Wa, None),
        _Side(c.frame_b, np.zeros(3), Wb, None),
    ]


def _sides(model: Any, name: str, q: FloatArray) -> tuple[str, list[_Side]] | None:
    from ..model.planar import PlanarModel
    from ..model.spatial import SpatialModel

    if isinstance(model, PlanarModel):
        return _planar_sides(model, name, q)
    if isinstance(model, SpatialModel):
        if name not in {j.name for j in model.joints}:
            return None  # quaternion norm rows
        return _spatial_sides(model, name, q)
    if hasattr(model, "robot_constraints") and hasattr(model, "frame_placement"):
        return _frame_sides(model, name, q)
    return None


# ---------------------------------------------------------------------------- the read-out
def _one(
    model: Model,
    t: float,
    q: FloatArray,
    f_c: FloatArray,
    act: frozenset[str],
    names: list[str],
    tol: float,
) -> dict[str, dict[str, Any]]:
    A = model.constraint_jacobian(t, q, act)
    m = A.shape[0]
    rows = model.row_slices(act)
    if m:
        # rank by the rank policy (equilibrated A); (Aᵀ)⁺ = U_r Σ_r⁻¹ V_rᵀ of A truncated to it,
        # as nonmin.core.pseudo_inverse
        rank = int(range_basis(A, tol).rank)
        U, s, Vt = np.linalg.svd(A, full_matrices=True)
        U0 = U[:, rank:]  # orthonormal basis of N(Aᵀ): the undetermined directions of λ
        lam = U[:, :rank] @ ((Vt[:rank] @ f_c) / s[:rank])
    else:
        U0 = np.zeros((0, 0))
        lam = np.zeros(0)
    out: dict[str, dict[str, Any]] = {}
    for nm in names:
        if nm not in rows:
            out[nm] = {}
            continue
        sl = rows[nm]
        AI = A[sl]
        lamI = lam[sl]
        UI = U0[sl]
        gen = AI.T @ lamI
        mult_det = (
            np.linalg.norm(UI, axis=1) <= DETERMINED_RTOL
            if UI.size
            else np.ones(sl.stop - sl.start, bool)
        )
        rec: dict[str, Any] = {
            "multipliers": lamI,
            "multipliers_determined": mult_det,
            "generalized": gen,
        }
        got = _sides(model, nm, q)
        if got is not None:
            kind, sides = got
            rec["kind"] = kind
            # ground sides: the opposite of the other body's wrench
            maps: list[FloatArray] = []  # each acts on λ_I
            for i, sd in enumerate(sides):
                if sd.cols is None and sd.W.shape[1] == 0:  # ground in a planar/spatial model
                    other = sides[1 - i]
                    if other.cols is None or other.W.shape[1] == 0:
                        maps.append(np.zeros((3 if kind == "planar" else 6, sl.stop - sl.start)))
                        continue
                    gw = (_planar_ground if kind == "planar" else _spatial_ground)(
                        model, q, other, sd.point
                    )
                    maps.append(gw @ AI[:, other.cols].T)
                elif sd.cols is None:
                    maps.append(sd.W)
                else:
                    maps.append(sd.W @ AI[:, sd.cols].T)
            for key, L, sd in (("a", maps[0], sides[0]), ("b", maps[1], sides[1])):
                w = L @ lamI
                if UI.size:
                    var = np.linalg.norm(L @ UI, axis=1)
                    scale = np.linalg.norm(L, axis=1)
                    det = var <= DETERMINED_RTOL * np.maximum(scale, 1e-300)
                else:
                    det = np.ones(L.shape[0], dtype=bool)
                d = 2 if kind == "planar" else 3
                rec[f"force_{key}"] = w[:d]
                rec[f"torque_{key}"] = w[d:]
                rec[f"determined_{key}"] = det
                rec[f"body_{key}"] = sd.body
                rec[f"point_{key}"] = sd.point
        out[nm] = rec
    return out


def reactions(
    model: Model,
    q: ArrayLike,
    f_c: ArrayLike,
    *,
    t: ArrayLike = 0.0,
    active: Iterable[str] | str | Iterable[frozenset[str]] | None = None,
    names: Iterable[str] | None = None,
    rtol: float | None = None,
) -> dict[str, Reaction]:
    """The wrench of every named constraint on the bodies it joins, read from ``f_c``.

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,) or (N, n)
        Coordinates of one state or of N samples.
    f_c : array_like, shape like q
        Generalized constraint forces (``Trajectory.f_c``, ``solve_dynamics(...).f_c``, ...).
    t : float or array_like, shape (N,)
        Times (rheonomic constraints).
    active : iterable of str, or a sequence of N frozensets, optional
        The active set (one for all states, or one per sample: ``Trajectory.active``).
    names : iterable of str, optional
        Constraints to report (default: every constraint of the model).
    rtol : float, optional
        Rank tolerance of A (default :data:`nonmin.core.DEFAULT_RTOL`).

    Returns
    -------
    dict of str to Reaction
        In the model's constraint order; see :class:`Reaction` for frames, points and the
        ``determined`` masks.

    Raises
    ------
    ShapeError
        q and f_c of different or wrong shapes.
    UnknownNameError
        A name that is not a constraint of the model.
    """
    qa = np.asarray(q, dtype=np.float64)
    fa = np.asarray(f_c, dtype=np.float64)
    n = model.n
    if qa.ndim not in (1, 2) or qa.shape[-1] != n:
        raise ShapeError(f"q must have shape ({n},) or (N, {n}), got shape {qa.shape}")
    if fa.shape != qa.shape:
        raise ShapeError(f"f_c must have the shape of q {qa.shape}, got shape {fa.shape}")
    single = qa.ndim == 1
    Q = qa.reshape(-1, n)
    Fc = fa.reshape(-1, n)
    N = Q.shape[0]
    try:
        T = np.broadcast_to(np.asarray(t, dtype=np.float64), (N,))
    except ValueError:
        raise ShapeError(
            f"t must be a scalar or have shape ({N},), got shape {np.shape(t)}"
        ) from None
    if (
        active is None
        or isinstance(active, str)
        or (
            not isinstance(active, list | tuple)
            or not active
            or not isinstance(next(iter(active)), frozenset | set)
        )
    ):
        acts = [model.resolve_active(active)] * N  # type: ignore[arg-type]
    else:
        acts = [model.resolve_active(a) for a in active]  # type: ignore[arg-type]
        if len(acts) != N:
            raise ShapeError(f"active must hold one set per state ({N}), got {len(acts)}")
    all_names = list(model.constraint_names)
    want = all_names if names is None else [model.constraint(nm).name for nm in names]
    if isinstance(names, str):
        raise InputError("names must be an iterable of constraint names, not one string")
    tol = resolve_rtol(rtol)
    per = [_one(model, float(T[i]), Q[i], Fc[i], acts[i], want, tol) for i in range(N)]
    out: dict[str, Reaction] = {}
    for nm in want:
        dim = model.constraint(nm).dim
        proto = next((p[nm] for p in per if p[nm] and "kind" in p[nm]), None)
        if proto is None:  # not active anywhere, or no wrench: look the geometry up once
            got = _sides(model, nm, Q[0])
            kind = got[0] if got is not None else "generalized"
        else:
            kind = proto["kind"]
        d, tdim = {"planar": (2, 1), "spatial": (3, 3), "frame": (3, 3)}.get(kind, (0, 0))
        meta_src = proto
        if meta_src is None and kind != "generalized":
            got = _sides(model, nm, Q[0])
            assert got is not None
            meta_src = {
                "body_a": got[1][0].body,
                "body_b": got[1][1].body,
                "point_a": got[1][0].point,
                "point_b": got[1][1].point,
            }
        arr: dict[str, Any] = {
            "force_a": np.zeros((N, d)),
            "torque_a": np.zeros((N, tdim)),
            "force_b": np.zeros((N, d)),
            "torque_b": np.zeros((N, tdim)),
            "determined_a": np.ones((N, d + tdim), dtype=bool),
            "determined_b": np.ones((N, d + tdim), dtype=bool),
            "multipliers": np.zeros((N, dim)),
            "multipliers_determined": np.ones((N, dim), dtype=bool),
            "generalized": np.zeros((N, n)),
            "active": np.zeros(N, dtype=bool),
        }
        for i, p in enumerate(per):
            rec = p[nm]
            if not rec:
                continue
            arr["active"][i] = True
            for key in ("multipliers", "multipliers_determined", "generalized"):
                arr[key][i] = rec[key]
            if kind != "generalized":
                for key in (
                    "force_a",
                    "torque_a",
                    "force_b",
                    "torque_b",
                    "determined_a",
                    "determined_b",
                ):
                    arr[key][i] = rec[key]
        if single:
            arr = {k: v[0] for k, v in arr.items()}
        out[nm] = Reaction(
            name=nm,
            kind=kind,
            body_a="" if meta_src is None else str(meta_src["body_a"]),
            body_b="" if meta_src is None else str(meta_src["body_b"]),
            point_a=np.zeros(0)
            if meta_src is None
            else np.asarray(meta_src["point_a"], dtype=float),
            point_b=np.zeros(0)
            if meta_src is None
            else np.asarray(meta_src["point_b"], dtype=float),
            frame="body",
            **arr,
        )
    return out


def impulses(
    model: Model,
    q: ArrayLike,
    qd_before: ArrayLike,
    qd_after: ArrayLike,
    *,
    t: float = 0.0,
    active: Iterable[str] | str | None = None,
    names: Iterable[str] | None = None,
    rtol: float | None = None,
) -> dict[str, Reaction]:
    """The impulse of an impact on every named constraint, as wrenches on the bodies it joins.

    The velocity jump of an impact at ``q`` is caused by the impulse ``p = M (q̇⁺ − q̇⁻)``
    (docs/theory.md, "Simultaneous impacts": ``p = A_bᵀΛ_b + Σ a_iᵀΛ_i`` over the rows that
    carry it), read like a generalized constraint force by :func:`reactions`: each
    constraint's force impulse (N·s) and torque impulse (N·m·s) on its two bodies, in their
    frames, with ``determined`` masks where redundant rows leave the split undecided (three
    contacts under a planar bar: only the sum and the moment are decided).

    Parameters
    ----------
    model : Model
    q : array_like, shape (n,)
        Configuration of the impact.
    qd_before, qd_after : array_like, shape (n,)
        Velocities before and after it.
    t : float
        Time (rheonomic constraints).
    active : iterable of str, optional
        The constraints that carry the impulse (default: the model's default active set).
        For a simulated impact, :attr:`nonmin.sim.EventRecord.impulses` uses the bilateral
        constraints active across it and every contact in the impact set.
    names : iterable of str, optional
        Constraints to report (default: every constraint of the model).
    rtol : float, optional
        Rank tolerance of A.

    Returns
    -------
    dict of str to Reaction
        Fields as in :class:`Reaction`, read as impulses (``multipliers``: Λ of the rows;
        ``generalized``: the constraint's part ``A_Iᵀ Λ_I`` of ``p``).

    Raises
    ------
    ShapeError
        A vector of the wrong shape.
    UnknownNameError
        A name that is not a constraint of the model.
    """
    n = model.n
    vecs = []
    for nm, x in (("q", q), ("qd_before", qd_before), ("qd_after", qd_after)):
        a = np.asarray(x, dtype=np.float64)
        if a.shape != (n,):
            raise ShapeError(f"{nm} must have shape ({n},), got shape {a.shape}")
        vecs.append(a)
    qa, v0, v1 = vecs
    p = model.mass_matrix(qa) @ (v1 - v0)
    return reactions(model, qa, p, t=t, active=active, names=names, rtol=rtol)
