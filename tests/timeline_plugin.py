"""Where the default run's time goes, per worker (issue 17, target 7): an opt-in pytest plugin.

    PYTHONPATH=tests NONMIN_TIMELINE=/tmp/tl python -m pytest -p timeline_plugin
    python tests/timeline_plugin.py /tmp/tl          # the summary

Each process (the xdist workers gw0, gw1, or ``main`` without xdist) appends one JSON line per
test to ``DIR/tl_<worker>.jsonl``: wall start and end, and the CPU time (user + sys) of the
process itself and of its waited-for children (tutorial and CLI subprocesses, mypy) over the
test's setup, call and teardown. CPU time is the measure to compare under load (the host is
shared); ``--durations`` gives wall time only. The summary prints each worker's CPU before its
first test (start-up and collection), its span and idle tail, and the tests and modules that
take the most CPU.
"""

from __future__ import annotations

import collections
import json
import os
import resource
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import pytest

_out: TextIO | None = None


def _cpu() -> tuple[float, float]:
    s = resource.getrusage(resource.RUSAGE_SELF)
    c = resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime, c.ru_utime + c.ru_stime


def _worker() -> str:
    return os.environ.get("PYTEST_XDIST_WORKER", "main")


def _write(rec: dict[str, Any]) -> None:
    global _out
    folder = os.environ.get("NONMIN_TIMELINE")
    if not folder:
        return
    if _out is None:
        Path(folder).mkdir(parents=True, exist_ok=True)
        _out = open(Path(folder) / f"tl_{_worker()}.jsonl", "a", encoding="utf-8")
    _out.write(json.dumps(rec) + "\n")
    _out.flush()


def pytest_collection_finish(session: pytest.Session) -> None:
    s, c = _cpu()
    _write({"id": "__collected__", "w": _worker(), "t": time.time(), "cpu": s, "ccpu": c})


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Any:
    t0 = time.time()
    s0, c0 = _cpu()
    yield
    s1, c1 = _cpu()
    _write({"id": item.nodeid, "w": _worker(), "t0": t0, "t1": time.time(), "cpu": s1 - s0, "ccpu": c1 - c0})


def pytest_sessionfinish(session: pytest.Session) -> None:
    global _out
    s, c = _cpu()
    _write({"id": "__end__", "w": _worker(), "t": time.time(), "cpu": s, "ccpu": c})
    if _out is not None:
        _out.close()
        _out = None


def summary(folder: str, top: int = 40) -> None:
    rows: list[dict[str, Any]] = []
    marks: dict[tuple[str, str], dict[str, Any]] = {}
    for fn in sorted(Path(folder).glob("tl_*.jsonl")):
        for line in fn.read_text(encoding="utf-8").splitlines():
            r = json.loads(line)
            if r["id"].startswith("__"):
                marks[(r["w"], r["id"])] = r
            else:
                rows.append(r)
    if not rows:
        print(f"no tests recorded in {folder}")
        return
    end = max(r["t1"] for r in rows)
    start = min(r["t0"] for r in rows)
    total = sum(r["cpu"] + r["ccpu"] for r in rows)
    print(f"{len(rows)} tests, CPU in tests {total:.1f} s (children {sum(r['ccpu'] for r in rows):.1f} s), "
          f"first test to last end {end - start:.1f} s")
    for w in sorted({r["w"] for r in rows}):
        mine = [r for r in rows if r["w"] == w]
        col = marks.get((w, "__collected__"))
        fin = marks.get((w, "__end__"))
        first = min(r["t0"] for r in mine)
        last = max(r["t1"] for r in mine)
        busy = sum(r["t1"] - r["t0"] for r in mine)
        print(f"  {w}: {len(mine)} tests, CPU at collection end {col['cpu'] if col else float('nan'):.1f} s, "
              f"first test at +{first - start:.1f} s, last end at +{last - start:.1f} s (idle tail "
              f"{end - last:.1f} s), in tests {busy:.1f} s wall, "
              f"process CPU at end {fin['cpu'] if fin else float('nan'):.1f} + children "
              f"{fin['ccpu'] if fin else float('nan'):.1f} s")
    by_mod: collections.Counter[str] = collections.Counter()
    n_mod: collections.Counter[str] = collections.Counter()
    for r in rows:
        m = r["id"].split("::")[0]
        by_mod[m] += r["cpu"] + r["ccpu"]
        n_mod[m] += 1
    print("\nCPU by module [s]:")
    for m, c in by_mod.most_common(top):
        print(f"  {c:7.1f} {n_mod[m]:5d}  {m}")
    print("\nCPU by test [s] (self, children, wall, worker):")
    for r in sorted(rows, key=lambda r: -(r["cpu"] + r["ccpu"]))[:top]:
        print(f"  {r['cpu']:6.2f} {r['ccpu']:6.2f} {r['t1'] - r['t0']:6.2f} {r['w']:>4}  {r['id']}")


if __name__ == "__main__":
    summary(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 40)
