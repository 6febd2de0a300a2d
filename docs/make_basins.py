"""Basins of the crossed four-bar's two assembly branches over initial velocities
(docs/sweeps.md, picture docs/img/basins_crossed_four_bar.png).

The crossed four-bar (crank 1 m, coupler 2 m, rocker 1 m, ground 2 m) is started at its change
point: crank angle θ = 0 and rocker angle ψ = 0, every bar on the ground line. There the
closure's Jacobian loses rank and the velocities allowed are two-dimensional: any crank rate
θ̇0 with any rocker rate ψ̇0. Each run goes on for ``--t`` seconds (RK4, dt = 1e-3, mass-metric
projection) and is classified by the assembly branch it is on at the end: parallelogram (ψ = θ)
or anti-parallelogram (ψ = arg((e^{iθ} − 2)/(1 − 2e^{iθ}))), whichever residual is smaller
over the last 0.2 s (at a later change point both vanish for an instant).

Usage: ``python docs/make_basins.py [--n 41] [--t 2] [--vmax 8] [--store basins.zarr]``
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from nonmin import library, sweep
from nonmin.library import Mechanism
from nonmin.sweeps import Grid

HERE = Path(__file__).resolve().parent
_BAR = library.get("crossed_four_bar")
#: The change point: crank (x, y, θ), coupler, rocker all on the ground line.
Q0 = np.array([0.5, 0.0, 0.0, 2.0, 0.0, 0.0, 2.5, 0.0, 0.0])


def change_point(crank_rate: float = 0.0, rocker_rate: float = 0.0) -> Mechanism:
    """The crossed four-bar at its change point with these crank and rocker rates (rad/s).

    At θ = ψ = 0 the centres of mass move vertically: crank ½θ̇, rocker ½ψ̇, coupler
    ½(θ̇ + ψ̇); the coupler turns at ½(ψ̇ − θ̇). Every such velocity satisfies A q̇ = 0.
    """
    wc, wr = float(crank_rate), float(rocker_rate)
    qd = np.array([0.0, 0.5 * wc, wc, 0.0, 0.5 * (wc + wr), 0.5 * (wr - wc), 0.0, 0.5 * wr, wr])
    return Mechanism(model=_BAR.model, state=_BAR.model.state(Q0, qd), t_final=2.0,
                     description="crossed four-bar at its change point", reference="")  # fmt: skip


def branch_residuals(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance (rad) of each sample from the parallelogram and the anti-parallelogram branch."""
    th, psi = q[..., 2], q[..., 8]

    def wrap(a: np.ndarray) -> np.ndarray:
        return np.abs((a + math.pi) % (2 * math.pi) - math.pi)

    z = np.exp(1j * th)
    return wrap(psi - th), wrap(psi - np.angle((z - 2.0) / (1.0 - 2.0 * z)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=41, help="grid points per axis")
    ap.add_argument("--t", type=float, default=2.0, help="horizon [s]")
    ap.add_argument("--vmax", type=float, default=8.0, help="largest initial rate [rad/s]")
    ap.add_argument("--store", default=None, help="Zarr store (resumable); default: in memory")
    ap.add_argument("--out", default=str(HERE / "img" / "basins_crossed_four_bar.png"))
    args = ap.parse_args()
    t_eval = np.linspace(0.0, args.t, round(args.t / 0.01) + 1)
    w0 = time.perf_counter()
    res = sweep(change_point,
                {"params.crank_rate": Grid(-args.vmax, args.vmax, args.n),
                 "params.rocker_rate": Grid(-args.vmax, args.vmax, args.n)},
                t_span=args.t, dt=1e-3, t_eval=t_eval, store=args.store, progress=True)  # fmt: skip
    wall = time.perf_counter() - w0
    ds = res.dataset
    q = np.asarray(ds["q"].values)
    para, anti = branch_residuals(q)
    tail = t_eval >= args.t - 0.2
    pm, am = para[:, tail].mean(axis=1), anti[:, tail].mean(axis=1)
    ok = np.asarray(ds["status"].values) == "success"
    code = np.where(~ok, np.nan, np.where(pm < am, 0.0, 1.0))
    wc = np.asarray(ds["params.crank_rate"].values)
    wr = np.asarray(ds["params.rocker_rate"].values)
    print(f"{res.runs} runs in {wall:.1f} s ({res.computed} computed, {res.failed} failed); "
          f"anti-parallelogram {int(np.nansum(code))}, parallelogram {int(np.sum(code == 0))}; "
          f"largest closure {float(np.nanmax(ds['closure'].values)):.1e} m")  # fmt: skip

    from matplotlib.colors import ListedColormap

    from nonmin.viz import save_figure
    from nonmin.viz._mpl import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 5.2))
    u = np.unique(wc)
    img = np.full((u.size, u.size), np.nan)
    img[np.searchsorted(u, wr), np.searchsorted(u, wc)] = code
    ax.pcolormesh(u, u, img, shading="nearest", cmap=ListedColormap(["#4477aa", "#ee6677"]), vmin=0, vmax=1)
    ax.plot(u, u, "k--", lw=0.8, label="ψ̇ = θ̇ (parallelogram tangent)")
    ax.plot(u, -3 * u, "k:", lw=0.8, label="ψ̇ = −3θ̇ (anti-parallelogram tangent)")
    ax.set_xlim(u[0], u[-1])
    ax.set_ylim(u[0], u[-1])
    ax.set_xlabel("initial crank rate θ̇0 [rad/s]")
    ax.set_ylabel("initial rocker rate ψ̇0 [rad/s]")
    ax.set_title(f"crossed four-bar from its change point: branch at t = {args.t:g} s\n"
                 "blue: parallelogram, red: anti-parallelogram", fontsize=10)  # fmt: skip
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    print(save_figure(fig, args.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
