"""The validation benchmarks: quick versions in the default suite, full ones marked slow.

Each test runs one benchmark of :mod:`nonmin.validation` and demands that every stated target
is met; the record's table is printed on failure so the numbers are in the test log.
"""

from __future__ import annotations

import pytest

from nonmin.errors import UnknownNameError
from nonmin.validation import (
    BENCHMARKS,
    ValidationRecord,
    a01_pendulum,
    a02_n_four_bar,
    a03_andrews,
    a04_bricard,
    arm2r_wall,
    crossed_four_bar,
    format_table,
    run_all,
)


def _assert_passed(rec: ValidationRecord) -> None:
    assert not rec.error, rec.error
    assert rec.passed, "\n" + format_table([rec])


def test_a01_quick() -> None:
    rec = a01_pendulum(quick=True)
    _assert_passed(rec)
    assert rec.check("max |P1 − P1_exact| over the run").value < 1e-6  # type: ignore[operator]


def test_a02_n2_quick_passes_the_first_singular_configuration() -> None:
    rec = a02_n_four_bar(2, quick=True)
    _assert_passed(rec)
    assert rec.check("singular (horizontal) configurations passed").value == 1
    assert rec.check("max |B0 − B0_ref| over the run").value < 1e-8  # type: ignore[operator]


def test_a02_horizontal_times_lie_on_the_reduction() -> None:
    """The located singular configurations are where the reduction's crank is horizontal."""
    import numpy as np

    from nonmin.validation._references import a02_parallelogram_reference
    from nonmin.validation._suite import _a02_horizontal_times

    t40 = _a02_horizontal_times(40, 20.0)
    assert t40.size == 20  # the N = 40 crank turns over: one horizontal passage per half turn
    assert abs(t40[0] - 0.7215) < 1e-3
    theta, _ = a02_parallelogram_reference(40, np.concatenate([[0.0], t40]))
    assert np.max(np.abs(np.sin(theta[1:]))) < 1e-9
    assert _a02_horizontal_times(2, 10.0).size == 10
    assert _a02_horizontal_times(40, 0.05).size == 0


def test_a03_quick() -> None:
    _assert_passed(a03_andrews(quick=True))


def test_a04_quick_redundant_constraint() -> None:
    rec = a04_bricard(quick=True)
    _assert_passed(rec)
    rows, ranks = str(rec.check("constraint rows / rank of A (min, max)").value).split(" / ")
    assert int(rows) == int(ranks.split(",")[0]) + 1  # exactly one redundant row


def test_crossed_four_bar_quick_through_a_change_point() -> None:
    rec = crossed_four_bar(quick=True)
    _assert_passed(rec)
    assert rec.check("change points passed (reference)").value >= 1  # type: ignore[operator]


def test_arm2r_wall_quick_impact_and_release() -> None:
    rec = arm2r_wall(quick=True)
    _assert_passed(rec)
    assert rec.check("contact released").value is True


def test_run_all_rejects_unknown_names() -> None:
    with pytest.raises(UnknownNameError, match="A99"):
        run_all(quick=True, only=["A99"])


@pytest.mark.slow
@pytest.mark.parametrize("key", sorted(BENCHMARKS))
def test_full_benchmark(key: str) -> None:
    _assert_passed(BENCHMARKS[key](False))
