"""Progress reporting for long runs: tqdm when installed, a plain stderr line otherwise.

Quiet when stderr is not a terminal (``progress=None``), always on with ``progress=True``,
off with ``progress=False``.
"""

from __future__ import annotations

import sys
import time
from typing import Any

__all__ = ["Progress"]


class Progress:
    """Time-based progress bar over ``[t0, t1]`` (updated at most ~10 times per second)."""

    def __init__(self, t0: float, t1: float, enabled: bool | None) -> None:
        if enabled is None:
            enabled = bool(getattr(sys.stderr, "isatty", lambda: False)())
        self.enabled = bool(enabled)
        self.t0, self.t1 = t0, t1
        self._bar: Any = None
        self._last = 0.0
        self._shown = 0.0
        self._start = time.monotonic()
        if not self.enabled:
            return
        try:
            from tqdm import tqdm
        except ImportError:  # plain fallback (the "progress" extra is optional)
            self._bar = None
        else:
            self._bar = tqdm(total=t1 - t0, unit="s(sim)", file=sys.stderr, leave=False,
                             bar_format="{l_bar}{bar}| {n:.3g}/{total:.3g} s [{elapsed}<{remaining}]")

    def update(self, t: float) -> None:
        """Report that the simulation reached time ``t``."""
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and t < self.t1:
            return
        self._last = now
        done = min(t, self.t1) - self.t0
        if self._bar is not None:
            self._bar.update(done - self._shown)
        else:
            frac = done / (self.t1 - self.t0)
            sys.stderr.write(f"\rsimulate: t = {t:.6g} s ({100 * frac:5.1f} %)")
            sys.stderr.flush()
        self._shown = done

    def close(self) -> None:
        """Finish the bar."""
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.close()
        else:
            sys.stderr.write("\n")
            sys.stderr.flush()
