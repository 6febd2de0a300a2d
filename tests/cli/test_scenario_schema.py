"""Malformed scenario files give ScenarioError naming the file, the key, expected and received."""

from pathlib import Path

import pytest

from nonmin.errors import ScenarioError
from nonmin.io import SCENARIO_SCHEMA, load_scenario

ROOT = Path(__file__).resolve().parents[2]


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        ('[model]\nlibrary = "A01_pendulum"\n[simulate]\ndt = "fast"\n', ["simulate.dt", "expected a number", "string 'fast'"]),
        ('[model]\nlibrary = "A01_pendulum"\n[simulate]\nstepsize = 1\n', ["unknown key 'simulate.stepsize'", "expected one of"]),
        ('[model]\nlibrary = 3\n', ["model.library", "expected a string", "integer 3"]),
        ('[simulate]\nt_final = 1.0\n', ["missing required table [model]"]),
        ('[model]\nlibrary = "x"\n[initial]\nq = [1, "a"]\n', ["initial.q[1]", "expected a list of a number"]),
        ('[model]\nlibrary = "x"\n[[events]]\nat_time = 1.0\n', ["missing required key 'events[0].name'"]),
        ('[model]\nlibrary = "x"\n[[events]]\nname = "e"\ntransition = "explode"\n', ["events[0].transition", "one of"]),
        ('[model]\nlibrary = "x"\nbogus = 1\n', ["unknown key 'model.bogus'"]),
        ('[model\nlibrary = "x"\n', ["not valid TOML"]),
        ('[model]\nlibrary = "x"\n[output]\nplots = "yes"\n', ["output.plots", "expected a boolean"]),
    ],
)
def test_malformed_scenarios(tmp_path, text, fragments):
    p = _write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(p)
    msg = str(info.value)
    assert str(p) in msg
    for frag in fragments:
        assert frag in msg, msg


def test_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario(tmp_path / "nope.toml")


def test_every_schema_key_is_documented():
    doc = (ROOT / "docs" / "scenarios.md").read_text()

    def walk(section, prefix=""):
        for k in section.keys:
            yield prefix + k, k
        for k, sub in section.sections.items():
            yield from walk(sub, prefix + k + ".")
        for k, sub in section.array_sections.items():
            yield from walk(sub, prefix + k + ".")

    for path, key in walk(SCENARIO_SCHEMA):
        assert f"`{key}`" in doc, f"docs/scenarios.md does not document {path}"


EXAMPLES = ROOT / "examples"


def test_planar_description_and_urdf_constraints_build(tmp_path):
    from nonmin.io import run_scenario

    sc = load_scenario(EXAMPLES / "slider_crank_planar.toml")
    res = run_scenario(sc, tmp_path / "sc", t_final=0.2, progress=False, write=False)
    traj = res.trajectory
    assert traj.status.value == "success" and traj.phi_norm.max() < 1e-10
    assert res.model.n == 9 and "motor" in res.model.constraint_names
    pytest.importorskip("pinocchio")
    sc = load_scenario(EXAMPLES / "fourbar_urdf.toml")
    res = run_scenario(sc, tmp_path / "fb", t_final=0.2, progress=False, write=False)
    m = res.model
    assert m.constraint("closure").dim == 3
    assert set(res.trajectory.rank.tolist()) == {2}  # a 3D point closure of a planar loop: rank 2
    assert res.trajectory.energy_drift < 1e-6


@pytest.mark.parametrize(
    ("items", "fragment"),
    [
        ('[[model.planar.items]]\ncall = "explode"\n', "model.planar.items[0].call: expected one of"),
        ('[[model.planar.items]]\ncall = "body"\nname = "b"\nmass = 1.0\n', "missing key(s) ['inertia']"),
        ('[[model.planar.items]]\ncall = "body"\nname = "b"\nmass = 1.0\ninertia = 1.0\ncolour = "red"\n',
         "unknown key(s) ['colour']"),
        ('[[model.planar.items]]\ncall = "body"\nname = "b"\nmass = -1.0\ninertia = 1.0\n', "items[0]"),
    ],
)
def test_bad_planar_descriptions(tmp_path, items, fragment):
    p = _write(tmp_path, "[model.planar]\n" + items)
    sc = load_scenario(p)
    with pytest.raises(ScenarioError) as info:
        sc.build_model()
    assert str(p) in str(info.value) and fragment in str(info.value), str(info.value)


def test_bad_frame_constraint(tmp_path):
    p = _write(
        tmp_path,
        '[model]\nurdf = "x.urdf"\n[[model.constraints]]\ntype = "glue"\nname = "c"\n',
    )
    (tmp_path / "x.urdf").write_text("<robot name='x'><link name='a'/></robot>")
    with pytest.raises(ScenarioError, match=r"model.constraints\[0\].type: expected one of"):
        load_scenario(p).build_model()


def test_frame_constraint_vector_with_text_names_the_key(tmp_path):
    """placement_a = [1, "x", 2] was 'table [model.params]: ValueError: could not convert string
    to float' (the wrong table, a raw message)."""
    pytest.importorskip("pinocchio")
    from nonmin.model.robots import data_path

    p = _write(tmp_path, f'[model]\nurdf = "{data_path("fourbar.urdf")}"\n[[model.constraints]]\ntype = "point"\n'
                         'name = "c"\nframe_a = "coupler_tip"\nframe_b = "rocker_tip"\nplacement_a = [1, "x", 2]\n')  # fmt: skip
    with pytest.raises(ScenarioError, match=r"key model.constraints\[0\].placement_a: expected a list of numbers"):
        load_scenario(p).build_model()


_OPTIONS_BASE = '[model]\nlibrary = "crossed_four_bar"\n[simulate]\nt_final = 0.05\n{extra}[simulate.options]\n{opt}\n'


@pytest.mark.parametrize(
    ("opt", "extra", "fragments"),
    [
        # the runner sets these itself: they were "got multiple values" TypeErrors (exit 4)
        ('throw = true', "", ["simulate.options.throw"]),
        ('progress = true', "", ["simulate.options.progress", "--progress"]),
        ('controller = "x"', "", ["simulate.options.controller", "[controller]"]),
        ('events = []', "", ["simulate.options.events", "[[events]]"]),
        ('active = ["A"]', "", ["simulate.options.active", "initial.active"]),
        # file names from a data file outside the output folder (checkpoint wrote anywhere)
        ('checkpoint = "{escape}"', "", ["simulate.options.checkpoint", "--checkpoint-every"]),
        ('checkpoint_every = 0.01', "", ["simulate.options.checkpoint_every", "--checkpoint-every"]),
        ('resume = "/tmp/x.npz"', "", ["simulate.options.resume", "--resume"]),
        # output_dt silently won over t_eval
        ('t_eval = [0.0, 0.05]', "output_dt = 0.01\n", ["simulate.options.t_eval", "simulate.output_dt"]),
    ],
)
def test_simulate_options_the_runner_owns_are_refused(tmp_path, opt, extra, fragments):
    """[simulate.options] cannot set what the runner sets itself, nor name files to write or read."""
    from nonmin.io import run_scenario

    escape = tmp_path / "elsewhere" / "escaped.npz"
    p = _write(tmp_path, _OPTIONS_BASE.format(opt=opt.replace("{escape}", str(escape)), extra=extra))
    sc = load_scenario(p)
    with pytest.raises(ScenarioError) as info:
        run_scenario(sc, tmp_path / "out", progress=False)
    msg = str(info.value)
    assert str(p) in msg
    for frag in fragments:
        assert frag in msg, msg
    assert not escape.exists()
    assert not (tmp_path / "out" / "trajectory.npz").exists()


@pytest.mark.parametrize(
    ("table", "fragments"),
    [
        ('type = "regulator"\nKp = 10.0\n', ["missing key 'controller.target'", "'regulator'"]),
        ('type = "force_control"\n', ["'controller.target'", "'controller.forces'", "'force_control'"]),
    ],
)
def test_controller_table_without_a_required_key_names_it(tmp_path, table, fragments):
    """A [controller] table without its target said "_regulator() missing 1 required
    keyword-only argument: 'target'" (an internal name)."""
    from nonmin.io import run_scenario

    p = _write(tmp_path, '[model]\nlibrary = "five_bar"\n[simulate]\nt_final = 0.01\n[controller]\n' + table)
    with pytest.raises(ScenarioError) as info:
        run_scenario(load_scenario(p), tmp_path / "out", progress=False)
    msg = str(info.value)
    assert "_regulator" not in msg and "_hybrid_force" not in msg, msg
    for frag in fragments:
        assert frag in msg, msg
