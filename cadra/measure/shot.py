"""Stage one over a shot: every station's images -> trajectory measurement file and reports.

:func:`measure_shot` is the library call behind ``cadra1`` (docs/stage1.md). Stations are
measured by :func:`cadra.measure.station.measure_station` (pure, picklable), in parallel on the
available cores (a process pool; ``workers=1`` runs in-process), with a progress bar. Outputs go
to a temporary sibling directory moved into place at the end (:func:`cadra.io.atomic.
atomic_output_dir`): an interrupted or failed run leaves nothing behind, an existing output
directory is never overwritten unless asked, and an output directory that is or holds an input
(shot file, facility file, images; links resolved) is refused
(:func:`cadra.io.atomic.check_output_dir`). The pool's workers ignore Ctrl-C (the parent
handles it) and die with the parent, even a SIGKILLed one (:func:`_worker_init`).

Output directory::

    trajectory.csv        the trajectory measurement file (cadra.io.trajectory)
    quality.csv           per station and view: wires, affine, silhouette-fit figures, flags
    trajectory.png        one page: x-z, x-y, theta and psi vs x with error bars
    overlays/stNN_VIEW.png  every image with the fitted wires and silhouette
    report.md             what was measured, what failed and why
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.io.trajectory import station_rows, trajectory_to_csv
from cadra.measure.station import VIEWS, StationResult, measure_station


@dataclass(frozen=True)
class Stage1Result:
    """What :func:`measure_shot` measured (tables as written) and where it wrote them."""

    trajectory: pd.DataFrame
    quality: pd.DataFrame
    stations: tuple[StationResult, ...]
    out_dir: Path | None
    seconds: float

    @property
    def any_failed(self) -> bool:
        return bool((self.trajectory["status"] == "failed").any())


def _task(args):
    station_id, paths, body_spec, facility_path, overlays = args
    return measure_station(station_id, paths, body_spec, facility_path, overlays=overlays)


def quality_rows(results) -> pd.DataFrame:
    """Per station and view: the figures a range engineer checks (docs/stage1.md)."""
    rows = []
    for r in results:
        for name in VIEWS:
            v = r.views.get(name)
            row = {"station": r.station, "view": name}
            if v is None:
                row.update(status="failed", reason="not measured")
                rows.append(row)
                continue
            row.update(status="ok" if v.ok and not v.warnings else
                       ("warning" if v.ok else "failed"),
                       reason=v.reason, warnings="; ".join(v.warnings), image=v.image_path,
                       seconds=v.seconds)
            w = v.wires
            if w is not None:
                row.update(wires_found=w.n_found, affine_rms_px=w.affine_rms_px,
                           affine_rms_um=w.affine_rms_m * 1e6,
                           wire_residuals_px="; ".join(
                               f"{x.name}={x.residual_px:+.4f}" if x.found else f"{x.name}=missing"
                               for x in w.wires))
                fm = w.formation   # the wires' image formation (profile model), or centroids
                blur = (math.nan,) * 3 if fm is None else (fm.sigma_c, fm.sigma_d, fm.fringe_w)
                row.update(wire_centres="centroid" if fm is None else "profile model",
                           **dict(zip(("wire_blur_before_px", "wire_blur_after_px",
                                       "wire_fringe_width_px"), blur, strict=True)))
            f = v.fit
            if f is not None and f.ok:
                row.update(
                    u_ref_px=f.ref_px[0], v_ref_px=f.ref_px[1],
                    axis_angle_px_deg=math.degrees(f.axis_angle_px_rad),
                    sigma_u_px=f.sigma_ref_px[0], sigma_v_px=f.sigma_ref_px[1],
                    sigma_axis_deg=math.degrees(f.sigma_axis_px_rad),
                    a_m=f.pose[0], b_m=f.pose[1], angle_deg=math.degrees(f.pose[2]),
                    tilt_deg=math.degrees(v.tilt_rad),
                    edge_sigma_px=f.edge_sigma_px, curvature_bias_px2=f.curvature_bias_px2,
                    edge_offset_rms_px=f.offset_rms_px, intensity_resid_rms=f.resid_rms,
                    n_segments=f.n_segments, n_rejected=f.n_rejected,
                    iterations=f.iterations, converged=f.converged,
                    ls_minus_centroid_u_px=f.ref_px[0] - f.centroid_ref_px[0],
                    ls_minus_centroid_v_px=f.ref_px[1] - f.centroid_ref_px[1],
                    ls_minus_centroid_axis_deg=math.degrees(
                        f.axis_angle_px_rad - f.centroid_axis_px_rad),
                )
                roll = getattr(r, "roll", None)
                if roll is not None and name in roll.best.views:
                    vr = roll.best.views[name]   # this view's roll, modulo 90 deg
                    row.update(roll_mod90_deg=math.degrees(vr.roll_rad) % 90.0,
                               sigma_roll_deg=math.degrees(vr.sigma_rad),
                               roll_candidates=len(roll.candidates),
                               roll_mirror_chi2=(roll.candidates[1].chi2_excess
                                                 if len(roll.candidates) > 1 else math.nan))
            rows.append(row)
    return pd.DataFrame(rows)


def with_roll_track(results, times_s: dict) -> list:
    """``results`` with each measured station's roll set on its pose (``phi_rad``,
    ``sigma_phi_rad``): a finned body's roll candidates resolved along the shot by continuity
    (:func:`cadra.measure.roll.resolve_roll_track`; docs/stage1.md, "Roll of a finned body").
    Unchanged when no station measured a roll (a body of revolution)."""
    from dataclasses import replace

    rolls = [r.roll if r.pose is not None else None for r in results]
    if all(x is None for x in rolls):
        return list(results)
    from cadra.measure.roll import resolve_roll_track

    order = np.argsort([times_s[r.station] for r in results], kind="stable")
    t = [times_s[results[k].station] for k in order]
    phi, sig, _ = resolve_roll_track(t, [rolls[k] for k in order])
    out = list(results)
    for j, k in enumerate(order):
        if math.isfinite(phi[j]):
            r = out[k]
            out[k] = replace(r, pose=replace(r.pose, phi_rad=float(phi[j]),
                                             sigma_phi_rad=float(sig[j])))
    return out


def _watch_parent(parent_pid: int, period_s: float = 0.5) -> None:
    """Exit this process (a pool worker) as soon as its parent is gone."""
    import time

    while True:
        time.sleep(period_s)
        if os.getppid() != parent_pid:
            os._exit(1)


def _worker_init(parent_pid: int) -> None:
    """Pool worker set-up: die with the parent, leave Ctrl-C to the parent.

    On Linux the kernel sends the worker SIGKILL when its parent dies
    (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon thread polls :func:`os.getppid`. So a
    killed ``cadra1`` (SIGKILL included) leaves no orphan blocked on the pool's pipe. SIGINT is
    ignored here: a terminal's Ctrl-C reaches the whole process group, and the parent alone
    handles it (it terminates the pool and exits with status 130).
    """
    import signal
    import sys
    import threading

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    armed = False
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            pr_set_pdeathsig = 1
            armed = libc.prctl(pr_set_pdeathsig, int(signal.SIGKILL), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:  # the parent died before the death signal was armed
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True,
                         name="cadra-parent-watch").start()


def measure_shot(shot_path: str | os.PathLike, out_dir: str | os.PathLike | None = None, *,
                 workers: int | None = None, progress: bool = True, overlays: bool = True,
                 overwrite: bool = False, truth: pd.DataFrame | None = None) -> Stage1Result:
    """Measure every station of a shot; write the outputs to ``out_dir`` (None: write nothing).

    ``workers``: processes (default: the available cores; 1 = in this process). ``truth``: an
    optional table (``x_m, y_m, z_m, theta_deg, psi_deg``) drawn on the trajectory plot.
    Bad stations are flagged in the tables, never raised; bad shot/facility files raise
    ``ValueError``/``OSError`` before anything is written.
    """
    import time

    from cadra.io.facility_file import load_facility, resolve_facility_path
    from cadra.io.shotfile import load_shot

    t0 = time.perf_counter()
    shot = load_shot(shot_path)
    facility_path = str(resolve_facility_path(shot.facility))
    facility = load_facility(facility_path)
    known = set(facility.station_ids)
    tasks, inputs = [], [Path(shot_path), Path(facility_path)]
    for rec in shot.stations:
        if rec.station not in known:
            raise ValueError(f"shot {shot.shot_id}: station {rec.station} is not in facility "
                             f"{facility.name!r}")
        paths = {v: str(shot.image_path(rec.station, v)) for v in rec.images}
        inputs += [Path(p) for p in paths.values()]
        tasks.append((rec.station, paths, dict(shot.model), facility_path, overlays))
    if out_dir is not None:
        from cadra.io.atomic import check_output_dir

        out_dir = Path(out_dir)
        check_output_dir(out_dir, inputs)  # inputs are never overwritten (UnsafeOutputError)
        if out_dir.exists() and not overwrite:
            raise FileExistsError(f"{out_dir} exists; refusing to overwrite (use --overwrite)")
    workers = (os.cpu_count() or 1) if workers is None else max(int(workers), 1)
    workers = min(workers, len(tasks)) or 1
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), desc=f"cadra1 {shot.shot_id}", unit="station")
    results = []
    try:
        if workers == 1:
            for t in tasks:
                results.append(_task(t))
                if bar is not None:
                    bar.update()
        else:
            import multiprocessing as mp

            # fork where the platform has it: workers inherit the loaded modules and compiled
            # kernels instead of importing them again (seconds per worker otherwise)
            method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
            ctx = mp.get_context(method)
            # leaving the block (done, failed or interrupted) terminates the workers at once;
            # each worker also dies with this process (_worker_init)
            with ctx.Pool(workers, initializer=_worker_init, initargs=(os.getpid(),)) as pool:
                for res in pool.imap(_task, tasks):
                    results.append(res)
                    if bar is not None:
                        bar.update()
    finally:
        if bar is not None:
            bar.close()
    times = {rec.station: rec.time_s for rec in shot.stations}
    results = with_roll_track(results, times)
    table = station_rows(results, times)
    quality = quality_rows(results)
    meta = {"shot_id": shot.shot_id, "shot_file": str(Path(shot_path).resolve()),
            "facility": facility.name, "facility_file": facility_path,
            "body": shot.model.get("name", shot.model.get("kind")),
            "producer": "cadra1 (silhouette least squares, docs/stage1.md)",
            "frame": "facility F: x downrange, y port, z up, origin station 1 (m)"}
    if out_dir is not None:
        _write_outputs(out_dir, table, quality, results, meta, shot, truth, overwrite)
    return Stage1Result(table, quality, tuple(results), out_dir, time.perf_counter() - t0)


def _write_outputs(out_dir: Path, table, quality, results, meta, shot, truth, overwrite):
    from cadra.io.atomic import atomic_output_dir
    from cadra.measure.plots import trajectory_figure

    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        (tmp / "trajectory.csv").write_text(trajectory_to_csv(table, meta), encoding="utf-8")
        quality.to_csv(tmp / "quality.csv", index=False, float_format="%.8g")
        plot_table = table.assign(ok=table["status"] != "failed")
        for c in ("theta_deg", "psi_deg", "sigma_theta_deg", "sigma_psi_deg"):
            plot_table[c] = plot_table[c].astype(float)
        fig = trajectory_figure(plot_table, truth)
        fig.suptitle(f"{shot.shot_id}: stage-one trajectory measurement "
                     f"({int((table['status'] != 'failed').sum())}/{len(table)} stations)")
        fig.savefig(tmp / "trajectory.png", dpi=110)
        import matplotlib.pyplot as plt

        plt.close(fig)
        (tmp / "overlays").mkdir()
        for r in results:
            for name, v in r.views.items():
                if v.overlay_png:
                    (tmp / "overlays" / f"st{r.station:02d}_{name}.png").write_bytes(
                        v.overlay_png)
        truth_lines = []
        if truth is not None:
            from cadra.body import body_from_spec
            from cadra.measure.truth_compare import compare_with_truth, comparison_markdown

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
