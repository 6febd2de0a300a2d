"""The compiled engine is built by the install and importable, in an optimized build."""

import nonmin
from nonmin import _engine


def test_engine_is_built_optimized_and_versioned():
    info = _engine.build_info()
    assert info["version"] == nonmin.__version__
    assert info["optimized"] is True
    assert info["cplusplus"] >= 201703
    assert info["eigen"].startswith("3.")
