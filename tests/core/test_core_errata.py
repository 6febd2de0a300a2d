"""The paper's printed eqs. (ddq_sim) and (fc_fp) are wrong; nonmin uses the corrected forms.

ERRATA 1: printed ``qdd = M̄⁻¹P(f + h) − SᵀΩqd``; correct ``qdd = M̄⁻¹P(f + h) + SᵀΩqd``.
ERRATA 2: printed ``f_⊥ + f_c = −S(f_∥ + h) + QMΩqd``; correct ``… + SMΩqd``.

The printed forms are implemented here from the paper's text and shown to violate
``A qdd + Ȧ qd = 0`` / disagree with the KKT solution on a coupled-M example, while nonmin's
functions agree with the corrected forms and with KKT. If nonmin used the printed sign or the
printed (fc_fp), these tests would fail.
"""

from __future__ import annotations

import numpy as np
import pytest
from core_testlib import REF_RTOL, kkt_solve, random_spd, rel

from nonmin.core import constraint_force, forward_dynamics, solve_dynamics

#: A printed formula is "wrong" when it misses the reference by more than this (relative).
WRONG_RTOL = 1e-3


def _example(seed: int, coupled: bool = True):
    """n = 5, m = 2, coupled SPD M, random A, Ȧ, admissible qd ∈ N(A), loads."""
    rng = np.random.default_rng(seed)
    n, m = 5, 2
    A = rng.standard_normal((m, n))
    Adot = rng.standard_normal((m, n))
    Ap = np.linalg.pinv(A)
    P = np.eye(n) - Ap @ A
    Q = np.eye(n) - P
    M = random_spd(rng, n, 50.0)
    if not coupled:  # remove the N–N⊥ coupling: PMQ = 0
        M = P @ M @ P + Q @ M @ Q
    qd = P @ rng.standard_normal(n)
    h = rng.standard_normal(n) * 3
    f = rng.standard_normal(n)
    Lam = -Ap @ Adot
    Om = Lam - Lam.T
    mu = np.trace(P @ M @ P) / (n - m)
    Mbar = P @ M @ P + mu * Q
    Mbar_inv = np.linalg.inv(Mbar)
    S = np.eye(n) - M @ Mbar_inv @ P
    return dict(A=A, Adot=Adot, P=P, Q=Q, M=M, qd=qd, h=h, f=f, Om=Om, Lam=Lam, mu=mu,
                Mbar_inv=Mbar_inv, S=S)


def _qdd(ex, sign):
    """Eq. (ddq_sim) with the Ω term's sign: −1 printed, +1 corrected (ERRATA 1)."""
    return ex["Mbar_inv"] @ ex["P"] @ (ex["f"] + ex["h"]) + sign * ex["S"].T @ ex["Om"] @ ex["qd"]


@pytest.mark.parametrize("seed", range(5))
def test_printed_ddq_sim_sign_violates_constraint_and_nonmin_does_not(seed):
    ex = _example(seed)
    A, Adot, qd = ex["A"], ex["Adot"], ex["qd"]
    gamma = Adot @ qd
    printed, corrected = _qdd(ex, -1.0), _qdd(ex, +1.0)
    qdd_kkt, _ = kkt_solve(ex["M"], A, ex["h"] + ex["f"], gamma)
    qdd = forward_dynamics(ex["M"], ex["h"], A, gamma, ex["f"])
    # nonmin == corrected == KKT, and satisfies A qdd + Ȧqd = 0
    assert rel(qdd, corrected) <= REF_RTOL
    assert rel(qdd, qdd_kkt) <= REF_RTOL
    assert np.linalg.norm(A @ qdd + gamma) <= REF_RTOL * np.linalg.norm(gamma)
    # printed sign: Q qdd = −Λqd instead of +Λqd, so A qdd + Ȧqd = 2Ȧqd ≠ 0
    assert np.linalg.norm(A @ printed + gamma) >= 1.0 * np.linalg.norm(gamma)
    assert rel(ex["Q"] @ printed, -ex["Lam"] @ qd) <= REF_RTOL * 1e2
    assert rel(printed, qdd_kkt) >= WRONG_RTOL
    # the first printed line has the same sign error (it equals the second printed line):
    # M̄⁻¹P(f + h + MΩqd) − μM̄⁻¹Ωqd
    first_line = ex["Mbar_inv"] @ (
        ex["P"] @ (ex["f"] + ex["h"] + ex["M"] @ ex["Om"] @ qd) - ex["mu"] * ex["Om"] @ qd
    )
    assert rel(first_line, printed) <= REF_RTOL * 1e2
    # the corrected first line M̄⁻¹[P(f + h − MΩqd) + μΩqd] is nonmin's result
    fixed_first = ex["Mbar_inv"] @ (
        ex["P"] @ (ex["f"] + ex["h"] - ex["M"] @ ex["Om"] @ qd) + ex["mu"] * ex["Om"] @ qd
    )
    assert rel(qdd, fixed_first) <= REF_RTOL


@pytest.mark.parametrize("seed", range(5))
def test_printed_fc_fp_disagrees_with_kkt_when_M_couples(seed):
    ex = _example(seed)
    A, Adot, qd, S, M, P, Q = (ex[k] for k in ("A", "Adot", "qd", "S", "M", "P", "Q"))
    gamma = Adot @ qd
    f, h, Om = ex["f"], ex["h"], ex["Om"]
    _, lam = kkt_solve(M, A, h + f, gamma)
    ref = Q @ f + A.T @ lam  # f_⊥ + f_c from KKT
    printed = -S @ (P @ f + h) + Q @ M @ Om @ qd
    corrected = -S @ (P @ f + h) + S @ M @ Om @ qd
    assert np.abs(P @ M @ Q).max() > 0.1  # the example really couples N and N⊥
    assert rel(corrected, ref) <= REF_RTOL * 10
    assert rel(printed, ref) >= WRONG_RTOL
    fc = constraint_force(M, h, A, gamma, f)
    assert rel(Q @ f + fc, corrected) <= REF_RTOL * 10
    assert rel(fc, A.T @ lam, np.linalg.norm(h + f)) <= REF_RTOL
    # (fc_R) as printed is right: f_c = −S(f + h − MΩqd)
    assert rel(fc, -S @ (f + h - M @ Om @ qd), np.linalg.norm(h + f)) <= REF_RTOL * 10


def test_printed_fc_fp_is_right_only_without_coupling():
    """With PMQ = 0 the printed (fc_fp) coincides with the corrected form (SMΩqd = QMΩqd)."""
    ex = _example(11, coupled=False)
    S, M, P, Q, Om, qd = (ex[k] for k in ("S", "M", "P", "Q", "Om", "qd"))
    assert np.abs(P @ M @ Q).max() <= 1e-12 * np.abs(M).max()
    assert rel(S @ M @ Om @ qd, Q @ M @ Om @ qd) <= REF_RTOL * 10
    sol = solve_dynamics(M, ex["h"], ex["A"], ex["Adot"] @ qd, ex["f"])
    printed = -S @ (P @ ex["f"] + ex["h"]) + Q @ M @ Om @ qd
    assert rel(Q @ ex["f"] + sol.f_c, printed) <= REF_RTOL * 10
