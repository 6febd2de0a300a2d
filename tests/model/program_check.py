"""Shared check of a compiled engine Program against its model's Python evaluation.

Used by the planar, SymPy-tape and spatial program tests: every term (M, h, f_passive, B, the
active rows of A, γ, φ and the velocity residual, both energies) to ``rel_tol`` relative to
``max(1, |reference|)``.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def close(got: Any, ref: Any, what: str, rel_tol: float) -> None:
    """Assert ``|got − ref| ≤ rel_tol · max(1, |ref|)`` (max norms) and equal shapes."""
    got = np.asarray(got, dtype=float)
    ref = np.asarray(ref, dtype=float)
    assert got.shape == ref.shape, f"{what}: shape {got.shape} != {ref.shape}"
    if ref.size:
        scale = max(1.0, float(np.max(np.abs(ref))))
        err = float(np.max(np.abs(got - ref)))
        assert err <= rel_tol * scale, f"{what}: max |engine − reference| = {err:.3g} (scale {scale:.3g})"


def active_rows(prog: Any, mask: np.ndarray) -> np.ndarray:
    """Row indices of the active constraints in the program's stacked arrays."""
    idx = [np.arange(r, r + d) for (_, _, r, d), on in zip(prog.constraints, mask, strict=True) if on]
    return np.concatenate(idx) if idx else np.zeros(0, dtype=int)


def check_terms(model: Any, t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str], rel_tol: float) -> None:
    """The model's engine program evaluated at (t, q, qd, active) against ``model.evaluate``."""
    prog = model.engine_program()
    assert prog is not None
    mask = model.active_mask(active)
    T = prog.evaluate(t, q, qd, mask)
    ref = model.evaluate(t, q, qd, active)
    for name in ("M", "h", "f_passive", "B"):
        close(getattr(T, name), getattr(ref, name), name, rel_tol)
    rows = active_rows(prog, mask)
    for name in ("A", "gamma", "phi", "velocity"):
        close(getattr(T, name)[rows], getattr(ref.constraints, name), f"{name} {sorted(active)}", rel_tol)
    close(np.array(T.kinetic), np.array(model.kinetic_energy(q, qd)), "kinetic energy", rel_tol)
    close(np.array(T.potential), np.array(model.potential_energy(q)), "potential energy", rel_tol)
