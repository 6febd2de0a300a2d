"""Issue 19's corpus of bad inputs and faults: every case must end in the exact typed error
naming the argument, file or key, with no file lost and no code run (see corpus.py).

The fast cases run in the default suite; the fault cases in subprocesses (a file-size limit, a
kill -9 in mid-write) are marked slow. Totals: ``python tests/reliability/run_corpus.py``.
"""

from __future__ import annotations

import corpus
import pytest


@pytest.mark.parametrize("case", corpus.fast_cases(), ids=lambda c: c.id)
def test_case_is_typed_and_clear(case: corpus.Case, tmp_path) -> None:
    out = corpus.classify(case, tmp_path)
    if case.known_issue:
        corpus._check_known(case, out)
    assert out.kind == "typed and clear", f"{out.kind}: {out.detail}"


@pytest.mark.slow
@pytest.mark.parametrize("case", [c for c in corpus.CASES if c.slow], ids=lambda c: c.id)
def test_fault_case_is_typed_and_clear(case: corpus.Case, tmp_path) -> None:
    out = corpus.classify(case, tmp_path)
    if case.known_issue:
        corpus._check_known(case, out)
    assert out.kind == "typed and clear", f"{out.kind}: {out.detail}"


def test_corpus_is_large_and_covers_every_category() -> None:
    assert len(corpus.CASES) >= 300
    cats = {c.category for c in corpus.CASES}
    for word in ("security", "durability", "trajectory files", "API", "callbacks", "scenario", "command line",
                 "robot files"):
        assert any(word in c for c in cats), word
