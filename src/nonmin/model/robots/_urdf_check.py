"""Checks of a URDF file before Pinocchio parses it: the file is data from elsewhere.

Pinocchio's parser accepts things that are not physical (``mass="heavy"`` becomes 0, a
negative inertia is taken as it is) and reports a kinematic cycle as a missing body. This
module reads the XML with the standard library (no network, no external entities, no DTD
expansion beyond expat's limits), and raises, naming the file and the element:

* :class:`~nonmin.errors.FileFormatError`: not XML, not a ``<robot>``, a missing or
  non-numeric attribute;
* :class:`~nonmin.errors.ModelError`: a negative, zero-with-inertia or non-finite mass, an
  inertia that is not positive semi-definite (the triangle inequality is not checked: CAD
  exports of real robots, e.g. ANYmal's base, violate it at round-off level), a joint
  whose parent or child link does not exist, a link with two parent joints (a closed loop:
  URDF describes trees — close loops with constraints), no root or several roots (a cycle),
  an unknown joint type, a zero joint axis, lower limit above upper.

It also returns the position limits of revolute and prismatic joints (see
:func:`joint_limit_text`): with ``joint_limits=True`` (the default) they become unilateral
constraints; with ``joint_limits=False`` they are not enforced and the warning names them.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ...errors import FileFormatError, ModelError

__all__ = ["MAX_URDF_BYTES", "check_urdf", "joint_limit_text"]

#: Largest URDF file read (bytes).
MAX_URDF_BYTES = 64 * 2**20

_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical")

#: Relative tolerance of the inertia check (eigenvalues ≥ −tol·trace).
INERTIA_RTOL = 1e-9


def _number(el: ET.Element, attr: str, where: str, file: Path, default: float | None = None) -> float:
    raw = el.get(attr)
    if raw is None:
        if default is not None:
            return default
        raise FileFormatError(f"{file}: {where}: missing attribute {attr!r}")
    try:
        val = float(raw)
    except ValueError:
        raise FileFormatError(f"{file}: {where}: attribute {attr}={raw!r} is not a number") from None
    if not math.isfinite(val):
        raise ModelError(f"{file}: {where}: attribute {attr}={raw!r} must be finite")
    return val


def _vector(el: ET.Element | None, attr: str, where: str, file: Path) -> np.ndarray | None:
    if el is None or el.get(attr) is None:
        return None
    raw = el.get(attr, "")
    try:
        vals = np.array([float(x) for x in raw.split()], dtype=float)
    except ValueError:
        raise FileFormatError(f"{file}: {where}: attribute {attr}={raw!r} must hold 3 numbers") from None
    if vals.shape != (3,) or not np.isfinite(vals).all():
        raise FileFormatError(f"{file}: {where}: attribute {attr}={raw!r} must hold 3 finite numbers")
    return vals


def _check_inertial(link: ET.Element, file: Path) -> None:
    name = link.get("name")
    inertial = link.find("inertial")
    if inertial is None:
        return
    where = f"link {name!r} <inertial>"
    mass_el = inertial.find("mass")
    if mass_el is None:
        raise FileFormatError(f"{file}: {where}: missing <mass value=...>")
    mass = _number(mass_el, "value", f"{where} <mass>", file)
    _vector(inertial.find("origin"), "xyz", f"{where} <origin>", file)
    _vector(inertial.find("origin"), "rpy", f"{where} <origin>", file)
    inertia_el = inertial.find("inertia")
    if inertia_el is None:
        raise FileFormatError(f"{file}: {where}: missing <inertia .../>")
    keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
    v = {k: _number(inertia_el, k, f"{where} <inertia>", file, default=0.0) for k in keys}
    eye = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                    [v["ixz"], v["iyz"], v["izz"]]])  # fmt: skip
    if mass < 0.0:
        raise ModelError(f"{file}: {where}: mass must be > 0, got {mass!r}")
    scale = float(np.trace(eye))
    if mass == 0.0 and np.any(eye != 0.0):
        raise ModelError(
            f"{file}: {where}: mass 0 with a non-zero inertia is not physical (a massless link "
            "has no <inertial>, or mass 0 and inertia 0)"
        )
    eig = np.linalg.eigvalsh(eye)
    tol = INERTIA_RTOL * max(abs(scale), np.finfo(float).tiny)
    if eig[0] < -tol:
        raise ModelError(
            f"{file}: {where}: the inertia matrix must be positive semi-definite, its smallest "
            f"eigenvalue is {eig[0]:.6g}"
        )


def check_urdf(path: str | Path) -> dict[str, tuple[str, float, float]]:
    """Validate a URDF file; return ``{joint: (type, lower, upper)}`` of its position limits.

    Raises
    ------
    FileFormatError, ModelError
        See the module docstring; messages name the file and the element.
    """
    file = Path(path)
    try:
        size = file.stat().st_size
        if size > MAX_URDF_BYTES:
            raise FileFormatError(f"{file}: {size} bytes, more than the {MAX_URDF_BYTES} a URDF may have")
        data = file.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{file}: cannot read the URDF file: {exc.strerror or exc}") from None
    if b"<!ENTITY" in data:
        raise FileFormatError(f"{file}: URDF files must not declare XML entities (<!ENTITY>)")
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise FileFormatError(f"{file}: not well-formed XML: {exc}") from None
    if root.tag != "robot":
        raise FileFormatError(f"{file}: the root element must be <robot>, got <{root.tag}>")
    links: dict[str, ET.Element] = {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise FileFormatError(f"{file}: a <link> without a name")
        if name in links:
            raise ModelError(f"{file}: link {name!r} is defined twice")
        links[name] = link
        _check_inertial(link, file)
    if not links:
        raise ModelError(f"{file}: the robot has no <link>")
    parent_of: dict[str, str] = {}
    children: dict[str, list[str]] = {}
    joints: set[str] = set()
    limits: dict[str, tuple[str, float, float]] = {}
    for joint in root.findall("joint"):
        jname = joint.get("name")
        if not jname:
            raise FileFormatError(f"{file}: a <joint> without a name")
        where = f"joint {jname!r}"
        if jname in joints:
            raise ModelError(f"{file}: {where} is defined twice")
        joints.add(jname)
        jtype = joint.get("type")
        if jtype not in _JOINT_TYPES:
            raise ModelError(f"{file}: {where}: type must be one of {list(_JOINT_TYPES)}, got {jtype!r}")
        ends = {}
        for end in ("parent", "child"):
            el = joint.find(end)
            lname = None if el is None else el.get("link")
            if lname is None:
                raise FileFormatError(f"{file}: {where}: missing <{end} link=...>")
            if lname not in links:
                raise ModelError(f"{file}: {where}: {end} link {lname!r} is not a <link> of the file")
            ends[end] = lname
        if ends["parent"] == ends["child"]:
            raise ModelError(f"{file}: {where}: parent and child are the same link {ends['child']!r}")
        child = ends["child"]
        if child in parent_of:
            raise ModelError(
                f"{file}: {where}: link {child!r} already has the parent joint "
                f"{parent_of[child]!r}; a link with two parents closes a loop, and URDF describes "
                "trees — keep one joint and close the loop with a constraint ([[model.constraints]] "
                "or FrameConstraint)"
            )
        parent_of[child] = jname
        children.setdefault(ends["parent"], []).append(child)
        origin = joint.find("origin")
        _vector(origin, "xyz", f"{where} <origin>", file)
        _vector(origin, "rpy", f"{where} <origin>", file)
        if jtype in ("revolute", "continuous", "prismatic"):
            axis = _vector(joint.find("axis"), "xyz", f"{where} <axis>", file)
            if axis is not None and not np.linalg.norm(axis) > 0.0:
                raise ModelError(f"{file}: {where}: the axis must not be zero")
        limit = joint.find("limit")
        if jtype in ("revolute", "prismatic") and limit is not None:
            lo = _number(limit, "lower", f"{where} <limit>", file, default=0.0)
            hi = _number(limit, "upper", f"{where} <limit>", file, default=0.0)
            for attr in ("effort", "velocity"):
                if limit.get(attr) is not None and _number(limit, attr, f"{where} <limit>", file) < 0:
                    raise ModelError(f"{file}: {where} <limit>: {attr} must be ≥ 0")
            if lo > hi:
                raise ModelError(f"{file}: {where} <limit>: lower = {lo:g} is above upper = {hi:g}")
            if lo < hi:
                limits[jname] = (jtype, lo, hi)
    roots = [n for n in links if n not in parent_of]
    if len(roots) != 1:
        what = "no root link (every link has a parent: a kinematic cycle)" if not roots else \
            f"{len(roots)} root links {sorted(roots)[:6]} (links no joint connects)"
        raise ModelError(f"{file}: the URDF tree has {what}; a URDF is one tree of links")
    seen = {roots[0]}
    stack = [roots[0]]
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in seen:
                seen.add(c)
                stack.append(c)
    if len(seen) != len(links):
        cyc = sorted(set(links) - seen)[:6]
        raise ModelError(f"{file}: links {cyc} are not reachable from the root {roots[0]!r} (a kinematic cycle)")
    return limits


def joint_limit_text(limits: dict[str, tuple[str, float, float]], file: str | Path) -> str:
    """The warning that names the position limits not enforced (``joint_limits=False``)."""
    shown = ", ".join(f"{j} [{lo:g}, {hi:g}]" for j, (_, lo, hi) in list(limits.items())[:8])
    more = f" and {len(limits) - 8} more" if len(limits) > 8 else ""
    return (
        f"{file}: joint position limits are not enforced by the dynamics (joint_limits=False): "
        f"{shown}{more}; a joint can move past them. Pass joint_limits=True to enforce them as "
        "unilateral constraints, or joint_limits='ignore' to silence this warning"
    )
