"""The built-in controllers compiled into the engine's loop (``engine/src/sim_control.cpp``).

:func:`compile_controller` turns a controller value into the engine's ``SimControl`` for one
active set, or returns None when it must be called back (a user controller, the Tracker's
passivity law on a program without C and Ȧ in the engine — spatial, SymPy, function models —,
a controller of a model of another layout or without a compiled
program). A controller built on another model instance with the simulated model's layout is
compiled on its own model's program and evaluates it at every call (``own_terms``), as the
Python controller evaluates its own model. What compiles:

* :class:`~nonmin.control.Regulator` (σ ≥ 0: the spring e + σ‖e‖η of its law): its target
  per active set (projected here once;
  under an active rheonomic constraint the engine projects it at every time, as ``target_for``);
* :class:`~nonmin.control.Tracker` with ``method="computed_torque"``, and with
  ``method="passivity"`` on planar models (constant M: C = 0, Ȧ from the program's tangent) and
  robots (the tree program's Christoffel C and Ȧ), W recorded as ``SimControl.lyapunov``: its
  reference as a value
  the engine evaluates — a piecewise polynomial (:meth:`Reference.constant`,
  :meth:`Reference.polynomial`, :meth:`Reference.spline`) — or a Python function called back
  for ``(q*, q̇*, q̈*)(t)`` alone (:meth:`Reference.from_functions`), the rest compiled;
* :class:`~nonmin.control.ForceControl` over either, constant force targets as values and
  callables called back;
* :class:`~nonmin.control.Switched`: the controller it picks for the active set (each run of
  the engine has one active set; the event layer starts a new one after a switch).

The Python classes stay the specification; the engine's results agree with them to round-off
(``tests/control/test_control_engine.py``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..errors import NonminError
from ..model import Model
from ._common import ControlState
from ._targets import Reference

__all__ = ["compile_controller", "merge_state", "signal"]


def _eng() -> Any:
    from .. import _engine as eng  # type: ignore[attr-defined]  # the compiled extension

    return eng


def _is(obj: Any, cls: str) -> bool:
    """Whether obj is exactly the class ``nonmin.control.<cls>`` (a subclass may change the law:
    it is called back). By name: the classes call this module (no import circle)."""
    t = type(obj)
    return t.__module__.startswith("nonmin.control.") and t.__qualname__ == cls


def _arr(x: Any) -> Any:
    return np.ascontiguousarray(x, dtype=np.float64)


def signal(ref: Reference, n: int) -> Any:
    """The engine's form of a reference: its piecewise polynomial, else its functions called back."""
    eng = _eng()
    pp = ref.piecewise
    if pp is not None:
        x, c, hold = pp
        return eng.SimPiecewisePolynomial(_arr(x), _arr(c), bool(hold))

    def triple(t: float) -> Any:
        q, v, a = ref(t)
        return _arr(np.stack([np.asarray(q, dtype=float), np.asarray(v, dtype=float), np.asarray(a, dtype=float)]))

    return eng.SimPySignal(triple, n, True)


def _force_signal(target: Any, dim: int) -> Any | None:
    eng = _eng()
    if callable(target):

        def value(t: float) -> Any:
            return _arr(np.atleast_1d(np.asarray(target(t), dtype=float)))

        return eng.SimPySignal(value, dim, False)
    arr = np.atleast_1d(np.asarray(target, dtype=float))
    if arr.shape != (dim,) or not np.isfinite(arr).all():
        return None  # the Python controller raises its InputError
    return eng.SimPiecewisePolynomial(_arr([0.0, 1.0]), _arr(arr[None, None, :]), False)


def compile_controller(controller: Any, model: Model, program: Any, active: frozenset[str]) -> Any | None:
    """The engine's ``SimControl`` for ``controller`` on ``model`` with the active set ``active``,
    or None when the controller is to be called back (see the module docstring)."""
    outer = controller
    slot = None
    if _is(controller, "Switched"):
        try:
            slot, controller = controller.select(active)
        except NonminError:
            return None  # the Python controller raises
    cons = model.constraints

    def other_active_set(t: float, q: Any, qd: Any, mask: bytes) -> Any:
        # u for an active set the compiled form was not made for (the engine's event layer
        # changed it; until the loop returns to Python): the Python controller (u does not
        # depend on its bookkeeping state)
        act = frozenset(c.name for c, a in zip(cons, mask, strict=True) if a)
        u = outer(t, np.asarray(q), np.asarray(qd), None, active=act)
        return [float(x) for x in np.asarray(u, dtype=float).ravel()]

    try:
        out = _compile(controller, model, program, active, other_active_set)
    except NonminError:
        return None  # (a target that cannot be projected: the Python controller raises)
    if out is not None and slot is not None:
        out.switched = (outer, slot)
    return out


def _compile(ctrl: Any, model: Model, program: Any, active: frozenset[str], other: Any) -> Any | None:
    outer = ctrl
    forces: list[tuple[int, Any]] = []
    if _is(ctrl, "ForceControl"):
        motion = ctrl.motion
        if motion.rtol != ctrl.rtol:  # two rank tolerances in one evaluation: called back
            return None
        names = list(model.constraint_names)
        for nm, target in ctrl.forces.items():
            dim = model.constraint(nm).dim
            sig = _force_signal(target, dim)
            if sig is None:
                return None
            forces.append((names.index(nm), sig))
        ctrl = motion
    own = getattr(ctrl, "model", None)
    own_terms = own is not model
    if own_terms:
        # a controller of another model instance (e.g. built on an equal model, as tutorial 03
        # does): compiled on its own model's program when that has the loop's layout; the law
        # then evaluates its own program at every call, as the Python controller does
        program = _own_program(own, model)
        if program is None:
            return None
    c: Any = ctrl  # (its validated private fields)
    n = model.n
    rheonomic = any(x.kind == "rheonomic" and x.name in active for x in model.constraints)
    reference = None
    sigma, xi0 = 0.0, None
    if _is(ctrl, "Regulator"):
        law = 0
        sigma = float(ctrl.sigma)
        xi0 = _arr(c._xi0) if sigma > 0.0 else None
        project = rheonomic  # target_for projects at every time then
        q_star = c._q_star if project else c.target_for(active)
    elif _is(ctrl, "Tracker") and ctrl.method == "computed_torque":
        law = 1
        project = True
        q_star = np.zeros(n)
        reference = signal(c._ref, n)
    elif _is(ctrl, "Tracker") and ctrl.method == "passivity" and _eng().sim_passivity_supported(program):
        law = 2  # (C and Ȧ in the engine: planar and rigid-body-tree programs)
        project = True
        q_star = np.zeros(n)
        reference = signal(c._ref, n)
    else:
        return None
    o: Any = outer
    return _eng().SimControl(
        program, law, _arr(q_star), _arr(c._Kp), _arr(c._Kd), [tuple(int(i) for i in b) for b in c._qblocks],
        _arr(o._lo), _arr(o._hi), -1.0 if o.rtol is None else float(o.rtol), o.on_infeasible == "raise",
        project, ctrl.target_policy == "reject", ctrl.metric == "mass", [int(i) for i in ctrl.fixed],
        reference, forces, other, float(getattr(ctrl, "lambda_", 1.0)), own_terms, sigma, xi0,
    )  # fmt: skip


def _layout(m: Any) -> tuple[Any, ...]:
    return (m.n, m.k, tuple((c.name, c.kind, int(c.dim)) for c in m.constraints))


def _own_program(own: Any, model: Model) -> Any | None:
    """The compiled program of the controller's own model when it has the simulated model's
    layout (n, k, the constraints' names, kinds and dims in order), else None (called back)."""
    if not isinstance(own, Model) or _layout(own) != _layout(model):
        return None
    make = getattr(own, "engine_program", None)
    return make() if callable(make) else None


def merge_state(state: Any, compiled: Any, k: int) -> Any:
    """The controller state after the steps the compiled controller saw: ``ControlState.record``
    over them (in the picked mode's slot of a :class:`Switched` state)."""
    sw = getattr(compiled, "switched", None)
    if sw is not None:
        outer, slot = sw
        n_ctrl = len(outer._controllers())
        st = state if isinstance(state, tuple) and len(state) == n_ctrl else outer.initial_state()
        new = list(st)
        new[slot] = _merge(st[slot], compiled, k)
        return tuple(new)
    return _merge(state, compiled, k)


def _merge(state: Any, compiled: Any, k: int) -> Any:
    st = state if isinstance(state, ControlState) else ControlState.initial(k)
    d = compiled.stats
    if d["steps"] == 0:
        return st
    sat_steps = st.saturated_steps or (0,) * k
    max_u = st.max_abs_u or (0.0,) * k
    return replace(
        st,
        steps=st.steps + int(d["steps"]),
        saturated_steps=tuple(int(a + b) for a, b in zip(sat_steps, d["saturated_steps"])),
        saturated=tuple(bool(b) for b in d["saturated"]),
        infeasible_steps=st.infeasible_steps + int(d["infeasible_steps"]),
        min_sigma_pb=min(st.min_sigma_pb, float(d["min_sigma_pb"])),
        max_abs_u=tuple(max(float(a), float(b)) for a, b in zip(max_u, d["max_abs_u"])),
    )
