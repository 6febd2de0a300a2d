"""The numba loop of nonmin ≤ 0.1, frozen: the baseline of issue 17's target 4 (see fastpath.py)."""
