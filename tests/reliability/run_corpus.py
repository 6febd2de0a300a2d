"""Run the bad-input and fault corpus and print the totals of docs/reliability.md.

    python tests/reliability/run_corpus.py            # the fast cases (default test suite)
    python tests/reliability/run_corpus.py --slow     # plus the fault cases in subprocesses
    python tests/reliability/run_corpus.py --list     # one line per case with its outcome

Each case runs in a fresh temporary folder under a time limit (corpus.HANG_SECONDS); a crash of
this process would be a crash of nonmin (none is caught here on purpose).
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import corpus


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--slow", action="store_true", help="include the slow fault cases")
    ap.add_argument("--list", action="store_true", help="print every case and its outcome")
    ap.add_argument("-k", default="", help="only cases whose id contains this text")
    args = ap.parse_args(argv)
    cases = [c for c in corpus.CASES if (args.slow or not c.slow) and args.k in c.id]
    totals: collections.Counter[str] = collections.Counter()
    by_cat: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    bad = []
    t0 = time.perf_counter()
    for c in cases:
        with tempfile.TemporaryDirectory(prefix="nonmin-corpus-") as d:
            out = corpus.classify(c, Path(d))
        totals[out.kind] += 1
        by_cat[c.category][out.kind] += 1
        if args.list:
            print(f"{out.kind:18s} {out.seconds:6.2f}s  {c.category} :: {c.id} :: {out.detail[:160]}")
        if out.kind != "typed and clear":
            bad.append((c, out))
    wall = time.perf_counter() - t0
    print(f"\ncases tried: {len(cases)}   wall time: {wall:.1f} s")
    for kind in corpus.KINDS:
        print(f"  {kind:18s} {totals[kind]}")
    print("crashes: 0 (the run completed)")
    print("\nby category (cases / typed and clear):")
    for cat, cnt in sorted(by_cat.items()):
        print(f"  {cat:48s} {sum(cnt.values()):4d} / {cnt['typed and clear']}")
    for c, out in bad:
        known = f"  (known issue: {c.known_issue})" if c.known_issue else ""
        print(f"\nNOT CLEAR [{out.kind}] {c.category} :: {c.id}{known}\n    {out.detail}")
    return 0 if not bad else 1


if __name__ == "__main__":
    sys.exit(main())
