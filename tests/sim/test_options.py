"""simulate's options as values (Solver, EventSet, Output) and their flat shorthands."""

from __future__ import annotations

import numpy as np
import pytest

import nonmin
from nonmin import EventSet, Output, Solver, library, simulate
from nonmin.errors import InputError
from nonmin.sim import Event


@pytest.fixture(scope="module")
def four_bar():  # type: ignore[no-untyped-def]
    return library.get("crossed_four_bar")


def test_values_give_bitwise_the_run_of_the_flat_keywords(four_bar) -> None:  # type: ignore[no-untyped-def]
    t = np.linspace(0.0, 0.2, 11)
    flat = simulate(four_bar, (0.0, 0.2), method="dopri5", rtol=1e-9, atol=1e-11, t_eval=t, progress=False)
    grouped = simulate(four_bar, (0.0, 0.2), solver=Solver("dopri5", rtol=1e-9, atol=1e-11),
                       output=Output(t_eval=t, progress=False))  # fmt: skip
    assert np.array_equal(flat.q, grouped.q) and np.array_equal(flat.qd, grouped.qd)
    assert flat.metadata["options"] == grouped.metadata["options"]


def test_method_and_dt_shorthands_equal_the_solver(four_bar) -> None:  # type: ignore[no-untyped-def]
    a = simulate(four_bar, 0.05, method="rk4", dt=1e-3, progress=False)
    b = simulate(four_bar, 0.05, solver=Solver("rk4", dt=1e-3), progress=False)
    assert np.array_equal(a.q, b.q)
    # the same field given both ways with the same value is fine
    c = simulate(four_bar, 0.05, solver=Solver("rk4", dt=1e-3), dt=1e-3, progress=False)
    assert np.array_equal(a.q, c.q)


def test_contradicting_a_value_names_the_field(four_bar) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=r"dt=0\.002 contradicts the Solver value given \(Solver\.dt = 0\.001\)"):
        simulate(four_bar, 0.05, solver=Solver(dt=1e-3), dt=2e-3)
    with pytest.raises(InputError, match=r"restitution=0\.5 contradicts the EventSet"):
        simulate(four_bar, 0.05, events=EventSet(restitution=0.2), restitution=0.5)
    with pytest.raises(InputError, match=r"throw=False contradicts the Output"):
        simulate(four_bar, 0.05, output=Output(), throw=False)


def test_unknown_keyword_lists_values_and_shorthands(four_bar) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=r"unknown keyword argument\(s\) \['stepsize'\].*solver=.*'rtol'"):
        simulate(four_bar, 0.05, stepsize=1e-3)


@pytest.mark.parametrize(
    ("make", "needle"),
    [
        (lambda: Solver(dt=-1.0), "dt must be a positive finite number, got -1.0"),
        (lambda: Solver(rtol=0), "rtol must be a positive finite number, got 0"),
        (lambda: Solver(rank_rtol=2.0), r"rank_rtol must lie in \(0, 1\), got 2.0"),
        (lambda: Solver(max_steps=0), "max_steps must be an integer ≥ 1, got 0"),
        (lambda: Solver(method=3), "method must be an Integrator object or a method name, got int"),
        (lambda: EventSet(restitution=1.5), r"restitution must lie in \[0, 1\], got 1.5"),
        (lambda: EventSet(restitution={"floor": -0.1}), r"restitution\['floor'\] must lie in \[0, 1\]"),
        (lambda: EventSet(events=[3]), "events must be Event values, got int"),
        (lambda: EventSet(zeno_window=0.0), "zeno_window must be a positive finite number"),
        (lambda: EventSet(event_rearm=float("nan")), "event_rearm must be ≥ 0"),
        (lambda: Output(t_eval="abc"), "t_eval must be an array of times, got str"),
    ],
)
def test_values_validate_where_they_are_written(make, needle) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=needle):
        make()


def test_wrong_value_types_are_named(four_bar) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(InputError, match=r"solver must be a nonmin\.sim\.Solver value, got dict"):
        simulate(four_bar, 0.05, solver={"dt": 1e-3})
    with pytest.raises(InputError, match=r"output must be a nonmin\.sim\.Output value, got list"):
        simulate(four_bar, 0.05, output=[0.0, 0.1])


def test_event_set_takes_events_and_contact_settings(four_bar) -> None:  # type: ignore[no-untyped-def]
    ev = Event(lambda t, q, qd, f_c: t - 0.02, direction=1, name="late")
    es = EventSet([ev], contact=False)
    assert es.events == (ev,) and es.contact is False
    assert EventSet(ev).events == (ev,)
    a = simulate(four_bar, 0.05, dt=1e-3, events=es, progress=False)
    b = simulate(four_bar, 0.05, dt=1e-3, events=[ev], contact=False, progress=False)
    assert [r.name for r in a.events] == [r.name for r in b.events] == ["late"]
    assert np.array_equal(a.q, b.q)


def test_values_are_frozen_and_compare() -> None:
    s = Solver("rk4", dt=1e-3)
    with pytest.raises(AttributeError):
        s.dt = 2e-3  # type: ignore[misc]
    assert s == Solver(method="rk4", dt=1e-3)
    assert Output(t_eval=[0.0, 1.0]) == Output(t_eval=np.array([0.0, 1.0]))
    assert Output(t_eval=[0.0, 1.0]) != Output(t_eval=[0.0, 2.0])
    t = Output(t_eval=[0.0, 1.0]).t_eval
    assert t is not None and not t.flags.writeable


def test_values_are_exported_at_the_top() -> None:
    assert nonmin.Solver is Solver and nonmin.EventSet is EventSet and nonmin.Output is Output


def test_text_and_booleans_are_not_numbers_for_dt_and_t_span() -> None:
    """simulate(m, "1", dt="1e-3") ran (float() parses text); dt=True was already refused."""
    import pytest

    from nonmin import library, simulate
    from nonmin.errors import InputError

    bar = library.get("crossed_four_bar")
    with pytest.raises(InputError, match="dt must be a positive finite number, got '1e-3'"):
        simulate(bar, 0.01, dt="1e-3")
    with pytest.raises(InputError, match="t_span must be"):
        simulate(bar, "1", dt=1e-3)
    with pytest.raises(InputError, match="t_span must be"):
        simulate(bar, (0.0, "1"), dt=1e-3)
    with pytest.raises(InputError, match="rtol must be a positive finite number"):
        simulate(bar, 0.01, method="dopri5", rtol="1e-6")


def test_t_eval_must_be_a_non_empty_1d_array_of_numbers() -> None:
    """t_eval=np.zeros((2, 2)) was flattened (one sample), t_eval=[] gave a 'success' run with no
    sample at all, and t_eval=["0", "0.01"] was parsed."""
    import pytest

    from nonmin import library, simulate
    from nonmin.errors import InputError, ShapeError

    bar = library.get("crossed_four_bar")
    with pytest.raises(ShapeError, match=r"t_eval must be a non-empty 1-D array of times, got shape \(2, 2\)"):
        simulate(bar, 0.01, dt=1e-3, t_eval=np.zeros((2, 2)))
    with pytest.raises(ShapeError, match=r"got shape \(0,\)"):
        simulate(bar, 0.01, dt=1e-3, t_eval=[])
    with pytest.raises(InputError, match="t_eval"):
        simulate(bar, 0.01, dt=1e-3, t_eval=["0", "0.01"])
    assert len(simulate(bar, 0.01, dt=1e-3, t_eval=0.01)) == 1  # one time is one sample
