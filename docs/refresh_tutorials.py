"""Re-run the tutorials and rewrite their output blocks with what the code prints now.

Usage::

    python docs/refresh_tutorials.py [docs/tutorials/01_planar_mechanism.md ...] [--check]

Each tutorial's ```python blocks run in order in one namespace (in a temporary directory, with
the Agg backend); a ```text block that directly follows a python block (only blank lines in
between) is replaced by what that block printed. ``--check`` rewrites nothing and exits with
status 1 when some output differs (numbers move when the numerics change; the test suite
checks the claims, not every digit: ``tests/docs/test_tutorials.py``).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

TUTORIALS = Path(__file__).resolve().parent / "tutorials"
_FENCE = re.compile(r"^```(\w+)\n(.*?)^```\n", flags=re.S | re.M)


def refresh(text: str, workdir: Path) -> str:
    """The Markdown ``text`` with every output block replaced by the preceding block's output."""
    namespace: dict[str, object] = {"__name__": "__main__"}
    out: list[str] = []
    pos = 0
    last_output: str | None = None
    last_end = -1
    cwd = Path.cwd()
    os.chdir(workdir)
    try:
        for m in _FENCE.finditer(text):
            lang, body = m.group(1), m.group(2)
            out.append(text[pos : m.start()])
            if lang == "python":
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf):
                    exec(compile(body, "<tutorial>", "exec"), namespace)
                last_output, last_end = buf.getvalue(), m.end()
                out.append(m.group(0))
            elif lang == "text" and last_output is not None and not text[last_end : m.start()].strip():
                lines = [ln.rstrip() for ln in last_output.splitlines()]
                out.append("```text\n" + "\n".join(lines) + "\n```\n")
                last_output = None
            else:
                out.append(m.group(0))
            pos = m.end()
        out.append(text[pos:])
    finally:
        os.chdir(cwd)
    return "".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pages", nargs="*", type=Path, help="tutorial pages (default: all)")
    parser.add_argument("--check", action="store_true", help="only report pages whose output changed")
    args = parser.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    pages = args.pages or sorted(TUTORIALS.glob("*.md"))
    changed = []
    for page in pages:
        old = page.read_text(encoding="utf-8")
        with tempfile.TemporaryDirectory() as tmp:
            new = refresh(old, Path(tmp))
        if new != old:
            changed.append(page)
            if not args.check:
                page.write_text(new, encoding="utf-8")
        print(f"{page}: {'changed' if new != old else 'up to date'}")
    return 1 if (args.check and changed) else 0


if __name__ == "__main__":
    sys.exit(main())
