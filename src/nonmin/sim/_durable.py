"""Durable runs: checkpoints, resume, the up-front budget of a run, and user callbacks.

* :class:`Checkpointer` wraps the progress reporter the driver already calls after every
  accepted step (and after every compiled chunk): every ``checkpoint_every`` seconds of
  simulated time it writes the samples so far, durably (temporary file, fsync, rename), as a
  trajectory with status ``interrupted``; the file is always a complete, loadable trajectory.
* :func:`resume_point` reads such a file (or any trajectory of the same model) and gives the
  state to continue from; :func:`join` puts the earlier samples in front of the new ones.
* :func:`check_budget` refuses, before anything runs, a fixed-step run whose step count exceeds
  ``max_steps`` or whose recorded samples would exceed :data:`MAX_RECORD_BYTES`.
* :func:`user_call` runs a user callback (controller, guard, reset, controller update): an
  exception in it becomes a :class:`~nonmin.errors.SimulationError` that names the callback and
  the time.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import InputError, NonminError, OutputError, SimulationError
from ._trajectory import Status, Trajectory, load_trajectory

__all__ = ["MAX_RECORD_BYTES", "Checkpointer", "check_budget", "join", "resume_point", "user_call"]

#: Largest memory (bytes) the recorded samples of one run may take (estimated before the run
#: for fixed-step methods and t_eval; enforced while recording for adaptive ones).
MAX_RECORD_BYTES = 4 * 2**30


def sample_bytes(n: int, k: int, c: int) -> int:
    """Bytes of one recorded sample: t, 4 vectors of n (q, qd, qdd, f_c), u (k), 6 scalar
    diagnostics and the active mask (c booleans); Python list overhead is not counted."""
    return 8 * (1 + 4 * n + k + 6) + c


#: How simulate calls each kind of user callback (named in the error when the callback's
#: signature does not take that call).
CALL_FORMS = {
    "controller": "controller(t, q, qd, state, *, active) -> u, shape (k,) (state: the "
                  "controller's initial_state(), None for a plain function)",
    "controller.update": "controller.update(t, q, qd, state, *, active) -> new state",
    "controller.initial_state": "controller.initial_state() -> state",
    "guard": "guard(t, q, qd, f_c) -> float",
    "Reset fn": "fn(t, q, qd, active) -> (q, qd)",
}


def _call_form(what: str) -> str | None:
    for key in sorted(CALL_FORMS, key=len, reverse=True):
        if what == key or what.endswith(": " + key):
            return CALL_FORMS[key]
    return None


def _takes(fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> bool:
    """Whether ``fn``'s signature accepts this call (True when it cannot be inspected)."""
    import inspect

    try:
        inspect.signature(fn).bind(*args, **kwargs)
    except TypeError:
        return False
    except ValueError:  # no signature (some builtins)
        return True
    return True


def user_call(what: str, t: float, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Call a user callback; a non-nonmin exception becomes a SimulationError naming it.

    A ``TypeError`` because the callback's signature does not take simulate's call (a
    controller written as ``lambda t, q, qd: ...``) says how it is called.
    """
    try:
        return fn(*args, **kwargs)
    except NonminError:
        raise
    except Exception as exc:
        form = _call_form(what)
        if isinstance(exc, TypeError) and form is not None and not _takes(fn, args, kwargs):
            raise SimulationError(
                f"{what} cannot be called the way simulate calls it ({type(exc).__name__}: {exc}); "
                f"expected {form}"
            ) from exc
        raise SimulationError(f"{what} raised {type(exc).__name__}: {exc} (at t = {t:.12g})") from exc


def finite_output(what: str, t: float, value: Any, shape: tuple[int, ...], names: tuple[str, ...] = ()) -> np.ndarray:
    """Coerce a callback's array output; wrong shape or NaN/inf is a SimulationError naming the entry."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SimulationError(f"{what} returned {type(value).__name__}, not numbers, at t = {t:.12g}: {exc}") from None
    if arr.shape != shape:
        raise SimulationError(f"{what} must return shape {shape}, got shape {arr.shape} at t = {t:.12g}")
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.argmax(bad.ravel()))
        label = f" ({names[i]})" if i < len(names) else ""
        raise SimulationError(
            f"{what} returned a non-finite value at t = {t:.12g}: entry {i}{label} = {arr.ravel()[i]!r}"
        )
    return arr


def check_budget(*, t0: float, t1: float, h: float | None, max_steps: int, t_out: np.ndarray | None,
                 n: int, k: int, c: int) -> None:
    """Refuse, before the run, what cannot finish: too many fixed steps, too many samples."""
    per = sample_bytes(n, k, c)
    if h is not None:
        steps = (t1 - t0) / h
        if not steps - max_steps <= 1e-9 * max(1.0, steps):  # round-off in the span / dt
            raise InputError(
                f"t_span {(t0, t1)} with dt = {h:g} takes {steps:.3g} steps, more than "
                f"max_steps = {max_steps}; shorten t_span, take a larger dt or raise max_steps"
            )
    if t_out is not None:
        samples = float(t_out.size)
        what = f"t_eval ({t_out.size} times)"
    elif h is not None:
        samples = (t1 - t0) / h + 1
        what = f"every step of dt = {h:g} over {(t0, t1)}"
    else:
        return
    if samples * per > MAX_RECORD_BYTES:
        raise InputError(
            f"recording {what} needs about {samples * per / 2**30:.3g} GiB "
            f"({samples:.3g} samples × {per} bytes), more than {MAX_RECORD_BYTES / 2**30:g} GiB; "
            "pass a coarser t_eval"
        )


class Checkpointer:
    """The driver's progress reporter, plus a durable checkpoint every ``every`` seconds."""

    def __init__(self, bar: Any, path: str | os.PathLike[str] | None, every: float | None,
                 t0: float, snapshot: Callable[[Status, str], Trajectory]) -> None:
        self.bar = bar
        self.path = path
        self.every = every
        self.next = t0 + every if every else math.inf
        self.snapshot = snapshot
        self.written = 0
        self.failed = 0

    def update(self, t: float) -> None:
        self.bar.update(t)
        if self.path is not None and t >= self.next:
            self.save(t)
            assert self.every is not None
            self.next = t + self.every

    def save(self, t: float) -> None:
        """Write a checkpoint of the samples so far (status ``interrupted``)."""
        self.write(self.snapshot(Status.INTERRUPTED, f"checkpoint at t = {t:.12g}"))

    def write(self, traj: Trajectory) -> None:
        """Write ``traj`` to the checkpoint file; a write failure (full disk, ...) warns and the
        run goes on (the previous checkpoint is intact, and the samples are still in memory)."""
        assert self.path is not None
        try:
            traj.save(self.path)
        except OutputError as exc:
            self.failed += 1
            t_end = float(traj.t[-1]) if len(traj) else float("nan")
            warnings.warn(f"checkpoint at t = {t_end:.12g} not written: {exc}", RuntimeWarning, stacklevel=3)
            return
        self.written += 1

    def close(self) -> None:
        self.bar.close()


def check_checkpoint(checkpoint: Any, every: Any) -> tuple[str | None, float | None]:
    """Validate the ``checkpoint`` / ``checkpoint_every`` pair of :func:`simulate`."""
    if checkpoint is None:
        if every is not None:
            raise InputError("checkpoint_every needs checkpoint= (the file to write)")
        return None, None
    try:
        path = os.fspath(checkpoint)
    except TypeError:
        raise InputError(f"checkpoint must be a file path, got {type(checkpoint).__name__}") from None
    if not str(path).endswith(".npz"):
        raise InputError(f"checkpoint must name a .npz file, got {path!r}")
    if every is None:
        return str(path), None
    try:
        val = float(every)
    except (TypeError, ValueError):
        raise InputError(f"checkpoint_every must be a positive number of seconds, got {every!r}") from None
    if not (math.isfinite(val) and val > 0):
        raise InputError(f"checkpoint_every must be a positive finite number of seconds, got {every!r}")
    return str(path), val


def resume_point(resume: Any, model: Any, t1: float) -> Trajectory:
    """The earlier trajectory a run resumes from, checked against the model and ``t1``."""
    prev = resume if isinstance(resume, Trajectory) else load_trajectory(resume)
    where = "resume" if isinstance(resume, Trajectory) else f"resume {os.fspath(resume)!r}"
    if tuple(prev.coordinate_names) != tuple(model.coordinate_names):
        raise InputError(
            f"{where}: the trajectory's coordinates {list(prev.coordinate_names)[:6]} are not the "
            f"model's {list(model.coordinate_names)[:6]}"
        )
    if tuple(prev.constraint_names) != tuple(model.constraint_names):
        raise InputError(f"{where}: the trajectory's constraints are not the model's")
    if len(prev) == 0:
        raise InputError(f"{where}: the trajectory holds no samples")
    if prev.status is Status.FAILED:
        raise InputError(f"{where}: the run failed ({prev.message}); a failed run cannot be resumed")
    if not prev.t[-1] < t1:
        raise InputError(f"{where}: the trajectory already reaches t = {prev.t[-1]:.12g} ≥ t1 = {t1:.12g}")
    return prev


def join(prev: Trajectory, new: Trajectory, drop_last: bool) -> Trajectory:
    """The samples of ``prev`` (without its last one if ``drop_last``) followed by ``new``'s."""
    from ._trajectory import _ARRAYS, _BALANCE

    cut = len(prev) - 1 if drop_last else len(prev)
    arrays: dict[str, Any] = {a: np.concatenate((np.asarray(getattr(prev, a))[:cut], np.asarray(getattr(new, a))))
              for a in _ARRAYS}
    for a in _BALANCE:  # cumulative: the resumed run's continue from the earlier run's last value
        old = np.asarray(getattr(prev, a))
        arrays[a] = np.concatenate((old[:cut], np.asarray(getattr(new, a)) + (float(old[-1]) if old.size else 0.0)))
    meta = dict(new.metadata)
    meta["resumed_at"] = float(prev.t[-1])
    return Trajectory(
        **arrays,
        constraint_names=new.constraint_names,
        coordinate_names=new.coordinate_names,
        actuator_names=new.actuator_names,
        events=tuple(prev.events) + tuple(new.events),
        status=new.status,
        message=new.message,
        n_steps=prev.n_steps + new.n_steps,
        n_rhs=prev.n_rhs + new.n_rhs,
        n_rejected=prev.n_rejected + new.n_rejected,
        metadata=meta,
    )
