"""Seed 003 (Cohen, Clare & Stevens, the Basic Finner's rolling motion) Tables 2 and 3 as data.

``cadra/data/seed003_table2.csv``: the coefficients of the global fit at alpha = 57 deg, one
row each in the table's order, with the printed value, standard deviation and signal/noise.
``cadra/data/seed003_table3.csv``: their correlations, the upper triangle as printed (signed;
the printed rho formula squares the sign away, the table does not). Transcribed as printed
(``cadra/data/README.md``).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

DATA = Path(__file__).resolve().parent.parent / "data"
TABLE2_PATH = DATA / "seed003_table2.csv"
TABLE3_PATH = DATA / "seed003_table3.csv"


@lru_cache(maxsize=1)
def _table2() -> pd.DataFrame:
    df = pd.read_csv(TABLE2_PATH, dtype={"coefficient": str})
    if tuple(df.columns) != ("coefficient", "value", "sigma", "signal_noise"):
        raise ValueError(f"{TABLE2_PATH}: unexpected columns {list(df.columns)}")
    return df


def table2_order() -> tuple[str, ...]:
    """The coefficients in Table 2's order."""
    return tuple(_table2()["coefficient"])


def table2() -> dict[str, tuple[float, float, float]]:
    """Table 2: coefficient -> (value, standard deviation, printed signal/noise)."""
    return {r.coefficient: (float(r.value), float(r.sigma), float(r.signal_noise))
            for r in _table2().itertuples()}


def table3() -> pd.DataFrame:
    """Table 3 as a full symmetric correlation matrix in Table 2's order (a fresh copy)."""
    df = pd.read_csv(TABLE3_PATH, index_col="coefficient")
    order = list(table2_order())
    if list(df.index) != order or list(df.columns) != order:
        raise ValueError(f"{TABLE3_PATH}: rows and columns must be Table 2's coefficients in "
                         "its order")
    upper = np.triu(df.to_numpy(float))
    R = np.where(np.isnan(upper), 0.0, upper)
    R = R + np.triu(R, 1).T
    return pd.DataFrame(R, index=order, columns=order)


__all__ = ["TABLE2_PATH", "TABLE3_PATH", "table2", "table2_order", "table3"]
