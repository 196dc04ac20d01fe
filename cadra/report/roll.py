"""The outputs of seed 003's segmented roll fit (docs/segmented_roll.md): Tables 2 and 3, the
segments, the steady spins, the report page and the plot of Figs. 5-6.

:func:`write_roll` writes a :class:`cadra.studies.segmented_roll.SegmentedFit` to a folder
atomically (:func:`cadra.atomic.atomic_output_dir`): ``report.md``, each table as
``<name>.csv`` and ``<name>.md`` (``table2``, ``table3``, ``paper_table3``, ``segments``,
``steady_spins``), and ``roll_fit.png``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_output_dir
from cadra.report import figures, markdown

#: the report's sections: title and table name
SECTIONS = (("Coefficients (seed 003 Table 2 layout)", "table2"),
            ("Correlations (Table 3 layout)", "table3"),
            ("Steady spins of the fitted coefficients", "steady_spins"),
            ("Segments: bias, rms, runs of sign", "segments"))


def table_markdown(df: pd.DataFrame, digits: int = 5) -> str:
    """A table with its index as the first column, numbers to ``digits`` significant
    figures (:func:`cadra.report.markdown.frame`)."""
    return markdown.frame(df, digits, index=True) + "\n"


def report_markdown(fit, tables: Mapping[str, pd.DataFrame], records: Sequence,
                    alpha_rad: float) -> str:
    """The report page: records, bearing angle, segments, the fit's status and steps, notes,
    and those of :data:`SECTIONS`' tables that ``tables`` holds."""
    res = fit.result
    lines = ["# Segmented roll fit (seed 003, ROMOF)", "",
             f"Records: {', '.join(r.name for r in records)}; bearing angle of attack "
             f"{math.degrees(alpha_rad):.3f} deg; {len(fit.segments)} segments; fit "
             f"{res.status}, chi^2/dof {res.reduced_chi2:.4f} ({res.dof} dof). Steps: "
             + "; ".join(", ".join(s) for s in fit.step_names) + ".", ""]
    if fit.notes:
        lines += ["**Notes:** " + "; ".join(fit.notes), ""]
    for title, key in SECTIONS:
        if key in tables:
            lines += [f"## {title}", "", table_markdown(tables[key]), ""]
    return "\n".join(lines)


def plot_segmented_fit(sf):
    """Seed 003 Figs. 5-6 for one fit: each run's measured roll (0-360 deg) against frame,
    the fit's values (the fit problem's, from its residual table) and the segment starts;
    below, the residuals (deg). Returns the figure."""
    res = sf.result.residuals
    res = res[res["channel"] == "phi"]
    names = sorted({s.record for s in sf.segments})
    fig, axes = figures.subplots(2 * len(names), 1, figsize=(11, 3.2 * len(names)),
                                 sharex=False, squeeze=False,
                                 gridspec_kw={"height_ratios": [3, 1] * len(names)})
    axes = axes[:, 0]
    for i, name in enumerate(names):
        top, bot = axes[2 * i], axes[2 * i + 1]
        g = res[res["shot_id"].str.startswith(name + ":")]
        top.plot(g["station"], np.degrees(np.mod(g["measured"], 2 * np.pi)), ".", ms=2,
                 label="measured")
        top.plot(g["station"], np.degrees(np.mod(g["fitted"], 2 * np.pi)), ".", ms=1,
                 color="k", label="fit")
        for s in sf.segments:
            if s.record == name:
                top.axvline(s.start, color="0.8", lw=0.5, zorder=0)
        top.set_ylabel(f"{name}: roll, deg")
        top.set_ylim(0, 360)
        top.legend(loc="upper right", fontsize=7)
        bot.plot(g["station"], np.degrees(g["residual"]), ".", ms=1.5)
        bot.set_ylabel("residual, deg")
        bot.set_xlabel("frame")
    return fig


def write_roll(fit, tables: Mapping[str, pd.DataFrame], records: Sequence, alpha_rad: float,
               out_dir: str | os.PathLike, *, overwrite: bool = False,
               digits: int = 5) -> Path:
    """The fit's folder (module doc), atomically; an existing one is refused unless
    ``overwrite``."""
    out_dir = Path(out_dir)
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="roll") as tmp:
        for name, df in tables.items():
            df.to_csv(tmp / f"{name}.csv")
            (tmp / f"{name}.md").write_text(table_markdown(df, digits), encoding="utf-8")
        figures.save(plot_segmented_fit(fit), tmp / "roll_fit.png")
        (tmp / "report.md").write_text(report_markdown(fit, tables, records, alpha_rad),
                                       encoding="utf-8")
    return out_dir


__all__ = ["SECTIONS", "plot_segmented_fit", "report_markdown", "table_markdown", "write_roll"]
