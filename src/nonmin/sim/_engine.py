"""The engine path of :func:`nonmin.sim.simulate`: the whole loop in the compiled engine.

``simulate(..., engine="engine")`` (and ``"auto"`` when the run is covered) runs the loop of
``nonmin._engine`` (C++: ``engine/src/sim_loop.cpp``): the integrator (RK4, DOPRI5 with its
error control on projected solutions and dense output, implicit midpoint), the stabilization
(mass-metric or Euclidean projection with the Gauss–Newton cutoff rules, Baumgarte, none), the
output sampling (every step, or ``t_eval`` from the continuous extension) and the diagnostics
the :class:`~nonmin.sim.Trajectory` records — the algorithm of the general driver, whose
results it reproduces to round-off.

The model is the model's own compiled program when it has one
(``Model.engine_program()``), else a :class:`nonmin._engine.PyProgram` that evaluates the model
through :meth:`~nonmin.model.Model.evaluate` / ``mass_matrix`` / ``constraint_terms`` /
``potential_energy`` in a Python callback (any model source runs on the engine; the GIL is
taken only inside the callback). A controller is called back the same way (compiled
controllers replace the callback later).

Covered: the methods ``"rk4"``, ``"rk8"``, ``"dopri5"``, ``"dop853"``, ``"midpoint"`` (the five classes exactly), the
stabilizations ``"none"``, ``"baumgarte"``, ``"projection"`` (exactly those classes), ``t_eval``,
``project_initial``, ``rank_rtol``, ``max_steps``, ``h0``, controllers (Python callback), user
events and automatic unilateral contact. The contact guards are evaluated, located and their
transitions applied in the engine (``engine/src/sim_events.cpp``: Brent's method on the
method's partial steps, the simultaneous impact, the Gauss check, releases), which returns
once per event with what it did (``SIM_TRANSITION``); user guards are called back at each
projected step end (:func:`._simulate._engine_watch`) and the step in which one crosses is
left to the general driver, which takes it from its start, locates the crossing and applies
the transition (Activate/Deactivate, Reset, and any contact event of that step) exactly as
before, and the engine resumes after it. Not covered (the
general driver runs them): custom :class:`~nonmin.sim.Integrator` or
:class:`~nonmin.sim.Stabilization` subclasses, and runs with the core's backend set to
``"numpy"`` under ``engine="auto"``.

The loop runs in chunks of steps (about :data:`CHUNK_SECONDS` of wall time each) so the
progress bar moves, ``KeyboardInterrupt`` is honoured between chunks and ``max_steps`` is
checked. A numerical failure (kernel status, non-finite acceleration, step-size underflow,
implicit midpoint without convergence, max_steps) ends the chunk at the last accepted step and
the general driver continues from there: errors are raised by the same code, with the same
types and messages, as with ``engine="python"``. An exception raised in a callback propagates
as it is.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import SYMMETRY_RTOL
from ..core._fast import get_backend
from ..core.linalg import SPD_RTOL
from ..errors import InputError
from ..model import Model
from . import _durable, _integrators
from ._integrators import DOP853, RK4, RK8, DormandPrince5, ImplicitMidpoint
from ._stabilization import Baumgarte, NoStabilization, Projection

FloatArray = NDArray[np.float64]

#: Target wall time (s) of one engine chunk (progress, interrupts, step budget in between).
CHUNK_SECONDS = 0.25

#: A step's cost in units of the run's start (the initial projection and one evaluation):
#: RK4 takes four evaluations and a projection, DOPRI5 six or seven; rejected steps, projection
#: iterations and samples add more. The first chunk is CHUNK_SECONDS over this many starts.
START_STEP_RATIO = 16.0


def _first_chunk(start_seconds: float) -> int:
    """Steps of the first chunk, from the time the start took (at least 16, at most 2**20)."""
    return int(min(max(16.0, CHUNK_SECONDS / max(START_STEP_RATIO * start_seconds, 1e-9)), 1 << 20))


_KINDS = {"holonomic": 0, "rheonomic": 1, "nonholonomic": 2, "unilateral": 3}


@functools.cache
def _engine() -> Any:
    """The compiled extension, imported at the first run (import nonmin stays light)."""
    from .. import _engine as eng  # type: ignore[attr-defined]  # the compiled extension (no stubs)

    return eng


# --------------------------------------------------------------------------- eligibility


def ineligible(
    integ: Any, stab: Any, events: tuple[Any, ...], unilateral: tuple[str, ...], engine: str
) -> str | None:
    """Why the engine loop cannot run this simulation, or None when it covers it."""
    if type(integ) not in (RK4, RK8, DormandPrince5, DOP853, ImplicitMidpoint):
        return f"method {getattr(integ, 'name', '') or type(integ).__name__!r} is not one of the built-in integrators"
    if type(stab) not in (NoStabilization, Baumgarte, Projection):
        return f"stabilization {stab!r} is not one of the built-in stabilizations"
    if engine == "auto" and get_backend() == "numpy":
        return "the nonmin.core backend is 'numpy' (the NumPy reference kernels)"
    return None


# --------------------------------------------------------------------------- the model


class ModelCallback:
    """The callback of :class:`nonmin._engine.PyProgram`: evaluates a Python model into the
    engine's buffers.

    ``need`` (``NEED_*`` flags of the engine) selects the calls: the dynamics terms come from
    :meth:`Model.evaluate` (as the general driver's right-hand side), the mass matrix alone from
    ``mass_matrix`` and the constraint terms alone from ``constraint_terms`` (as its
    projection), the potential energy from ``potential_energy`` (as its samples). The active
    constraints' rows are written at their stacked rows over all constraints.
    """

    def __init__(self, model: Model) -> None:
        self.model = model
        eng = _engine()
        self._dyn = int(eng.NEED_H | eng.NEED_B)
        self._m = int(eng.NEED_M)
        self._b = int(eng.NEED_B)
        self._cons = int(eng.NEED_A | eng.NEED_GAMMA | eng.NEED_PHI | eng.NEED_VELOCITY)
        self._energy = int(eng.NEED_ENERGY)
        self._active: dict[bytes, tuple[frozenset[str], Any]] = {}
        self._start: list[int] = []
        i = 0
        for c in model.constraints:
            self._start.append(i)
            i += c.dim
        self.m_all = i

    def active(self, mask: bytes) -> tuple[frozenset[str], Any]:
        """The active set of an engine mask and its stacked rows (a slice when contiguous)."""
        hit = self._active.get(mask)
        if hit is None:
            cons = self.model.constraints
            act = frozenset(c.name for c, a in zip(cons, mask) if a)
            rows = [r for c, s, a in zip(cons, self._start, mask) if a for r in range(s, s + c.dim)]
            idx: Any = np.asarray(rows, dtype=np.intp)
            if rows and rows == list(range(rows[0], rows[0] + len(rows))):
                idx = slice(rows[0], rows[0] + len(rows))
            hit = (act, idx)
            self._active[mask] = hit
        return hit

    def __call__(
        self, t: float, q: FloatArray, qd: FloatArray, mask: bytes, need: int, M: FloatArray,
        h: FloatArray, fp: FloatArray, B: FloatArray, A: FloatArray, gamma: FloatArray,
        phi: FloatArray, vel: FloatArray,
    ) -> float:  # fmt: skip
        act, rows = self.active(mask)
        model = self.model
        ct = None
        if need & self._dyn:
            terms = model.evaluate(t, q, qd, act)
            if need & self._m:
                M[...] = terms.M
            h[...] = terms.h
            fp[...] = terms.f_passive
            if need & self._b:
                B[...] = terms.B
            ct = terms.constraints
        else:
            if need & self._m:
                M[...] = model.mass_matrix(q)
            if need & self._cons:
                ct = model.constraint_terms(t, q, qd, act)
        if ct is not None and ct.A.shape[0]:
            A[rows] = ct.A
            gamma[rows] = ct.gamma
            phi[rows] = ct.phi
            vel[rows] = ct.velocity
        if need & self._energy:
            return float(model.potential_energy(q))
        return 0.0


def program_for(model: Model) -> Any:
    """The model's engine program: its own compiled one, else the Python callback."""
    own = getattr(model, "engine_program", None)
    prog = own() if callable(own) else None
    if prog is not None:
        return prog
    eng = _engine()
    cb = ModelCallback(model)
    cons = []
    for c, s in zip(model.constraints, cb._start):
        cons.append((c.name, _KINDS[c.kind], s, int(c.dim)))
    return eng.PyProgram(model.n, model.k, cons, cb)


class ControllerCallback:
    """A Python controller called back by the engine: ``u`` at every evaluation of the
    dynamics (shape-checked as the general driver does), ``update`` after every accepted
    step. The controller state lives here (:attr:`state`)."""

    def __init__(self, controller: Any, state: Any, k: int, model_cb: ModelCallback | None, model: Model) -> None:
        self.controller = controller
        self.state = state
        self.k = k
        self._cb = model_cb if model_cb is not None else ModelCallback(model)
        self._has_update = hasattr(controller, "update")
        self._names = model.actuator_names

    def control(self, t: float, q: FloatArray, qd: FloatArray, mask: bytes, u_out: FloatArray) -> None:
        act = self._cb.active(mask)[0]
        raw = _durable.user_call("controller", t, self.controller, t, q, qd, self.state, active=act)
        u_out[...] = _durable.finite_output("controller", t, raw, (self.k,), self._names)

    def update(self, t: float, q: FloatArray, qd: FloatArray, mask: bytes) -> None:
        if self._has_update:
            act = self._cb.active(mask)[0]
            self.state = _durable.user_call("controller.update", t, self.controller.update, t, q, qd,
                                            self.state, active=act)  # fmt: skip


def compiled_controller(controller: Any, model: Model, program: Any, active: frozenset[str]) -> Any | None:
    """The engine's compiled form of a controller for one active set, or None (then it is
    called back): what its ``engine_controller(model, program, active)`` returns (the
    protocol of :class:`nonmin.control.Controller`; the simulator imports no controller)."""
    make = getattr(controller, "engine_controller", None)
    return None if make is None else make(model, program, active)


def merge_state(controller: Any, state: Any, compiled: Any) -> Any:
    """The controller state after the steps its compiled form took (the controller's
    ``engine_state(state, compiled)``)."""
    return controller.engine_state(state, compiled)


# --------------------------------------------------------------------------- the run


def _projection_options(stab: Projection) -> Any:
    po = _engine().SimProjection()
    po.tol = float(stab.tol)
    po.max_iter = int(stab.max_iter)
    po.velocity = bool(stab.velocity)
    po.euclidean = stab.metric == "euclidean"
    po.velocity_rtol = -1.0 if stab.velocity_rtol is None else float(stab.velocity_rtol)
    if stab.energy and stab.energy_level is not None:
        po.energy_level = float(stab.energy_level)
    return po


def options(
    integ: Any, stab: Any, *, dt: float, t1: float, h0: float, rank_rtol: float | None,
    drift_factor: float, project_initial: bool, max_steps: int, t_grid: float | None = None,
) -> Any:  # fmt: skip
    """The engine's settings of a run (:class:`nonmin._engine.SimOptions`); ``t_grid``: the
    origin of the fixed steps' grid (the run's ``t_span`` start; SingularPassages.align).

    Built once per distinct settings and shared (the integrator and stabilization are frozen
    values, the engine copies the settings into its loop, and nothing changes them after):
    repeated runs skip the ~30 attribute writes."""
    signs = tuple(math.copysign(1.0, x) for x in (t1, 0.0 if t_grid is None else t_grid))  # (-0.0 == 0.0)
    return _options(integ, stab, dt, t1, h0, rank_rtol, drift_factor, project_initial, max_steps, t_grid, signs)


@functools.lru_cache(maxsize=64)
def _options(
    integ: Any, stab: Any, dt: float, t1: float, h0: float, rank_rtol: float | None, drift_factor: float,
    project_initial: bool, max_steps: int, t_grid: float | None, signs: tuple[float, ...],
) -> Any:  # fmt: skip
    eng = _engine()
    o = eng.SimOptions()
    if type(integ) is RK4:
        o.method = eng.SimMethod.rk4
        o.dt = float(dt)
    elif type(integ) is RK8:
        o.method = eng.SimMethod.rk8
        o.dt = float(dt)
    elif type(integ) is ImplicitMidpoint:
        o.method = eng.SimMethod.midpoint
        o.dt = float(dt)
        o.xtol = float(integ.xtol)
        o.max_iter = int(integ.max_iter)
        o.max_halvings = int(integ.max_halvings)
    elif type(integ) in (DormandPrince5, DOP853):
        o.method = eng.SimMethod.dopri5 if type(integ) is DormandPrince5 else eng.SimMethod.dop853
        o.rtol = float(integ.rtol)
        o.atol = float(integ.atol)
        o.h_max = float(integ.h_max)
        o.h_min_factor = float(integ.h_min_factor)
        o.h0 = float(h0)
    else:  # pragma: no cover - ineligible() decides first
        raise InputError(f"engine: unsupported integrator {integ!r}")
    if isinstance(stab, Projection):
        o.stabilization = eng.SimStabilization.projection
        o.projection = _projection_options(stab)
    elif isinstance(stab, Baumgarte):
        o.stabilization = eng.SimStabilization.baumgarte
        o.alpha = float(stab.alpha)
        o.beta = float(stab.beta)
    else:
        o.stabilization = eng.SimStabilization.none
    o.initial_projection = _projection_options(Projection())
    o.project_initial = bool(project_initial)
    o.rank_rtol = -1.0 if rank_rtol is None else float(rank_rtol)
    o.drift_factor = float(drift_factor)
    o.spd_rtol = float(SPD_RTOL)
    o.sym_rtol = float(SYMMETRY_RTOL)
    o.t1 = float(t1)
    if t_grid is not None:
        o.t_grid = float(t_grid)
    o.max_steps = int(max_steps)
    o.passages = bool(getattr(integ, "passages", True))
    o.partial_samples = bool(_integrators.ADAPTIVE_PARTIAL_SAMPLES)
    return o


class EngineResult(NamedTuple):
    """What the engine did: new state, counters, and why it returned."""

    started: bool  # the start (initial projection and evaluation) succeeded
    t: float
    y: FloatArray
    h: float
    steps: int
    n_rhs: int
    n_rejected: int
    out_i: int
    handover: bool  # a numerical failure: the general driver continues from (t, y)
    event: bool  # a watched guard crossed: the general driver takes the next step
    message: str
    guards: list[float]  # the contact guards' values at the last accepted step end (or event)
    transition: bool = False  # the engine located contact events and applied them (`events`)
    events: tuple[dict[str, Any], ...] = ()  # what the engine's event layer applied
    slip: tuple[tuple[int, float, float], ...] = ()  # friction contacts' (slip, d0, d1) at the end
    painleve: tuple[int, float, float] | None = None  # (friction contact, t, factor) when met
    friction_work: float = 0.0  # the friction forces' work (J) from the run's start to (t, y)
    work: float = 0.0  # the work of controllers and applied forces (J) from the run's start to (t, y)


def run(
    program: Any,
    *,
    opts: Any,
    active_mask: NDArray[np.uint8],
    t_out: FloatArray | None,
    sink: Callable[[dict[str, Any]], None],
    progress: Any,
    start: tuple[float, FloatArray, FloatArray] | None = None,
    resume: tuple[float, FloatArray, float, int, int] | None = None,
    controller: ControllerCallback | None = None,
    watch: Callable[[float, FloatArray, FloatArray, FloatArray], bool] | None = None,
    guards: list[tuple[bool, int, int, float]] | None = None,
    compiled: Any = None,
    contact: tuple[list[float], float] | None = None,
    passage_seed: tuple[FloatArray, FloatArray] | None = None,
    friction: list[tuple[int, int, float, int, float, float]] | None = None,
    work0: float = 0.0,
    ctrl_work0: float = 0.0,
) -> EngineResult:
    """Run the engine loop to ``opts.t1``, a handover or a watched event.

    Either ``start = (t0, q0, qd0)`` (initial projection, evaluation and sample; the values
    given with ``guards`` are then replaced by the guards' values at the first point) or
    ``resume = (t, y, h, n_steps, out_i)`` (a state the general driver reached). Every block of samples is
    given to ``sink`` as soon as it is taken (so an interruption keeps them). ``contact =
    (restitution per constraint, impact velocity threshold)`` configures the engine's event
    layer (engine/src/sim_events.cpp), which locates and applies contact events itself when no
    user guard is watched (``transition`` and ``events`` of the result). ``work0``: the friction
    forces' work done before the start or resume (the samples' ``friction_work`` continue it);
    ``ctrl_work0`` the work of controllers and applied forces (the samples' ``work`` continue it).
    """
    eng = _engine()
    tv = np.zeros(0) if t_out is None else np.ascontiguousarray(t_out, dtype=np.float64)
    ctl = (None, None) if controller is None else (controller.control, controller.update)
    loop = eng.SimLoop(program, active_mask, opts, tv, t_out is None, ctl[0], ctl[1], watch, guards or [],
                       compiled)  # fmt: skip

    if contact is not None and guards:
        loop.set_contact(contact[0], contact[1])
    if friction:  # Coulomb friction (engine/src/sim_friction.cpp): (normal, tangent, mu, slip)
        loop.set_friction(friction)
        loop.friction_work = float(work0)
    loop.work = float(ctrl_work0)

    def fric_end() -> dict[str, Any]:
        if not friction:
            return {}
        return {"slip": tuple(loop.friction_slip), "painleve": loop.painleve,
                "friction_work": float(loop.friction_work)}  # fmt: skip

    def take() -> None:
        blk = loop.take()
        if blk["t"].size:
            blk["active_mask"] = blk["active_mask"].astype(bool)
            sink(blk)

    chunk = 16
    if start is not None:
        t0, q, qd = start
        w0 = time.perf_counter()
        code = loop.start(t0, np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float))
        if code == eng.SIM_DONE and guards and not loop.arm_guards():  # the guards at the first point
            code = eng.SIM_HANDOVER
        if code != eng.SIM_DONE:
            y0 = np.concatenate((q, qd))
            return EngineResult(False, t0, y0, 0.0, 0, 0, 0, 0, True, False, str(loop.message), [], **fric_end(), work=float(loop.work))
        # the first chunk from the start's time (a projection and an evaluation: a step costs
        # a few of them, START_STEP_RATIO), so a short run is one chunk; the first sample is
        # taken with the chunk's
        chunk = _first_chunk(time.perf_counter() - w0)
        if passage_seed is not None and passage_seed[0].size:
            loop.seed_passages(np.ascontiguousarray(passage_seed[0], dtype=float),
                               np.ascontiguousarray(passage_seed[1], dtype=float).ravel())  # fmt: skip
    else:
        assert resume is not None
        t, y, h, steps, out_i = resume
        loop.resume(t, np.ascontiguousarray(y, dtype=float), float(h), int(steps), int(out_i))
    if friction and not loop.arm_friction():  # the friction guards at the state reached
        take()
        return EngineResult(True, float(loop.t), np.asarray(loop.y), float(loop.h), int(loop.n_steps), 0, 0,
                            int(loop.out_i), True, False, str(loop.message), list(loop.guard_values),
                            **fric_end(), work=float(loop.work))  # fmt: skip
    code = eng.SIM_DONE
    t1 = float(opts.t1)
    pending = start is not None  # samples recorded and not taken yet (the start's)
    try:
        while loop.t < t1:
            w0 = time.perf_counter()
            steps0 = loop.n_steps
            pending = True
            code = loop.run(chunk)
            elapsed = time.perf_counter() - w0
            take()
            pending = False
            progress.update(loop.t)
            if code != eng.SIM_DONE:
                break
            if loop.n_steps > steps0:
                chunk = int(min(max(16, chunk * CHUNK_SECONDS / max(elapsed, 1e-6)), 1 << 20))
    except BaseException as exc:  # Ctrl-C or a callback's error: the caller keeps the counts
        exc.engine_counts = (int(loop.n_steps), int(loop.n_rhs), int(loop.n_rejected))  # type: ignore[attr-defined]
        raise
    finally:  # the samples not taken yet: the start's when no step was run, or an exception's
        if pending:
            take()
    return EngineResult(True, float(loop.t), np.asarray(loop.y), float(loop.h), int(loop.n_steps),
                        int(loop.n_rhs), int(loop.n_rejected), int(loop.out_i),
                        code == eng.SIM_HANDOVER, code == eng.SIM_EVENT, str(loop.message),
                        list(loop.guard_values), code == eng.SIM_TRANSITION,
                        tuple(loop.events) if code == eng.SIM_TRANSITION else (), **fric_end(), work=float(loop.work))  # fmt: skip
