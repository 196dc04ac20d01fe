"""Plot of a station bias table against the facility's history.

matplotlib is imported lazily and used through :class:`matplotlib.figure.Figure` (Agg canvas,
no pyplot state); nothing is shown. Positions are drawn in mm, times in microseconds; the
library values are SI (:mod:`cadra.calibration.history`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from cadra.calibration.history import CHANNELS, BiasTable, compare, table_sha256

#: display scale and unit per channel (x, y, z in mm; time in microseconds)
_DISPLAY = {"x": (1e3, "mm"), "y": (1e3, "mm"), "z": (1e3, "mm"), "time": (1e6, "µs")}


def plot_biases(new: BiasTable, history: Sequence[BiasTable] = (), ax=None, *,
                max_previous: int = 5, threshold_sigma: float = 3.0,
                family_alpha: float = 0.05):
    """Bias vs station, one panel per channel, with the history overlaid.

    Each panel shows the new table's bias ± 1 sigma (channels not estimated are left out),
    the last ``max_previous`` history entries faintly (older = fainter, legend by date), and
    marks the stations :func:`cadra.calibration.history.compare` flags: a red ring where the
    station moved since the latest entry (family-wise flag), a black square where its bias is
    significantly non-zero (family-wise flag).

    Parameters
    ----------
    new : the bias table to show.
    history : earlier tables, oldest first; ``new`` itself is skipped if it is in there.
    ax : None (a new 4-panel figure) or a sequence of 4 Axes (x, y, z, time) on one figure.
    max_previous : number of history entries drawn.
    threshold_sigma, family_alpha : passed to :func:`compare`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if ax is None:
        from matplotlib.figure import Figure

        fig = Figure(figsize=(9, 8), layout="constrained")
        axes = list(fig.subplots(4, 1, sharex=True))
    else:
        axes = list(ax)
        if len(axes) != 4:
            raise ValueError(f"ax: expected 4 Axes (x, y, z, time), got {len(axes)}")
        fig = axes[0].figure
    digest = table_sha256(new)
    previous = [t for t in history if table_sha256(t) != digest][-max_previous:] \
        if max_previous > 0 else []
    flags = compare(new, list(history), threshold_sigma=threshold_sigma,
                    family_alpha=family_alpha)
    n_prev = len(previous)
    width = 0.6 / (n_prev + 1)
    for j, (chan, a) in enumerate(zip(CHANNELS, axes, strict=True)):
        scale, unit = _DISPLAY[chan]
        for k, t in enumerate(previous):
            est = t.estimated[:, j]
            fade = 0.15 + 0.35 * (k + 1) / n_prev
            a.errorbar(t.stations[est] - 0.3 + k * width, t.bias[est, j] * scale,
                       yerr=t.sigma[est, j] * scale, fmt="o", ms=3, color="0.4", alpha=fade,
                       elinewidth=0.8, capsize=0, label=t.created_utc[:10] if j == 0 else None)
        est = new.estimated[:, j]
        a.errorbar(new.stations[est] + 0.3, new.bias[est, j] * scale,
                   yerr=new.sigma[est, j] * scale, fmt="o", ms=5, color="C0", capsize=2,
                   label=f"{new.created_utc[:10]} (new)" if j == 0 else None)
        sel = flags[flags["channel"] == chan]
        x_new = sel["station"].to_numpy() + 0.3
        y_new = sel["bias"].to_numpy() * scale
        moved = sel["moved_family"].to_numpy()
        biased = sel["biased_family"].to_numpy()
        if moved.any():
            a.plot(x_new[moved], y_new[moved], "o", ms=12, mfc="none", mec="red", mew=1.5,
                   label="moved (family-wise)")
        if biased.any():
            a.plot(x_new[biased], y_new[biased], "s", ms=9, mfc="none", mec="k", mew=1.0,
                   label="bias ≠ 0 (family-wise)")
        a.axhline(0.0, color="0.6", lw=0.8)
        a.set_ylabel(f"{chan} bias ({unit})")
        a.grid(True, alpha=0.3)
        if a.get_legend_handles_labels()[1]:
            a.legend(fontsize=7, ncol=min(4, n_prev + 3), loc="best")
    axes[-1].set_xlabel("station")
    axes[-1].set_xticks(np.unique(np.concatenate([new.stations,
                                                  *(t.stations for t in previous)])))
    axes[0].set_title(f"{new.facility} station biases, {new.created_utc} "
                      f"({len(new.shots)} shots)")
    return fig


__all__ = ["plot_biases"]
