"""The API reference builds offline from the docstrings (docs/build_api.py, pdoc)."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

pytest.importorskip("pdoc")

ROOT = Path(__file__).resolve().parents[2]


def _load_builder():
    spec = importlib.util.spec_from_file_location("nonmin_docs_build_api", ROOT / "docs" / "build_api.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("api")
    builder = _load_builder()
    index = builder.build(out)
    assert index == out / "index.html"
    return out


# page -> names that must be documented on it
EXPECTED = {
    "nonmin/core.html": ["forward_dynamics", "nullspace_projector", "impact_map", "solve_dynamics"],
    "nonmin/sim.html": ["simulate", "Trajectory", "Event", "Activate"],
    "nonmin/model.html": ["assemble", "FunctionModel"],
    "nonmin/model/planar.html": ["PlanarBuilder", "PlanarModel"],
    "nonmin/control.html": ["Regulator", "Tracker", "ForceControl"],
    "nonmin/errors.html": ["ShapeError", "MissingDependencyError"],
    "nonmin/library.html": ["arm2r_wall", "five_bar"],
    "nonmin/io.html": ["load_scenario", "run_scenario"],
    "nonmin/viz.html": ["plot_trajectory"],
}


def test_index_and_module_pages(site: Path) -> None:
    assert (site / "index.html").stat().st_size > 0
    assert (site / "search.js").is_file()
    for page, names in EXPECTED.items():
        html = (site / page).read_text(encoding="utf-8")
        for name in names:
            assert f'id="{name}"' in html, f"{name} not documented in {page}"


def test_numpydoc_sections_rendered(site: Path) -> None:
    html = (site / "nonmin/core.html").read_text(encoding="utf-8")
    # numpydoc "Parameters" / "Returns" sections become headings, not raw underlines
    assert "Parameters" in html and "Returns" in html
    assert "----------" not in html


def test_private_modules_and_cli_not_documented(site: Path) -> None:
    pages = {p.relative_to(site).as_posix() for p in site.rglob("*.html")}
    assert not any("/_" in p or p.startswith("_") for p in pages), sorted(pages)
    assert "nonmin/cli.html" not in pages


def test_site_is_offline(site: Path) -> None:
    """No script, stylesheet or image is loaded from the network (math/mermaid off)."""
    for page in site.rglob("*.html"):
        html = page.read_text(encoding="utf-8")
        assert not re.search(r'<script[^>]+src="(https?:)?//', html), page
        assert not re.search(r'<link[^>]+href="(https?:)?//', html), page
        assert not re.search(r'<img[^>]+src="(https?:)?//', html), page
        assert "mathjax" not in html.lower(), page
