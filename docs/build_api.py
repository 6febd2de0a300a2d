"""Build nonmin's API reference: a static HTML site generated from the docstrings with pdoc.

Usage::

    python docs/build_api.py [--out docs/_build/api]

Needs the ``docs`` extra (``pip install -e ".[docs]"``: pdoc). The build is offline: math
rendering (MathJax) and Mermaid, the only pdoc features that load files from a CDN, are off,
and the search index is a local file. Optional dependencies of nonmin (pinocchio, mujoco,
sympy, matplotlib) are imported when present, so that their modules are documented too;
a missing one leaves its lazily imported names out of the site.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path

#: The public packages documented (private ``_modules`` are not; their names are re-exported).
MODULES: tuple[str, ...] = (
    "nonmin",
    "nonmin.core",
    "nonmin.model",
    "nonmin.model.planar",
    "nonmin.model.spatial",
    "nonmin.model.symbolic",
    "nonmin.model.robots",
    "nonmin.library",
    "nonmin.sim",
    "nonmin.analysis",
    "nonmin.control",
    "nonmin.viz",
    "nonmin.io",
    "nonmin.errors",
)

DEFAULT_OUT = Path(__file__).resolve().parent / "_build" / "api"


def build(out: Path | str = DEFAULT_OUT, modules: Sequence[str] = MODULES) -> Path:
    """Render the API reference of ``modules`` into ``out``; return the path of ``index.html``."""
    try:
        import pdoc
        import pdoc.render
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise SystemExit("build_api.py needs pdoc: pip install -e '.[docs]'") from exc
    import nonmin

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    pdoc.render.configure(
        docformat="numpy",
        math=False,  # MathJax would be fetched from a CDN
        mermaid=False,  # idem
        search=True,  # local index (search.js)
        show_source=False,
        footer_text=f"nonmin {nonmin.__version__}",
    )
    # only the listed modules: "!" patterns exclude everything else pdoc would walk into
    specs = [*modules, r"!nonmin\.cli", r"!nonmin\.validation.*"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pdoc.pdoc(*specs, output_directory=out)
    unresolved = [w for w in caught if "type annotation" in str(w.message)]
    if unresolved:  # string annotations pdoc cannot evaluate are shown verbatim
        print(f"note: {len(unresolved)} type annotation(s) shown as written (not resolvable by pdoc)")
    index = out / "index.html"
    if not index.is_file():  # pdoc writes it for two or more modules
        raise SystemExit(f"pdoc did not write {index}")
    return index


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    args = parser.parse_args(argv)
    index = build(args.out)
    pages = sorted(p.relative_to(args.out) for p in args.out.rglob("*.html"))
    print(f"wrote {len(pages)} pages into {args.out} (open {index})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
