"""Files and the report of a sphere calibration (docs/calibration.md)."""

from __future__ import annotations

import os
from pathlib import Path

from cadra.calibration.history import save_bias_table
from cadra.io.atomic import atomic_output_dir
from cadra.numfmt import pm


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
             "unbiased majority of the stations at zero (docs/calibration.md).", "",
             "| station | x (mm) | y (mm) | z (mm) | time (µs) |", "|---|---|---|---|---|"]
    for k, st in enumerate(table.stations):
        cells = []
        for c, f in enumerate((1e3, 1e3, 1e3, 1e6)):
            b, sg = table.bias[k, c], table.sigma[k, c]
            cells.append("—" if not sg == sg else pm(b * f, sg * f))
        lines.append(f"| {st} | " + " | ".join(cells) + " |")
    lines += ["", "## Residual rms per shot (µm), before → after the correction", "",
              "| shot | x | y | z |", "|---|---|---|---|"]
    for sid in est.shots:
        b, a = est.shot_rms_before[sid], est.shot_rms_after[sid]
        lines.append(f"| {sid} | " + " | ".join(f"{b[c] * 1e6:.2f} → {a[c] * 1e6:.2f}"
                                              for c in "xyz") + " |")
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
    from cadra.calibration.plots import plot_biases

    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        save_bias_table(table, tmp / "bias_table.csv")
        comparison.to_csv(tmp / "comparison.csv", index=False)
        plot_biases(table, history).savefig(tmp / "biases.png", dpi=110)
        (tmp / "report.md").write_text(
            calibration_markdown(est, table, comparison, history, warnings,
                                 history_file=history_file, entry=entry,
                                 append_error=append_error),
            encoding="utf-8")
    return out_dir
