"""Validation records, report writer, reference data and the Test Set score (fast, no simulation)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nonmin.errors import InputError, ShapeError
from nonmin.validation import (
    Check,
    ValidationRecord,
    a02_parallelogram_reference,
    format_table,
    load_a01_exact,
    load_a02_n2_exact,
    load_a03_reference,
    significant_digits,
    write_report,
)


def test_check_comparisons() -> None:
    assert Check("a", 1e-9, 1e-8, "<=").passed
    assert not Check("a", 1e-7, 1e-8, "<=").passed
    assert Check("s", 8.5, 8.0, ">=").passed
    assert not Check("s", 7.9, 8.0, ">=").passed
    assert Check("b", True, True, "==").passed
    assert not Check("b", False, True, "==").passed
    assert not Check("nan", math.nan, 1.0, "<=").passed
    assert not Check("inf", math.inf, 1.0, "<=").passed
    assert Check("r", 123.0).passed  # reported only


def test_record_passed_and_table() -> None:
    ok = ValidationRecord("good", (Check("x", 1.0, 2.0, "<="), Check("y", "text")), wall_time=0.5)
    bad = ValidationRecord("bad", (Check("x", 3.0, 2.0, "<=", "m"),), wall_time=1.0)
    broken = ValidationRecord("broken", (), error="SimulationError: boom")
    assert ok.passed and not bad.passed and not broken.passed
    assert ok.check("x").value == 1.0
    with pytest.raises(KeyError):
        ok.check("nope")
    table = format_table([ok, bad, broken])
    assert "FAIL" in table and "pass" in table
    assert "1/3 benchmarks passed" in table
    assert "bad" in table.splitlines()[-1] and "broken" in table.splitlines()[-1]
    d = bad.to_dict()
    assert d["passed"] is False and d["checks"][0]["unit"] == "m"


def test_write_report(tmp_path) -> None:  # type: ignore[no-untyped-def]
    rec = ValidationRecord("A00 demo", (Check("err | pipe", 1e-12, 1e-8, "<=", "m"),),
                           settings={"method": "rk4", "dt": 1e-3}, reference="closed form",
                           wall_time=0.25, notes="a note")
    p = write_report([rec], tmp_path / "sub" / "validation.md", command="nonmin validate --full")
    text = p.read_text(encoding="utf-8")
    assert "`nonmin validate --full`" in text
    assert "## Machine" in text and "cpu_count" in text and "load_average" in text
    assert "err \\| pipe" in text and "a note" in text and "1/1 benchmarks" in text


def test_reference_files_match_the_benchmark_statement() -> None:
    a01 = load_a01_exact(10.0)
    assert a01.shape[1] == 5 and a01[-1, 0] == 10.0
    np.testing.assert_allclose(a01[-1, 1:3], [0.275087462576117, -0.961419205099125], atol=1e-12)
    a01l = load_a01_exact(2000.0)
    np.testing.assert_allclose(a01l[-1, 1:3], [-0.814603068589032, -0.580018827836935], atol=1e-12)
    with pytest.raises(InputError, match="horizon"):
        load_a01_exact(5.0)
    a02 = load_a02_n2_exact()
    row = a02[np.argmin(np.abs(a02[:, 0] - 10.0))]
    np.testing.assert_allclose(row[1:], [0.3284581115, 0.9445185382, 1.4230514702, -0.4948688455],
                               atol=1e-10)
    names, ref = load_a03_reference()
    assert len(names) == 27 and names[0] == "beta"
    assert ref[0] == pytest.approx(15.81077119629904, abs=1e-14)


def test_a02_reduction_matches_the_exact_file() -> None:
    data = load_a02_n2_exact()[:1001]
    theta, omega = a02_parallelogram_reference(2, data[:, 0])
    np.testing.assert_allclose(np.cos(theta), data[:, 1], atol=2e-11)
    np.testing.assert_allclose(np.sin(theta), data[:, 2], atol=2e-11)
    np.testing.assert_allclose(-np.sin(theta) * omega, data[:, 3], atol=2e-10)
    with pytest.raises(InputError):
        a02_parallelogram_reference(0, data[:, 0])
    with pytest.raises(ShapeError):
        a02_parallelogram_reference(2, np.zeros((2, 2)))


def test_significant_digits_formula() -> None:
    ref = np.array([10.0, -2.0])
    y = ref + np.array([1.1e-7, 3e-9])
    score, per = significant_digits(y, ref, rtol=1e-6, atol=1e-6)
    # denominators atol/rtol + |ref| = 11 and 3
    np.testing.assert_allclose(per, -np.log10([1.1e-7 / 11.0, 3e-9 / 3.0]))
    assert score == pytest.approx(8.0)
    exact, _ = significant_digits(ref, ref, rtol=1e-6, atol=1e-6)
    assert exact == math.inf
    with pytest.raises(ShapeError):
        significant_digits(ref, ref[:1], rtol=1.0, atol=1.0)


def test_record_round_trip() -> None:
    rec = ValidationRecord("x", (Check("a", 1e-9, 1e-8, "<=", "m"), Check("b", True, True, "=="),
                                 Check("c", math.inf, 1.0, "<="), Check("d", "text")),
                           settings={"dt": 1e-3}, wall_time=2.0, notes="n", quick=True)
    back = ValidationRecord.from_dict(rec.to_dict())
    assert back.to_dict() == rec.to_dict()
    assert not back.check("c").passed


def test_module_cli_assembles_saved_records(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import json

    from nonmin.validation.__main__ import main

    good = ValidationRecord("g", (Check("x", 1.0, 2.0, "<="),), wall_time=1.0)
    bad = ValidationRecord("b", (Check("x", 3.0, 2.0, "<="),), wall_time=1.0)
    f1, f2 = tmp_path / "g.json", tmp_path / "b.json"
    f1.write_text(json.dumps(good.to_dict()))
    f2.write_text(json.dumps([bad.to_dict()]))
    notes = tmp_path / "notes.md"
    notes.write_text("Runs made one per process.")
    report = tmp_path / "v.md"
    assert main(["--assemble", str(f1), "--report", str(report), "--notes-file", str(notes)]) == 0
    assert "Runs made one per process." in report.read_text()
    assert main(["--assemble", str(f1), str(f2)]) == 1


def test_a04_period_quadrature_converges() -> None:
    """The A04 period from the 1-DOF energy integral (product-of-exponentials loop, independent
    of nonmin's models): 24 … 64 Gauss–Legendre nodes agree to ~2e-12 s (measured
    4.991711513688255 / 4.99171151368736 / 4.991711513686187 with 24 / 40 / 64; DOPRI5 and DOP853
    at rtol 1e-12 put nonmin's turning points within 1.8e-12 s of k·T/2)."""
    from nonmin.validation import a04_bricard_period
    from nonmin.validation._references import _a04_closure, _a04_solve

    assert abs(a04_bricard_period(nodes=32) - 4.991711513688) < 1e-10
    # the other turning point: θ1 = π with the symmetric closure θ1 = θ3 = θ5, θ2 = θ4 = θ6
    th = np.zeros(6)
    while th[0] < 3.0:
        th = _a04_solve(th[0] + 0.05, th)
    assert np.abs(_a04_closure(th)).max() < 1e-14
    np.testing.assert_allclose(th[[0, 2, 4]], th[0], atol=1e-12)
    np.testing.assert_allclose(th[[1, 3, 5]], th[1], atol=1e-12)
