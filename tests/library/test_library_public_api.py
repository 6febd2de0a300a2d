"""The public surfaces of nonmin.library and nonmin.model.planar are curated and pinned."""

import nonmin.library as lib
import nonmin.model.planar as planar


def test_library_public_names():
    assert {
        "Mechanism",
        "AndrewsModel",
        "a01_pendulum",
        "a02_n_four_bar",
        "a03_andrews",
        "arm2r_wall",
        "crossed_four_bar",
        "crossed_four_bar_reference",
        "dual_arm_grasp",
        "five_bar",
        "get",
        "n_four_bar_reference",
        "names",
        "register",
        "slider_crank",
    } <= set(lib.__all__)
    for name in lib.__all__:
        assert getattr(lib, name).__doc__, name


def test_planar_public_names():
    assert set(planar.__all__) == {
        "GROUND", "AngleDriver", "AngleLimit", "Body", "ConstantSpeed", "ContactTangent", "Gear", "Joint",
        "JointActuator",
        "PlanarBuilder", "PlanarModel", "Point", "PointForce", "PointOnLine", "PointRef",
        "Prismatic", "Revolute", "Rod", "RotationalSpring", "Spring", "Torque", "Weld",
    }
    for name in planar.__all__:
        assert hasattr(planar, name)


def test_horizon_and_parameter_errors_are_named() -> None:
    """t_final=-1 or NaN built a Mechanism with that horizon; omega0=NaN said only "q and qd
    must be finite", naming neither the mechanism nor the parameter."""
    import math

    import pytest

    from nonmin import library
    from nonmin.errors import InputError, NonFiniteError

    for bad in (-1.0, 0.0, math.nan, math.inf):
        with pytest.raises(InputError, match="t_final must be a positive finite horizon"):
            library.get("crossed_four_bar", t_final=bad)
    with pytest.raises(NonFiniteError, match=r"mechanism 'crossed_four_bar' with parameters \{'omega0': nan\}"):
        library.get("crossed_four_bar", omega0=math.nan)
