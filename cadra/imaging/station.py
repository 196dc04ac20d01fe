"""Measure one station: both views' images -> the station's 3-D pose (stage one, per station).

:func:`measure_station` is a pure function of plain, picklable data (the station's geometry,
its images as arrays or paths, the body's spec dict, settings) returning a
:class:`StationResult`, so a process pool or a Dask scheduler can ship it. Per view
(docs/stage1.md; the view's own steps, 2-4, in :mod:`cadra.imaging.view`):

1. take the image (an array, :func:`cadra.io.images.station_image`, or a file,
   :func:`cadra.io.images.load_station_image`; a bad one fails that view with its
   reason);
2. locate the model roughly (:func:`cadra.imaging.silhouette.locate.locate_model`) with the view's
   nominal projection;
3. find and fit the fiducial wires, solve the image->plane affine and so the view's
   :class:`~cadra.optics.projection.Projection` (:func:`cadra.imaging.wires.fit.measure_wires`),
   the model's box excluded;
4. fit the silhouette (method a, :mod:`cadra.imaging.silhouette.fit`) and the area centroid
   (method b, :mod:`cadra.imaging.silhouette.centroid`) with the wires masked.

The two views are then alternated: each view's outline depends on the axis' tilt out of its
plane, which the other view measures; two or three rounds converge (the outline depends on the
tilt only through its cosine). Finally :func:`cadra.imaging.combine.combine_views`.

For a finned body (:class:`cadra.body.FinnedBody`) the outline depends on the roll as well:
its templates are made at the station's current roll estimate, and after each round the roll
is measured from the fin silhouettes of both views with the poses held
(:mod:`cadra.imaging.roll`); the rounds go on until tilts and roll settle.
``StationResult.roll`` keeps the station's roll candidates; the shot's driver chooses among them
by continuity (:func:`cadra.imaging.roll.resolve_roll_track`).

Every problem is a reason string on the view or station; nothing raises for bad data.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from cadra.body import FinnedBody
from cadra.conventions import axis_from_inclinations, axis_from_projected_angles
from cadra.facility.reference import Station
from cadra.imaging.combine import StationPose, ViewPose, combine_views
from cadra.imaging.distorted import (
    BOW_PASSES,
    add_bows,
    bow_warning,
    declare_bows,
    distortion_pose_sigma,
    ideal_image,
    undeclared_bows,
    wires_miss_cause,
)
from cadra.imaging.roll import measure_roll, wrap_period
from cadra.imaging.silhouette.edge_model import MAX_EDGE_SIGMA_PX
from cadra.imaging.silhouette.fit import FitSettings, ViewFit
from cadra.imaging.silhouette.locate import locate_model, pose_from_coarse
from cadra.imaging.view import (
    PreparedImage,
    ViewAttempt,
    ViewResult,
    body_of,
    fit_view,
    image_name,
    model_box,
    view_image,
    view_template,
    view_templates,
)
from cadra.optics.distortion import distorted

VIEWS = ("top", "side")

#: roll (rad) of a finned body's templates before its roll is measured: halfway between the
#: mirror folds at 0 and 45 deg (docs/stage1.md, "Roll of a finned body")
ROLL_START_RAD = math.radians(22.5)
#: a finned body's view is refitted with a fresh edge model when its template's roll moved
#: more than this since the last fit (rad)
ROLL_RESTART_RAD = math.radians(0.2)
#: start rolls (rad) of a finned body's first fit of a view, tried in turn until one fits
ROLL_TRIES_RAD = tuple(math.radians(x) for x in (22.5, 0.0, 45.0, 11.25, 33.75))
#: ... and beyond the first, while the fit rejects more than this share of its segments: a
#: start far from the fins' roll can leave the nose and fins rejected and the body slid along
#: its axis (a point-source station's top view, 54 % rejected: 119 px off)
ROLL_START_REJECTED = 0.3
#: a finned body's rounds stop when the roll moves less than this between rounds (rad)
ROLL_TOL_RAD = math.radians(0.002)
#: A point-source station's rounds stop once the 3-D pose its shadow templates are made at
#: moves less than this, m (a shadow's shape changes by about size x move / spark distance:
#: 1e-6 m moves a 30 mm bullet's 1.5 m from its spark by 2e-8 m, 1e-4 px)
CONICAL_POSITION_TOL_M = 1e-6
#: a station whose two views disagree on x by more than this many of their combined sigmas
#: (the disagreement is ~N(0, 1): docs/stage1.md, "The two views' x errors") is failed: a
#: swapped, foreign or repeated image, not a measurement
X_CONSISTENCY_MAX = 6.0
#: a view whose found wires miss their surveyed lines by more than this rms (px; ~0.0006 px
#: on the renderer's views, 0.0012 at most over a shot) fails its station: the image is not
#: this view's
WIRE_RMS_MAX_PX = 0.05


@dataclass(frozen=True)
class StationResult:
    """A station's outcome. ``status``: ``"ok"``, ``"warning"`` (measured, see ``warnings``)
    or ``"failed"`` (not measured, see ``reason``)."""

    station: int
    status: str
    reason: str
    pose: StationPose | None
    views: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    roll: object | None = None      # a finned body's cadra.imaging.roll.StationRoll


def _station_pose3d(poses: Mapping[str, ViewPose], sphere: bool):
    """(reference point, m; unit axis) of a station from its two views' poses (the rays'
    intersection, the planes through the sparks): what a point-source template is made at."""
    p = combine_views(poses["top"], poses["side"])
    axis = (1.0, 0.0, 0.0) if sphere else tuple(axis_from_inclinations(p.theta_rad, p.psi_rad))
    return (p.x_m, p.y_m, p.z_m), axis


def _view_pose(fit: ViewFit, wires, view=None) -> ViewPose:
    """The view's pose for combination: the silhouette fit's sigma, the wire affine's
    uncertainty at the model's position and a calibrated distortion's (its coefficients'
    covariance carried to the model's point and direction, :func:`distortion_pose_sigma`),
    added in quadrature."""
    s_ang = math.sqrt(fit.cov[2, 2])
    finite = math.isfinite(s_ang)   # a sphere's angle is not measured: placeholder 0 +- 0
    s_aff = wires.position_sigma_m(fit.ref_px)
    s_dis = (0.0, 0.0, 0.0) if view is None else distortion_pose_sigma(view, wires, fit.pose)
    return ViewPose(a_m=fit.pose[0], b_m=fit.pose[1], angle_rad=fit.pose[2] if finite else 0.0,
                    sigma_a_m=math.sqrt(fit.cov[0, 0] + s_aff[0] ** 2 + s_dis[0] ** 2),
                    sigma_b_m=math.sqrt(fit.cov[1, 1] + s_aff[1] ** 2 + s_dis[1] ** 2),
                    sigma_angle_rad=math.hypot(s_ang, s_dis[2]) if finite else 0.0,
                    projection=wires.projection, tilt_sensitivity=fit.tilt_sensitivity)


def measure_station(station: Station, images: Mapping[str, np.ndarray | str | os.PathLike],
                    body_spec: dict, settings: FitSettings | None = None, max_rounds: int = 3,
                    overlays: bool = True, formations: Mapping | None = None,
                    find_distortion: bool = True) -> StationResult:
    """Measure one station from its images (see the module docstring).

    With ``find_distortion``, a view that declares no distortion but whose wires bow as one
    radial distortion bows them (:func:`cadra.imaging.distorted.undeclared_bows`) is measured
    again with that distortion, found from its wires, declared; the station's warnings say so
    (docs/stage1.md, "An undeclared distortion").

    ``station``: the station's geometry (:meth:`cadra.facility.reference.Facility.station`);
    ``images``: view name -> the image, a grey ``uint8``/``uint16`` array (as the renderer
    or a frame grabber gives it) or an image file's path; ``body_spec``: the shot's model
    table (:func:`cadra.body.spec.body_from_spec`). With ``overlays`` each image's overlay
    (fitted wires and silhouette) comes back as PNG bytes in ``views[name].overlay_png``.
    ``formations``: view name -> the view's wire formation shared over the shot
    (:func:`view_formation`); a view without one fits its image's own.
    """
    args = (images, body_spec, settings, max_rounds, overlays, formations)
    # a station failed by its wires is explained (a radial search, seconds a view) only once
    # the bow's passes are done, and only if it still fails
    result = _measure_once(station, *args, explain=not find_distortion)
    bows, found = undeclared_bows(station, result.views) if find_distortion else {}, {}
    for _ in range(BOW_PASSES):     # each pass measures the bow that the last one left
        if not bows:
            break
        found = add_bows(found, bows)
        result = _measure_once(declare_bows(station, found), *args, explain=False)
        bows = undeclared_bows(station, result.views)
    if find_distortion and result.status == "failed":    # as declared, and why it fails
        result = _measure_once(station, *args, explain=True)
    if not found:
        return result
    notes = tuple(f"{n}: {bow_warning(b)}" for n, b in found.items())
    return replace(result, status="failed" if result.status == "failed" else "warning",
                   warnings=(*notes, *result.warnings))


def _measure_once(station: Station, images, body_spec: dict, settings: FitSettings | None,
                  max_rounds: int, overlays: bool, formations: Mapping | None,
                  explain: bool = True) -> StationResult:
    """:func:`measure_station` with the station's views as declared; ``explain``: a view
    whose wires miss their survey is searched for a radial distortion that explains it."""
    import time

    settings = FitSettings() if settings is None else settings
    body = body_of(body_spec)
    station_id = station.id
    conical = point_source_station(station, body)
    image_names = {n: image_name(station_id, n, src) for n, src in images.items()}
    images_in, images, results = images, {}, {}
    sphere = body.kind == "sphere"
    for name in VIEWS:
        view = station.views.get(name)
        src = images_in.get(name)
        if view is None:
            results[name] = ViewResult(name, image_names.get(name, "None"), False,
                                       f"facility has no {name} view")
            continue
        if src is None:
            results[name] = ViewResult(name, "", False, "no image listed in the shot file")
            continue
        img = view_image(view, src, image_names[name])
        if not isinstance(img, np.ndarray):
            results[name] = ViewResult(name, image_names[name], False, img.reason)
            continue
        images[name] = img
    # first guess of each view's out-of-plane tilt from the other view's rough axis angle
    nominal = {n: distorted(v.optics(), v.distortion) for n, v in station.views.items()}
    # an image the shot's formation pass began (PreparedImage) was located there alike,
    # through the view's distortion as it was declared
    prepared = {n: src for n, src in images_in.items()
                if isinstance(src, PreparedImage) and n in station.views
                and src.distortion is station.views[n].distortion}
    coarse = {n: (prepared[n].coarse if n in prepared
                  else locate_model(img, view_template(body, n, 0.0, 256), nominal[n]))
              for n, img in images.items()}
    tilts = {"top": 0.0, "side": 0.0}
    if not sphere and all(n in coarse and coarse[n].ok for n in VIEWS):
        phi = {n: pose_from_coarse(coarse[n], view_template(body, n, 0.0, 256), nominal[n])[2]
               for n in VIEWS}
        a = axis_from_projected_angles(phi["side"], phi["top"])
        tilts = {"top": math.asin(a[2]), "side": math.asin(a[1])}
    pose3d = None
    if conical:     # the rough 3-D pose the first shadow templates are made at
        if not all(n in coarse and coarse[n].ok for n in VIEWS):
            why = "; ".join(f"{n} view: {coarse[n].reason}" for n in VIEWS
                            if n in coarse and not coarse[n].ok)
            return StationResult(station_id, "failed", "a point-source station needs both "
                                 "views to place the model in depth" + (f" ({why})" if why
                                                                          else ""),
                                 None, results)
        rough = {}
        for n in VIEWS:
            a, b, phi = pose_from_coarse(coarse[n], view_template(body, n, 0.0, 256), nominal[n])
            rough[n] = ViewPose(a, b, phi if math.isfinite(phi) else 0.0, 1e-4, 1e-4, 1e-3,
                                projection=nominal[n])
        pose3d = _station_pose3d(rough, sphere)
        tilts = _tilts_of(station, pose3d[1])
    fits: dict[str, ViewResult] = {}
    masks: dict[str, np.ndarray] = {}
    wires_made: dict = {}   # each view's wires, measured once for its first fits' tries
    finned = isinstance(body, FinnedBody)
    roll, station_roll = ROLL_START_RAD, None
    rounds = (2 if conical else 1) if sphere else (max_rounds + 2 if finned else max_rounds)
    for _round in range(rounds):
        for name, img in images.items():
            t0 = time.perf_counter()
            prev = fits.get(name)
            if prev is not None and not prev.ok:
                continue
            # a finned body's first fit, before its roll is measured, may fail with fins far
            # from the template's, or slide along the axis with most segments rejected or its
            # edge width at stage A's cap: then the other start rolls are tried, and the fit
            # with an edge width below the cap that rejects least is kept. A refit at a new
            # roll starts afresh from the last pose, and (that failing or as poor) from the
            # rough location, as a first fit at that roll
            restart = (prev is not None
                       and abs(wrap_period(roll - prev.roll_rad)) > ROLL_RESTART_RAD)
            tries = (tuple((r, None) for r in ROLL_TRIES_RAD) if finned and prev is None
                     else ((roll, prev), (roll, None)) if restart else ((roll, prev),))
            best = None
            for view_roll, start in tries:
                try:
                    att = fit_view(
                        img, station.views[name], body, tilts[name], settings, start,
                        coarse[name], final=sphere or _round > 0, masks=masks, roll=view_roll,
                        formation=(formations or {}).get(name), pose3d=pose3d,
                        restart=start is not None and restart,
                        first_pass=prepared[name].first_pass if name in prepared else None,
                        wires_made=wires_made)
                except Exception as exc:  # noqa: BLE001 - one bad image must not stop a shot
                    att = ViewAttempt(None, f"measurement error ({type(exc).__name__}: {exc})")
                if att.fit is not None and att.fit.ok:
                    # a try whose edge width ends at stage A's cap fitted no edges, one whose
                    # kept segments leave its pose undetermined fitted too few: the worst
                    # kind, whatever share of its segments it kept
                    score = (att.fit.edge_sigma_px >= 0.999 * MAX_EDGE_SIGMA_PX
                             or not att.fit.determined,
                             att.fit.n_rejected / max(att.fit.n_segments, 1))
                    if best is None or score < best[0]:
                        best = (score, att, view_roll)
                    if score <= (False, ROLL_START_REJECTED):
                        break
            if best is not None:
                _, att, view_roll = best
            ok = att.fit is not None and att.fit.ok
            fits[name] = ViewResult(name, image_names[name], ok, att.reason, att.fit, att.wires,
                                    att.affine, tilts[name], att.warnings,
                                    time.perf_counter() - t0 + (prev.seconds if prev else 0.0),
                                    projection=None if att.wires is None
                                    else att.wires.projection,
                                    roll_rad=view_roll)
        if not all(n in fits and fits[n].ok for n in VIEWS) or (sphere and not conical):
            break
        moved_m = 0.0
        if conical:     # the shadow templates follow the pose the views now give
            try:
                new3d = _station_pose3d({n: _view_pose(fits[n].fit, fits[n].wires)
                                         for n in VIEWS}, sphere)
            except (ValueError, np.linalg.LinAlgError) as exc:
                return StationResult(station_id, "failed", "the two views' rays from their "
                                     f"sparks do not meet ({exc})", None, fits)
            moved_m = float(np.linalg.norm(np.subtract(new3d[0], pose3d[0])))
            pose3d = new3d
            new = _tilts_of(station, pose3d[1])
        else:
            a = axis_from_projected_angles(fits["side"].fit.pose[2], fits["top"].fit.pose[2])
            new = {"top": math.asin(a[2]), "side": math.asin(a[1])}
        change = max(abs(new[n] - tilts[n]) for n in VIEWS)
        tilts = new
        if sphere:
            if moved_m < CONICAL_POSITION_TOL_M:
                break
            continue
        roll_settled = True
        if finned:
            try:
                station_roll = measure_roll(body, station.views, images, fits, tilts, masks,
                                            settings, station_roll, pose3d)
            except Exception as exc:  # noqa: BLE001 - the pose stands without a roll
                station_roll = None
                roll_warning = f"roll not measured ({type(exc).__name__}: {exc})"
                fits = {n: replace(r, warnings=(*r.warnings, roll_warning))
                        for n, r in fits.items()}
                break
            new_roll = station_roll.best.roll_rad
            roll_settled = abs(wrap_period(new_roll - roll)) < ROLL_TOL_RAD
            roll = new_roll
        if (change < 2e-5 and moved_m < CONICAL_POSITION_TOL_M and roll_settled
                and _round > 0):   # round 0 is a quick pass
            break
    results.update(fits)
    if overlays:
        from cadra.imaging.overlay import encode_png, view_overlay

        for name, img in images.items():
            r = results[name]
            tpl = (view_templates(body, station.views[name], r.tilt_rad, r.roll_rad, pose3d,
                                   False)[0] if r.fit is not None and r.fit.ok else None)
            # drawn on a distorted view's ideal image, where its wires, outline and
            # reference point are
            png = encode_png(view_overlay(ideal_image(station.views[name], img), r, tpl,
                                          station_id))
            results[name] = ViewResult(**{**r.__dict__, "overlay_png": png})
    ok_views = [n for n in VIEWS if n in results and results[n].ok]
    warnings = tuple(f"{n}: {w}" for n in ok_views for w in results[n].warnings)
    if len(ok_views) < 2:
        failed = [n for n in VIEWS if n not in ok_views]
        reason = "; ".join(f"{n} view: {results[n].reason}" for n in failed if n in results)
        return StationResult(station_id, "failed", reason or "no usable view", None, results,
                             warnings)
    pose = combine_views(*(_view_pose(results[n].fit, results[n].wires, station.views[n])
                           for n in VIEWS))
    if sphere:
        pose = StationPose(**{**pose.__dict__, "theta_rad": math.nan, "psi_rad": math.nan,
                              "sigma_theta_rad": math.nan, "sigma_psi_rad": math.nan})
    def radial(name):   # an undeclared distortion? only for a view declaring none
        from cadra.imaging.wires.distortion import radial_from_wires

        view = station.views[name]
        if view.distortion is not None or not coarse.get(name, None) or not coarse[name].ok:
            return None
        return radial_from_wires(images[name], view, model_box(images[name], coarse[name]))

    wrong = _views_disagree(pose, results, radial if explain else None)
    if wrong:
        return StationResult(station_id, "failed", wrong, pose, results, warnings,
                             roll=station_roll)
    status = "warning" if warnings else "ok"
    return StationResult(station_id, status, "", pose, results, warnings, roll=station_roll)


def point_source_station(station: Station, body) -> bool:
    """Whether the station's views are point-source ones (then both must be)."""
    kinds = {v.projection for v in station.views.values()}
    if "point_source" not in kinds:
        return False
    if len(kinds) > 1:
        raise ValueError(f"station {station.id}: one point-source and one parallel view; "
                         f"stage one measures a station whose views share their optics")
    return True


def _tilts_of(station: Station, axis) -> dict[str, float]:
    """Each view's tilt of the axis out of its plane (along its sight axis), rad."""
    a = np.asarray(axis, dtype=float)
    return {n: math.asin(float(np.clip(a[station.views[n].sight_axis], -1.0, 1.0)))
            for n in VIEWS}


def _views_disagree(pose: StationPose, results: dict, radial=None) -> str:
    """Why a station's views cannot both be its own ("" if they can): their x beyond
    :data:`X_CONSISTENCY_MAX` sigmas apart, or a view's wires off their surveyed lines beyond
    :data:`WIRE_RMS_MAX_PX` (a swapped, foreign or repeated image, or an undeclared image
    distortion when ``radial(view name)``, a
    :func:`~cadra.imaging.wires.distortion.radial_from_wires` result, explains the wires;
    flagged, never used)."""
    why = []
    for name in VIEWS:
        rms = results[name].wires.affine_rms_px
        if rms > WIRE_RMS_MAX_PX:
            cause = wires_miss_cause(radial(name) if radial is not None else None,
                                     WIRE_RMS_MAX_PX)
            why.append(f"{name} view: its wires miss their surveyed lines by {rms:.3g} px rms "
                       f"(> {WIRE_RMS_MAX_PX:g}): {cause}")
    xc = pose.x_consistency_sigma
    if xc > X_CONSISTENCY_MAX:
        why.append(f"the two views disagree on x by {xc:.3g} sigma (> {X_CONSISTENCY_MAX:g}): "
                   f"swapped, foreign or repeated images?")
    return "; ".join(why)
