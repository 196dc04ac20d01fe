"""Markdown tables: the one builder every report uses.

A table is a header and rows of cells; a cell is text (a ``|`` in it is escaped, a newline
folded to a space), or a number shown with ``str``. Callers format numbers themselves (with
:func:`cadra.numfmt.pm` for ``value ± sigma``), so the report says what the number is.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np
import pandas as pd


def cell(value) -> str:
    """One cell's text: ``|`` escaped, newlines folded, None and NaN empty."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return " ".join(str(value).split("\n")).replace("|", "\\|")


def table(header: Sequence[str], rows: Iterable[Sequence]) -> list[str]:
    """The lines of a Markdown table (no blank line before or after)."""
    head = [cell(h) for h in header]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        cells = [cell(c) for c in row]
        if len(cells) != len(head):
            raise ValueError(f"a row of {len(cells)} cells in a table of {len(head)} columns")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def frame(df: pd.DataFrame, digits: int = 5, index: bool = False) -> str:
    """A DataFrame as a Markdown table, floats to ``digits`` significant digits (a value that
    is not finite left empty), with the index as the first column when ``index``."""
    def fmt(v):
        if isinstance(v, float | np.floating) and not isinstance(v, bool):
            return f"{float(v):.{digits}g}" if math.isfinite(v) else ""
        if isinstance(v, np.bool_ | np.integer):
            return v.item()
        return v

    header = ([df.index.name or ""] if index else []) + [str(c) for c in df.columns]
    rows = ([*([fmt(k)] if index else []), *(fmt(v) for v in row)]
            for k, row in zip(df.index, df.itertuples(index=False, name=None), strict=True))
    return "\n".join(table(header, rows))


__all__ = ["cell", "frame", "table"]
