"""The result of a simulation: an immutable :class:`Trajectory` with diagnostics and metadata.

Saved as ONE self-describing ``.npz`` file: every array under its field name plus a
``__metadata__`` entry holding JSON (format version, nonmin version, UTC date, model
description, solver options, events, status, counters). No pickles: it loads with
``allow_pickle=False``.
"""

from __future__ import annotations

import datetime as _dt
import enum
import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ._events import EventRecord

__all__ = ["FORMAT_VERSION", "Status", "Trajectory", "load_trajectory"]

FloatArray = NDArray[np.float64]

#: Version of the ``.npz`` trajectory file layout.
FORMAT_VERSION = 1

_ARRAYS = (
    "t",
    "q",
    "qd",
    "qdd",
    "f_c",
    "u",
    "active_mask",
    "rank",
    "cond",
    "mu",
    "energy",
    "phi_norm",
    "velocity_residual_norm",
)


class Status(enum.Enum):
    """How a simulation ended."""

    SUCCESS = "success"
    EVENT_TERMINATED = "event_terminated"
    FAILED = "failed"


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Samples of a simulated motion with per-sample diagnostics.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Sample times (non-decreasing; an event appears twice: before and after its transition).
    q, qd, qdd : ndarray, shape (N, n)
        Coordinates, velocities, accelerations.
    f_c : ndarray, shape (N, n)
        Generalized constraint force (computed without multipliers).
    u : ndarray, shape (N, k)
        Actuator inputs (k = 0 without actuators).
    active_mask : ndarray of bool, shape (N, c)
        ``active_mask[i, j]``: constraint ``constraint_names[j]`` active at sample i.
    rank : ndarray of int, shape (N,)
        Numerical rank of the active A.
    cond : ndarray, shape (N,)
        ``cond(M̄)`` (2-norm).
    mu : ndarray, shape (N,)
        Virtual mass used.
    energy : ndarray, shape (N,)
        ``T + V``.
    phi_norm : ndarray, shape (N,)
        ``‖φ‖∞`` of the active holonomic rows.
    velocity_residual_norm : ndarray, shape (N,)
        ``‖A qd + φ_t‖∞``.
    constraint_names, coordinate_names, actuator_names : tuple of str
    events : tuple of EventRecord
    status : Status
    message : str
    n_steps, n_rhs, n_rejected : int
        Accepted steps, right-hand-side evaluations, rejected attempts.
    metadata : dict
        Model description, options, nonmin version, date (JSON-serializable).
    """

    t: FloatArray
    q: FloatArray
    qd: FloatArray
    qdd: FloatArray
    f_c: FloatArray
    u: FloatArray
    active_mask: NDArray[np.bool_]
    rank: NDArray[np.int64]
    cond: FloatArray
    mu: FloatArray
    energy: FloatArray
    phi_norm: FloatArray
    velocity_residual_norm: FloatArray
    constraint_names: tuple[str, ...]
    coordinate_names: tuple[str, ...]
    actuator_names: tuple[str, ...] = ()
    events: tuple[EventRecord, ...] = ()
    status: Status = Status.SUCCESS
    message: str = ""
    n_steps: int = 0
    n_rhs: int = 0
    n_rejected: int = 0
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in _ARRAYS:
            arr = getattr(self, name)
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)

    # ------------------------------------------------------------------ convenience
    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def success(self) -> bool:
        """True unless the run failed."""
        return self.status is not Status.FAILED

    @property
    def active(self) -> tuple[frozenset[str], ...]:
        """Active set of every sample, as frozensets of constraint names."""
        names = self.constraint_names
        cache: dict[bytes, frozenset[str]] = {}
        out = []
        for row in self.active_mask:
            key = row.tobytes()
            if key not in cache:
                cache[key] = frozenset(n for n, a in zip(names, row, strict=True) if a)
            out.append(cache[key])
        return tuple(out)

    @property
    def energy_drift(self) -> float:
        """``max |E − E(t0)|`` over the samples (includes impact losses)."""
        if len(self) == 0:
            return 0.0
        return float(np.max(np.abs(self.energy - self.energy[0])))

    def __repr__(self) -> str:
        return (
            f"Trajectory(samples={len(self)}, t=[{self.t[0] if len(self) else 0:.6g}, "
            f"{self.t[-1] if len(self) else 0:.6g}], n={len(self.coordinate_names)}, "
            f"events={len(self.events)}, status={self.status.value!r}, n_steps={self.n_steps}, "
            f"n_rhs={self.n_rhs})"
        )

    # ------------------------------------------------------------------ derived data
    def outputs(self, model: Any) -> dict[str, FloatArray]:
        """Evaluate ``model.outputs(t, q, qd)`` at every sample; arrays stacked on axis 0."""
        rows = [model.outputs(float(t), q, qd) for t, q, qd in zip(self.t, self.q, self.qd, strict=True)]
        if not rows:
            return {}
        return {k: np.stack([np.asarray(r[k], dtype=float) for r in rows]) for k in rows[0]}

    def plot(self, **kwargs: Any) -> Any:
        """Delegate to :func:`nonmin.viz.plot_trajectory` (needs the ``plot`` extra)."""
        from ..viz import plot_trajectory  # type: ignore[attr-defined]

        return plot_trajectory(self, **kwargs)

    # ------------------------------------------------------------------ files
    def _metadata_json(self) -> str:
        from .. import __version__

        meta = dict(self.metadata)
        meta.update(
            {
                "format": "nonmin.Trajectory",
                "format_version": FORMAT_VERSION,
                "nonmin_version": __version__,
                "saved_utc": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
                "constraint_names": list(self.constraint_names),
                "coordinate_names": list(self.coordinate_names),
                "actuator_names": list(self.actuator_names),
                "events": [e.to_dict() for e in self.events],
                "status": self.status.value,
                "message": self.message,
                "n_steps": self.n_steps,
                "n_rhs": self.n_rhs,
                "n_rejected": self.n_rejected,
            }
        )
        return json.dumps(meta, default=_json_default)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the trajectory to one ``.npz`` file (arrays + JSON metadata)."""
        arrays = {name: np.asarray(getattr(self, name)) for name in _ARRAYS}
        arrays["__metadata__"] = np.array(self._metadata_json())
        p = os.fspath(path)
        with open(p, "wb") as fh:
            np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Trajectory:
        """Read a file written by :meth:`save`."""
        return load_trajectory(path)

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write a flat CSV: t, q_*, qd_*, qdd_*, u_*, diagnostics, active flags.

        ``#`` header lines carry the metadata JSON; the column line follows.
        """
        cols: list[str] = ["t"]
        cols += [f"q_{c}" for c in self.coordinate_names]
        cols += [f"qd_{c}" for c in self.coordinate_names]
        cols += [f"qdd_{c}" for c in self.coordinate_names]
        cols += [f"fc_{c}" for c in self.coordinate_names]
        cols += [f"u_{a}" for a in self.actuator_names]
        cols += ["rank", "cond", "mu", "energy", "phi_norm", "velocity_residual_norm"]
        cols += [f"active_{c}" for c in self.constraint_names]
        data = np.column_stack(
            [
                self.t,
                self.q,
                self.qd,
                self.qdd,
                self.f_c,
                self.u,
                self.rank,
                self.cond,
                self.mu,
                self.energy,
                self.phi_norm,
                self.velocity_residual_norm,
                self.active_mask.astype(float),
            ]
        )
        header = "nonmin trajectory; metadata: " + self._metadata_json() + "\n" + ",".join(cols)
        np.savetxt(os.fspath(path), data, delimiter=",", header=header, comments="# ", fmt="%.17g")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, frozenset | set):
        return sorted(obj)
    return repr(obj)


def load_trajectory(path: str | os.PathLike[str]) -> Trajectory:
    """Load a :class:`Trajectory` saved with :meth:`Trajectory.save`.

    Raises
    ------
    InputError
        If the file is not a nonmin trajectory file or has a newer format version.
    """
    p = os.fspath(path)
    try:
        data = np.load(p, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"load_trajectory: cannot read {p!r} as a .npz file: {exc}") from None
    with data:
        if "__metadata__" not in data.files:
            raise InputError(f"load_trajectory: {p!r} has no __metadata__ entry (not a nonmin trajectory)")
        meta = json.loads(str(data["__metadata__"]))
        if meta.get("format") != "nonmin.Trajectory":
            raise InputError(f"load_trajectory: {p!r} is not a nonmin trajectory file")
        if int(meta.get("format_version", 0)) > FORMAT_VERSION:
            raise InputError(
                f"load_trajectory: {p!r} has format version {meta['format_version']}, "
                f"this nonmin reads up to {FORMAT_VERSION}"
            )
        missing = [a for a in _ARRAYS if a not in data.files]
        if missing:
            raise InputError(f"load_trajectory: {p!r} lacks arrays {missing}")
        arrays: dict[str, Any] = {a: np.array(data[a]) for a in _ARRAYS}
    events = tuple(EventRecord.from_dict(e) for e in meta.pop("events", []))
    kw: dict[str, Any] = {
        "constraint_names": tuple(meta.pop("constraint_names")),
        "coordinate_names": tuple(meta.pop("coordinate_names")),
        "actuator_names": tuple(meta.pop("actuator_names")),
        "status": Status(meta.pop("status")),
        "message": meta.pop("message"),
        "n_steps": int(meta.pop("n_steps")),
        "n_rhs": int(meta.pop("n_rhs")),
        "n_rejected": int(meta.pop("n_rejected")),
    }
    return Trajectory(**arrays, events=events, metadata=meta, **kw)
