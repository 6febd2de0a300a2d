"""Balance an inverted four-bar on a cart with an LQR designed on the tangent space.

A cart on a horizontal rail (pushed by one force) carries a four-bar linkage standing
upright: two cranks of different lengths pinned to the cart and a coupler between their tips
(15 absolute coordinates x, y, θ of cart, cranks and coupler; 13 constraint rows; 2 degrees of
freedom). ``nonmin.equilibrium`` finds the upright (unstable) rest configuration,
``nonmin.modes`` shows its divergent mode, ``nonmin.linear.LQR`` designs the regulator on the
4-state tangent-space linearization and runs as the simulation's controller; released 0.15 rad
away from upright, the linkage returns to the target and the cart to x = 0.

Run: python examples/lqr_cart_four_bar.py [--out DIR] [--quick]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _example_common import figure, parse, save

import nonmin
from nonmin.linear import LQR
from nonmin.model import assemble
from nonmin.model.planar import PlanarBuilder

#: Geometry (m): pivots on the cart at (∓BASE/2, 0), crank lengths, coupler length.
BASE, LEFT, RIGHT, COUPLER = 0.30, 0.60, 0.50, 0.25


def _bar(length: float, mass: float) -> float:
    return mass * length**2 / 12.0


def cart_four_bar() -> nonmin.model.Model:
    """The cart with its four-bar (bars uniform, COM at the middle; points at the ends)."""
    b = PlanarBuilder(
        "cart_four_bar", gravity=(0.0, -9.81), description="inverted four-bar on a cart"
    )
    b.body("cart", mass=2.0, inertia=0.05, points={"P1": (-BASE / 2, 0.0), "P2": (BASE / 2, 0.0)})
    b.body(
        "left",
        mass=0.6,
        inertia=_bar(LEFT, 0.6),
        points={"L0": (-LEFT / 2, 0.0), "L1": (LEFT / 2, 0.0)},
    )
    b.body(
        "right",
        mass=0.5,
        inertia=_bar(RIGHT, 0.5),
        points={"R0": (-RIGHT / 2, 0.0), "R1": (RIGHT / 2, 0.0)},
    )
    b.body("coupler", mass=0.3, inertia=_bar(COUPLER, 0.3),
           points={"C0": (-COUPLER / 2, 0.0), "C1": (COUPLER / 2, 0.0)})  # fmt: skip
    b.prismatic("rail", ("ground", (0.0, 0.0)), ("cart", (0.0, 0.0)), axis=(1.0, 0.0))
    b.revolute("hip_left", "P1", "L0")
    b.revolute("hip_right", "P2", "R0")
    b.revolute("knee_left", "L1", "C0")
    b.revolute("knee_right", "R1", "C1")
    b.actuator("push", "rail")
    return b.build()


def upright_guess(model: nonmin.model.Model, lean: float = 0.0) -> np.ndarray:
    """A configuration near upright (cranks near vertical), assembled onto the constraints."""
    a, c = np.pi / 2 + lean, np.pi / 2 + lean - 0.1
    pl = np.array([-BASE / 2, 0.0]) + LEFT / 2 * np.array([np.cos(a), np.sin(a)])
    pr = np.array([BASE / 2, 0.0]) + RIGHT / 2 * np.array([np.cos(c), np.sin(c)])
    tl = np.array([-BASE / 2, 0.0]) + LEFT * np.array([np.cos(a), np.sin(a)])
    tr = np.array([BASE / 2, 0.0]) + RIGHT * np.array([np.cos(c), np.sin(c)])
    mid, d = 0.5 * (tl + tr), tr - tl
    q = [0.0, 0.0, 0.0, *pl, a, *pr, c, *mid, np.arctan2(d[1], d[0])]
    return assemble(model, q, fixed=["cart.x"]).q


def main(argv: list[str] | None = None) -> None:
    args = parse("lqr_cart_four_bar", __doc__, argv)
    model = cart_four_bar()
    eq = nonmin.equilibrium(model, upright_guess(model))
    q_star = eq.q.copy()
    q_star[0::3] -= eq.q[
        0
    ]  # the whole machine may rest anywhere on the rail: put the cart at x = 0
    m = nonmin.modes(model, q_star)
    lin = nonmin.linearize(model, q_star)
    print(
        f"equilibrium in {eq.iterations} steps (residual {eq.residual:.1e}); tangent state "
        f"{lin.A.shape[0]}; open-loop eigenvalues {np.round(np.sort_complex(m.eigenvalues), 4)}"
    )
    lqr = LQR(model, q_star, weight_q=10.0, weight_qd=1.0, weight_u=0.1)
    design = lqr.design()
    print(f"closed-loop eigenvalues {np.round(np.sort_complex(design.closed_loop_eigenvalues), 3)}")
    q0 = upright_guess(model, lean=0.15)
    t1 = 1.0 if args.quick else 6.0
    traj = nonmin.simulate(model, (0.0, t1), q0, controller=lqr, method="rk4", dt=2e-3)
    err = np.abs(traj.q - q_star).max(axis=1)
    print(
        f"start max|q − q*| = {err[0]:.3f}; after {t1:g} s: {err[-1]:.2e}; max |u| = "
        f"{np.abs(traj.u).max():.2f} N; closure {np.max(traj.phi_norm):.1e}"
    )
    fig, ax = figure(2, size=(7, 5))
    ax[0].semilogy(traj.t, err)
    ax[0].set_ylabel("max |q − q*|")
    ax[1].plot(traj.t, traj.u[:, 0])
    ax[1].set_ylabel("cart force (N)")
    ax[1].set_xlabel("t (s)")
    ax[0].set_title("Inverted four-bar on a cart: LQR on the tangent space")
    save(fig, args.out, "lqr.png")


if __name__ == "__main__":
    main()
