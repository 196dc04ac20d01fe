"""Files, the report and the plot of a sphere calibration (docs/calibration.md).

Positions are shown in mm and times in µs (the station survey's units); the library's values
are SI (:mod:`cadra.calibration.history`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from cadra.atomic import atomic_output_dir
from cadra.calibration.history import CHANNELS, BiasTable, compare, save_bias_table, table_sha256
from cadra.numfmt import pm
from cadra.report import figures, markdown
from cadra.units import from_si

#: display unit (unit-table name, printed label) per bias channel
_UNITS = {"x": ("mm", "mm"), "y": ("mm", "mm"), "z": ("mm", "mm"), "time": ("us", "µs")}
#: per channel: printed unit and the display value per SI value
_DISPLAY = {c: (label, float(from_si(1.0, u))) for c, (u, label) in _UNITS.items()}


def history_sentence(history_file: str | os.PathLike | None, entry: int | None = None,
                     append_error: str | None = None) -> str:
    """What became of the estimate in the station history, in one sentence for the report.

    ``history_file`` None: not recorded (``--no-history``); ``append_error``: the append failed
    and why (the history is unchanged); else recorded as ``entry`` (1-based)."""
    if history_file is None:
        return "Station history: not recorded (--no-history)."
    if append_error is not None:
        return (f"**Station history: NOT recorded.** The append to {history_file} failed: "
                f"{append_error}. The history is unchanged; the comparison below is with the "
                "entries read before the attempt.")
    return (f"Station history: recorded in {history_file} as entry {entry}; compared with the "
            f"{entry - 1} entries before it, read under the history's lock.")


def calibration_markdown(est, table, comparison, history, warnings=(), *,
                         history_file: str | os.PathLike | None = None,
                         entry: int | None = None, append_error: str | None = None) -> str:
    """The calibration report: what became of the estimate in the station history (first, so
    a failed append cannot be missed: :func:`history_sentence`), biases per station, residual
    rms before -> after the correction, the comparison with the station history, warnings."""
    lines = [f"# Sphere calibration: facility {est.facility}", "",
             history_sentence(history_file, entry, append_error), "",
             f"Shots: {', '.join(est.shots)} (speeds "
             f"{', '.join(f'{v:.0f}' for v in est.shot_speeds_m_s)} m/s). {est.method}.",
             f"chi^2/dof after correction: {est.chi2:.1f}/{est.dof} = "
             f"{est.chi2 / max(est.dof, 1):.3f}. Timing biases "
             f"{'estimated' if est.timing_estimated else 'not estimated'}.", "",
             "Biases are given in the robust gauge: common offsets, trends along the range and "
             "(for x and time) a curvature along it cannot be told from the shots' own initial "
             "state and drag law; of those, the estimate carries the part that puts the "
             "unbiased majority of the stations at zero (docs/calibration.md).", ""]
    rows = []
    for k, st in enumerate(table.stations):
        cells = [st]
        for c, chan in enumerate(CHANNELS):
            f = _DISPLAY[chan][1]
            b, sg = table.bias[k, c], table.sigma[k, c]
            cells.append("—" if not sg == sg else pm(b * f, sg * f))
        rows.append(cells)
    lines += markdown.table(["station"] + [f"{c} ({_DISPLAY[c][0]})" for c in CHANNELS], rows)
    um = float(from_si(1.0, "um"))
    lines += ["", "## Residual rms per shot (µm), before → after the correction", ""]
    lines += markdown.table(("shot", "x", "y", "z"), (
        [sid] + [f"{est.shot_rms_before[sid][c] * um:.2f} → "
                 f"{est.shot_rms_after[sid][c] * um:.2f}" for c in "xyz"]
        for sid in est.shots))
    lines += ["", f"## Comparison with the station history ({len(history)} earlier "
              "entries)", ""]
    if len(history):
        moved = comparison[comparison["moved_family"].astype(bool)] \
            if "moved_family" in comparison else comparison.iloc[0:0]
        lines.append(f"{len(moved)} station channel(s) moved significantly (family-wise test; "
                     "per-test z in comparison.csv).")
        for _, row in moved.iterrows():
            lines.append(f"- station {row['station']} {row['channel']}: moved "
                         f"{row['z_move']:+.1f} sigma")
    else:
        lines.append("No earlier entries.")
    lines += ["", "![biases](biases.png)", ""]
    for w in (*est.warnings, *warnings):
        lines.append(f"- warning: {w}")
    return "\n".join(lines) + "\n"


def write_calibration(est, table, comparison, history, out_dir: str | os.PathLike, *,
                      warnings=(), history_file=None, entry=None, append_error=None,
                      overwrite: bool = False) -> Path:
    """``bias_table.csv``, ``comparison.csv``, ``biases.png``, ``report.md``, atomically.

    Write it after the estimate was appended to the station history (``history_file``,
    ``entry``), or with ``append_error`` saying why it was not: the report never claims a
    record that is not there (:func:`history_sentence`)."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="calibration") as tmp:
        save_bias_table(table, tmp / "bias_table.csv")
        comparison.to_csv(tmp / "comparison.csv", index=False)
        figures.save(plot_biases(table, history), tmp / "biases.png")
        (tmp / "report.md").write_text(
            calibration_markdown(est, table, comparison, history, warnings,
                                 history_file=history_file, entry=entry,
                                 append_error=append_error),
            encoding="utf-8")
    return out_dir


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
        fig, axes = figures.subplots(4, 1, figsize=(9, 8), sharex=True)
        axes = list(axes)
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
        unit, scale = _DISPLAY[chan]
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


def station_lines(table: BiasTable, threshold_sigma: float = 3.0) -> list[str]:
    """The console's account of a bias table: per station, every estimated channel
    ``bias ± sigma`` in mm or µs, marked ``*`` beyond ``threshold_sigma``."""
    lines = []
    for k, st in enumerate(table.stations):
        cells = []
        for c, chan in enumerate(CHANNELS):
            label, f = _DISPLAY[chan]
            b, sg = table.bias[k, c], table.sigma[k, c]
            if np.isfinite(sg) and sg > 0:
                mark = " *" if abs(b) > threshold_sigma * sg else ""
                cells.append(f"{chan} {pm(b * f, sg * f, label)}{mark}")
        lines.append(f"  station {st:2d}: " + ", ".join(cells))
    return lines


__all__ = ["calibration_markdown", "history_sentence", "plot_biases", "station_lines",
           "write_calibration"]
