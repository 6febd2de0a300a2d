"""Reference solutions and scores used by the validation suite.

* tabulated exact solutions shipped in ``nonmin/data/validation`` (A01, A02 N = 2, A03),
* the exact 1-DOF reduction of the A02 N four-bar in its parallelogram mode,
* the Test Set for IVP Solvers' significant-digit score.
"""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from ..errors import InputError, ShapeError

__all__ = [
    "A02_N2_B0_AT_10S",
    "A02_N2_VB0_AT_10S",
    "a02_parallelogram_reference",
    "load_a01_exact",
    "load_a02_n2_exact",
    "load_a03_reference",
    "significant_digits",
]

FloatArray = NDArray[np.float64]

#: A02, N = 2: B0 at t = 10 s in the parallelogram mode (benchmark statement).
A02_N2_B0_AT_10S = (0.3284581115, 0.9445185382)
#: A02, N = 2: velocity of B0 at t = 10 s.
A02_N2_VB0_AT_10S = (1.4230514702, -0.4948688455)



def _load_csv(name: str) -> FloatArray:
    ref = resources.files("nonmin").joinpath("data", "validation", name)
    with resources.as_file(ref) as p:
        return np.loadtxt(p, delimiter=",", comments="#", dtype=np.float64)


def load_a01_exact(horizon: float = 2000.0) -> FloatArray:
    """Exact A01 pendulum solution (Jacobi elliptic functions), start at (+1, 0).

    Parameters
    ----------
    horizon : {10.0, 2000.0}
        10 s file (0.01 s steps) or 2000 s file (0.5 s steps).

    Returns
    -------
    ndarray, shape (N, 5)
        Columns t, x, y, vx, vy of point P1.
    """
    if horizon == 10.0:
        return _load_csv("A01_pendulum_exact_0-10s.csv")
    if horizon == 2000.0:
        return _load_csv("A01_pendulum_exact_0-2000s.csv")
    raise InputError(f"horizon must be 10.0 or 2000.0 (the tabulated files), got {horizon!r}")


def load_a02_n2_exact() -> FloatArray:
    """Exact A02 (N = 2) motion of B0, t = 0..20 s every 0.01 s: columns t, x, y, vx, vy."""
    return _load_csv("A02_NfourBar_N2_exact_0-20s.csv")


def load_a03_reference() -> tuple[tuple[str, ...], FloatArray]:
    """Test Set reference y(0.03) of Andrews' mechanism: 27 names and values."""
    ref = resources.files("nonmin").joinpath(
        "data", "validation", "A03_andrews_testset_reference_t0.03.csv"
    )
    names: list[str] = []
    values: list[float] = []
    with resources.as_file(ref) as p:
        for line in p.read_text(encoding="utf-8").splitlines():
            if not line or line.startswith("#") or line.startswith("index"):
                continue
            _, name, value = line.split(",")
            names.append(name)
            values.append(float(value))
    return tuple(names), np.asarray(values)


def a02_parallelogram_reference(
    n: int, t: FloatArray, *, g: float = 9.81, rtol: float = 1e-13, atol: float = 1e-13
) -> tuple[FloatArray, FloatArray]:
    """Crank angle of the A02 N four-bar in its parallelogram mode (exact 1-DOF reduction).

    ``I θ̈ = −g c cos θ`` with ``I = (N+1)/3 + N``, ``c = (N+1)/2 + N``, ``θ(0) = π/2``,
    ``θ̇(0) = −1 rad/s`` (unit links and masses), integrated with DOP853.

    Parameters
    ----------
    n : int
        Number of four-bar loops (N ≥ 1).
    t : array_like, shape (T,)
        Increasing sample times starting at 0.

    Returns
    -------
    theta, theta_dot : ndarray, shape (T,)
    """
    if n < 1:
        raise InputError(f"n must be ≥ 1, got {n}")
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or t.size < 1:
        raise ShapeError(f"t must have shape (T,) with T ≥ 1, got {t.shape}")
    inertia = (n + 1) / 3.0 + n
    c = (n + 1) / 2.0 + n

    def rhs(_t: float, y: FloatArray) -> list[float]:
        return [y[1], -g * c * math.cos(y[0]) / inertia]

    sol = solve_ivp(
        rhs,
        (0.0, float(t[-1])),
        [math.pi / 2.0, -1.0],
        method="DOP853",
        rtol=rtol,
        atol=atol,
        t_eval=t,
    )
    if not sol.success:  # pragma: no cover - smooth ODE
        raise RuntimeError(f"A02 reference integration failed: {sol.message}")
    return sol.y[0], sol.y[1]


def significant_digits(
    y: FloatArray, ref: FloatArray, *, rtol: float, atol: float
) -> tuple[float, FloatArray]:
    """The Test Set for IVP Solvers' significant-digit score.

    ``scd = min_i −log10(|y_i − ref_i| / (atol/rtol + |ref_i|))`` (Mazzia & Magherini).

    Parameters
    ----------
    y, ref : array_like, shape (k,)
        Computed and reference values.
    rtol, atol : float
        The tolerances the solver ran with (they set the absolute floor ``atol/rtol``).

    Returns
    -------
    score : float
        The minimum over components (``inf`` if every component is exact).
    per_component : ndarray, shape (k,)
    """
    y = np.asarray(y, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if y.shape != ref.shape:
        raise ShapeError(f"y and ref must have the same shape, got {y.shape} and {ref.shape}")
    err = np.abs(y - ref) / (atol / rtol + np.abs(ref))
    with np.errstate(divide="ignore"):
        per = -np.log10(err)
    return float(np.min(per)), per
