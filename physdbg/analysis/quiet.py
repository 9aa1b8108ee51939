"""numpy's floating-point warnings kept from the user while a run is analysed.

The analysis meets NaN, infinity, empty and constant samples by design (a run that blew
up, a gap that never grows) and says so in words in its report; numpy's RuntimeWarning
on top, with a source path and a line of code, is noise to whoever reads the report.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np


@contextmanager
def quiet_numerics() -> Iterator[None]:
    """No floating-point warnings from numpy inside (errstate and RuntimeWarning)."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield
