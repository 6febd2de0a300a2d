"""The passage indicator's smallest eigenvalue (``sym_min_eigenvalue``, 91c3849) against LAPACK.

The engine's singular-passage indicator σ = √λ_min(G) of the Gram matrix of the active rows
uses its own tridiagonalization and Newton/bisection for up to 32 live rows; the Python driver
uses ``numpy.linalg.eigvalsh``. Both are backward stable, so they must agree to a small
multiple of k·eps·‖G‖ on any symmetric positive semidefinite matrix: random Gram matrices,
near-singular ones (a passage), exactly rank-deficient ones, diagonal and 1 × 1 / 2 × 2 cases.
"""

from __future__ import annotations

import numpy as np
import pytest

from nonmin import _engine
from nonmin.errors import ShapeError

EPS = np.finfo(float).eps


def _agree(G: np.ndarray) -> None:
    k = G.shape[0]
    ref = float(np.linalg.eigvalsh(G)[0])
    got = _engine.sym_min_eigenvalue(np.ascontiguousarray(G))
    # (plus a few times the smallest normal number: the Sturm pivots' guard, LAPACK's pivmin)
    tol = 2.0 * k * EPS * float(np.linalg.norm(G, 2)) + 4.0 * np.finfo(float).tiny
    assert abs(got - ref) <= tol, f"k = {k}: {got!r} against eigvalsh {ref!r} (tol {tol:.3g})"


@pytest.mark.parametrize("k", [1, 2, 3, 5, 8, 14, 21, 32])
def test_random_gram_matrices(k: int) -> None:
    rng = np.random.default_rng(k)
    for _ in range(60):
        n = k + int(rng.integers(0, 6))
        D = rng.standard_normal((k, n)) * 10.0 ** rng.uniform(-3, 3, size=(k, 1))
        _agree(D @ D.T)


@pytest.mark.parametrize("k", [2, 4, 8, 16, 32])
def test_near_singular_and_rank_deficient(k: int) -> None:
    rng = np.random.default_rng(100 + k)
    for scale in (1e-2, 1e-5, 1e-8, 1e-12, 0.0):
        for _ in range(15):
            D = rng.standard_normal((k, k + 2))
            D[-1] = D[0] + scale * rng.standard_normal(k + 2)  # two rows nearly equal: a passage
            _agree(D @ D.T)
    _agree(np.diag(np.arange(k, 0, -1, dtype=float)))
    _agree(np.zeros((k, k)))


def test_reads_the_lower_triangle_and_checks_its_shape() -> None:
    G = np.array([[4.0, 99.0], [1.0, 3.0]])  # the upper entry is not read
    lam = _engine.sym_min_eigenvalue(G)
    assert abs(lam - np.linalg.eigvalsh(np.array([[4.0, 1.0], [1.0, 3.0]]))[0]) <= 8 * EPS * 5
    with pytest.raises(ShapeError, match="square"):
        _engine.sym_min_eigenvalue(np.zeros((2, 3)))
