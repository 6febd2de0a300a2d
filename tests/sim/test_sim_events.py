"""Events: location to 1e-10 s, transitions as values, terminal events."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import ellipk

from conftest import G, make_pendulum
from nonmin.errors import InputError
from nonmin.model import FunctionConstraint, FunctionModel
from nonmin.sim import Activate, Deactivate, Event, Reset, Status, simulate

EVENT_TOL = 1e-10

#: Exact quarter period of the A01 pendulum released from the horizontal: T/4 = K(1/2)/√g.
QUARTER = float(np.sqrt(1.0 / G) * ellipk(0.5))


def _bottom(t: float, q: np.ndarray, qd: np.ndarray, f_c: np.ndarray) -> float:
    return float(q[0])


@pytest.mark.parametrize(
    "kw",
    [
        {"dt": 1e-3},
        {"method": "dopri5", "rtol": 1e-12, "atol": 1e-14},
    ],
    ids=["rk4", "dopri5"],
)
def test_pendulum_bottom_crossing_located_to_1e_10(kw: dict) -> None:
    ev = Event(_bottom, direction=-1, name="bottom")
    tr = simulate(make_pendulum(), (0.0, 0.8), [1.0, 0.0], events=[ev], **kw)
    assert [e.name for e in tr.events] == ["bottom"]
    assert abs(tr.events[0].t - QUARTER) < EVENT_TOL
    # the event time is also a sample (before and after the transition)
    assert np.count_nonzero(tr.t == tr.events[0].t) == 2


def test_direction_filters_crossings() -> None:
    up = Event(_bottom, direction=+1, name="up")
    both = Event(_bottom, direction=0, name="both")
    tr = simulate(make_pendulum(), (0.0, 2.0), [1.0, 0.0], dt=2e-3, events=[up, both])
    names = [e.name for e in tr.events]
    # x crosses 0 downward at T/4 and upward at 3T/4 (T = 2.3678 s)
    assert names.count("both") == 2
    assert names.count("up") == 1
    t_up = next(e.t for e in tr.events if e.name == "up")
    assert abs(t_up - 3 * QUARTER) < 1e-8


def test_terminal_event_stops_with_status() -> None:
    ev = Event(_bottom, direction=-1, terminal=True, name="stop")
    tr = simulate(make_pendulum(), (0.0, 5.0), [1.0, 0.0], dt=1e-3, events=[ev])
    assert tr.status is Status.EVENT_TERMINATED
    assert tr.success
    assert abs(tr.t[-1] - QUARTER) < EVENT_TOL
    assert "stop" in tr.message


def _free_point_with_rod() -> FunctionModel:
    """A free point mass (x, y) with a rod to the origin that can be switched on."""
    rod = FunctionConstraint.holonomic(
        "rod",
        phi=lambda q: [0.5 * (q @ q - 1.0)],
        jacobian=lambda q: q[None, :],
        adot_qd=lambda q, qd: [qd @ qd],
    )
    return FunctionModel(
        name="point",
        coordinate_names=("x", "y"),
        mass=lambda q: np.diag([2.0, 2.0]),
        coriolis=lambda q, qd: np.zeros((2, 2)),
        conservative=lambda q: [0.0, -2.0 * G],
        potential=lambda q: 2.0 * G * q[1],
        constraints=(rod,),
        default_active=(),
    )


def test_activate_applies_the_impact_map_and_deactivate_releases() -> None:
    """A falling point is caught by a rod when |q| reaches 1: plastic impact, then pendulum."""
    model = _free_point_with_rod()

    def reach(t: float, q: np.ndarray, qd: np.ndarray, f_c: np.ndarray) -> float:
        return float(q @ q - 1.0)

    catch = Event(reach, direction=+1, transition=Activate("rod"), name="catch")
    tr = simulate(model, (0.0, 0.6), [0.6, 0.0], [0.0, 0.0], dt=1e-3, events=[catch])
    (ev,) = tr.events
    # free fall from (0.6, 0): |q| = 1 at y = -0.8, t = sqrt(1.6/g)
    assert abs(ev.t - np.sqrt(2 * 0.8 / G)) < EVENT_TOL
    q, v = ev.q_before, ev.qd_before
    r = q / np.linalg.norm(q)
    expected = v - (v @ r) * r  # classical plastic impact: the radial velocity is removed
    assert np.allclose(ev.qd_after, expected, atol=1e-12)
    assert ev.active_before == frozenset() and ev.active_after == frozenset({"rod"})
    after = tr.t > ev.t
    assert tr.phi_norm[after].max() < 1e-10
    assert all(a == frozenset({"rod"}) for a, keep in zip(tr.active, after, strict=True) if keep)

    drop = Event(lambda t, q, qd, f_c: t - 0.5, transition=Deactivate("rod"), name="drop")
    tr2 = simulate(model, (0.0, 0.6), [0.6, 0.0], [0.0, 0.0], dt=1e-3, events=[catch, drop])
    assert [e.name for e in tr2.events] == ["catch", "drop"]
    assert tr2.active[-1] == frozenset()
    assert abs(tr2.events[1].t - 0.5) < EVENT_TOL


def test_reset_transition_maps_the_state() -> None:
    def flip(t: float, q: np.ndarray, qd: np.ndarray, active: frozenset[str]) -> tuple:
        return q, -qd, active

    ev = Event(_bottom, direction=-1, transition=Reset(flip), name="flip")
    tr = simulate(make_pendulum(), (0.0, 0.8), [1.0, 0.0], dt=1e-3, events=[ev])
    (rec,) = tr.events
    assert np.allclose(rec.qd_after, -rec.qd_before)
    # swinging back: x > 0 again at the end
    assert tr.q[-1, 0] > 0


def test_event_values_validate() -> None:
    with pytest.raises(InputError, match="direction"):
        Event(_bottom, direction=2)
    with pytest.raises(InputError, match="callable"):
        Event(guard=3.0)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="restitution"):
        Activate("rod", restitution=1.5)
    with pytest.raises(InputError, match="names"):
        Deactivate([])
    with pytest.raises(InputError, match="transition"):
        Event(_bottom, transition="rod")  # type: ignore[arg-type]
