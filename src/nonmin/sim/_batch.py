"""Many runs in one call: :func:`simulate_batch` and its result :class:`BatchTrajectory`.

The k runs go to the compiled engine together (``engine/src/sim_batch.cpp``): each run is the
engine loop of :func:`simulate` — the same integrator, stabilization, rank policy and output
sampling, its own step control and active set — and threads take runs one at a time with the
GIL released, one loop (all buffers) per thread and model, nothing allocated per step.
Automatic contact goes through the engine's event layer (``engine/src/sim_events.cpp``: guards,
location, simultaneous impacts, releases) inside the batch, and compiled controllers
(``Controller.engine_controller``: Regulator, computed-torque Tracker, ForceControl, Switched)
are copied per thread and run, one per active set met. A run that the engine loop does not
finish alone (a numerical failure it hands over, a Zeno accumulation, an active set without a
compiled controller) is made again by :func:`simulate`, and runs the batched loop does not cover
at all (user events, whose guards and transitions are Python; Coulomb friction, whose modes
start in Python; a controller without a compiled form; a model without a compiled program;
custom Integrator/Stabilization classes; the energy projection, whose level is per run) are made
one by one through :func:`simulate`: every run's result is the one :func:`simulate` gives for it
(bit for bit without events; to round-off with contact, whose start :func:`simulate` takes in
Python), whichever path ran it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_float_array
from ..errors import InputError, NonFiniteError, ShapeError
from ..model import Model
from . import _engine
from ._events import EventRecord
from ._trajectory import Status, Trajectory

__all__ = ["BatchTrajectory", "simulate_batch"]

FloatArray = NDArray[np.float64]

#: Largest size (bytes) of the stacked sample arrays of one batch.
MAX_BATCH_BYTES = 4 * 2**30

#: Per-sample arrays a batch can record (``record=``); the scalars (energy, phi_norm,
#: velocity_residual_norm, rank, cond, mu, work) are always recorded.
RECORDABLE = ("q", "qd", "qdd", "f_c", "u")

_SCALARS = ("energy", "phi_norm", "velocity_residual_norm", "cond", "mu", "work")


@dataclass(frozen=True, eq=False)
class BatchTrajectory:
    """The k runs of :func:`simulate_batch`: indexes like a list of :class:`Trajectory`, stacks
    like arrays.

    ``batch[i]`` is run i as a :class:`Trajectory`; ``batch[2:5]`` / ``batch[mask]`` a smaller
    batch; ``len(batch)`` is k; iteration yields the Trajectories. The stacked arrays hold the
    samples of every run on the common output grid ``t``.

    Attributes
    ----------
    t : ndarray, shape (N,)
        The output times (common to every run).
    q, qd : ndarray, shape (k, N, n)
        Coordinates and velocities (NaN after a run that failed before t1). ``qdd``, ``f_c``
        (k, N, n) and ``u`` (k, N, nu) when recorded (``record=``), else None.
    energy, phi_norm, velocity_residual_norm, cond, mu : ndarray, shape (k, N)
    rank : ndarray of int, shape (k, N)
        (−1 where not reached).
    status : tuple of Status, length k
    message : tuple of str, length k
    n_steps, n_rhs, n_rejected : ndarray of int, shape (k,)
    engine : tuple of str, length k
        Which path ran each run: ``"batch"`` (the batched engine loop), ``"batch, then
        simulate"`` (the engine handed a failure over), ``"simulate"`` (not covered by the batch).
    work : ndarray, shape (k, N), or None
        W, the work of controllers and applied forces (:attr:`Trajectory.work`), integrated by
        each run's method (NaN where not reached).
    events : tuple of tuple of EventRecord, length k
        The events of each run (automatic contact; user events of runs made by simulate).
    active_mask : ndarray of bool, shape (k, N, c), or None
        The active constraints at each sample (with automatic contact; else each run's initial
        set, ``active``, holds throughout).
    """

    t: FloatArray
    q: FloatArray | None
    qd: FloatArray | None
    qdd: FloatArray | None
    f_c: FloatArray | None
    u: FloatArray | None
    energy: FloatArray
    phi_norm: FloatArray
    velocity_residual_norm: FloatArray
    cond: FloatArray
    mu: FloatArray
    rank: NDArray[np.int64]
    status: tuple[Status, ...]
    message: tuple[str, ...]
    n_steps: NDArray[np.int64]
    n_rhs: NDArray[np.int64]
    n_rejected: NDArray[np.int64]
    engine: tuple[str, ...]
    coordinate_names: tuple[str, ...]
    constraint_names: tuple[str, ...]
    actuator_names: tuple[str, ...]
    active: tuple[frozenset[str], ...]
    runs: tuple[Trajectory | None, ...] = field(repr=False)  # the simulate() results it holds
    metadata: dict[str, Any] = field(default_factory=dict, repr=False)
    events: tuple[tuple[EventRecord, ...], ...] = ()
    active_mask: NDArray[np.bool_] | None = None
    work: FloatArray | None = None

    def __len__(self) -> int:
        return len(self.status)

    @property
    def success(self) -> NDArray[np.bool_]:
        """Per run: reached its end (or a terminal event)."""
        return np.array([s in (Status.SUCCESS, Status.EVENT_TERMINATED) for s in self.status], dtype=bool)

    @property
    def energy_drift(self) -> FloatArray:
        """Per run: ``max_t |E(t) − E(t0)|`` over the samples reached."""
        e = self.energy
        return np.asarray(np.nanmax(np.abs(e - e[:, :1]), axis=1), dtype=float) if e.shape[1] else np.zeros(len(self))

    @property
    def closure(self) -> FloatArray:
        """Per run: ``max_t ‖φ‖∞`` of the active holonomic rows over the samples reached."""
        p = self.phi_norm
        return np.asarray(np.nanmax(p, axis=1), dtype=float) if p.shape[1] else np.zeros(len(self))

    def __iter__(self) -> Iterator[Trajectory]:
        for i in range(len(self)):
            yield self[i]

    @overload
    def __getitem__(self, i: int) -> Trajectory: ...
    @overload
    def __getitem__(self, i: slice | Sequence[int] | NDArray[Any]) -> BatchTrajectory: ...

    def __getitem__(self, i: Any) -> Trajectory | BatchTrajectory:
        if isinstance(i, int | np.integer):
            j = int(i)
            if j < 0:
                j += len(self)
            if not 0 <= j < len(self):
                raise IndexError(f"run {i} out of range for a batch of {len(self)}")
            return self._run(j)
        idx = np.arange(len(self))[i]

        def pick(a: Any) -> Any:
            return None if a is None else a[idx]

        return BatchTrajectory(
            t=self.t, q=pick(self.q), qd=pick(self.qd), qdd=pick(self.qdd), f_c=pick(self.f_c),
            u=pick(self.u), energy=self.energy[idx], phi_norm=self.phi_norm[idx],
            velocity_residual_norm=self.velocity_residual_norm[idx], cond=self.cond[idx], mu=self.mu[idx],
            rank=self.rank[idx], status=tuple(self.status[j] for j in idx),
            message=tuple(self.message[j] for j in idx), n_steps=self.n_steps[idx], n_rhs=self.n_rhs[idx],
            n_rejected=self.n_rejected[idx], engine=tuple(self.engine[j] for j in idx),
            coordinate_names=self.coordinate_names, constraint_names=self.constraint_names,
            actuator_names=self.actuator_names, active=tuple(self.active[j] for j in idx),
            runs=tuple(self.runs[j] for j in idx), metadata=self.metadata,
            events=tuple(self.events[j] for j in idx) if self.events else (), active_mask=pick(self.active_mask),
            work=pick(self.work),
        )  # fmt: skip

    def _run(self, j: int) -> Trajectory:
        held = self.runs[j]
        if held is not None:
            return held
        N = int(np.count_nonzero(self.rank[j] >= 0))
        n, nu, c = len(self.coordinate_names), len(self.actuator_names), len(self.constraint_names)

        def arr(a: Any, w: int) -> FloatArray:
            return np.full((N, w), np.nan) if a is None else np.array(a[j, :N])

        mask = np.array([nm in self.active[j] for nm in self.constraint_names], dtype=bool)
        am = np.repeat(mask[None], N, axis=0).reshape(N, c) if self.active_mask is None \
            else self.active_mask[j, :N].copy()  # fmt: skip
        return Trajectory(
            t=self.t[:N].copy(), q=arr(self.q, n), qd=arr(self.qd, n), qdd=arr(self.qdd, n),
            f_c=arr(self.f_c, n), u=arr(self.u, nu) if nu else np.zeros((N, 0)),
            active_mask=am, rank=self.rank[j, :N].copy(),
            cond=self.cond[j, :N].copy(), mu=self.mu[j, :N].copy(), energy=self.energy[j, :N].copy(),
            phi_norm=self.phi_norm[j, :N].copy(),
            velocity_residual_norm=self.velocity_residual_norm[j, :N].copy(),
            work=None if self.work is None else self.work[j, :N].copy(),
            constraint_names=self.constraint_names, coordinate_names=self.coordinate_names,
            actuator_names=self.actuator_names, status=self.status[j], message=self.message[j],
            n_steps=int(self.n_steps[j]), n_rhs=int(self.n_rhs[j]), n_rejected=int(self.n_rejected[j]),
            events=self.events[j] if self.events else (),
            metadata={**self.metadata, "engine": self.engine[j], "run": j},
        )  # fmt: skip

    def __repr__(self) -> str:
        ok = int(np.count_nonzero(self.success))
        return (f"BatchTrajectory(runs={len(self)}, samples={self.t.shape[0]}, n={len(self.coordinate_names)}, "
                f"succeeded={ok}, failed={len(self) - ok})")  # fmt: skip


# --------------------------------------------------------------------------- inputs


def _stack(x: ArrayLike | None, name: str, n: int, k: int | None) -> FloatArray | None:
    if x is None:
        return None
    try:
        a = np.array(as_float_array(x, name))  # text, booleans, complex: refused by name
    except ShapeError:
        raise ShapeError(f"{name} must be an array of shape (k, {n}) or ({n},), got {type(x).__name__}") from None
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != n or (k is not None and a.shape[0] not in (1, k)):
        want = f"({k}, {n})" if k is not None else f"(k, {n})"
        raise ShapeError(f"{name} must have shape {want} or ({n},), got shape {np.shape(x)}")
    if not np.isfinite(a).all():
        bad = int(np.argmax(~np.isfinite(a).all(axis=1)))
        raise NonFiniteError(f"{name}: run {bad} is not finite")
    return a


def _models(model: Model, params: Any, k: int | None) -> tuple[list[Model], NDArray[np.int32] | None]:
    """The distinct models of the runs and each run's index among them (None: one model)."""
    if params is None:
        return [model], None
    if isinstance(params, Mapping):  # {field: k values}
        keys = list(params)
        cols = [list(params[key]) for key in keys]
        lens = {len(c) for c in cols}
        if len(lens) != 1:
            raise ShapeError(f"params: every field needs the same number of values, got {dict(zip(keys, lens))}")
        rows: list[Any] = [dict(zip(keys, vals)) for vals in zip(*cols)]
    elif isinstance(params, Sequence) and not isinstance(params, str):
        rows = list(params)
    else:
        raise InputError(f"params must be a sequence of k Models or dicts, or a dict of k-value lists, got "
                         f"{type(params).__name__}")  # fmt: skip
    if k is not None and len(rows) not in (1, k):
        raise ShapeError(f"params: {len(rows)} entries for {k} runs")
    models: list[Model] = []
    index: dict[Any, int] = {}
    of = np.empty(len(rows), dtype=np.int32)
    for i, r in enumerate(rows):
        if isinstance(r, Model):
            key: Any = ("model", id(r))
            build: Any = r
        elif isinstance(r, Mapping):
            key = ("replace", repr(sorted(r.items(), key=lambda kv: str(kv[0]))))
            build = None
        else:
            raise InputError(f"params[{i}] must be a Model or a dict of model.replace() fields, got {type(r).__name__}")
        j = index.get(key)
        if j is None:
            if build is None:
                try:
                    build = model.replace(**dict(r))
                except TypeError as exc:
                    raise InputError(f"params[{i}]: {exc}") from None
            if build.n != model.n or build.constraint_names != model.constraint_names or build.k != model.k:
                raise ShapeError(f"params[{i}]: the model's sizes or constraints differ from the batch's model")
            j = len(models)
            models.append(build)
            index[key] = j
        of[i] = j
    return models, of


def simulate_batch(
    model: Any,
    t_span: float | Sequence[float],
    q0: ArrayLike | None = None,
    qd0: ArrayLike | None = None,
    *,
    params: Any = None,
    active: Iterable[str] | Sequence[Iterable[str]] | None = None,
    record: Iterable[str] = ("q", "qd"),
    threads: int | None = None,
    controller: Any = None,
    method: Any = None,
    dt: float | None = None,
    solver: Any = None,
    stabilization: Any = "projection",
    events: Any = (),
    output: Any = None,
    engine: str = "auto",
    **options: Any,
) -> BatchTrajectory:
    """Simulate k runs of one model (or k parameter variants) in the compiled engine at once.

    Run i starts from ``(q0[i], qd0[i])`` with the model ``params[i]`` and the active set
    ``active[i]``; every other setting is :func:`simulate`'s and means the same for each run.
    (A function of its own rather than ``simulate`` with a (k, n) ``q0``: its result is a
    :class:`BatchTrajectory`, not a :class:`Trajectory`, and its failures never raise.)

    Parameters
    ----------
    model : Model or Mechanism
        As for :func:`simulate` (a mechanism's state supplies the defaults of q0, qd0, active).
    t_span : (float, float) or float
    q0, qd0 : array_like, shape (k, n) or (n,)
        Initial coordinates and velocities per run (a single row is shared by every run; qd0
        defaults to zero).
    params : sequence of k dicts or Models, or dict of k-value sequences, optional
        Per-run model parameters: each dict gives fields of ``model.replace(**fields)`` (e.g.
        ``{"gravity": (0.0, -1.62)}``), equal dicts share one model; a Model is used as it is;
        ``{"gravity": [g1, g2, ...]}`` is the column form. Every variant must have the model's
        coordinates, actuators and constraints.
    active : iterable of str, or a sequence of k of them, optional
        Initial active set, shared or per run (default: the model's).
    record : iterable of str, default ("q", "qd")
        Per-sample arrays to keep among ``"q", "qd", "qdd", "f_c", "u"`` (the scalar
        diagnostics are always kept): at 10⁴ runs × 2001 samples a (k, N, n) array of a
        9-coordinate model is 1.4 GB.
    threads : int, optional
        Threads of the batched engine loop (default: the machine's cores).
    controller, method, dt, solver, stabilization, events, output, engine, **options
        As for :func:`simulate` (the values :class:`~nonmin.sim.Solver`,
        :class:`~nonmin.sim.EventSet`, :class:`~nonmin.sim.Output` and their flat shorthands),
        shared by every run. ``t_eval`` is the common output grid (default with a fixed-step
        method: every step, ``t0 + i dt``; an adaptive method needs it). ``throw``,
        ``progress``, ``checkpoint``, ``resume``, ``reactions`` are not batch options: a failed
        run keeps its status and message and never stops the batch.

    Returns
    -------
    BatchTrajectory

    Raises
    ------
    InputError, ShapeError, NonFiniteError, UnknownNameError
        Bad arguments (as :func:`simulate`; per-run arrays name the run).
    """
    from dataclasses import replace

    from . import _simulate as S
    from ._options import resolve_options
    from ._stabilization import Projection, resolve_stabilization

    for bad in ("throw", "progress", "checkpoint", "checkpoint_every", "resume", "reactions"):
        if bad in options:
            raise InputError(f"simulate_batch: {bad!r} is not a batch option (a failed run keeps its status)")
    flat = dict(options)
    if method is not None:
        flat["method"] = method
    if dt is not None:
        flat["dt"] = dt
    sol, evset, out = resolve_options(solver, events, output, flat)
    if out.checkpoint is not None or out.reactions or not out.throw or out.progress:
        raise InputError("simulate_batch: output= may set t_eval only (no checkpoint, reactions, throw, progress)")
    rec = tuple(record)
    unknown = sorted(set(rec) - set(RECORDABLE))
    if unknown:
        raise InputError(f"record: unknown array(s) {unknown}; known: {list(RECORDABLE)}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int | np.integer) or threads < 1):
        raise InputError(f"threads must be an integer ≥ 1, got {threads!r}")
    # ---------------------------------------------------------------- model / states
    if not isinstance(model, Model):
        inner = getattr(model, "model", None)
        if not isinstance(inner, Model):
            raise InputError(f"model must be a nonmin Model or a mechanism with .model, got {type(model).__name__}")
        st = getattr(model, "state", None)
        model = inner
        if st is not None:
            q0 = st.q if q0 is None else q0
            qd0 = st.qd if qd0 is None else qd0
            active = st.active if active is None else active
    n = model.n
    if q0 is None:
        raise InputError("simulate_batch: q0 is required for a bare model (shape (k, n))")
    Q = _stack(q0, "q0", n, None)
    V = _stack(qd0, "qd0", n, None)
    sizes = {Q.shape[0] if Q is not None else 1, V.shape[0] if V is not None else 1}
    if params is not None and not isinstance(params, Mapping | Model):
        sizes.add(len(params))
    elif isinstance(params, Mapping):
        sizes.update(len(list(v)) for v in params.values())
    per_run_active = (active is not None and not isinstance(active, str)
                      and isinstance(active, Sequence) and len(active) > 0
                      and all(not isinstance(a, str) for a in active))  # fmt: skip
    if per_run_active:
        assert isinstance(active, Sequence)
        sizes.add(len(active))
    sizes.discard(1)
    if len(sizes) > 1:
        raise ShapeError(f"simulate_batch: q0, qd0, params and active give different run counts {sorted(sizes)}")
    k = sizes.pop() if sizes else 1
    assert Q is not None
    Q = np.ascontiguousarray(np.broadcast_to(Q, (k, n)))
    V = np.zeros((k, n)) if V is None else np.ascontiguousarray(np.broadcast_to(V, (k, n)))
    models, of = _models(model, params, k)
    of_all = np.zeros(k, dtype=np.int32) if of is None else np.ascontiguousarray(np.broadcast_to(of, (k,)))
    if per_run_active:
        assert isinstance(active, Sequence)
        acts = tuple(model.resolve_active(a) for a in active)
    else:
        a0 = model.resolve_active(active)  # type: ignore[arg-type]
        acts = (a0,) * k
    # ---------------------------------------------------------------- settings
    t0, t1 = S._t_span(t_span)
    dt = sol.dt
    integ = S._resolve_method(sol.method, dt, sol.rtol, sol.atol)
    stab = resolve_stabilization(stabilization)
    t_eval = out.t_eval
    if t_eval is None:
        if integ.adaptive:
            raise InputError("simulate_batch: an adaptive method needs t_eval (the runs' steps differ)")
        h = getattr(integ, "dt", None) or dt or S.DEFAULT_DT
        steps = max(1, math.ceil((t1 - t0) / h - 1e-9))
        t_out: FloatArray = t0 + h * np.arange(steps + 1, dtype=float)
        t_out[-1] = t1
    else:
        try:
            t_out = np.asarray(np.array(t_eval, dtype=float).ravel(), dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"t_eval must be an array of times, got {type(t_eval).__name__}") from None
        if not np.isfinite(t_out).all():
            raise NonFiniteError("t_eval must be finite")
        if t_out.size and (np.any(np.diff(t_out) < 0) or t_out[0] < t0 or t_out[-1] > t1):
            raise InputError(f"t_eval must be non-decreasing and inside t_span {(t0, t1)}")
    N = int(t_out.size)
    width = sum(n if r != "u" else model.k for r in rec) + len(_SCALARS) + 1
    if k * N * width * 8 > MAX_BATCH_BYTES:
        raise InputError(
            f"simulate_batch: {k} runs × {N} samples × {width} values need {k * N * width * 8 / 2**30:.3g} GiB "
            f"(limit {MAX_BATCH_BYTES / 2**30:g}); pass a coarser t_eval or record fewer arrays"
        )
    rank_rtol = sol.rank_rtol
    if rank_rtol is None and integ.adaptive:
        rank_rtol = S.ADAPTIVE_RANK_RTOL
    pi = sol.project_initial
    project_initial = isinstance(stab, Projection) if pi is None else bool(pi)
    max_steps = sol.max_steps
    h0 = sol.h0
    h_init = (0.0 if h0 is None else S._positive(h0, "h0")) if integ.adaptive else \
        S._positive(getattr(integ, "dt", None) or dt or S.DEFAULT_DT, "dt")  # fmt: skip
    if integ.adaptive and dt is not None and hasattr(integ, "h_max"):
        integ = type(integ)(**{**integ.__dict__, "h_max": dt})
    from . import _durable

    _durable.check_budget(t0=t0, t1=t1, h=dt if integ.adaptive else h_init, max_steps=int(max_steps),
                          t_out=t_out, n=n, k=model.k, c=len(model.constraint_names))  # fmt: skip
    # ---------------------------------------------------------------- which runs batch
    names = model.constraint_names
    unilateral = tuple(c.name for c in model.constraints if c.kind == "unilateral") if evset.contact else ()
    contact = bool(unilateral)
    why = None
    if engine not in ("auto", "engine"):
        why = f"engine={engine!r}"
    elif evset.events:
        why = "user events (their guards and transitions run in Python)"
    elif contact and model.friction_contacts:
        why = "Coulomb friction (the contacts' modes start in Python)"
    elif isinstance(stab, Projection) and stab.energy:
        why = "the energy projection (its level is per run)"
    else:
        why = _engine.ineligible(integ, stab, (), (), engine)
    progs: list[Any] = []
    if why is None:
        eng = _engine._engine()
        for m in models:
            p = _engine.program_for(m)
            if isinstance(p, eng.PyProgram):
                why = f"model {m.name!r} has no compiled program"
                break
            progs.append(p)
    ctrls: list[tuple[int, list[int], Any]] = []
    if why is None and controller is not None:
        ctrls, why = _compiled_controllers(controller, models, progs, of_all, acts, names, unilateral)
    if why is not None and engine == "engine":
        raise InputError(f"simulate_batch(engine='engine') cannot batch these runs: {why}")
    meta: dict[str, Any] = {
        "model": S._describe(model),
        "options": {"t_span": [t0, t1], "method": integ.name or type(integ).__name__, "integrator": repr(integ),
                    "dt": None if integ.adaptive else h_init, "stabilization": repr(stab),
                    "rank_rtol": rank_rtol, "runs": k, "record": list(rec)},
    }  # fmt: skip
    masks = np.array([[nm in a for nm in names] for a in acts], dtype=np.uint8).reshape(k, len(names))
    sim_kw: dict[str, Any] = {"solver": sol, "events": evset, "stabilization": stabilization, "engine": engine,
                              "controller": controller, "output": replace(out, t_eval=t_out, throw=False)}  # fmt: skip
    run_events: list[tuple[EventRecord, ...]] = [()] * k
    if why is None:
        opts = _engine.options(integ, stab, dt=h_init, t1=t1, h0=h_init, rank_rtol=rank_rtol,
                               drift_factor=S.DRIFT_RANK_FACTOR, project_initial=project_initial,
                               max_steps=int(max_steps), t_grid=t0)  # fmt: skip
        flags = 0
        for r in rec:
            flags |= int(getattr(eng, "REC_" + ("FC" if r == "f_c" else r.upper())))
        if isinstance(evset.restitution, Mapping):
            S._check_names(model, evset.restitution, "restitution")
        rest = [S._restitution_of(evset.restitution if isinstance(evset.restitution, float)
                                  else dict(evset.restitution), c.name) for c in model.constraints]  # fmt: skip
        d = eng.simulate_batch(progs, of_all, float(t0), Q, V, np.ascontiguousarray(masks), opts,
                               np.ascontiguousarray(t_out), flags, int(threads or 0), contact=contact,
                               restitution=rest, v_thresh=float(evset.impact_velocity_threshold),
                               zeno_max=int(evset.zeno_max_events), zeno_window=float(evset.zeno_window),
                               controllers=ctrls)  # fmt: skip
        if contact:
            d["active_mask"] = d["active_mask"].astype(bool)
            run_events = [tuple(_record(model, e) for e in run) for run in d["events"]]
        outcome = d["outcome"]
        status = [Status.SUCCESS] * k
        message = ["reached the end of t_span"] * k
        runs: list[Trajectory | None] = [None] * k
        engines = ["batch"] * k
        redo = [i for i in range(k) if int(outcome[i]) != int(eng.SIM_DONE)]
        meta["engine"] = "batch"
    else:
        d = _empty(k, N, n, model.k, rec)
        if contact or evset.events:
            d["active_mask"] = np.zeros((k, N, len(names)), dtype=bool)
        status, message, runs, engines = [Status.SUCCESS] * k, [""] * k, [None] * k, ["simulate"] * k
        redo = list(range(k))
        meta["engine"] = f"simulate, one run at a time ({why})"
    for i in redo:  # through simulate, exactly as one run
        tr = S.simulate(models[int(of_all[i])], (t0, t1), Q[i], V[i], active=acts[i], **sim_kw)
        _fill(d, i, tr, t_out, rec)
        runs[i] = tr
        run_events[i] = tr.events
        status[i], message[i] = tr.status, tr.message
        engines[i] = "simulate" if why is not None else "batch, then simulate"
    return BatchTrajectory(
        t=t_out, q=d.get("q"), qd=d.get("qd"), qdd=d.get("qdd"), f_c=d.get("f_c"), u=d.get("u"),
        energy=d["energy"], phi_norm=d["phi_norm"], velocity_residual_norm=d["velocity_residual_norm"],
        cond=d["cond"], mu=d["mu"], work=d["work"], rank=d["rank"], status=tuple(status), message=tuple(message),
        n_steps=np.asarray(d["n_steps"], dtype=np.int64), n_rhs=np.asarray(d["n_rhs"], dtype=np.int64),
        n_rejected=np.asarray(d["n_rejected"], dtype=np.int64), engine=tuple(engines),
        coordinate_names=model.coordinate_names, constraint_names=names, actuator_names=model.actuator_names,
        active=acts, runs=tuple(runs), metadata=meta, events=tuple(run_events) if (contact or evset.events) else (),
        active_mask=d.get("active_mask"),
    )  # fmt: skip


#: Most unilateral constraints for which a batch compiles the controller of every active set
#: they can make (2^u sets per initial one); above, controlled contact runs are made one by one.
MAX_CONTACT_SETS = 6


def _compiled_controllers(
    controller: Any, models: list[Model], progs: list[Any], of_all: NDArray[np.int32],
    acts: tuple[frozenset[str], ...], names: tuple[str, ...], unilateral: tuple[str, ...],
) -> tuple[list[tuple[int, list[int], Any]], str | None]:  # fmt: skip
    """The compiled controller of each (model, active set) the runs start in and, with contact,
    of each set the unilateral constraints can make from it: ``(program index, mask, compiled)``
    prototypes for the engine (copied per thread and run), or why the runs are not batched."""
    if len(unilateral) > MAX_CONTACT_SETS:
        return [], f"a controller with {len(unilateral)} unilateral constraints (more than {MAX_CONTACT_SETS})"
    out: list[tuple[int, list[int], Any]] = []
    seen: set[tuple[int, frozenset[str]]] = set()
    starts = sorted({(int(j), a) for j, a in zip(of_all, acts)}, key=lambda x: (x[0], sorted(x[1])))
    for j, a in starts:
        base = a - set(unilateral)
        sets = [a] + [base | {u for b, u in enumerate(unilateral) if bits >> b & 1}
                      for bits in range(1 << len(unilateral))]  # fmt: skip
        for s_i, act in enumerate(sets):
            if (j, act) in seen:
                continue
            seen.add((j, act))
            compiled = _engine.compiled_controller(controller, models[j], progs[j], act)
            if compiled is None:
                if s_i == 0:
                    return [], f"controller {type(controller).__name__} has no compiled form here"
                continue  # (a run reaching this set is made again by simulate)
            out.append((j, [int(nm in act) for nm in names], compiled))
    return out, None


def _record(model: Model, d: Mapping[str, Any]) -> EventRecord:
    def names(mask: Any) -> frozenset[str]:
        return frozenset(nm for nm, a in zip(model.constraint_names, mask) if a)

    return EventRecord(float(d["t"]), str(d["name"]), str(d["transition"]), d["q_before"], d["qd_before"],
                       d["q_after"], d["qd_after"], names(d["active_before"]), names(d["active_after"]))  # fmt: skip


def _empty(k: int, N: int, n: int, nu: int, rec: tuple[str, ...]) -> dict[str, Any]:
    d: dict[str, Any] = {r: np.full((k, N, nu if r == "u" else n), np.nan) for r in rec}
    for s in _SCALARS:
        d[s] = np.full((k, N), np.nan)
    d["rank"] = np.full((k, N), -1, dtype=np.int64)
    for c in ("n_steps", "n_rhs", "n_rejected"):
        d[c] = np.zeros(k, dtype=np.int64)
    return d


def _fill(d: dict[str, Any], i: int, tr: Trajectory, t_out: FloatArray, rec: tuple[str, ...]) -> None:
    """Run i's samples at the output times (the last sample at each time: after an event)."""
    for key in (*rec, *_SCALARS, "rank"):
        d[key][i] = -1 if key == "rank" else np.nan
    if "active_mask" in d:
        d["active_mask"][i] = False
    if len(tr):
        j = np.searchsorted(tr.t, t_out, side="right") - 1
        ok = (j >= 0) & (tr.t[np.clip(j, 0, None)] == t_out)
        jj = j[ok]
        for key in (*rec, *_SCALARS, "rank"):
            d[key][i][ok] = getattr(tr, key)[jj]
        if "active_mask" in d:
            d["active_mask"][i][ok] = tr.active_mask[jj]
    d["n_steps"][i] = tr.n_steps
    d["n_rhs"][i] = tr.n_rhs
    d["n_rejected"][i] = tr.n_rejected
