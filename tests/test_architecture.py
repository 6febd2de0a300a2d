"""The layout tells the architecture: every import in ``src/nonmin`` goes downward.

The import graph is read from the source (every ``import`` statement, at module level, inside
functions and under ``TYPE_CHECKING`` alike), so a lazy import cannot hide a circle. Two rules:

1. No circle between modules (a package's ``__init__`` re-exporting its own submodules is not
   a circle; a submodule importing its parent package's ``__init__`` is, and is refused).
2. Between the layers of ``docs/architecture.md``, imports go only to a lower layer.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"

#: Layers from the bottom up (docs/architecture.md); a package imports only from lower rows.
#: Packages in the same row do not import each other.
LAYERS: list[set[str]] = [
    {"nonmin.errors", "nonmin._version", "nonmin._engine"},
    {"nonmin._files", "nonmin._validation"},
    {"nonmin._export"},
    {"nonmin.core"},
    {"nonmin.model"},
    {"nonmin.library", "nonmin.control"},
    {"nonmin.viz"},
    {"nonmin.analysis", "nonmin.linear"},
    {"nonmin.sim"},
    {"nonmin.io", "nonmin.validation"},
    {"nonmin.sweeps"},
    {"nonmin.cli"},
]

#: Known circles, each with the reason it is still there (empty when the house is straight).
KNOWN_CIRCLES: dict[frozenset[str], str] = {}


def _modules() -> dict[str, Path]:
    mods = {}
    for f in (SRC / "nonmin").rglob("*.py"):
        parts = list(f.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = f
    return mods


#: The compiled extension (C++, no Python source): the bottom layer with the base modules.
EXTENSION = "nonmin._engine"


@functools.cache  # read once per process: every test below walks the same graph
def _graph() -> dict[str, set[str]]:
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    edges[EXTENSION] = set()
    known = set(mods) | {EXTENSION}
    for mod, f in mods.items():
        pkg = mod.split(".") if f.name == "__init__.py" else mod.split(".")[:-1]
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg[: len(pkg) - (node.level - 1)]
                    m = ".".join(base + ([node.module] if node.module else []))
                else:
                    m = node.module or ""
                subs = [f"{m}.{a.name}" for a in node.names if f"{m}.{a.name}" in known]
                # ``from . import _sub`` imports the submodule, not a name of the package
                targets = subs if len(subs) == len(node.names) else [m, *subs]
            for t in targets:
                if not t.startswith("nonmin"):
                    continue
                while t not in known and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in known and t != mod and not (f.name == "__init__.py" and t.startswith(mod + ".")):
                    edges[mod].add(t)
    return edges


def _circles(edges: dict[str, set[str]]) -> list[frozenset[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[frozenset[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def _layer(mod: str) -> int | None:
    for i, row in enumerate(LAYERS):
        if any(mod == p or mod.startswith(p + ".") for p in row):
            return i
    return None


def test_the_graph_is_read() -> None:
    """The reader sees real edges (a check of the check): simulate imports the model layer."""
    edges = _graph()
    assert {"nonmin.model", "nonmin.core"} <= edges["nonmin.sim._simulate"]
    assert "nonmin.model.planar._elements" in edges["nonmin.model.planar._model"]


def test_no_import_circles() -> None:
    circles = [c for c in _circles(_graph()) if c not in KNOWN_CIRCLES]
    assert not circles, "import circles: " + "; ".join(" ↔ ".join(sorted(c)) for c in circles)


def test_known_circles_still_exist() -> None:
    """A known circle that has gone must leave the list (so the list cannot go stale)."""
    now = set(_circles(_graph()))
    gone = [sorted(c) for c in KNOWN_CIRCLES if c not in now]
    assert not gone, f"remove from KNOWN_CIRCLES: {gone}"


@pytest.mark.parametrize("row", range(len(LAYERS)))
def test_layers_import_only_downward(row: int) -> None:
    edges = _graph()
    bad = []
    for mod, targets in edges.items():
        if _layer(mod) != row:
            continue
        for t in targets:
            lt = _layer(t)
            if lt is None or t == "nonmin":
                bad.append(f"{mod} → {t} (not in a layer)")
            elif lt > row or (lt == row and t.split(".")[:2] != mod.split(".")[:2]):
                bad.append(f"{mod} → {t}")
    assert not bad, "upward or sideways imports:\n" + "\n".join(sorted(bad))
