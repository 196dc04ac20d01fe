"""Values as the file formats hold them: numpy scalars and arrays as Python numbers and lists,
mappings with string keys, tuples as lists. One conversion for every writer of JSON and TOML
(results, reports, shot files)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np


def plain(value, *, nonfinite_as_none: bool = True):
    """``value`` in plain Python types. A float that is not finite becomes None when
    ``nonfinite_as_none`` (strict JSON has no NaN; a figure that could not be formed is
    null), else stays (TOML writes ``nan`` and ``inf``). Anything else that is not a number,
    string, bool or None is written as its ``str``."""
    if isinstance(value, Mapping):
        return {str(k): plain(v, nonfinite_as_none=nonfinite_as_none)
                for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v, nonfinite_as_none=nonfinite_as_none) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist(), nonfinite_as_none=nonfinite_as_none)
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        value = float(value)
        return None if nonfinite_as_none and not math.isfinite(value) else value
    if value is None or isinstance(value, str):
        return value
    return str(value)


__all__ = ["plain"]
