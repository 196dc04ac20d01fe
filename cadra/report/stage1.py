"""Stage one's outputs: the trajectory file, the quality table, overlays, one page of plots
and the report (docs/stage1.md).

:func:`write_stage1` writes a :class:`cadra.imaging.shot.Stage1Result` to a folder, atomically
(:func:`cadra.atomic.atomic_output_dir`: built in a temporary sibling and moved into place;
an output that is or holds one of the measurement's inputs is refused, an existing one unless
``overwrite``)::

    trajectory.csv          the trajectory measurement file (cadra.io.trajectory)
    quality.csv             per station and view: wires, affine, silhouette-fit figures, flags
    trajectory.png          one page: x-z, x-y, theta and psi vs x with error bars
    overlays/stNN_VIEW.png  every image with the fitted wires and silhouette
    report.md               what was measured, what failed and why (and, with a truth table,
                            measured minus truth: truth_comparison.csv)
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.atomic import atomic_output_dir, check_output_dir
from cadra.channels import OBSERVED
from cadra.imaging.truth_compare import TruthComparison, compare_with_truth
from cadra.io.trajectory import trajectory_to_csv
from cadra.report import figures, markdown


def trajectory_figure(traj, truth=None):
    """One page: x-z and x-y paths (cm), theta and psi (deg) vs x, with 1-sigma error bars.

    ``traj`` is a trajectory-measurement table (docs/stage1.md columns); ``truth`` an optional
    table with ``x_m, y_m, z_m, theta_deg, psi_deg`` drawn as a line.
    """
    ok = traj[traj["ok"]] if "ok" in traj else traj
    fig, axes = figures.subplots(2, 2, figsize=(11, 7.5), sharex=True)
    panels = (
        (axes[0, 0], "z_m", "sigma_z_m", 100.0, "z (cm, + up)", "side view: x-z"),
        (axes[0, 1], "y_m", "sigma_y_m", 100.0, "y (cm, + port)", "top view: x-y"),
        (axes[1, 0], "theta_deg", "sigma_theta_deg", 1.0, "theta (deg, + nose up)",
         "inclination to the x-y plane"),
        (axes[1, 1], "psi_deg", "sigma_psi_deg", 1.0, "psi (deg, + nose to port)",
         "inclination to the x-z plane"),
    )
    for ax, col, scol, scale, label, title in panels:
        if truth is not None and col in truth:
            ax.plot(truth["x_m"], truth[col] * scale, "-", color="0.6", lw=1, label="truth")
        ax.errorbar(ok["x_m"], ok[col] * scale, yerr=ok[scol] * scale, fmt="o", ms=4,
                    color="C0", ecolor="C3", capsize=2, label="measured (1 sigma)")
        bad = traj[~traj["ok"]] if "ok" in traj else traj.iloc[:0]
        for x in bad["x_m"].dropna() if "x_m" in bad else ():
            ax.axvline(x, color="C3", alpha=0.3)
        ax.set_ylabel(label)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("x (m, downrange)")
    axes[0, 0].legend(fontsize=8)
    return fig


def write_stage1(result, out_dir: str | os.PathLike, *, truth: pd.DataFrame | None = None,
                 overwrite: bool = False) -> Path:
    """Write stage one's folder (module doc) for ``result``; ``truth``: an optional table
    (``x_m, y_m, z_m, theta_deg, psi_deg``) drawn on the trajectory plot and compared with
    the measurement in the report. Raises :class:`cadra.atomic.UnsafeOutputError` for an
    output that is or holds an input, ``FileExistsError`` for an existing one (without
    ``overwrite``)."""
    out_dir = Path(out_dir)
    check_output_dir(out_dir, result.inputs, kind="stage one")
    if out_dir.exists() and not overwrite:
        raise FileExistsError(f"{out_dir} exists; refusing to overwrite (use --overwrite)")
    table, quality, meta, shot = result.trajectory, result.quality, result.meta, result.shot
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="stage one") as tmp:
        (tmp / "trajectory.csv").write_text(trajectory_to_csv(table, meta), encoding="utf-8")
        quality.to_csv(tmp / "quality.csv", index=False, float_format="%.8g")
        plot_table = table.assign(ok=table["status"] != "failed")
        for c in ("theta_deg", "psi_deg", "sigma_theta_deg", "sigma_psi_deg"):
            plot_table[c] = plot_table[c].astype(float)
        fig = trajectory_figure(plot_table, truth)
        fig.suptitle(f"{shot.shot_id}: stage-one trajectory measurement "
                     f"({int((table['status'] != 'failed').sum())}/{len(table)} stations)")
        figures.save(fig, tmp / "trajectory.png")
        (tmp / "overlays").mkdir()
        for r in result.stations:
            for name, v in r.views.items():
                if v.overlay_png:
                    (tmp / "overlays" / f"st{r.station:02d}_{name}.png").write_bytes(
                        v.overlay_png)
        truth_lines = []
        if truth is not None:
            from cadra.body import body_from_spec

            try:
                # a finned body's roll is known to the period of its fins only
                n_fins = len(getattr(body_from_spec(shot.model), "fin_phi_rad", ()))
                cmp = compare_with_truth(table, truth, roll_period_rad=2 * math.pi
                                         / max(n_fins, 1))
            except ValueError as exc:
                truth_lines = ["## Measured minus truth", "", f"Not compared: {exc}.", ""]
            else:
                cmp.per_station.to_csv(tmp / "truth_comparison.csv", index=False,
                                       float_format="%.8g")
                truth_lines = comparison_markdown(cmp)
        (tmp / "report.md").write_text(_report(table, quality, meta, truth_lines),
                                       encoding="utf-8")
    return out_dir


def _report(table, quality, meta, truth_lines=()) -> str:
    n = len(table)
    failed = table[table["status"] == "failed"]
    warned = table[table["status"] == "warning"]
    lines = [f"# Stage one: {meta['shot_id']}", "",
             f"{n - len(failed)} of {n} stations measured"
             f" ({len(warned)} with warnings, {len(failed)} failed).", ""]
    if len(failed):
        lines += ["## Failed stations", ""]
        lines += [f"- station {int(r.station)}: {r.reason}" for r in failed.itertuples()]
        lines.append("")
    if len(warned):
        lines += ["## Warnings", ""]
        lines += [f"- station {int(r.station)}: {r.warnings}" for r in warned.itertuples()]
        lines.append("")
    ok = quality[quality["status"] != "failed"]
    xc = table["x_consistency"].dropna()
    if len(ok) and "sigma_u_px" in ok and len(xc):
        lines += ["## Figures", "",
                  f"- median position sigma: {np.nanmedian(ok['sigma_u_px']):.4f} px (u), "
                  f"{np.nanmedian(ok['sigma_v_px']):.4f} px (v)",
                  f"- median wire-affine rms: {np.nanmedian(ok['affine_rms_px']):.4f} px",
                  f"- median edge-offset rms: {np.nanmedian(ok['edge_offset_rms_px']):.4f} px",
                  f"- largest |x_top - x_side| / sigma: "
                  f"{np.max(np.abs(xc)):.2f}", ""]
    lines += list(truth_lines)
    lines += ["Files: trajectory.csv (docs/stage1.md), quality.csv, trajectory.png, "
              "overlays/" + (", truth_comparison.csv" if truth_lines else "") + ".", ""]
    return "\n".join(lines)


def _scaled(value: float, unit: str) -> str:
    """A position error in micrometres, an angle error in degrees."""
    if unit == "m":
        return f"{value * 1e6:+.3f} µm"
    return f"{value:+.5f}°" if unit == "deg" else f"{value:+.4g} {unit}"


def comparison_markdown(cmp: TruthComparison) -> list[str]:
    """The report's section: the shot-wide figures per channel, and the stations whose
    error is beyond 3 sigma."""
    lines = ["## Measured minus truth", "",
             "Per channel over the measured stations (truth_comparison.csv has every station). "
             "z = error / reported sigma; for independent errors with honest sigmas the "
             "shot-wide mean z is 0 ± 1/√n and the rms z is 1.", ""]
    lines += markdown.table(
        ("channel", "n", "mean error", "rms error", "mean z", "rms z", "max abs z", "p (chi²)"),
        ((r.channel, r.n, _scaled(r.mean_error, r.unit),
          _scaled(r.rms_error, r.unit).lstrip("+"), f"{r.mean_z:+.2f} ± {r.mean_z_sigma:.2f}",
          f"{r.rms_z:.2f}", f"{r.max_abs_z:.2f}", f"{r.chi2_p:.3g}")
         for r in cmp.summary.itertuples()))
    lines.append("")
    big = []
    for c in OBSERVED:
        col = f"{c.name}_error_sigma"
        if col not in cmp.per_station:
            continue
        for st, z in zip(cmp.per_station["station"], cmp.per_station[col], strict=True):
            if np.isfinite(z) and abs(z) > 3.0:
                big.append(f"- station {int(st)} {c.name}: {z:+.2f} sigma")
    if big:
        lines += ["Beyond 3 sigma:", "", *big, ""]
    if cmp.unmatched:
        lines += [f"Stations without a truth row (not compared): {cmp.unmatched}", ""]
    return lines


def station_lines(table: pd.DataFrame) -> list[str]:
    """Each measured station of a trajectory table as ``value ± sigma`` (positions in mm,
    angles in deg: :func:`cadra.numfmt.pm`); a failed station is left out (its reason is
    reported on its own)."""
    from cadra.numfmt import pm

    lines = []
    for r in table.itertuples():
        if r.status == "failed":
            continue
        cells = [f"{c} {pm(getattr(r, f'{c}_m') * 1e3, getattr(r, f'sigma_{c}_m') * 1e3, 'mm')}"
                 for c in ("x", "y", "z")]
        cells += [f"{c} {pm(getattr(r, f'{c}_deg'), getattr(r, f'sigma_{c}_deg'), 'deg')}"
                  for c in ("theta", "psi")]
        lines.append(f"  station {r.station:2d}: " + ", ".join(cells))
    return lines


__all__ = ["comparison_markdown", "station_lines", "trajectory_figure", "write_stage1"]
