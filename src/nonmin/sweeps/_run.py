"""Running a sweep: blocks of runs as batched engine calls, locally or on Dask, stored as they
finish."""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, NonminError
from ._spec import Grid, RunInputs, SweepSpec, Uniform, key_values, parse_vary

__all__ = ["SweepResult", "run_block", "sweep"]

#: Output samples per run when neither the scenario (output_dt) nor the options (t_eval) say.
DEFAULT_SAMPLES = 201

#: Runs per task (one batched engine call, one chunk of the store, one commit).
DEFAULT_CHUNK = 64


def _status_name(st: Any) -> str:
    return str(getattr(st, "value", st))


def _output_grid(inp: RunInputs) -> np.ndarray:
    te = inp.options.get("t_eval")
    if te is not None:
        return np.asarray(te, dtype=float)
    t0, t1 = inp.t_span
    return np.linspace(t0, t1, DEFAULT_SAMPLES)


def run_block(spec: SweepSpec, rows: Sequence[Mapping[str, Any]], n: int, N: int, threads: int = 1) -> dict[str, Any]:
    """Simulate the runs ``rows`` (key values) of ``spec``: one batched engine call per group of
    runs that share their settings. Runs that cannot be set up, or fail, keep status "failed"
    and their message. Results: arrays with a leading axis of ``len(rows)``."""
    from ..sim import simulate_batch

    k = len(rows)
    res: dict[str, Any] = {
        "q": np.full((k, N, n), np.nan), "qd": np.full((k, N, n), np.nan), "t": np.full((k, N), np.nan),
        "energy": np.full((k, N), np.nan), "phi_norm": np.full((k, N), np.nan),
        "status": ["failed"] * k, "message": [""] * k, "events": np.zeros(k, dtype=np.int64),
        "n_steps": np.zeros(k, dtype=np.int64), "energy_drift": np.full(k, np.nan),
        "closure": np.full(k, np.nan), "wall_time": np.full(k, np.nan),
    }  # fmt: skip
    cache: dict[str, Any] = {}
    groups: dict[str, list[tuple[int, RunInputs]]] = {}
    for i, row in enumerate(rows):
        try:
            inp = spec.inputs(row, cache)
            grid = _output_grid(inp)
            if grid.shape[0] != N:
                raise InputError(f"this run has {grid.shape[0]} output samples, the sweep {N}: keep the horizon "
                                 "and output_dt / t_eval size equal over the sweep")  # fmt: skip
        except (NonminError, TypeError, ValueError) as exc:
            res["message"][i] = f"{type(exc).__name__}: {exc}"
            continue
        groups.setdefault(inp.group_key(), []).append((i, inp))
    for members in groups.values():
        idx = [i for i, _ in members]
        inps = [inp for _, inp in members]
        first = inps[0]
        opts = dict(first.options)
        opts["t_eval"] = _output_grid(first)
        w0 = time.perf_counter()
        try:
            bt = simulate_batch(
                first.model, first.t_span, np.array([inp.q0 for inp in inps]),
                np.array([inp.qd0 for inp in inps]), params=[inp.model for inp in inps],
                active=[inp.active for inp in inps], threads=threads, **opts,
            )  # fmt: skip
        except (NonminError, TypeError, ValueError) as exc:
            for i in idx:
                res["message"][i] = f"{type(exc).__name__}: {exc}"
            continue
        wall = (time.perf_counter() - w0) / len(idx)
        drift, closure = bt.energy_drift, bt.closure
        assert bt.q is not None and bt.qd is not None
        for j, i in enumerate(idx):
            res["q"][i] = bt.q[j]
            res["qd"][i] = bt.qd[j]
            res["t"][i] = bt.t
            res["energy"][i] = bt.energy[j]
            res["phi_norm"][i] = bt.phi_norm[j]
            res["status"][i] = _status_name(bt.status[j])
            res["message"][i] = bt.message[j]
            held = bt.runs[j]
            res["events"][i] = len(bt.events[j]) if bt.events else (0 if held is None else len(held.events))
            res["n_steps"][i] = int(bt.n_steps[j])
            res["energy_drift"][i] = drift[j]
            res["closure"][i] = closure[j]
            res["wall_time"][i] = wall
    return res


# --------------------------------------------------------------------------- progress


class _Progress:
    """Runs done, failures, ETA on stderr (one line, rewritten)."""

    def __init__(self, total: int, skipped: int, show: bool) -> None:
        self.total, self.skipped, self.show = total, skipped, show
        self.done = 0
        self.failed = 0
        self.t0 = time.perf_counter()
        self.last = 0.0

    def update(self, runs: int, failed: int) -> None:
        self.done += runs
        self.failed += failed
        now = time.perf_counter()
        if self.show and (now - self.last > 0.5 or self.done + self.skipped >= self.total):
            self.last = now
            el = now - self.t0
            todo = self.total - self.skipped
            eta = el / self.done * (todo - self.done) if self.done else float("nan")
            eta_s = f"{eta:.0f} s" if np.isfinite(eta) else "?"
            sys.stderr.write(
                f"\rsweep: {self.done + self.skipped}/{self.total} runs ({self.skipped} from the store), "
                f"{self.failed} failed, {el:.1f} s, ETA {eta_s}   "
            )
            sys.stderr.flush()

    def close(self) -> None:
        if self.show:
            sys.stderr.write("\n")


# --------------------------------------------------------------------------- result


@dataclass(frozen=True)
class SweepResult:
    """What :func:`sweep` did: the labeled result and the counts of this call."""

    dataset: Any  # xarray.Dataset
    store: Path | None
    runs: int
    computed: int  # runs simulated by this call
    skipped: int  # runs already in the store
    failed: int  # runs with status "failed" (in the whole sweep)

    def __repr__(self) -> str:
        return (f"SweepResult(runs={self.runs}, computed={self.computed}, skipped={self.skipped}, "
                f"failed={self.failed}, store={str(self.store) if self.store else None!r})")  # fmt: skip


def _axes(vary: Any) -> tuple[tuple[Any, ...], ...]:
    if vary is None:
        return ()
    if isinstance(vary, str):
        vary = [vary]
    if isinstance(vary, Mapping):
        items = list(vary.items())
    else:
        items = [parse_vary(v) if isinstance(v, str) else tuple(v) for v in vary]
    out: list[tuple[Any, Any]] = []
    for key, ax in items:
        if not (isinstance(key, str) or (isinstance(key, tuple) and key and all(isinstance(k, str) for k in key))):
            raise InputError(f"vary: keys must be strings (or a tuple of them: a zipped axis), got {key!r}")
        if isinstance(ax, str):
            ax = parse_vary(f"{key}={ax}")[1]
        if not isinstance(ax, Grid | Uniform):
            if isinstance(ax, np.ndarray):
                ax = list(ax)
            elif not isinstance(ax, Sequence) or isinstance(ax, str):
                raise InputError(f"vary[{key!r}]: expected a list of values, Grid or Uniform, got {type(ax).__name__}")
            ax = list(ax)
        out.append((key, ax))
    return tuple(out)


def _require() -> None:
    """xarray and zarr (extra ``sweep``), or a MissingDependencyError naming the extra."""
    import importlib.util

    missing = [m for m in ("xarray", "zarr") if importlib.util.find_spec(m) is None]
    if missing:
        from ..errors import MissingDependencyError

        raise MissingDependencyError(f"nonmin.sweep needs {', '.join(missing)}: pip install 'nonmin[sweep]'")


def _base(base: Any, allow_code: bool) -> Any:
    if isinstance(base, str | os.PathLike):
        from ..io import load_scenario

        return load_scenario(Path(base), allow_code=allow_code)
    return base


def _client(scheduler: Any) -> tuple[Any, bool]:
    """A dask.distributed Client (and whether this call made it)."""
    try:
        from dask.distributed import Client
    except ImportError:
        from ..errors import MissingDependencyError

        raise MissingDependencyError(
            "a Dask scheduler needs dask.distributed: pip install 'nonmin[sweep]'"
        ) from None
    if isinstance(scheduler, Client):
        return scheduler, False
    if isinstance(scheduler, str):
        return Client(scheduler), True
    raise InputError(f"scheduler must be an address 'tcp://HOST:PORT' or a dask.distributed.Client, got "
                     f"{type(scheduler).__name__}")  # fmt: skip


def sweep(
    base: Any,
    vary: Any = None,
    *,
    samples: int | None = None,
    seed: int | None = None,
    store: str | os.PathLike[str] | None = None,
    scheduler: Any = None,
    workers: int | None = None,
    chunk: int = DEFAULT_CHUNK,
    progress: bool | None = None,
    allow_code: bool = False,
    t_span: Any = None,
    on_block: Callable[[int, int, int], None] | None = None,
    **options: Any,
) -> SweepResult:
    """Run many simulations over grids, random samples and lists of values; store them as they
    finish; resume what is missing.

    Parameters
    ----------
    base : scenario file, Scenario, Model or Mechanism
        What every run starts from. A scenario's keys are dotted TOML paths
        (``model.params.omega0``, ``simulate.dt``, ``initial.qd[2]``); a model's are ``q0``,
        ``qd0``, ``q0.<coordinate>``, ``qd0.<coordinate>``, ``params.<field>``
        (``model.replace``), ``t_final`` and :func:`~nonmin.sim.simulate` keywords.
    vary : dict or list of "KEY=..." strings
        The axes: ``{key: [values...] | Grid(start, stop, count) | Uniform(low, high) |
        "start:stop:count" | "low:high"}``. Value axes and grids are crossed; uniform axes are
        drawn ``samples`` times (each draw crossed with the grid).
    samples, seed : int, optional
        Random draws and the generator's seed (``numpy.random.default_rng(seed)``).
    store : path, optional
        A Zarr folder (see :mod:`nonmin.sweeps._store`): each block of runs is written and
        committed as it finishes; calling again with the same sweep and store computes only
        the blocks not yet committed. Without it the result is kept in memory only.
    scheduler : "tcp://HOST:PORT" or dask.distributed.Client, optional
        Run the blocks as Dask tasks (each a batched engine call on a worker); default: a local
        thread pool of ``workers`` threads, each running a block in the engine with the GIL
        released.
    workers : int, optional
        Local threads (default: the machine's cores).
    chunk : int, default 64
        Runs per block (task, engine call, store chunk and commit).
    progress : bool, optional
        Runs done, failures and ETA on stderr (default: when stderr is a terminal).
    allow_code : bool
        Let a scenario's entry points run (as :func:`nonmin.io.load_scenario`).
    t_span, **options
        For a model base: the horizon and :func:`simulate` keywords shared by the runs (with
        ``q0``/``qd0``/``active`` when the model has no default state). Without ``t_eval`` the
        runs are sampled at 201 evenly spaced times.
    on_block : callable(b, lo, hi), optional
        Called after block ``b`` (runs ``lo:hi``) is committed.

    Returns
    -------
    SweepResult
        ``.dataset``: an xarray Dataset with dims (run, time, coordinate): ``q``, ``qd``, ``t``,
        ``energy``, ``phi_norm`` per sample; per run ``status`` ("success", "failed", ...,
        "pending" if not run), ``message``, ``events``, ``n_steps``, ``energy_drift``,
        ``closure``, ``wall_time``, and every swept key as a variable along ``run``.
    """
    from ..io import Scenario

    _require()
    base = _base(base, allow_code)
    axes = _axes(vary)
    if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int) or samples < 1):
        raise InputError(f"samples must be an integer ≥ 1, got {samples!r}")
    if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
        raise InputError(f"chunk must be an integer ≥ 1, got {chunk!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise InputError(f"workers must be an integer ≥ 1, got {workers!r}")
    if isinstance(base, Scenario) and (options or t_span is not None):
        raise InputError(f"sweep of a scenario: options {sorted(options)} belong in the scenario or in vary")
    spec = SweepSpec(base=base, axes=axes, samples=samples, seed=seed, t_span=t_span, options=options)
    table = spec.table()
    runs = len(table)
    first = spec.inputs(table[0], {})
    times = _output_grid(first)
    N = int(times.shape[0])
    model = first.model
    coords = list(model.coordinate_names)
    n = len(coords)
    keys = key_values(table)
    header = spec.describe()
    st = None
    if store is not None:
        from ._store import SweepStore

        st = SweepStore(store, header=header, runs=runs, chunk=chunk, times=times, coordinates=coords, keys=keys)
        blocks = st.blocks()
        done = st.done()
    else:
        blocks = [(b, lo, min(lo + chunk, runs)) for b, lo in enumerate(range(0, runs, chunk))]
        done = set()
        mem: dict[int, Any] = {}
    todo = [blk for blk in blocks if blk[0] not in done]
    skipped = sum(hi - lo for b, lo, hi in blocks if b in done)
    show = sys.stderr.isatty() if progress is None else bool(progress)
    bar = _Progress(runs, skipped, show)
    computed = 0

    def finished(b: int, lo: int, hi: int, res: dict[str, Any]) -> None:
        nonlocal computed
        if st is not None:
            st.write(b, lo, hi, res)
        else:
            mem[b] = (lo, hi, res)
        computed += hi - lo
        bar.update(hi - lo, sum(s == "failed" for s in res["status"]))
        if on_block is not None:
            on_block(b, lo, hi)

    try:
        for b, lo, hi, res in _execute(spec, table, todo, n, N, scheduler, workers):
            finished(b, lo, hi, res)
    finally:
        bar.close()
    if st is not None:
        ds = open_sweep(st.path)
    else:
        ds = _dataset(mem, runs, times, coords, keys, n, N, header)
    failed = sum(str(x) == "failed" for x in ds["status"].values)
    return SweepResult(ds, None if st is None else st.path, runs, computed, skipped, failed)


#: Sweep specs unpickled in this process (a Dask worker), by the digest of their pickle: the
#: blocks of a sweep that land on one worker share one spec, hence one model and its engine
#: program (built once per worker, not per task). Bounded; oldest dropped first.
_SPECS: dict[str, SweepSpec] = {}
_SPECS_MAX = 8


def _pack(spec: SweepSpec) -> tuple[str, bytes]:
    """The spec a worker needs, pickled once per sweep, and its digest. The axes are left out:
    a task gets its runs' key values (``table[lo:hi]``), and the whole axes in every task would
    make the data sent grow as runs² (a 1e4-run sweep of initial states: 2 MB per task)."""
    import dataclasses
    import hashlib

    import cloudpickle  # (a dependency of dask.distributed: model sources defined in __main__)

    blob = cloudpickle.dumps(dataclasses.replace(spec, axes=()), protocol=5)
    return hashlib.blake2b(blob, digest_size=16).hexdigest(), blob


def _remote_block(token: str, blob: bytes, rows: Sequence[Mapping[str, Any]], n: int, N: int) -> dict[str, Any]:
    """A Dask task: :func:`run_block` of the spec ``blob`` (unpickled once per worker process)."""
    spec = _SPECS.get(token)
    if spec is None:
        import pickle

        spec = pickle.loads(blob)
        if len(_SPECS) >= _SPECS_MAX:
            _SPECS.pop(next(iter(_SPECS)))
        _SPECS[token] = spec
    return run_block(spec, rows, n, N, 1)


def _execute(spec: SweepSpec, table: list[dict[str, Any]], todo: list[tuple[int, int, int]], n: int, N: int,
             scheduler: Any, workers: int | None) -> Iterator[tuple[int, int, int, dict[str, Any]]]:  # fmt: skip
    """Yield (b, lo, hi, results) as blocks finish."""
    if not todo:
        return
    if scheduler is not None:
        client, own = _client(scheduler)
        try:
            import uuid

            from dask.distributed import as_completed

            tag = uuid.uuid4().hex
            token, blob = _pack(spec)
            futs = {}
            for b, lo, hi in todo:
                f = client.submit(_remote_block, token, blob, table[lo:hi], n, N, pure=False,
                                  key=f"nonmin-sweep-{tag}-{b}")  # fmt: skip
                futs[f] = (b, lo, hi)
            # results are gathered as each task ends (a worker that dies afterwards holds none)
            for f, result in as_completed(list(futs), with_results=True):
                b, lo, hi = futs[f]
                yield b, lo, hi, result
        finally:
            if own:
                client.close()
        return
    nw = workers or os.cpu_count() or 1
    with ThreadPoolExecutor(max_workers=nw) as pool:
        pending: dict[Future[dict[str, Any]], tuple[int, int, int]] = {}
        it = iter(todo)
        for b, lo, hi in it:  # keep at most 2 blocks per thread in flight
            pending[pool.submit(run_block, spec, table[lo:hi], n, N, 1)] = (b, lo, hi)
            if len(pending) >= 2 * nw:
                break
        while pending:
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for f in done:
                b, lo, hi = pending.pop(f)
                nxt = next(it, None)
                if nxt is not None:
                    pending[pool.submit(run_block, spec, table[nxt[1]:nxt[2]], n, N, 1)] = nxt
                yield b, lo, hi, f.result()


def _dataset(mem: dict[int, Any], runs: int, times: np.ndarray, coords: list[str], keys: dict[str, np.ndarray],
             n: int, N: int, header: dict[str, Any]) -> Any:  # fmt: skip
    import xarray as xr

    from ._store import SUMMARIES

    q = np.full((runs, N, n), np.nan)
    qd = np.full((runs, N, n), np.nan)
    per_t = {name: np.full((runs, N), np.nan) for name in ("t", "energy", "phi_norm")}
    status = np.full(runs, "pending", dtype=object)
    message = np.full(runs, "", dtype=object)
    summ = {name: np.full(runs, fill, dtype=dt) for name, (dt, fill) in SUMMARIES.items()}
    for lo, hi, res in mem.values():
        q[lo:hi] = res["q"]
        qd[lo:hi] = res["qd"]
        for name in per_t:
            per_t[name][lo:hi] = res[name]
        status[lo:hi] = res["status"]
        message[lo:hi] = res["message"]
        for name in summ:
            summ[name][lo:hi] = res[name]
    data: dict[str, Any] = {"q": (("run", "time", "coordinate"), q), "qd": (("run", "time", "coordinate"), qd),
                            "status": ("run", status.astype(str)), "message": ("run", message.astype(str))}  # fmt: skip
    for name, arr in per_t.items():
        data[name] = (("run", "time"), arr)
    for name, arr in summ.items():
        data[name] = ("run", arr)
    for key, vals in keys.items():
        data[key] = (("run",) if vals.ndim == 1 else ("run", f"{key}_dim"), vals)
    import json

    return xr.Dataset(data, coords={"run": np.arange(runs), "time": times, "coordinate": coords},
                      attrs={"nonmin_sweep": json.dumps(header)})  # fmt: skip


def open_sweep(path: str | os.PathLike[str]) -> Any:
    """The xarray Dataset of a sweep store (lazily read; see :func:`sweep`)."""
    _require()
    import xarray as xr

    p = Path(path)
    if not (p / "zarr.json").exists():
        raise InputError(f"{p}: not a sweep store (no zarr.json)")
    ds = xr.open_zarr(str(p), consolidated=False)
    ds = ds.set_coords([c for c in ("run", "time", "coordinate") if c in ds.variables])
    return ds
