"""Validation suite: external benchmark problems with reference solutions and stated targets.

Each benchmark is a function returning a :class:`ValidationRecord` (the measured numbers, the
targets, pass/fail, the settings and the reference used)::

    >>> from nonmin import validation
    >>> records = validation.run_all(quick=True)            # doctest: +SKIP
    >>> print(validation.format_table(records))             # doctest: +SKIP
    >>> validation.write_report(records, "docs/validation.md")  # doctest: +SKIP

Problems (``shared/benchmarks/README.md``): IFToMM A01 pendulum, A02 N four-bar (N = 2, 40),
A03 Andrews' squeezing mechanism (Test Set score), A04 Bricard (redundant constraint), the
crossed four-bar (change point) and a 2R arm hitting a wall (impact and release).
``nonmin validate [--full] [--report PATH]`` is the command-line front end.
"""

from ._records import Check as Check
from ._records import ValidationRecord as ValidationRecord
from ._records import format_table as format_table
from ._records import machine_info as machine_info
from ._records import write_report as write_report
from ._references import a02_parallelogram_reference as a02_parallelogram_reference
from ._references import a04_bricard_period as a04_bricard_period
from ._references import load_a01_exact as load_a01_exact
from ._references import load_a02_n2_exact as load_a02_n2_exact
from ._references import load_a03_reference as load_a03_reference
from ._references import significant_digits as significant_digits
from ._suite import BENCHMARKS as BENCHMARKS
from ._suite import SETTINGS as SETTINGS
from ._suite import a01_pendulum as a01_pendulum
from ._suite import a02_n_four_bar as a02_n_four_bar
from ._suite import a03_andrews as a03_andrews
from ._suite import a04_bricard as a04_bricard
from ._suite import arm2r_wall as arm2r_wall
from ._suite import crossed_four_bar as crossed_four_bar
from ._suite import run_all as run_all

__all__ = [
    "BENCHMARKS",
    "SETTINGS",
    "Check",
    "ValidationRecord",
    "a01_pendulum",
    "a02_n_four_bar",
    "a02_parallelogram_reference",
    "a03_andrews",
    "a04_bricard",
    "a04_bricard_period",
    "arm2r_wall",
    "crossed_four_bar",
    "format_table",
    "load_a01_exact",
    "load_a02_n2_exact",
    "load_a03_reference",
    "machine_info",
    "run_all",
    "significant_digits",
]
