"""Meta-tests of the public documentation.

* Every name in the ``__all__`` of each public package has a docstring (functions, classes and
  modules their own ``__doc__``; constants a ``#:`` comment above, or a string below, their
  assignment in the module that defines them).
* Every function and class of :mod:`nonmin.core` has a numpydoc docstring with a
  ``Parameters``, ``Returns`` (or, for result classes, ``Attributes``) section when it takes
  arguments, and every core *kernel* names the paper equation (or remark / ERRATA entry) it
  implements.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import inspect
import re
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from nonmin.errors import MissingDependencyError


def _documented_packages() -> tuple[str, ...]:
    """The public packages, as listed once in docs/build_api.py (the API site's module list)."""
    path = Path(__file__).resolve().parents[2] / "docs" / "build_api.py"
    spec = importlib.util.spec_from_file_location("nonmin_docs_build_api_modules", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return tuple(mod.MODULES)


PUBLIC_PACKAGES = _documented_packages()

#: Functions of nonmin.core that implement an equation of the paper (or its corrected form).
CORE_KERNELS = (
    "actuation_projectors",
    "baumgarte_bias",
    "constraint_force",
    "constraint_force_projector",
    "constraint_inertia",
    "coriolis_bar",
    "forward_dynamics",
    "impact_map",
    "lambda_matrix",
    "nullspace_projector",
    "optimal_virtual_mass",
    "position_correction",
    "projector_derivative",
    "solve_dynamics",
)

#: Known gaps, reported to their owners; each entry is an expected failure (strict: the test
#: fails as soon as the gap is fixed, so that the entry gets removed).
KNOWN_GAPS: dict[str, str] = {}

_SECTION = re.compile(r"^(Parameters|Returns|Yields|Attributes)\n-{3,}\s*$", re.M)
_EQUATION = re.compile(r"\beqs?\.|\bequation|\bpaper\b|\bremark\b|\bERRATA\b|\bappendix\b", re.I)


def _public_names() -> list[tuple[str, str]]:
    out = []
    for pkg in PUBLIC_PACKAGES:
        mod = importlib.import_module(pkg)
        names = getattr(mod, "__all__", None)
        assert names, f"{pkg} has no __all__"
        out += [(pkg, name) for name in names]
    return out


def _param(key: str, *values: Any) -> Any:
    marks = [pytest.mark.xfail(strict=True, reason=KNOWN_GAPS[key])] if key in KNOWN_GAPS else []
    return pytest.param(*values, id=key, marks=marks)


@cache
def _sources(pkg: str) -> tuple[Path, ...]:
    mod = importlib.import_module(pkg)
    file = Path(mod.__file__ or "")
    if file.name == "__init__.py":
        return tuple(sorted(file.parent.rglob("*.py")))
    return (file,)


def _constant_doc(pkg: str, name: str) -> str:
    """The ``#:`` comment above, or the string below, the module-level assignment of ``name``."""
    for path in _sources(pkg):
        text = path.read_text(encoding="utf-8")
        if name not in text:
            continue
        lines = text.splitlines()
        body = ast.parse(text).body
        for i, node in enumerate(body):
            targets = node.targets if isinstance(node, ast.Assign) else (
                [node.target] if isinstance(node, ast.AnnAssign) else [])
            if not any(isinstance(t, ast.Name) and t.id == name for t in targets):
                continue
            comment = []
            k = node.lineno - 2
            while k >= 0 and lines[k].lstrip().startswith("#:"):
                comment.insert(0, lines[k].lstrip()[2:].strip())
                k -= 1
            if comment:
                return " ".join(comment)
            nxt = body[i + 1] if i + 1 < len(body) else None
            if isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant) and isinstance(nxt.value.value, str):
                return nxt.value.value
    return ""


def _own_doc(obj: Any) -> str:
    """The object's own docstring (not inherited, not dataclass-generated)."""
    doc = obj.__doc__ if isinstance(obj.__doc__, str) else ""
    if inspect.isclass(obj) and doc.startswith(f"{obj.__name__}("):
        return ""  # the signature-like docstring dataclasses generate
    return inspect.cleandoc(doc) if doc else ""


def _takes_arguments(obj: Any) -> bool:
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return False
    return any(p.name not in ("self", "cls") for p in sig.parameters.values())


@pytest.mark.parametrize(("pkg", "name"), [_param(f"{p}.{n}", p, n) for p, n in _public_names()])
def test_public_name_has_docstring(pkg: str, name: str) -> None:
    mod = importlib.import_module(pkg)
    try:
        obj = getattr(mod, name)
    except MissingDependencyError as exc:  # optional dependency not installed
        pytest.skip(str(exc))
    if inspect.ismodule(obj) or inspect.isclass(obj) or callable(obj):
        doc = _own_doc(obj)
    else:
        doc = _constant_doc(pkg, name)
    assert len(doc.strip()) >= 10, f"{pkg}.{name} ({type(obj).__name__}) has no docstring"


def _core_callables() -> list[str]:
    import nonmin.core as core

    return [n for n in core.__all__ if inspect.isfunction(getattr(core, n)) or inspect.isclass(getattr(core, n))]


@pytest.mark.parametrize("name", [_param(f"numpydoc:{n}", n) for n in _core_callables()])
def test_core_numpydoc_sections(name: str) -> None:
    import nonmin.core as core

    obj = getattr(core, name)
    doc = _own_doc(obj)
    assert doc, f"nonmin.core.{name} has no docstring"
    if _takes_arguments(obj):
        sections = _SECTION.findall(doc)
        assert sections, f"nonmin.core.{name}: numpydoc docstring without a Parameters/Returns section"


@pytest.mark.parametrize("name", [_param(f"equation:{n}", n) for n in CORE_KERNELS])
def test_core_kernel_cites_paper_equation(name: str) -> None:
    import nonmin.core as core

    assert name in core.__all__
    doc = _own_doc(getattr(core, name))
    assert _EQUATION.search(doc), f"nonmin.core.{name}: docstring names no paper equation"


def test_constant_doc_finder() -> None:
    """The ``#:`` finder itself (on a known constant, and on a name that does not exist)."""
    assert "rank" in _constant_doc("nonmin.core", "DEFAULT_RTOL")
    assert _constant_doc("nonmin.core", "NO_SUCH_CONSTANT") == ""
