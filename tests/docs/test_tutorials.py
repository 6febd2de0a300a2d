"""Every tutorial in docs/tutorials runs, and every output it shows is what it prints now.

Each page runs in a fresh interpreter (``docs/refresh_tutorials.py --check``: its ```python
blocks in order, in a temporary directory with the Agg backend) and must finish within
:data:`TIME_LIMIT`; each ```text block after a python block must say what that block prints
(numbers compared by value, round-off digits below 1e-12 aside), and the output must contain
the claims the prose makes (:data:`CLAIMS`). The README's quick start is checked the same way
(``tests/test_readme.py``). Refresh a stale page with ``python docs/refresh_tutorials.py PAGE``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TUTORIALS = ROOT / "docs" / "tutorials"
#: Wall-clock limit per tutorial [s] (generous: 8 processes share 2 cores during development).
TIME_LIMIT = 90.0
#: Tutorial -> phrases its output must contain: the claims its prose makes about the run.
CLAIMS = {
    "01_planar_mechanism.md": ["PASSED", "rank A = 7, trace P = 2.000", "status='success'",
                               "slider x in [-1.000, 1.000] m"],
    "02_switching_events.md": ["impact:wall", "latch    activate ['latch']",
                               "release  deactivate ['latch']", "rank A = 5", "(change "],
    "03_control_closed_chain.md": ["actuation condition holds: True", "-> [0.4 1.5] (goal [0.4 1.5])",
                                   "InfeasibleActuationError: at t = 0: actuation is infeasible"],
    "04_urdf_loop_closure.md": ["A: 3 rows, rank 2", "qdd = [nan nan nan]",
                                "(< 1e-12: True)", "brake    6 rows"],
}
EXPECTED = tuple(CLAIMS)


def python_blocks(text: str) -> list[str]:
    """The ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def tutorial_script(path: Path) -> str:
    """The runnable script of a tutorial: its python blocks joined in order."""
    blocks = python_blocks(path.read_text(encoding="utf-8"))
    return "\n\n".join(b.rstrip() for b in blocks) + "\n"


def test_block_extraction() -> None:
    text = "intro\n```python\nx = 1\n```\n\n```text\nnot code\n```\n```python\ny = x + 1\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = x + 1\n"]


def test_all_tutorials_present() -> None:
    names = sorted(p.name for p in TUTORIALS.glob("*.md"))
    for name in EXPECTED:
        assert name in names
        assert len(python_blocks((TUTORIALS / name).read_text(encoding="utf-8"))) >= 3


def run_checked(page: Path, workdir: Path) -> subprocess.CompletedProcess[str]:
    """Run ``docs/refresh_tutorials.py --check --echo`` on a page in a fresh interpreter."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONHASHSEED="0", NONMIN_NO_BROWSER="1")
    return subprocess.run(
        [sys.executable, str(ROOT / "docs" / "refresh_tutorials.py"), "--check", "--echo",
         "--workdir", str(workdir), str(page)],
        cwd=workdir, env=env, capture_output=True, text=True, timeout=TIME_LIMIT,
    )


@pytest.mark.parametrize("name", EXPECTED)
def test_tutorial_runs(name: str, tmp_path: Path) -> None:
    start = time.perf_counter()
    proc = run_checked(TUTORIALS / name, tmp_path)
    elapsed = time.perf_counter() - start
    assert proc.returncode == 0, (
        f"{name}: failed or shows stale output after {elapsed:.1f} s (refresh it with "
        f"python docs/refresh_tutorials.py docs/tutorials/{name}):\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    )
    for phrase in CLAIMS[name]:
        assert phrase in proc.stdout, f"{name}: output lacks {phrase!r}:\n{proc.stdout}"
    # every tutorial saves at least one figure; the files must be non-empty PNGs
    pngs = list(tmp_path.glob("*.png"))
    assert pngs, f"{name} wrote no figure"
    for png in pngs:
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_same_output_compares_numbers_by_value() -> None:
    import importlib.util

    spec = importlib.util.spec_from_file_location("nonmin_docs_refresh2", ROOT / "docs" / "refresh_tutorials.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.same_output("rank A = 7, e = 1.5e-15", "rank A = 7, e = 3.1e-16")
    assert mod.same_output("x = [1.  0.5]", "x = [1.0 0.50]")
    assert not mod.same_output("rank A = 7", "rank A = 6")
    assert not mod.same_output("drift 1.2e-06 J", "drift 1.3e-06 J")
    assert not mod.same_output("status success", "status failed")
    assert not mod.same_output("a b", "a b c")


def test_refresh_tool_rewrites_output_blocks(tmp_path: Path) -> None:
    """docs/refresh_tutorials.py replaces a text block only when it directly follows code."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("nonmin_docs_refresh", ROOT / "docs" / "refresh_tutorials.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    page = (
        "# t\n```python\nx = 6 * 7\nprint(x)\n```\n\n```text\nstale\n```\n"
        "prose\n```python\nprint(x + 1)\n```\nmore prose\n```text\nkept\n```\n"
    )
    new = mod.refresh(page, tmp_path)
    assert "```text\n42\n```" in new
    assert "```text\nkept\n```" in new and "stale" not in new


#: docs/contact.md: the claims its prose makes. Its first sections: reactions vs the closed
#: form, undetermined redundant pins, an impact's impulses by the lever rule, a driven
#: slider-crank vs its closed form, driver torque = inverse dynamics, redundant actuation; its
#: friction section: slip and stick against the closed forms, Painlevé, a two-point rest.
CONTACT_CLAIMS = [
    "ground -> bar | force on the bar, bar frame: (1501, 2)",
    "all determined: True",
    "pivot determined: [False False  True]  pivot2: [False False  True]",
    "engine program: True",
    "all ok: True",
    "ok=True fully_actuated=True dof=2 redundancy=2",
    "floor_l on the bar [0.       1.461643] N s, determined: True",
    "floor_r on the bar [0.       2.923286] N s, determined: True",
    "lever rule: 1.461643 and 2.923286 N s",
    "mu = 0.3: slip, s(1 s) = -1.060220 m (closed form -1.060220)",
    "mu = 0.6: stick, s(1 s) = 0.000000 m",
    "stick:floor at t = 0.407747196738 s, v0/(3 mu g) = 0.407747196738 s",
    "rolling: v = 2.000000000000 m/s (2 v0/3 = 2.000000000000)",
    "PainleveError at contact 'floor', t = 0.0, factor -0.125000 (closed form 1 - 1.5*3/4 = -0.125000)",
    "stick:heel@0.548 stick:toe@0.548",
    "at rest: {'heel': ('stick', 5.886), 'toe': ('stick', 5.886)}",
    "stick:floor at t = 0.6371049949 s (v0/(mu g) = 0.6371049949)",
]
#: docs/contact.md: printed residual -> the bound it must meet
CONTACT_BOUNDS = {
    r"max \|F - closed form\| = (\S+) N": 1e-8,
    r"max \|x - closed form\| = (\S+) m": 1e-9,
    r"max \|u_inverse - driver torque\| = (\S+) N m": 1e-7,
    r"replayed q̈ error (\S+)": 1e-9,
}


def test_contact_page_runs_and_its_output_is_current(tmp_path: Path) -> None:
    """docs/contact.md (contact, reactions and friction): its python blocks run in order, every
    shown output is what they print, and the output carries the prose's claims and meets its
    bounds. (One run of the page for all three: tests/analysis/test_contact_doc.py used to run it
    a second time, as a script, for the claims of its first sections.)"""
    page = ROOT / "docs" / "contact.md"
    assert len(python_blocks(page.read_text(encoding="utf-8"))) >= 5
    proc = run_checked(page, tmp_path)
    assert proc.returncode == 0, (
        "docs/contact.md fails or shows stale output (python docs/refresh_tutorials.py docs/contact.md):\n"
        f"{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    )
    for phrase in CONTACT_CLAIMS:
        assert phrase in proc.stdout, f"docs/contact.md: output lacks {phrase!r}:\n{proc.stdout}"
    for pattern, bound in CONTACT_BOUNDS.items():
        m = re.search(pattern, proc.stdout)
        assert m is not None, f"docs/contact.md: output lacks {pattern!r}:\n{proc.stdout}"
        assert float(m.group(1)) < bound, f"docs/contact.md: {pattern}: {m.group(1)} ≥ {bound}"


def test_architecture_page_example_runs(tmp_path: Path) -> None:
    """docs/architecture.md's simulate call with option values is a script a reader can paste
    (it used undefined names: mech, lock, np, and a 'floor' no model had)."""
    block = python_blocks((ROOT / "docs" / "architecture.md").read_text(encoding="utf-8"))[0]
    code = block + "\nprint(traj.status.value, traj.t[-1])\n"
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          timeout=TIME_LIMIT, env=dict(os.environ, MPLBACKEND="Agg"))  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.split() == ["event_terminated", "1.5"]
    assert (tmp_path / "run.npz").is_file()
