"""Stage one over a shot: every station's images -> the shot's trajectory table.

:func:`measure_shot` is the library call behind ``cadra1`` and :func:`cadra.measure`
(docs/stage1.md). It takes the shot's record (a :class:`cadra.io.shotfile.ShotFile` or its
file) and the images, as arrays in memory or the shot file's image files, and returns a
:class:`Stage1Result` in memory: the trajectory table, the per-view quality table and every
station's result. Nothing is written here; :func:`cadra.report.stage1.write_stage1` writes a
result's folder.

Stations are measured by :func:`cadra.imaging.station.measure_station` (pure, picklable), in
parallel on the available cores (a process pool; ``workers=1`` runs in-process), with a
progress bar. The pool's workers ignore Ctrl-C (the parent handles it) and die with the
parent, even a SIGKILLed one (:func:`_worker_init`).
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from cadra import cores
from cadra.body import body_from_spec
from cadra.imaging.silhouette.fit import FitSettings
from cadra.imaging.station import (
    VIEWS,
    StationResult,
    measure_station,
    point_source_station,
)
from cadra.imaging.wires.fit import CENTROIDS
from cadra.io.shotfile import ShotFile
from cadra.io.trajectory import station_rows


@dataclass(frozen=True, eq=False)
class Stage1Result:
    """What :func:`measure_shot` measured.

    Attributes
    ----------
    trajectory : the trajectory table (the trajectory file's columns and units,
        :mod:`cadra.io.trajectory`), one row per station.
    quality : per station and view, the figures a range engineer checks (docs/stage1.md).
    stations : every station's :class:`~cadra.imaging.station.StationResult`.
    shot : the shot's record (body, mass properties, air, spark times).
    meta : the trajectory file's metadata (shot id, shot and facility files, producer).
    inputs : the files the measurement read (shot, facility, images): an output folder must
        not be or hold any of them.
    seconds : wall time of the measurement.
    formations : view name -> the wires' image formation shared by the view's images
        (:class:`~cadra.imaging.wires.profile.Formation`, px; empty: each image its own;
        ``"centroid"``: no profile model).
    """

    trajectory: pd.DataFrame
    quality: pd.DataFrame
    stations: tuple[StationResult, ...]
    shot: ShotFile
    meta: dict
    inputs: tuple[Path, ...] = ()
    seconds: float = 0.0
    notes: tuple[str, ...] = field(default_factory=tuple)
    formations: dict = field(default_factory=dict)

    @property
    def any_failed(self) -> bool:
        return bool((self.trajectory["status"] == "failed").any())

    @property
    def n_measured(self) -> int:
        return int((self.trajectory["status"] != "failed").sum())

    def __repr__(self) -> str:
        return (f"<Stage1Result {self.shot.shot_id}: {self.n_measured}/{len(self.trajectory)} "
                f"stations measured, {self.seconds:.1f} s>")

    def shot_data(self, *, sigma_t_s: float = 0.0, min_sigma: dict | None = None,
                  effects=None):
        """The measurements as stage two's :class:`~cadra.flight.data.ShotData`, in memory
        (:func:`cadra.flight.data.shot_data_from_trajectory`); ``sigma_t_s`` the spark-time
        sigma (s), ``min_sigma`` floors of the sigmas (``{"position_m": .., "angle_rad":
        ..}``), ``effects`` the dynamics' effects."""
        from cadra.flight.data import shot_data_from_trajectory
        from cadra.io.trajectory import trajectory_from_table

        traj = trajectory_from_table(self.trajectory, self.meta,
                                     f"stage one's trajectory of {self.shot.shot_id}")
        return shot_data_from_trajectory(
            traj, self.shot, sigma_t_s=sigma_t_s, min_sigma=min_sigma, effects=effects,
            source={"shot_file": self.meta.get("shot_file", f"shot {self.shot.shot_id}"),
                    "trajectory_file": f"stage one's trajectory of {self.shot.shot_id}"})


def _task(args):
    """One station, in a worker or here: never raises (a worker that raised would leave the
    pool to terminate its siblings mid-task, which can deadlock); a failure is the
    station's, with its reason."""
    station, images, body_spec, overlays, formations, settings = args
    try:
        return measure_station(station, images, body_spec, settings=settings,
                               overlays=overlays, formations=formations)
    except Exception as exc:  # noqa: BLE001 - one station's failure must not stop the shot
        return StationResult(station.id, "failed",
                             f"measurement error ({type(exc).__name__}: {exc})", None, {}, ())


#: Images of each view the shot's wire formation is fitted from, spread along the shot.
FORMATION_IMAGES = 3


def shared_formations(tasks: list, body_spec: dict, n_images: int = FORMATION_IMAGES,
                      prepared: dict | None = None) -> dict:
    """Each view's wire formation, fitted over ``n_images`` of the shot's images of it spread
    along the range (:func:`cadra.imaging.view.view_formation`): view name -> formation
    (a view none of whose images serves is left out; its images fit their own).
    ``prepared``: a dict that receives the images read and begun, ``(station, view name)
    ->`` :class:`~cadra.imaging.view.PreparedImage`."""
    from cadra.imaging.view import view_formation

    out = {}
    for name in VIEWS:
        have = [(st.views[name], views[name]) for st, views, *_ in tasks
                if name in views and name in st.views]
        if not have:
            continue
        pick = np.unique(np.linspace(0, len(have) - 1, min(n_images, len(have)))
                         .round().astype(int))
        f = view_formation([have[i] for i in pick], body_spec, prepared)
        if f is not None:
            out[name] = f
    return out


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
                           wire_formation_from=("" if fm is None else
                                                f"view ({fm.n_images} images)" if fm.shared
                                                else "image"),
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
    (:func:`cadra.imaging.roll.resolve_roll_track`; docs/stage1.md, "Roll of a finned body").
    Unchanged when no station measured a roll (a body of revolution)."""
    from dataclasses import replace

    rolls = [r.roll if r.pose is not None else None for r in results]
    if all(x is None for x in rolls):
        return list(results)
    from cadra.imaging.roll import resolve_roll_track

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


@contextlib.contextmanager
def _pool_held_signals():
    """SIGINT and SIGTERM blocked while a pool is made: its workers, and the thread that
    forks their replacements, start with them blocked until :func:`_worker_init` has set the
    workers' own handlers. Here they are held pending and taken as soon as the pool exists."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _worker_init(parent_pid: int) -> None:
    """Pool worker set-up: die with the parent, leave Ctrl-C to the parent.

    On Linux the kernel sends the worker SIGKILL when its parent dies
    (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon thread polls :func:`os.getppid`. So a
    killed ``cadra1`` (SIGKILL included) leaves no orphan blocked on the pool's pipe. SIGINT is
    ignored here: a terminal's Ctrl-C reaches the whole process group, and the parent alone
    handles it (it terminates the pool and exits with status 130). SIGTERM gets its default
    action back (a command line turns it into an exception, which a worker must not inherit:
    the pool ends its workers with it). Both arrive blocked (:func:`_pool_held_signals`) and
    are unblocked only now, so a signal that reaches a worker between its fork and this set-up
    (the pool's terminate meeting a worker it has just forked to replace one) waits for the
    worker's own handlers instead of raising the command line's exception there.
    """
    import signal
    import sys
    import threading

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)   # the pool ends its workers by SIGTERM
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
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


def measure_shot(shot: ShotFile | str | os.PathLike,
                 images: Mapping[tuple[int, str], np.ndarray | str | os.PathLike] | None = None,
                 *, facility=None, workers: int | None = None, progress: bool = True,
                 overlays: bool = True, formation: str | Mapping = "view",
                 settings: FitSettings | None = None) -> Stage1Result:
    """Measure every station of a shot (module doc); nothing is written.

    ``shot``: the shot's record or its shot file. ``images``: ``(station, view)`` -> the image
    (a grey ``uint8``/``uint16`` array, or a file), default the shot file's image files.
    ``facility``: a :class:`cadra.facility.reference.Facility`, or a facility file or name
    (default: the shot's). ``workers``: processes (default: the available cores; 1 = in this
    process). ``overlays``: draw each image's overlay (PNG bytes in the station results).
    ``formation``: how the wires' image formation is fitted: ``"view"`` (default) once per
    view, over :data:`FORMATION_IMAGES` of the shot's images, then held for every image of
    the view that its score test accepts (:func:`shared_formations`); ``"image"`` from each
    image alone; ``"centroid"`` with no profile model (each wire's centres by centroid, with
    their phase term: the shot's quick look, ~25 % faster, the affine's sigma less honest;
    docs/stage1.md, "A quick look"); or a mapping view name -> formation (e.g.
    ``result.formations`` of another shot through the same cameras). The result's
    ``formations`` holds the shared ones. ``settings``: the silhouette fit's
    :class:`~cadra.imaging.silhouette.fit.FitSettings` for every image (default: its
    defaults).

    Bad stations are flagged in the tables, never raised; a bad shot or facility raises
    ``ValueError``/``OSError``.
    """
    import time

    from cadra.facility.reference import Facility
    from cadra.io.facility_file import load_facility, resolve_facility_path
    from cadra.io.shotfile import load_shot

    t0 = time.perf_counter()
    inputs: list[Path] = []
    shot_file = None
    if not isinstance(shot, ShotFile):
        shot_file = Path(shot)
        shot = load_shot(shot_file)
        inputs.append(shot_file)
    elif shot.source_path is not None:
        shot_file = Path(shot.source_path)
    facility_file = None
    if not isinstance(facility, Facility):
        facility_file = resolve_facility_path(facility if facility is not None
                                              else shot.facility)
        facility = load_facility(facility_file)
        inputs.append(Path(facility_file))
    known = set(facility.station_ids)
    tasks = []
    for rec in shot.stations:
        if rec.station not in known:
            raise ValueError(f"shot {shot.shot_id}: station {rec.station} is not in facility "
                             f"{facility.name!r}")
        if images is None:
            views = {v: shot.image_path(rec.station, v) for v in rec.images}
        else:
            views = {v: images[(rec.station, v)] for v in VIEWS if (rec.station, v) in images}
        inputs += [Path(p) for p in views.values() if isinstance(p, str | os.PathLike)]
        tasks.append((facility.station(rec.station), views, dict(shot.model), overlays))
    if tasks:   # a body the stations' optics cannot measure is the shot's error, not a station's
        body = body_from_spec(dict(shot.model))
        for station, *_ in tasks:
            point_source_station(station, body)
    workers = _workers(workers, len(tasks))
    prepared = {}   # the images the formation pass read and began, for stations measured here
    if isinstance(formation, Mapping):
        formations = dict(formation)
    elif formation == "view":
        formations = shared_formations(tasks, dict(shot.model),
                                       prepared=prepared if workers == 1 else None)
    elif formation == "image":
        formations = {}
    elif formation == CENTROIDS:
        formations = dict.fromkeys(VIEWS, CENTROIDS)
    else:
        raise ValueError(f"formation must be 'view', 'image', {CENTROIDS!r} or a mapping "
                         f"view -> formation, not {formation!r}")
    tasks = [(st, {n: prepared.get((st.id, n), src) for n, src in views.items()}, *rest,
              formations, settings) for st, views, *rest in tasks]
    results = _run(tasks, workers, f"cadra1 {shot.shot_id}" if progress else None)
    times = {rec.station: rec.time_s for rec in shot.stations}
    results = with_roll_track(results, times)
    meta = {"shot_id": shot.shot_id,
            "shot_file": str(shot_file.resolve()) if shot_file is not None else "",
            "facility": facility.name,
            "facility_file": str(facility_file or facility.source_path or ""),
            "body": shot.model.get("name", shot.model.get("kind")),
            "producer": "cadra1 (silhouette least squares, docs/stage1.md)",
            "frame": "facility F: x downrange, y port, z up, origin station 1 (m)"}
    return Stage1Result(station_rows(results, times), quality_rows(results), tuple(results),
                        shot, meta, tuple(inputs), time.perf_counter() - t0,
                        formations=formations)


def _workers(workers: int | None, n_tasks: int) -> int:
    """The processes ``n_tasks`` stations are measured in (``workers`` None: the cores)."""
    workers = cores.available() if workers is None else max(int(workers), 1)
    return min(workers, n_tasks) or 1


def _run(tasks: list, workers: int | None, label: str | None) -> list[StationResult]:
    """The station tasks, in a process pool of ``workers`` (default: the cores; 1 = here),
    with a progress bar labelled ``label`` (None: none)."""
    workers = _workers(workers, len(tasks))
    bar = None
    if label is not None:
        from tqdm import tqdm

        bar = tqdm(total=len(tasks), desc=label, unit="station")
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
            with _pool_held_signals():
                pool = ctx.Pool(workers, initializer=_worker_init, initargs=(os.getpid(),))
            with pool:
                for res in pool.imap(_task, tasks):
                    results.append(res)
                    if bar is not None:
                        bar.update()
    finally:
        if bar is not None:
            bar.close()
    return results


__all__ = ["FORMATION_IMAGES", "Stage1Result", "measure_shot", "quality_rows",
           "shared_formations", "with_roll_track"]
