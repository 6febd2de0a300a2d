"""``python -m nonmin.validation``: run benchmarks one per process and assemble the report.

Examples::

    # one benchmark, full version, record saved as JSON
    python -m nonmin.validation --full --only A01 --json rec_A01.json
    # assemble saved records (in the order given) into docs/validation.md
    python -m nonmin.validation --assemble rec_*.json --report docs/validation.md

``nonmin validate --full --report docs/validation.md`` runs everything serially in one process
instead; the records are the same.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from ._records import ValidationRecord, format_table, write_report
from ._suite import BENCHMARKS, run_all


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m nonmin.validation", description=__doc__)
    ap.add_argument("--full", action="store_true", help="full versions (default: quick)")
    ap.add_argument("--only", nargs="+", default=None, choices=sorted(BENCHMARKS))
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--json", default=None, help="save the records as a JSON list")
    ap.add_argument("--assemble", nargs="+", default=None, metavar="JSON",
                    help="read saved records instead of running")
    ap.add_argument("--report", default=None, help="write the Markdown report here")
    ap.add_argument("--command", default=None, help="regeneration command written in the report")
    ap.add_argument("--notes-file", default=None, help="Markdown added after the machine section")
    args = ap.parse_args(argv)
    if args.assemble:
        records: list[ValidationRecord] = []
        for f in args.assemble:
            data = json.loads(Path(f).read_text(encoding="utf-8"))
            for d in data if isinstance(data, list) else [data]:
                records.append(ValidationRecord.from_dict(d))
    else:
        records = run_all(quick=not args.full, only=args.only, jobs=args.jobs,
                          log=lambda s: print(s, file=sys.stderr, flush=True))
    if args.json:
        from .._files import write_text

        write_text(args.json, json.dumps([r.to_dict() for r in records], indent=1))
    print(format_table(records))
    if args.report:
        kw = {"command": args.command} if args.command else {}
        notes = Path(args.notes_file).read_text(encoding="utf-8") if args.notes_file else ""
        write_report(records, args.report, notes=notes, **kw)
        print(f"report written to {args.report}")
    return 0 if all(r.passed for r in records) else 1


if __name__ == "__main__":
    sys.exit(main())
