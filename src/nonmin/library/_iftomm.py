"""IFToMM benchmark problems A01 (simple pendulum) and A02 (N four-bar), planar builder models.

Source: M. González, D. Dopico, U. Lugrís, J. Cuadrado, "A benchmarking system for MBS
simulation software: problem standardization and performance measurement", Multibody System
Dynamics 16 (2006) 179–190; IFToMM Library of Computational Benchmark Problems
(https://www.iftomm-multibody.org/benchmark). See also ``shared/benchmarks/README.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ..errors import InputError
from ..model.planar import PlanarBuilder
from ._registry import Mechanism, register

__all__ = ["a01_pendulum", "a02_n_four_bar", "n_four_bar_reference"]

IFTOMM_REF = (
    "M. González, D. Dopico, U. Lugrís, J. Cuadrado, Multibody Syst. Dyn. 16 (2006) 179–190; "
    "IFToMM Library of Computational Benchmark Problems"
)

#: Largest N of the A02 N four-bar (2N + 1 bars, 6N + 3 coordinates): beyond it a typo in a
#: scenario or a forged file would build a model for minutes and gigabytes.
MAX_N = 1000


@register("A01_pendulum")
def a01_pendulum(*, g: float = 9.81, mirror: bool = False, t_final: float = 10.0) -> Mechanism:
    """IFToMM A01: simple pendulum, point mass 1 kg on a massless 1 m link, released at rest.

    Source: IFToMM benchmark A01 (González et al., Multibody Syst. Dyn. 16 (2006) 179–190).
    Model: one *point mass* (coordinates x, y only, M = I₂ kg) and a rod of length 1 m to the
    ground pivot at the origin (``φ = (x² + y² − 1)/2``). A rigid body with zero inertia would
    make M singular on N(A) (its rotation is unconstrained), hence the point mass.
    Initial state: P1 = (1, 0) (``mirror=True``: (−1, 0), the later IFToMM variant), at rest.
    Outputs: ``P1.position``, ``P1.velocity``. Exact solution: period 2.3678419475762374 s,
    P1(10 s) = (0.275087462576117, −0.961419205099125).
    """
    b = PlanarBuilder("A01_pendulum", gravity=(0.0, -float(g)), description="IFToMM A01 simple pendulum")
    b.point_mass("mass", mass=1.0, points=["P1"])
    b.rod("link", ("ground", (0.0, 0.0)), "P1", length=1.0)
    b.output("P1")
    model = b.build()
    x0 = -1.0 if mirror else 1.0
    state = model.state([x0, 0.0], [0.0, 0.0])
    return Mechanism(
        model=model,
        state=state,
        t_final=float(t_final),
        description="IFToMM A01 planar simple pendulum (point mass on a massless 1 m link)",
        reference=IFTOMM_REF + ", problem A01",
    )


def _n_four_bar_q0(N: int) -> tuple[np.ndarray, np.ndarray]:
    """Initial q, qd of the N four-bar in the builder's body order (cranks, then couplers)."""
    q: list[float] = []
    qd: list[float] = []
    for i in range(N + 1):  # cranks: centre (i, 0.5), θ = π/2, ω = −1
        q += [float(i), 0.5, math.pi / 2]
        qd += [0.5, 0.0, -1.0]
    for i in range(1, N + 1):  # couplers B_{i-1} B_i: centre (i − 0.5, 1), θ = 0, translating at (1, 0)
        q += [i - 0.5, 1.0, 0.0]
        qd += [1.0, 0.0, 0.0]
    return np.array(q), np.array(qd)


@register("A02_n_four_bar")
def a02_n_four_bar(*, N: int = 2, g: float = 9.81, t_final: float | None = None) -> Mechanism:
    """IFToMM A02: N four-bar mechanism (2N+1 links of 1 m, 1 kg), singular when horizontal.

    Source: IFToMM benchmark A02 (González et al., Multibody Syst. Dyn. 16 (2006) 179–190).
    Ground pivots ``A_i = (i, 0)``; cranks ``crank{i}`` from A_i to B_i (start vertical),
    couplers ``coupler{i}`` from B_{i−1} to B_i (start horizontal); uniform bars
    (I = 1/12 kg·m²); gravity 9.81 along −y. Joints: ``A{i}`` (ground–crank), ``B{i-1}r``
    (crank i−1 tip – coupler i start), ``B{i}l`` (coupler i end – crank i tip). Initial
    velocity: x-velocity of B0 = +1 m/s (cranks at −1 rad/s, couplers translating at (1, 0)).
    Outputs: ``B0.position``, ``B0.velocity``. Horizon: 10 s for N = 2 (later spec), 20 s
    otherwise (the original N = 40 spec). Exact reference: :func:`n_four_bar_reference`.
    """
    if isinstance(N, bool) or not isinstance(N, int | np.integer) or not 1 <= N <= MAX_N:
        raise InputError(f"N must be an integer in [1, {MAX_N}], got {N!r}")
    if isinstance(g, bool) or not isinstance(g, int | float | np.floating | np.integer) or not math.isfinite(g):
        raise InputError(f"g must be a finite number, got {g!r}")
    N = int(N)
    b = PlanarBuilder(f"A02_{N}_four_bar", gravity=(0.0, -float(g)), description=f"IFToMM A02, N = {N}")
    for i in range(N + 1):
        b.body(f"crank{i}", mass=1.0, inertia=1.0 / 12.0, points={f"B{i}": (0.5, 0.0)})
    for i in range(1, N + 1):
        b.body(f"coupler{i}", mass=1.0, inertia=1.0 / 12.0)
    for i in range(N + 1):
        b.revolute(f"A{i}", ("ground", (float(i), 0.0)), (f"crank{i}", (-0.5, 0.0)))
    for i in range(1, N + 1):
        b.revolute(f"B{i - 1}r", f"B{i - 1}", (f"coupler{i}", (-0.5, 0.0)))
        b.revolute(f"B{i}l", (f"coupler{i}", (0.5, 0.0)), f"B{i}")
    b.output("B0")
    model = b.build()
    q0, qd0 = _n_four_bar_q0(N)
    state = model.state(q0, qd0)
    horizon = (10.0 if N == 2 else 20.0) if t_final is None else float(t_final)
    return Mechanism(
        model=model,
        state=state,
        t_final=horizon,
        description=f"IFToMM A02 N four-bar mechanism, N = {N} ({2 * N + 1} links), singular when horizontal",
        reference=IFTOMM_REF + ", problem A02",
    )


def n_four_bar_reference(
    t: ArrayLike, *, N: int = 2, g: float = 9.81, rtol: float = 1e-12, atol: float = 1e-12
) -> dict[str, np.ndarray]:
    """Exact 1-DOF reduction of A02 along the parallelogram mode.

    ``I θ̈ = −g c cos θ`` with ``I = (N+1)/3 + N``, ``c = (N+1)/2 + N``, ``θ(0) = π/2``,
    ``θ̇(0) = −1`` (θ: crank angle from +x), integrated with ``solve_ivp`` (DOP853).

    Parameters
    ----------
    t : array_like, shape (k,)
        Increasing output times ≥ 0.

    Returns
    -------
    dict
        ``theta``, ``omega`` shape (k,); ``B0.position``, ``B0.velocity`` shape (k, 2);
        ``q``, ``qd`` shape (k, n) (full coordinates of the model).
    """
    ts = np.atleast_1d(np.asarray(t, dtype=float))
    inertia = (N + 1) / 3.0 + N
    c = (N + 1) / 2.0 + N

    def rhs(_t: float, y: np.ndarray) -> list[float]:
        return [y[1], -g * c * math.cos(y[0]) / inertia]

    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (0.0, max(float(ts.max()), 1e-9)), [math.pi / 2, -1.0], method="DOP853",
                    t_eval=ts, rtol=rtol, atol=atol)
    th, om = sol.y
    ct, st = np.cos(th), np.sin(th)
    n = 3 * (2 * N + 1)
    q = np.zeros((ts.size, n))
    qd = np.zeros((ts.size, n))
    for i in range(N + 1):
        q[:, 3 * i : 3 * i + 3] = np.stack([i + 0.5 * ct, 0.5 * st, th], axis=1)
        qd[:, 3 * i : 3 * i + 3] = np.stack([-0.5 * st * om, 0.5 * ct * om, om], axis=1)
    for i in range(1, N + 1):
        k = 3 * (N + i)
        q[:, k : k + 3] = np.stack([i - 0.5 + ct, st, np.zeros_like(th)], axis=1)
        qd[:, k : k + 3] = np.stack([-st * om, ct * om, np.zeros_like(th)], axis=1)
    return {
        "theta": th,
        "omega": om,
        "B0.position": np.stack([ct, st], axis=1),
        "B0.velocity": np.stack([-st * om, ct * om], axis=1),
        "q": q,
        "qd": qd,
    }

