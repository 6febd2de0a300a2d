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

from .._files import as_path, atomic_write
from ..errors import FileFormatError
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

#: The energy bookkeeping the simulation records besides ``energy`` (shape (N,), J): saved with
#: the other arrays, optional on load (files written before them get zeros; ``work``: NaN, the
#: marker of "not recorded", with which :func:`nonmin.viz.energy_balance` computes W itself).
_BALANCE = ("friction_work", "impact_loss", "work")
_FIELDS = (*_ARRAYS, *_BALANCE)


class Status(enum.Enum):
    """How a simulation ended."""

    SUCCESS = "success"
    EVENT_TERMINATED = "event_terminated"
    FAILED = "failed"
    INTERRUPTED = "interrupted"  #: stopped by KeyboardInterrupt (or a checkpoint of a running job)


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
    friction_work : ndarray, shape (N,)
        Work of the Coulomb friction forces of the slipping contacts from the start (J, ≤ 0):
        ``∫ Σ_j F_j e_j·v_t,j dt``, integrated by the engine step by step (Simpson's rule on each
        step's power; samples inside a step read the integral of its quadratic). Zeros without
        frictional contacts.
    impact_loss : ndarray, shape (N,)
        Energy taken out at the events from the start (J, ≥ 0 for dissipative impacts): at each
        event that changes the velocity (impact, activation, a contact that sticks) the kinetic
        energy before minus after, ``½ q̇⁻ᵀ M q̇⁻ − ½ q̇⁺ᵀ M q̇⁺`` at the event's q; at a user
        ``Reset``, ``E⁻ − E⁺``. It steps at the event's second sample (the one after it).
        With W the work of applied forces, ``E − E₀ − W − friction_work + impact_loss`` is the
        integration drift (:func:`nonmin.viz.energy_balance`).
    work : ndarray, shape (N,)
        W, the work of controllers, actuators, dampers and the constraint forces of driven
        (rheonomic) constraints from the start (J): ``∫ q̇ᵀ(B u + f_passive + f_c) dt``, integrated
        by the integrator itself as a quadrature state, its stage powers combined with the
        method's own weights (no evaluation of its own), so that ``E − E₀ − W − friction_work +
        impact_loss`` converges at the method's order (samples inside a step read the cubic
        Hermite interpolant of W; samples from a partial step its own quadrature). NaN where not
        recorded (files written before it, batch runs, steps of a custom integrator).
    constraint_names, coordinate_names, actuator_names : tuple of str
    events : tuple of EventRecord
    status : Status
    message : str
    n_steps, n_rhs, n_rejected : int
        Accepted steps, right-hand-side evaluations, rejected attempts.
    metadata : dict
        Model description, options, nonmin version, date (JSON-serializable).
    reactions : dict of str to Reaction
        Per-sample wrenches of the named constraints (:meth:`with_reactions`; empty until
        asked for). Saved with the trajectory.
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
    reactions: dict[str, Any] = field(default_factory=dict)
    friction_work: FloatArray | None = None
    impact_loss: FloatArray | None = None
    work: FloatArray | None = None

    def __post_init__(self) -> None:
        for name in _BALANCE:  # not recorded (an old file): zeros (work: NaN)
            if getattr(self, name) is None:
                N = int(np.shape(self.t)[0]) if np.ndim(self.t) else 0
                object.__setattr__(self, name, np.full(N, np.nan) if name == "work" else np.zeros(N))
        for name in _FIELDS:
            arr = getattr(self, name)
            if isinstance(arr, np.ndarray):
                arr.setflags(write=False)

    # ------------------------------------------------------------------ convenience
    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def success(self) -> bool:
        """True when the run reached its end (or a terminal event): not failed, not interrupted."""
        return self.status in (Status.SUCCESS, Status.EVENT_TERMINATED)

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

    def with_reactions(self, model: Any, names: Any = None, *, rtol: float | None = None) -> Trajectory:
        """A copy holding the reactions of the named constraints (default all) at every sample.

        Read from the stored ``f_c`` (eq. (fc_R), no multipliers) with
        :func:`nonmin.analysis.reactions`: each constraint's force and torque on the two
        bodies it joins, in their frames, with ``determined`` masks for redundant sets.
        ``traj.with_reactions(model).reactions["loop"].force_b`` has shape (N, d).
        """
        import dataclasses

        from ..analysis import reactions

        got = reactions(model, self.q, self.f_c, t=self.t, active=list(self.active), names=names, rtol=rtol)
        return dataclasses.replace(self, reactions={**self.reactions, **got})

    def plot(self, **kwargs: Any) -> Any:
        """Delegate to :func:`nonmin.viz.plot_trajectory` (needs the ``plot`` extra)."""
        from ..viz import plot_trajectory  # type: ignore[attr-defined]

        return plot_trajectory(self, **kwargs)

    # ------------------------------------------------------------------ files
    def _metadata_json(self) -> str:
        from .._version import __version__

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
        if self.reactions:
            meta["reactions"] = [r.metadata() for r in self.reactions.values()]
        return json.dumps(meta, default=_json_default)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the trajectory to one ``.npz`` file (arrays + JSON metadata).

        The file is written to a temporary name in the same folder, fsync'd and renamed over
        ``path``: a failure in mid-write (kill, full disk) leaves the previous file intact, and
        concurrent writers of one path leave the last complete file.

        Raises
        ------
        OutputError
            The file cannot be written (the message names it).
        """
        arrays = {name: np.asarray(getattr(self, name)) for name in _FIELDS}
        for i, r in enumerate(self.reactions.values()):
            arrays.update(r.to_arrays(f"reaction{i}."))
        arrays["__metadata__"] = np.array(self._metadata_json())
        with atomic_write(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Trajectory:
        """Read a file written by :meth:`save`."""
        return load_trajectory(path)

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write a plain CSV (one header row: t, q_*, qd_*, qdd_*, fc_*, u_*, diagnostics,
        active_*) and a sidecar ``<path>.json`` with the metadata and each column's unit.

        ``pandas.read_csv(path)`` loads it; see :func:`nonmin.io.to_csv` (also Parquet and
        xarray/NetCDF there).
        """
        from .._export import to_csv

        to_csv(self, path)


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, frozenset | set):
        return sorted(obj)
    return repr(obj)


#: Default cap (bytes, uncompressed) of what :func:`load_trajectory` reads: a file that declares
#: more (a zip bomb, or metadata claiming absurd sizes) is refused before anything is inflated.
MAX_LOAD_BYTES = 4 * 2**30

_FLOAT_ROWS = ("q", "qd", "qdd", "f_c")
_DIAGNOSTICS = ("cond", "mu", "energy", "phi_norm", "velocity_residual_norm")


def _bad(p: str, entry: str, what: str) -> FileFormatError:
    return FileFormatError(f"load_trajectory: {p!r}: entry {entry!r}: {what}")


def _names(meta: dict[str, Any], key: str, p: str) -> tuple[str, ...]:
    val = meta.get(key)
    if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
        raise _bad(p, f"__metadata__.{key}", f"expected a list of strings, got {type(val).__name__}")
    return tuple(val)


def _count(meta: dict[str, Any], key: str, p: str) -> int:
    val = meta.get(key)
    if isinstance(val, bool) or not isinstance(val, int) or val < 0:
        raise _bad(p, f"__metadata__.{key}", f"expected a non-negative integer, got {val!r}")
    return val


def _check_arrays(arrays: dict[str, Any], n: int, k: int, c: int, p: str) -> None:
    t = arrays["t"]
    if t.ndim != 1 or t.dtype.kind != "f":
        raise _bad(p, "t", f"expected a float array of shape (N,), got {t.dtype} shape {t.shape}")
    N = t.shape[0]
    want: dict[str, tuple[tuple[int, ...], str]] = {
        **{a: ((N, n), "f") for a in _FLOAT_ROWS},
        "u": ((N, k), "f"),
        "active_mask": ((N, c), "b"),
        "rank": ((N,), "iu"),
        **{a: ((N,), "f") for a in _DIAGNOSTICS},
        **{a: ((N,), "f") for a in _BALANCE if a in arrays},
    }
    for name, (shape, kinds) in want.items():
        arr = arrays[name]
        if arr.shape != shape or arr.dtype.kind not in kinds:
            kind = {"f": "float", "b": "bool", "iu": "integer"}[kinds]
            raise _bad(p, name, f"expected a {kind} array of shape {shape} (N = {N} samples, "
                       f"{n} coordinates, {k} actuators, {c} constraints), got {arr.dtype} shape {arr.shape}")
    for name in ("t", *_FLOAT_ROWS):
        bad = ~np.isfinite(arrays[name])
        if bad.any():
            raise _bad(p, name, f"{int(bad.sum())} NaN/inf values (first at index "
                       f"{tuple(int(i) for i in np.argwhere(bad)[0])})")
    if N > 1 and np.any(np.diff(t) < 0):
        i = int(np.argmax(np.diff(t) < 0))
        raise _bad(p, "t", f"sample times must be non-decreasing, t[{i + 1}] = {t[i + 1]!r} < t[{i}] = {t[i]!r}")


def _load_reactions(raw: Any, arrays: dict[str, Any], p: str) -> dict[str, Any]:
    """The :class:`~nonmin.analysis.Reaction` series saved by :meth:`Trajectory.save`."""
    if not raw:
        return {}
    from ..analysis import Reaction
    from ..analysis._reactions import _SERIES

    if not isinstance(raw, list):
        raise _bad(p, "__metadata__.reactions", f"expected a list, got {type(raw).__name__}")
    out: dict[str, Any] = {}
    for i, meta in enumerate(raw):
        try:
            got = {f: arrays[f"reaction{i}.{f}"] for f in _SERIES}
            r = Reaction.from_arrays(meta, got)
        except (KeyError, TypeError, ValueError) as exc:
            raise _bad(p, f"__metadata__.reactions[{i}]", f"malformed reaction ({type(exc).__name__}: {exc})") from None
        out[r.name] = r
    return out


def load_trajectory(path: str | os.PathLike[str], *, max_bytes: int = MAX_LOAD_BYTES) -> Trajectory:
    """Load a :class:`Trajectory` saved with :meth:`Trajectory.save`.

    The file is data only: nothing in it is executed (no pickles), and its metadata is
    provenance (where the run came from) that nothing acts on. Every entry is checked before
    a :class:`Trajectory` is built: the JSON metadata and its types, the shape and dtype of every
    array against the sample count and the name lists, finite and non-decreasing times.

    Parameters
    ----------
    path : str or path-like
    max_bytes : int
        Refuse files whose arrays declare more than this many uncompressed bytes
        (default :data:`MAX_LOAD_BYTES`, 4 GiB).

    Raises
    ------
    FileFormatError
        Missing, unreadable, truncated, corrupt (bad zip, bad CRC, bad JSON) or inconsistent
        file, a newer format version, or too large; the message names the file and the entry.
    """
    import zipfile
    import zlib

    p = str(as_path(path, "load_trajectory: path"))
    if not os.path.isfile(p):
        raise FileFormatError(f"load_trajectory: {p!r}: no such file")
    # (zipfile raises NotImplementedError for a header that declares a zip version or a
    # compression method it does not know: a damaged file, e.g. one flipped bit)
    try:
        with zipfile.ZipFile(p) as zf:
            declared = sum(i.file_size for i in zf.infolist())
            names = [i.filename for i in zf.infolist()]
    except (zipfile.BadZipFile, NotImplementedError, OSError, EOFError, ValueError) as exc:
        raise FileFormatError(f"load_trajectory: {p!r}: not a readable .npz (zip) file: {exc}") from None
    if declared > max_bytes:
        raise FileFormatError(
            f"load_trajectory: {p!r}: its entries declare {declared} uncompressed bytes, more than "
            f"max_bytes = {max_bytes}"
        )
    entry = "__metadata__"
    try:
        with np.load(p, allow_pickle=False) as data:
            if "__metadata__" not in data.files:
                raise FileFormatError(
                    f"load_trajectory: {p!r} has no __metadata__ entry (not a nonmin trajectory); "
                    f"entries: {sorted(names)}"
                )
            raw = data["__metadata__"]
            if raw.dtype.kind != "U" or raw.ndim != 0:
                raise _bad(p, entry, f"expected a JSON string, got {raw.dtype} shape {raw.shape}")
            try:
                meta = json.loads(str(raw))
            except (json.JSONDecodeError, RecursionError) as exc:
                raise _bad(p, entry, f"not valid JSON: {exc}") from None
            if not isinstance(meta, dict):
                raise _bad(p, entry, f"expected a JSON object, got {type(meta).__name__}")
            if meta.get("format") != "nonmin.Trajectory":
                raise FileFormatError(f"load_trajectory: {p!r} is not a nonmin trajectory file "
                                      f"(__metadata__.format = {meta.get('format')!r})")
            version = meta.get("format_version", 0)
            if isinstance(version, bool) or not isinstance(version, int):
                raise _bad(p, "__metadata__.format_version", f"expected an integer, got {version!r}")
            if version > FORMAT_VERSION:
                raise FileFormatError(
                    f"load_trajectory: {p!r} has format version {version}, this nonmin reads up "
                    f"to {FORMAT_VERSION}"
                )
            missing = [a for a in _ARRAYS if a not in data.files]
            if missing:
                raise FileFormatError(f"load_trajectory: {p!r} lacks arrays {missing}")
            arrays: dict[str, Any] = {}
            for a in _ARRAYS:
                entry = a
                arrays[a] = np.array(data[a])
            for a in _BALANCE:  # (absent from files written before they were recorded)
                if a in data.files:
                    entry = a
                    arrays[a] = np.array(data[a])
            reaction_arrays = {f: np.array(data[f]) for f in data.files if f.startswith("reaction")}
    except FileFormatError:
        raise
    except (zipfile.BadZipFile, zlib.error, NotImplementedError, OSError, EOFError, ValueError, KeyError,
            MemoryError) as exc:
        raise _bad(p, entry, f"cannot be read ({type(exc).__name__}: {exc})") from None
    coords = _names(meta, "coordinate_names", p)
    cons = _names(meta, "constraint_names", p)
    acts = _names(meta, "actuator_names", p)
    _check_arrays(arrays, len(coords), len(acts), len(cons), p)
    try:
        status = Status(meta.get("status"))
    except ValueError:
        raise _bad(p, "__metadata__.status", f"expected one of {[s.value for s in Status]}, "
                   f"got {meta.get('status')!r}") from None
    message = meta.get("message", "")
    if not isinstance(message, str):
        raise _bad(p, "__metadata__.message", f"expected a string, got {type(message).__name__}")
    counters = {key: _count(meta, key, p) for key in ("n_steps", "n_rhs", "n_rejected")}
    raw_events = meta.get("events", [])
    if not isinstance(raw_events, list):
        raise _bad(p, "__metadata__.events", f"expected a list, got {type(raw_events).__name__}")
    events = []
    n = len(coords)
    for i, e in enumerate(raw_events):
        try:
            rec = EventRecord.from_dict(e)
            if any(np.shape(getattr(rec, f)) != (n,) for f in ("q_before", "qd_before", "q_after", "qd_after")):
                raise ValueError(f"state vectors must have {n} entries")
            if not all(isinstance(nm, str) for nm in (*rec.active_before, *rec.active_after)):
                raise ValueError("active sets must hold constraint names")
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise _bad(p, f"__metadata__.events[{i}]", f"malformed event record ({type(exc).__name__}: {exc})") from None
        events.append(rec)
    reacts = _load_reactions(meta.pop("reactions", []), reaction_arrays, p)
    for key in ("constraint_names", "coordinate_names", "actuator_names", "status", "message",
                "n_steps", "n_rhs", "n_rejected", "events"):
        meta.pop(key, None)
    return Trajectory(**arrays, reactions=reacts, constraint_names=cons, coordinate_names=coords, actuator_names=acts,
                      events=tuple(events), status=status, message=message, metadata=meta,
                      n_steps=counters["n_steps"], n_rhs=counters["n_rhs"], n_rejected=counters["n_rejected"])
