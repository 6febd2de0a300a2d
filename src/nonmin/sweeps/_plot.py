"""A per-run metric of a sweep over its swept keys (``nonmin plot SWEEP.zarr``)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["PER_RUN_METRICS", "plot_sweep", "swept_keys"]

#: Per-run variables of a sweep that :func:`plot_sweep` draws by name.
PER_RUN_METRICS = ("energy_drift", "closure", "n_steps", "events", "wall_time", "failed")


def swept_keys(ds: Any) -> list[str]:
    """The sweep's keys with one number per run, in axis order."""
    try:
        spec = json.loads(ds.attrs["nonmin_sweep"]) if isinstance(ds.attrs.get("nonmin_sweep"), str) \
            else ds.attrs["nonmin_sweep"].get("spec", ds.attrs["nonmin_sweep"])  # fmt: skip
        keys = [a["key"] for a in spec.get("axes", [])]
    except (KeyError, TypeError, ValueError, AttributeError):
        keys = []
    return [k for k in keys if k in ds.variables and ds[k].dims == ("run",) and ds[k].dtype.kind == "f"]


def plot_sweep(ds: Any, metric: str | Any = "energy_drift", keys: list[str] | None = None, *,
               log: bool | None = None, title: str | None = None) -> Any:  # fmt: skip
    """Draw a per-run metric over one or two swept keys; returns the Matplotlib figure.

    Parameters
    ----------
    ds : xarray.Dataset or path
        A sweep (:func:`~nonmin.sweeps.sweep`'s ``.dataset`` or a store).
    metric : str or array of shape (run,)
        A per-run variable (:data:`PER_RUN_METRICS`; ``"failed"`` is 1 for failed runs) or
        values computed by the caller.
    keys : list of str, optional
        One or two swept keys (default: the first two with numeric values). On a full grid of
        two keys the metric is drawn as an image, else as coloured points.
    log : bool, optional
        Logarithmic colour/value scale (default: for energy_drift and closure).
    """
    from ..viz._mpl import pyplot

    if not hasattr(ds, "variables"):
        from ._run import open_sweep

        ds = open_sweep(ds)
    runs = int(ds.sizes["run"])
    if isinstance(metric, str):
        if metric == "failed":
            vals = np.array([str(x) == "failed" for x in ds["status"].values], dtype=float)
        elif metric in ds.variables and ds[metric].dims == ("run",):
            if ds[metric].dtype.kind not in "fiub":
                raise InputError(f"metric {metric!r}: its values are {ds[metric].dtype} per run, not a "
                                 f"number; plot one of {[m for m in PER_RUN_METRICS if m in ds.variables or m == 'failed']} "
                                 "('failed' marks the runs whose status is failed)")  # fmt: skip
            vals = np.asarray(ds[metric].values, dtype=float)
        else:
            raise InputError(f"metric {metric!r}: not a per-run variable of the sweep; known: "
                             f"{[m for m in PER_RUN_METRICS if m in ds.variables or m == 'failed']}")  # fmt: skip
        label = metric
    else:
        vals = np.asarray(metric, dtype=float)
        if vals.shape != (runs,):
            raise InputError(f"metric: expected {runs} values (one per run), got shape {vals.shape}")
        label = "metric"
    avail = swept_keys(ds)
    keys = avail[:2] if keys is None else list(keys)
    for k in keys:
        if k not in ds.variables or ds[k].dims != ("run",) or ds[k].dtype.kind not in "fiub":
            raise InputError(f"key {k!r}: not a swept key with one number per run; known: {avail}")
    if not keys or len(keys) > 2:
        raise InputError(f"plot_sweep needs one or two swept keys, got {keys} (available: {avail})")
    if log is None:
        log = isinstance(metric, str) and metric in ("energy_drift", "closure")
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    shown = np.where(vals > 0, vals, np.nan) if log else vals
    if len(keys) == 1:
        x = np.asarray(ds[keys[0]].values, dtype=float)
        order = np.argsort(x, kind="stable")
        ax.plot(x[order], shown[order], "o-", ms=3)
        ax.set_xlabel(keys[0])
        ax.set_ylabel(label)
        if log:
            ax.set_yscale("log")
    else:
        from matplotlib.colors import LogNorm

        x = np.asarray(ds[keys[0]].values, dtype=float)
        y = np.asarray(ds[keys[1]].values, dtype=float)
        ux, uy = np.unique(x), np.unique(y)
        norm = LogNorm() if log and np.any(shown > 0) else None
        if ux.size * uy.size == runs and runs > 1:
            img = np.full((uy.size, ux.size), np.nan)
            img[np.searchsorted(uy, y), np.searchsorted(ux, x)] = shown
            m = ax.pcolormesh(ux, uy, img, shading="nearest", norm=norm)
        else:
            m = ax.scatter(x, y, c=shown, s=12, norm=norm)
        fig.colorbar(m, ax=ax, label=label)
        ax.set_xlabel(keys[0])
        ax.set_ylabel(keys[1])
    ok = sum(str(x) == "success" for x in ds["status"].values)
    ax.set_title(title or f"{label} over {runs} runs ({ok} succeeded)")
    fig.tight_layout()
    return fig
