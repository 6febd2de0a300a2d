"""Trajectories as tables that other tools load in one line: CSV, Parquet, xarray/NetCDF.

Every export has the same columns (:func:`columns`), each with its unit:

* CSV (:func:`to_csv`): one plain header row, then the numbers (``pandas.read_csv(path)``,
  ``numpy.loadtxt(path, delimiter=",", skiprows=1)``); the metadata and the unit of every
  column go to a sidecar ``<file>.json`` (``{"columns": {name: unit}, "metadata": {...}}``).
* Parquet (:func:`to_parquet`, extra ``export``: pyarrow): units in each field's metadata
  (``b"unit"``), the trajectory's metadata JSON in the schema metadata (``b"nonmin"``).
* xarray (:func:`to_xarray`, :func:`to_netcdf`, extra ``export``): a ``Dataset`` over the
  dimensions ``t``, ``coordinate``, ``constraint``, ``actuator`` with ``units`` attributes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ._files import as_path, atomic_path, atomic_write
from .errors import missing_dependency

__all__ = ["columns", "coordinate_units", "to_csv", "to_netcdf", "to_parquet", "to_xarray"]

_LENGTH = ("x", "y", "z")
_ANGLE = ("theta", "phi", "psi", "angle")
_UNITLESS = ("qx", "qy", "qz", "qw", "e0", "e1", "e2", "e3")


def coordinate_units(model: Any | None, names: Sequence[str]) -> tuple[str, ...]:
    """The unit of each coordinate: ``"m"``, ``"rad"`` or ``"1"`` (quaternion components).

    Planar and spatial models name their coordinates ``body.x``/``.y``/``.z`` (m),
    ``body.theta`` (rad) and ``body.e0..e3`` (quaternion, 1); robots name 1-dof joints by the
    joint (revolute: rad, prismatic: m; read from the model when given) and free-flyer and
    spherical parts ``.x``..``.qw``. Names not recognized give ``"?"``.
    """
    joint_kind: dict[str, str] = {}
    pm = getattr(model, "_pm", None)
    if pm is not None:
        for jid in range(1, pm.njoints):
            short = pm.joints[jid].shortname().removeprefix("JointModel")
            # R, RX/RY/RZ, RevoluteUnaligned, RUB*: revolute; P, PX/PY/PZ, PrismaticUnaligned
            joint_kind[pm.names[jid]] = (
                "rad" if short.startswith("R") else "m" if short.startswith("P") and not
                short.startswith("Planar") else "?"
            )
    out = []
    for name in names:
        if name in joint_kind:
            out.append(joint_kind[name])
            continue
        tail = name.rsplit(".", 1)[-1]
        out.append(
            "m" if tail in _LENGTH else "rad" if tail in _ANGLE else "1" if tail in _UNITLESS else "?"
        )
    return tuple(out)


def _rate(unit: str) -> str:
    return "?" if unit == "?" else f"{unit}/s"


def _accel(unit: str) -> str:
    return "?" if unit == "?" else f"{unit}/s^2"


def _force(unit: str) -> str:
    return {"m": "N", "rad": "N*m", "1": "J"}.get(unit, "?")


def columns(traj: Any, model: Any | None = None) -> dict[str, tuple[np.ndarray, str]]:
    """The flat columns of a trajectory, in order: name → (values (T,), unit).

    ``t``; ``q_<c>``, ``qd_<c>``, ``qdd_<c>``, ``fc_<c>`` per coordinate c; ``u_<a>`` per
    actuator; ``rank``, ``cond``, ``mu``, ``energy``, ``phi_norm``,
    ``velocity_residual_norm``, ``friction_work``, ``impact_loss``, ``work`` (the energy
    balance's recorded terms, J; zeros for a trajectory without them, ``work`` NaN: not
    recorded); ``active_<k>`` (0/1) per constraint.
    """
    names = tuple(traj.coordinate_names)
    units = coordinate_units(model, names)
    cols: dict[str, tuple[np.ndarray, str]] = {"t": (np.asarray(traj.t, dtype=float), "s")}
    for prefix, arr, fn in (("q", traj.q, str), ("qd", traj.qd, _rate), ("qdd", traj.qdd, _accel),
                            ("fc", traj.f_c, _force)):
        a = np.asarray(arr, dtype=float).reshape(len(traj), len(names))
        for j, (c, u) in enumerate(zip(names, units, strict=True)):
            cols[f"{prefix}_{c}"] = (a[:, j], fn(u))
    u_arr = np.asarray(traj.u, dtype=float).reshape(len(traj), -1)
    for j, a_name in enumerate(traj.actuator_names):
        cols[f"u_{a_name}"] = (u_arr[:, j], "N or N*m")
    for key, unit in (("rank", "1"), ("cond", "1"), ("mu", "kg or kg*m^2"), ("energy", "J"),
                      ("phi_norm", "m, rad"), ("velocity_residual_norm", "m/s, rad/s")):
        cols[key] = (np.asarray(getattr(traj, key), dtype=float), unit)
    for key in _BALANCE:
        cols[key] = (_balance(traj, key), "J")
    mask = np.asarray(traj.active_mask, dtype=float).reshape(len(traj), -1)
    for j, c_name in enumerate(traj.constraint_names):
        cols[f"active_{c_name}"] = (mask[:, j], "1")
    return cols


#: The energy bookkeeping a trajectory records (nonmin.sim.Trajectory: friction work, impact loss).
_BALANCE = ("friction_work", "impact_loss", "work")


def _balance(traj: Any, key: str) -> np.ndarray:
    """A recorded energy array (T,) of the trajectory, zeros when it has none (``work``: NaN,
    "not recorded")."""
    a = getattr(traj, key, None)
    if a is None or np.shape(a) != (len(traj),):
        return np.full(len(traj), np.nan) if key == "work" else np.zeros(len(traj))
    return np.asarray(a, dtype=float)


def _metadata(traj: Any) -> dict[str, Any]:
    meta: dict[str, Any] = json.loads(traj._metadata_json())
    return meta


def to_csv(traj: Any, path: str | os.PathLike[str], model: Any | None = None) -> Path:
    """Write a plain CSV (one header row of column names) and its sidecar ``<path>.json``.

    ``pandas.read_csv(path)`` gives one column per name of :func:`columns`;
    ``json.load(open(str(path) + ".json"))`` gives ``{"columns": {name: unit}, "metadata":
    {...}}`` (the metadata of :meth:`~nonmin.sim.Trajectory.save`). Both files are written
    durably (temporary + fsync + rename).

    Returns
    -------
    Path
        The CSV file.
    """
    p = as_path(path, "to_csv: path")
    cols = columns(traj, model)
    data = np.column_stack([v for v, _ in cols.values()]) if len(traj) else np.zeros((0, len(cols)))
    header = ",".join(_csv_name(c) for c in cols)
    with atomic_write(p, "wb") as fh:
        np.savetxt(fh, data, delimiter=",", header=header, comments="", fmt="%.17g")
    side = {"format": "nonmin.Trajectory.csv", "file": p.name,
            "columns": {c: u for c, (_, u) in cols.items()}, "metadata": _metadata(traj)}
    with atomic_write(sidecar(p), "w", encoding="utf-8") as fh:
        json.dump(side, fh, indent=1)
    return p


def sidecar(path: str | os.PathLike[str]) -> Path:
    """The metadata file of a CSV export: ``<path>.json``."""
    p = Path(path)
    return p.with_name(p.name + ".json")


def _csv_name(name: str) -> str:
    return f'"{name}"' if any(ch in name for ch in ',"\n') else name


def to_parquet(traj: Any, path: str | os.PathLike[str], model: Any | None = None) -> Path:
    """Write a Parquet file (extra ``export``: pyarrow) with units and metadata.

    Each field's metadata holds ``{"unit": ...}``; the schema metadata ``"nonmin"`` holds the
    trajectory's metadata JSON. ``pandas.read_parquet(path)`` loads the table.
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise missing_dependency("pyarrow", "export", "Writing Parquet files") from None
    p = as_path(path, "to_parquet: path")
    cols = columns(traj, model)
    fields = [pa.field(c, pa.float64(), metadata={"unit": u}) for c, (_, u) in cols.items()]
    schema = pa.schema(fields, metadata={"nonmin": json.dumps(_metadata(traj))})
    table = pa.Table.from_arrays([pa.array(v) for v, _ in cols.values()], schema=schema)
    with atomic_path(p) as tmp:
        pq.write_table(table, tmp)
    return p


def to_xarray(traj: Any, model: Any | None = None) -> Any:
    """An ``xarray.Dataset`` of the trajectory (extra ``export``), with ``units`` attributes.

    Variables ``q``, ``qd``, ``qdd``, ``f_c`` (t, coordinate), ``u`` (t, actuator),
    ``active`` (t, constraint), and ``rank``, ``cond``, ``mu``, ``energy``, ``phi_norm``,
    ``velocity_residual_norm``, ``friction_work``, ``impact_loss``, ``work`` (t); ``coordinate_unit``
    (coordinate); the metadata JSON in
    ``attrs["nonmin"]``.
    """
    try:
        import xarray as xr
    except ImportError:
        raise missing_dependency("xarray", "export", "Building xarray datasets") from None
    names = list(traj.coordinate_names)
    units = coordinate_units(model, names)
    n, T = len(names), len(traj)
    vars_: dict[str, Any] = {}
    for key, arr, unit in (("q", traj.q, "m, rad (see coordinate_unit)"),
                           ("qd", traj.qd, "m/s, rad/s (see coordinate_unit)"),
                           ("qdd", traj.qdd, "m/s^2, rad/s^2 (see coordinate_unit)"),
                           ("f_c", traj.f_c, "N, N*m (conjugate to the coordinates)")):
        vars_[key] = (("t", "coordinate"), np.asarray(arr, dtype=float).reshape(T, n), {"units": unit})
    vars_["u"] = (("t", "actuator"), np.asarray(traj.u, dtype=float).reshape(T, -1), {"units": "N or N*m"})
    vars_["active"] = (("t", "constraint"), np.asarray(traj.active_mask, dtype=np.int8).reshape(T, -1),
                       {"units": "1", "description": "1 if the constraint is active"})
    for key, unit in (("rank", "1"), ("cond", "1"), ("mu", "kg or kg*m^2"), ("energy", "J"),
                      ("phi_norm", "m, rad"), ("velocity_residual_norm", "m/s, rad/s")):
        vars_[key] = (("t",), np.asarray(getattr(traj, key), dtype=float), {"units": unit})
    for key in _BALANCE:
        vars_[key] = (("t",), _balance(traj, key), {"units": "J"})
    vars_["coordinate_unit"] = (("coordinate",), np.array(units, dtype=object).astype(str), {})
    ds = xr.Dataset(
        vars_,
        coords={
            "t": ("t", np.asarray(traj.t, dtype=float), {"units": "s"}),
            "coordinate": names,
            "constraint": list(traj.constraint_names),
            "actuator": list(traj.actuator_names),
        },
        attrs={"nonmin": json.dumps(_metadata(traj)), "title": str(traj.metadata.get("scenario_name", ""))},
    )
    return ds


def to_netcdf(traj: Any, path: str | os.PathLike[str], model: Any | None = None) -> Path:
    """Write :func:`to_xarray`'s dataset to a NetCDF file (extra ``export``)."""
    p = as_path(path, "to_netcdf: path")
    ds = to_xarray(traj, model)
    with atomic_path(p) as tmp:
        ds.to_netcdf(tmp)
    return p
