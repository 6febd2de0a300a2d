"""The curated public surface is pinned, and importing nonmin stays light."""

import subprocess
import sys

import nonmin

EXPECTED_TOP = {
    "Activate", "Deactivate", "Event", "EventSet", "Model", "Output", "Reset", "Solver", "State",
    "Trajectory", "__version__",
    "assemble", "check_model", "constraint_force", "control", "core", "errors",
    "forward_dynamics", "impact_map", "library", "load_trajectory", "model", "sim", "simulate",
    "analysis", "inverse_dynamics", "reactions",
    "simulate_batch", "sweep", "sweeps",
    "linear", "linearize", "equilibrium", "modes",
}

EXPECTED_CORE = {
    "DEFAULT_RTOL", "SPD_RTOL", "DynamicsSolution", "RangeBasis", "actuation_projectors",
    "baumgarte_bias", "constraint_force", "constraint_force_projector", "constraint_inertia",
    "coriolis_bar", "forward_dynamics", "impact_map", "lambda_matrix", "nullspace_projector",
    "optimal_virtual_mass", "position_correction", "projector_derivative", "pseudo_inverse",
    "range_basis", "solve_dynamics",
}


def test_top_level_public_set():
    assert set(nonmin.__all__) == EXPECTED_TOP
    for name in nonmin.__all__:
        assert getattr(nonmin, name) is not None


def test_core_contract_names_present():
    # the kernel contract (names and argument order) is part of nonmin.core
    assert EXPECTED_CORE <= set(nonmin.core.__all__)
    import inspect

    sig = inspect.signature(nonmin.core.forward_dynamics)
    assert list(sig.parameters)[:5] == ["M", "h", "A", "adot_qd", "f"]
    assert list(inspect.signature(nonmin.core.impact_map).parameters)[:3] == ["M", "A", "qd_minus"]
    assert list(inspect.signature(nonmin.core.coriolis_bar).parameters)[:5] == ["M", "C", "A", "Adot", "mu"]


def test_import_does_not_pull_optional_dependencies():
    code = (
        "import sys, nonmin, nonmin.model, nonmin.sim, nonmin.control, nonmin.library;"
        "heavy = [m for m in ('pinocchio', 'mujoco', 'sympy', 'matplotlib', 'numba', 'tqdm', 'xarray', 'zarr',"
        "'dask', 'distributed') if m in sys.modules];"
        "print(','.join(heavy))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"importing nonmin loaded optional packages: {res.stdout}"
