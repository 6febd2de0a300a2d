"""Run the pages (README and tutorials), and check or rewrite the output they show.

Usage::

    python docs/refresh_tutorials.py [PAGE.md ...]            # rewrite the output blocks
    python docs/refresh_tutorials.py --check [PAGE.md ...]    # exit 1 when a page is stale

A page's ```python blocks run in order in one namespace (in a temporary directory, or
``--workdir``, with the Agg backend); a ```text block that directly follows a python block
(only blank lines in between) shows what that block prints. ``--check`` rewrites nothing: it
compares each shown block with what the code prints now, word by word, numbers by value
(:func:`same_output`: equal, or within 1e-9 relative, or both below 1e-12 in magnitude — the
round-off class, whose digits differ between BLAS builds), prints a diff of every stale block
and exits with status 1. Blocks fenced as ```py are shown, not run (snippets that open a
browser or need a user's file; they are tested elsewhere). ``--echo`` also prints everything
the page printed (the test suite checks its claims in it: ``tests/docs/test_tutorials.py``).
Default pages: README.md and docs/tutorials/*.md.
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import io
import os
import re
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

DOCS = Path(__file__).resolve().parent
TUTORIALS = DOCS / "tutorials"
ROOT = DOCS.parent
_FENCE = re.compile(r"^```(\w+)\n(.*?)^```\n", flags=re.S | re.M)
_TOKEN = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?|\w+|[^\w\s]")


class Shown(NamedTuple):
    """A ```text block that shows a python block's output: where it is, what it says, and
    what the code printed."""

    start: int
    end: int
    shown: str
    printed: str


def run_page(text: str, workdir: Path) -> tuple[list[Shown], str]:
    """Run a page's python blocks in ``workdir``; its output blocks and everything printed."""
    namespace: dict[str, object] = {"__name__": "__main__"}
    blocks: list[Shown] = []
    everything: list[str] = []
    last_output: str | None = None
    last_end = -1
    cwd = Path.cwd()
    os.chdir(workdir)
    try:
        for m in _FENCE.finditer(text):
            lang, body = m.group(1), m.group(2)
            if lang == "python":
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf):
                    exec(compile(body, "<page>", "exec"), namespace)
                last_output, last_end = buf.getvalue(), m.end()
                everything.append(last_output)
            elif lang == "text" and last_output is not None and not text[last_end : m.start()].strip():
                printed = "\n".join(ln.rstrip() for ln in last_output.splitlines())
                blocks.append(Shown(m.start(), m.end(), body.rstrip("\n"), printed))
                last_output = None
    finally:
        os.chdir(cwd)
    return blocks, "".join(everything)


def refresh(text: str, workdir: Path) -> str:
    """The Markdown ``text`` with every output block replaced by the preceding block's output."""
    blocks, _ = run_page(text, workdir)
    out, pos = [], 0
    for b in blocks:
        out.append(text[pos : b.start])
        out.append("```text\n" + b.printed + "\n```\n")
        pos = b.end
    out.append(text[pos:])
    return "".join(out)


def _number(tok: str) -> float | None:
    try:
        return float(tok)
    except ValueError:
        return None


def same_output(shown: str, printed: str, *, rtol: float = 1e-9, tiny: float = 1e-12) -> bool:
    """Whether a shown output block says what the code printed: the same words and
    punctuation, and numbers equal within ``rtol`` (or both of magnitude ≤ ``tiny``)."""
    a, b = _TOKEN.findall(shown), _TOKEN.findall(printed)
    if len(a) != len(b):
        return False
    for x, y in zip(a, b, strict=True):
        if x == y:
            continue
        fx, fy = _number(x), _number(y)
        if fx is None or fy is None:
            return False
        if abs(fx) <= tiny and abs(fy) <= tiny:
            continue
        if abs(fx - fy) > rtol * max(abs(fx), abs(fy)):
            return False
    return True


def check_page(page: Path, workdir: Path) -> tuple[list[str], str]:
    """Run a page; the diffs of its stale output blocks (empty: up to date) and its output."""
    blocks, everything = run_page(page.read_text(encoding="utf-8"), workdir)
    diffs = []
    for b in blocks:
        if not same_output(b.shown, b.printed):
            diffs.append("".join(difflib.unified_diff(
                (b.shown + "\n").splitlines(keepends=True), (b.printed + "\n").splitlines(keepends=True),
                f"{page.name} (shown)", f"{page.name} (printed now)")))
    return diffs, everything


def default_pages() -> list[Path]:
    return [ROOT / "README.md", *sorted(TUTORIALS.glob("*.md"))]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("pages", nargs="*", type=Path, help="pages (default: README and tutorials)")
    parser.add_argument("--check", action="store_true", help="only report pages whose output changed")
    parser.add_argument("--workdir", type=Path, default=None, help="run in this folder (kept)")
    parser.add_argument("--echo", action="store_true", help="print everything the pages print")
    args = parser.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    pages = args.pages or default_pages()
    stale = []
    for page in pages:
        with tempfile.TemporaryDirectory() as tmp:
            work = args.workdir or Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            if args.check:
                diffs, everything = check_page(page, work)
                if diffs:
                    stale.append(page)
                    for d in diffs:
                        print(d, file=sys.stderr)
            else:
                old = page.read_text(encoding="utf-8")
                new = refresh(old, work)
                everything = ""
                if new != old:
                    stale.append(page)
                    page.write_text(new, encoding="utf-8")
        if args.echo:
            print(everything)
        print(f"{page}: {'stale' if page in stale and args.check else 'rewritten' if page in stale else 'up to date'}",
              file=sys.stderr)
    return 1 if (args.check and stale) else 0


if __name__ == "__main__":
    sys.exit(main())
