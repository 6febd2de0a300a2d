"""Work–precision diagrams from ``sim_bench.py`` results (issue 18, target 4).

For every mechanism of one or more ``sim_bench.py`` JSON files (rows merged, later files
replacing rows of the same engine, setting and step): error against wall time per simulated
second, one curve per engine and method (the points of a curve are its steps or tolerances),
three panels — the first bar's end against the exact reduction (m), the energy drift (J) and
the closure error (m). Runs that leave the branch or fail are drawn as crosses at their error
(capped at 10). The figures go to ``docs/img/work_precision_<mechanism>.png``; the gaps — for
every peer point, the fastest nonmin run at least as accurate in all three measures, and where
a peer is faster at its accuracy, by how much — are printed as a Markdown table
(``--markdown``).

Run ``python benchmarks/work_precision.py results/sim_bench.json [more.json …]``.
"""

from __future__ import annotations

import argparse
import json
import re
from collections import defaultdict
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
MEASURES = [("error_vs_reference_max", "position error [m]"), ("energy_drift", "energy drift [J]"),
            ("closure_max", "closure error [m]")]  # fmt: skip
FLOOR = 1e-16  # round-off: errors below are drawn here
XLABEL = ["wall time per simulated second [s]"]
CAP = 10.0


def family(row: dict[str, Any]) -> str:
    """The curve a row belongs to: engine and method, without its step or tolerance."""
    s = re.sub(r"\s*rtol=[0-9.e+-]+", "", str(row["setting"]))
    s = re.sub(r"\s*\[(compiled|engine|python)[^\]]*\]", "", s)
    return f"{row['engine']} {s}".strip()


def merge(paths: list[str]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, dict[tuple[str, str, Any], dict[str, Any]]] = defaultdict(dict)
    for p in paths:
        data = json.loads(Path(p).read_text())
        for mech, block in data["mechanisms"].items():
            for r in block["rows"]:
                out[mech][(r["engine"], r["setting"], r.get("dt"))] = r
    return {m: list(rows.values()) for m, rows in out.items()}


def _ok(r: dict[str, Any]) -> bool:
    return str(r.get("status", "")).startswith("ok") and bool(r.get("on_branch")) and r.get("wall_per_sim_s")


#: Values below these count as equal when runs are matched (``--floor``): the closure's
#: round-off, and by default nothing else. A reference of finite accuracy or an energy at
#: round-off gets its own floor per run of this script (e.g. ``--floor error=1e-11``).
FLOORS = {"error_vs_reference_max": 0.0, "energy_drift": 0.0, "closure_max": 1e-13}
_FLOOR_KEYS = {"error": "error_vs_reference_max", "energy": "energy_drift", "closure": "closure_max"}


def gaps(rows: list[dict[str, Any]], floors: dict[str, float] | None = None) -> list[dict[str, Any]]:
    """For every peer point on the branch: the fastest nonmin point with every measure ≤ the
    peer's (values below ``floors``, default :data:`FLOORS`, equal), and the ratio of wall times."""
    fl = {**FLOORS, **(floors or {})}
    mine = [r for r in rows if r["engine"] == "nonmin" and _ok(r)]
    res = []
    for p in rows:
        if p["engine"] == "nonmin" or not _ok(p):
            continue
        best = None
        for r in mine:
            if all(p.get(k) is None or (r.get(k) is not None and float(r[k]) <= max(float(p[k]), fl[k]))
                   for k, _ in MEASURES):  # fmt: skip
                if best is None or r["wall_per_sim_s"] < best["wall_per_sim_s"]:
                    best = r
        res.append({"peer": p, "nonmin": best,
                    "ratio": None if best is None else best["wall_per_sim_s"] / p["wall_per_sim_s"]})
    return res


def plot(mech: str, rows: list[dict[str, Any]], out: Path, note: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fams: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        if r.get("wall_per_sim_s"):
            fams[family(r)].append(r)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    markers = "osD^v<>ph*"
    colors = plt.get_cmap("tab20").colors if len(fams) > 10 else plt.get_cmap("tab10").colors
    for i, (fam, rs) in enumerate(sorted(fams.items())):
        rs = sorted(rs, key=lambda r: r["wall_per_sim_s"])
        style = "-" if fam.startswith("nonmin") else "--"
        for ax, (key, label) in zip(axes, MEASURES, strict=True):
            good = [r for r in rs if _ok(r) and r.get(key) is not None]
            bad = [r for r in rs if not _ok(r)]
            x = [r["wall_per_sim_s"] for r in good]
            y = [min(CAP, max(FLOOR, float(r[key]))) for r in good]
            (ln,) = ax.plot(x, y, style, marker=markers[i % len(markers)], ms=4, label=fam,
                            color=colors[i % len(colors)])
            if bad:
                ax.plot([r["wall_per_sim_s"] for r in bad],
                        [min(CAP, max(FLOOR, float(r.get(key) or CAP))) for r in bad],
                        "x", color=ln.get_color(), ms=7)  # fmt: skip
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(XLABEL[0])
            ax.set_ylabel(label)
            ax.grid(True, which="major", alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(f"{mech}: work–precision (lower left is better; x: off branch or failed)"
                 + (f"\n{note}" if note else ""))
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def markdown(mechs: dict[str, list[dict[str, Any]]], floors: dict[str, float] | None = None) -> str:
    lines = []
    if floors:
        lines += ["Equal below: " + ", ".join(f"{k} {v:g}" for k, v in floors.items()), ""]
    for mech, rows in mechs.items():
        lines += [f"### {mech}", "",
                  "| peer | dt | err [m] | dE [J] | wall/s | fastest nonmin at least as accurate | wall/s | nonmin / peer |",
                  "|---|---|---|---|---|---|---|---|"]  # fmt: skip
        for g in sorted(gaps(rows, floors), key=lambda g: g["peer"]["wall_per_sim_s"]):
            p, b = g["peer"], g["nonmin"]
            who = "none" if b is None else f"{b['setting']}" + (f" dt={b['dt']:g}" if b.get("dt") else "")
            lines.append(
                f"| {p['engine']} {p['setting']} | {p.get('dt') or '-'} | {p['error_vs_reference_max'] or float('nan'):.1e} | "
                f"{p['energy_drift']:.1e} | {p['wall_per_sim_s']:.2e} | {who} | "
                f"{'-' if b is None else format(b['wall_per_sim_s'], '.2e')} | "
                f"{'-' if g['ratio'] is None else format(g['ratio'], '.2f')} |"
            )
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("json", nargs="+", help="sim_bench.py result files (later ones win)")
    ap.add_argument("--out", default=str(HERE.parent / "docs" / "img"))
    ap.add_argument("--markdown", default=None, help="write the gap tables here")
    ap.add_argument("--note", default="", help="a second title line (e.g. when and at what machine load)")
    ap.add_argument("--floor", action="append", default=[], metavar="MEASURE=VALUE",
                    help="count values of a measure (error, energy, closure) below VALUE as equal when "
                         "matching runs (a reference's own accuracy, round-off); repeatable")
    ap.add_argument("--xlabel", default="wall time per simulated second [s]",
                    help="the x axis (e.g. 'CPU time per simulated second [s]' for --cpu runs)")
    ap.add_argument("--error-label", default=None, help="the first panel's y label (e.g. 'angle error [rad]')")
    a = ap.parse_args(argv)
    floors = {}
    for f in a.floor:
        key, _, val = f.partition("=")
        floors[_FLOOR_KEYS[key.strip()]] = float(val)
    XLABEL[0] = a.xlabel
    if a.error_label:
        MEASURES[0] = (MEASURES[0][0], a.error_label)
    mechs = merge(a.json)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for mech, rows in mechs.items():
        plot(mech, rows, out / f"work_precision_{mech}.png", a.note)
        print(f"wrote {out / f'work_precision_{mech}.png'} ({len(rows)} points)")
    md = markdown(mechs, floors)
    if a.markdown:
        Path(a.markdown).write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
