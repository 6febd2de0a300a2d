"""The sweep's store: a Zarr group that xarray opens as a Dataset with dims (run, time,
coordinate), written block by block as the runs finish.

Why Zarr: chunked along the run axis, each block of runs (one task, one batched engine call)
writes its own chunk files and no other's, so blocks land in any order, from any worker,
without reading or rewriting what is there; xarray and Dask read it lazily; it is a folder of
plain files (no server, no lock). Chunks are aligned with the blocks: ``chunk`` runs per chunk
of every array.

Commit: a block's arrays are written first, then its commit record — entry ``b`` of the array
``commit`` (dim ``block``, one chunk per block: a JSON text with the block's runs, failures,
writer and time). Zarr writes every chunk file to a temporary file and renames it (atomic on
POSIX), so a record is there whole or not at all. A block counts as done only when its record
is; a process killed between the data and the record leaves arrays that the rerun overwrites.
A rerun of the same sweep reads the records and computes only the blocks without one.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["SweepStore", "commit_records"]

FORMAT = "nonmin.sweep"
FORMAT_VERSION = 1

#: Per-run summaries (run,) with their dtypes and fill values.
SUMMARIES: dict[str, tuple[Any, Any]] = {
    "events": ("int64", -1),
    "n_steps": ("int64", -1),
    "energy_drift": ("float64", float("nan")),
    "closure": ("float64", float("nan")),
    "wall_time": ("float64", float("nan")),
}


def commit_records(group: Any) -> list[dict[str, Any]]:
    """The commit records of a sweep's Zarr group (one per committed block; an entry that is
    empty or not a whole JSON record is not committed)."""
    out = []
    for text in (str(x) for x in np.asarray(group["commit"][:]).tolist()):
        if not text:
            continue
        try:
            out.append(json.loads(text))
        except ValueError:
            continue  # not a whole record: not committed
    return out


class SweepStore:
    """Create or reopen the Zarr store of a sweep (see the module's docstring)."""

    def __init__(self, path: str | os.PathLike[str], *, header: dict[str, Any], runs: int, chunk: int,
                 times: np.ndarray, coordinates: list[str], keys: dict[str, np.ndarray]) -> None:  # fmt: skip
        import zarr

        self.path = Path(path)
        self._arrays: dict[str, Any] = {}
        self.chunk = int(chunk)
        self.runs = int(runs)
        self.N = int(times.shape[0])
        self.n = len(coordinates)
        head: Any = {"format": FORMAT, "format_version": FORMAT_VERSION, "spec": header, "runs": self.runs,
                "chunk": self.chunk, "samples": self.N, "coordinates": coordinates}  # fmt: skip
        if (self.path / "zarr.json").exists():
            self.group: Any = zarr.open_group(str(self.path), mode="r+")
            raw: Any = self.group.attrs.get("nonmin_sweep", {})
            old: dict[str, Any] = dict(raw) if isinstance(raw, dict) else {}
            if old.get("format") != FORMAT:
                raise InputError(f"{self.path}: not a nonmin sweep store")
            if json.dumps(old.get("spec"), sort_keys=True) != json.dumps(header, sort_keys=True) or \
                    old.get("runs") != self.runs or old.get("samples") != self.N:  # fmt: skip
                raise InputError(
                    f"{self.path}: the store holds a different sweep (its base, axes, samples, seed or "
                    "sample count differ); choose another store or remove it"
                )
            self.chunk = int(old["chunk"])
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            g: Any = zarr.open_group(str(self.path), mode="w")
            g.attrs["nonmin_sweep"] = head
            c = self.chunk

            def arr(name: str, shape: tuple[int, ...], dims: list[str], dtype: Any, fill: Any,
                    chunks: tuple[int, ...] | None = None) -> Any:  # fmt: skip
                return g.create_array(name, shape=shape, chunks=chunks or (c, *shape[1:]), dtype=dtype,
                                      fill_value=fill, dimension_names=dims)  # fmt: skip

            arr("run", (self.runs,), ["run"], "int64", -1)[:] = np.arange(self.runs)
            arr("time", (self.N,), ["time"], "float64", np.nan, (max(self.N, 1),))[:] = times
            arr("coordinate", (self.n,), ["coordinate"], str, "", (max(self.n, 1),))[:] = np.array(coordinates)
            for name in ("q", "qd"):
                arr(name, (self.runs, self.N, self.n), ["run", "time", "coordinate"], "float64", np.nan)
            for name in ("t", "energy", "phi_norm"):
                arr(name, (self.runs, self.N), ["run", "time"], "float64", np.nan)
            arr("status", (self.runs,), ["run"], str, "pending")
            arr("message", (self.runs,), ["run"], str, "")
            for name, (dt, fill) in SUMMARIES.items():
                arr(name, (self.runs,), ["run"], dt, fill)
            nb = -(-self.runs // c)
            g.create_array("commit", shape=(nb,), chunks=(1,), dtype=str, fill_value="", dimension_names=["block"])
            for key, vals in keys.items():
                dims = ["run"] if vals.ndim == 1 else ["run", f"{key}_dim"]
                if vals.dtype.kind in "US":
                    a = arr(key, vals.shape, dims, str, "")
                    a[:] = vals.astype(str)
                else:
                    a = arr(key, vals.shape, dims, "float64", np.nan)
                    a[:] = vals
            self.group = g

    # ------------------------------------------------------------------ blocks
    def blocks(self) -> list[tuple[int, int, int]]:
        """Every block as (b, lo, hi)."""
        c = self.chunk
        return [(b, lo, min(lo + c, self.runs)) for b, lo in enumerate(range(0, self.runs, c))]

    def commits(self) -> list[dict[str, Any]]:
        """The commit records (one per committed block)."""
        return commit_records(self.group)

    def done(self) -> set[int]:
        """Blocks with a commit record."""
        return {int(r["block"]) for r in self.commits() if "block" in r}

    def _array(self, name: str) -> Any:
        """The group's array ``name``, opened once (``group[name]`` reads its metadata from disk
        each time: ~20 % of a block's write)."""
        a = self._arrays.get(name)
        if a is None:
            a = self._arrays[name] = self.group[name]
        return a

    def write(self, b: int, lo: int, hi: int, res: dict[str, Any]) -> None:
        """Write block b's results, then commit it."""
        g = self._array
        for name in ("q", "qd", "t", "energy", "phi_norm"):
            g(name)[lo:hi] = res[name]
        g("status")[lo:hi] = np.array(res["status"], dtype=str)
        g("message")[lo:hi] = np.array(res["message"], dtype=str)
        for name in SUMMARIES:
            g(name)[lo:hi] = res[name]
        rec = {"block": b, "runs": [lo, hi], "failed": int(sum(s == "failed" for s in res["status"])),
               "pid": os.getpid(), "time": time.time()}  # fmt: skip
        g("commit")[b : b + 1] = np.array([json.dumps(rec)], dtype=str)
