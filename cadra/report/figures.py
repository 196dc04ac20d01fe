"""One figure style for every report: matplotlib's object API, never pyplot.

A figure is a :class:`matplotlib.figure.Figure` made here (constrained layout), drawn on
through its Axes and saved with :func:`save` at one resolution. Nothing selects a backend
or touches pyplot's global state, so a notebook user keeps theirs, and headless use draws
on the Agg canvas ``savefig`` picks for PNG. matplotlib is imported when a figure is made.
"""

from __future__ import annotations

import os

#: resolution of every saved figure (dots per inch)
DPI = 110
#: colours: measured data, fitted curves, the truth or a reference, flagged points
MEASURED, FITTED, REFERENCE, FLAGGED = "C0", "C1", "0.4", "C3"


def new_figure(figsize: tuple[float, float] = (8.0, 5.0)):
    """A fresh figure with constrained layout (no pyplot state)."""
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained")


def subplots(nrows: int = 1, ncols: int = 1, *, figsize: tuple[float, float], **kwargs):
    """``(figure, axes)`` as ``Figure.subplots`` gives them (``squeeze`` as usual)."""
    fig = new_figure(figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save(fig, path: str | os.PathLike, dpi: int = DPI) -> None:
    """Write ``fig`` to ``path`` (its format from the suffix). Call it inside an output
    guard (:func:`cadra.atomic.atomic_output_dir`): the reports never write elsewhere."""
    fig.savefig(path, dpi=dpi)


__all__ = ["DPI", "FITTED", "FLAGGED", "MEASURED", "REFERENCE", "new_figure", "save",
           "subplots"]
