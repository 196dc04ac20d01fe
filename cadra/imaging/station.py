"""Measure one station: both views' images -> the station's 3-D pose (stage one, per station).

:func:`measure_station` is a pure function of plain, picklable data (the station's geometry,
its images as arrays or paths, the body's spec dict, settings) returning a
:class:`StationResult`, so a process pool or a Dask scheduler can ship it. Per view
(docs/stage1.md):

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

import functools
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
from cadra.imaging.silhouette.edges import MAX_EDGE_SIGMA_PX
from cadra.imaging.silhouette.fit import FitSettings, ViewFit, fit_silhouette
from cadra.imaging.silhouette.locate import locate_model, pose_from_coarse
from cadra.imaging.silhouette.template import (
    make_conical_template,
    make_template,
    outline_px,
)
from cadra.io.images import load_station_image, station_image
from cadra.optics.distortion import distorted
from cadra.optics.projection import Projection

VIEWS = ("top", "side")

#: Half-width (px) of the pixel mask about each found wire that the silhouette fit ignores.
WIRE_MASK_HALF_WIDTH_PX = 4.0
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
#: tilt step (rad) of the outline template that gives a view's pose sensitivity to the tilt
#: (ViewFit.tilt_sensitivity; linear within 3 % up to 1 deg)
TILT_STEP_RAD = math.radians(0.3)
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
class ViewResult:
    """One view's outcome: the fit (or why there is none) and the wire measurement."""

    view: str
    image_path: str
    ok: bool
    reason: str
    fit: ViewFit | None = None
    wires: object | None = None            # cadra.imaging.wires.fit.WireMeasurement
    affine: np.ndarray | None = None       # image -> plane actually used
    tilt_rad: float = 0.0
    warnings: tuple[str, ...] = ()
    seconds: float = 0.0
    overlay_png: bytes | None = None
    projection: Projection | None = None   # the view's optics with that affine
    roll_rad: float = 0.0                  # roll of the template (a finned body's)


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


@functools.lru_cache(maxsize=8)
def _body_cached(spec_items: tuple):
    from cadra.body.spec import body_from_spec

    return body_from_spec(dict(spec_items))


def _body(body_spec: dict):
    """The body of a spec, one object per distinct spec in a process (so its templates,
    cached per body object, are shared by the stations of a shot)."""
    from cadra.body.spec import body_from_spec

    try:
        return _body_cached(tuple(sorted(body_spec.items())))
    except TypeError:   # an unhashable or unorderable spec: build it afresh
        return body_from_spec(body_spec)


@functools.lru_cache(maxsize=64)
def _template_cached(body_key, body, view_name: str, tilt_rad: float, n_points: int,
                     roll_rad: float):
    return make_template(body, view_name, tilt_rad, n_points=n_points, roll_rad=roll_rad)


def _template(body, view_name: str, tilt_rad: float, n_points: int = 1024,
              roll_rad: float = 0.0):
    """Outline template, cached per process (a station asks for the same one repeatedly);
    the roll only for a finned body (a body of revolution's outline does not depend on it)."""
    roll = float(roll_rad) if isinstance(body, FinnedBody) else 0.0
    return _template_cached(id(body), body, view_name, float(tilt_rad), int(n_points), roll)


@functools.lru_cache(maxsize=64)
def _conical_template_cached(body_key, body, view, r_ref: tuple, axis: tuple, roll_rad: float,
                             n_points: int, tilt_rad: float):
    return make_conical_template(body, view.optics(), np.array(r_ref), np.array(axis),
                                 n_points=n_points, roll_rad=roll_rad, tilt_rad=tilt_rad)


def _view_templates(body, view, tilt_rad: float, roll_rad: float, pose3d, final: bool):
    """The view's outline template and (``final``) the pair at the tilt +- TILT_STEP_RAD that
    give the fit's tilt sensitivity. A parallel view's depends on the axis' tilt out of its
    plane; a point-source view's on the whole 3-D pose ``pose3d`` = (reference point, m; unit
    axis), the tilt stepped about the film's plane with the axis' film image kept."""
    if view.projection != "point_source":
        steps = ((_template(body, view.name, tilt_rad + TILT_STEP_RAD, roll_rad=roll_rad),
                  _template(body, view.name, tilt_rad - TILT_STEP_RAD, roll_rad=roll_rad),
                  TILT_STEP_RAD) if final else None)
        return _template(body, view.name, tilt_rad, roll_rad=roll_rad), steps
    r_ref, axis = pose3d
    roll = float(roll_rad) if isinstance(body, FinnedBody) else 0.0

    def at(a, tilt):
        return _conical_template_cached(id(body), body, view, tuple(r_ref), tuple(a), roll,
                                        1024, float(tilt))
    if not final:
        return at(axis, tilt_rad), None
    n = np.zeros(3)
    n[view.sight_axis] = 1.0
    a = np.asarray(axis, dtype=float)
    e = a - (a @ n) * n
    e /= np.linalg.norm(e)
    tau = math.asin(float(np.clip(a @ n, -1.0, 1.0)))
    stepped = [np.cos(tau + h) * e + np.sin(tau + h) * n
               for h in (TILT_STEP_RAD, -TILT_STEP_RAD)]
    return at(axis, tilt_rad), (at(stepped[0], tilt_rad + TILT_STEP_RAD),
                                at(stepped[1], tilt_rad - TILT_STEP_RAD), TILT_STEP_RAD)


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


def _wire_crossings(fit: ViewFit, template, projection, wires) -> list[str]:
    """Names of found wires whose image comes within the fit band of the model's outline."""
    if wires is None or not fit.ok:
        return []
    poly = outline_px(template, fit.pose, projection)
    names = []
    for w in wires.wires:
        if not w.found:
            continue
        p, t = np.asarray(w.point_px, float), np.asarray(w.direction_px, float)
        n = np.array([-t[1], t[0]])
        dist = (poly - p) @ n
        if dist.min() < WIRE_MASK_HALF_WIDTH_PX and dist.max() > -WIRE_MASK_HALF_WIDTH_PX:
            names.append(w.name)
    return names


@dataclass(frozen=True)
class _Attempt:
    """One try at a view: the silhouette fit (or None), why it failed ("" if it did not),
    the wires found, the affine used and the warnings."""

    fit: ViewFit | None
    reason: str
    wires: object | None = None
    affine: np.ndarray | None = None
    warnings: tuple[str, ...] = ()


def _model_box(img: np.ndarray, coarse, margin: int = 12) -> np.ndarray:
    """True on the model's rough bounding box (``coarse``, :func:`locate_model`) plus a
    margin: the pixels the wires' profiles must not use."""
    exclude = np.zeros(img.shape, bool)
    u0, v0, u1, v1 = coarse.bbox
    exclude[max(v0 - margin, 0):v1 + margin + 1, max(u0 - margin, 0):u1 + margin + 1] = True
    return exclude


def _measure_view(img, view, body, tilt: float, settings: FitSettings, prev=None,
                  coarse=None, final: bool = True, masks: dict | None = None,
                  roll: float = 0.0, restart: bool = False, formation=None,
                  pose3d=None) -> _Attempt:
    """Wires + silhouette of one loaded image; ``prev`` a previous ViewResult to warm-start,
    ``coarse`` the model's rough location (:func:`locate_model`); ``masks`` (view name ->
    wire mask) keeps the wire mask of the first pass for the refits (same affine);
    ``restart``: start the edge model afresh from ``prev``'s pose (a finned body whose roll,
    so template, changed much since ``prev``: its edge profile was fitted to mismatched fins);
    ``formation``: the view's wire formation shared over the shot (None: this image's own);
    ``pose3d``: a point-source view's expected 3-D pose (:func:`_view_templates`). A
    distorted view's wires and silhouette are both fitted in ``img``, the recorded image,
    through its distortion."""
    from cadra.imaging.wires.fit import measure_wires
    from cadra.imaging.wires.mask import wire_mask

    masks = {} if masks is None else masks

    template, tilt_step = _view_templates(body, view, tilt, roll, pose3d, final)
    if prev is None:
        if coarse is None:
            coarse = locate_model(img, template, view.optics())
        if not coarse.ok:
            return _Attempt(None, coarse.reason)
        wires = measure_wires(img, view, exclude=_model_box(img, coarse), formation=formation,
                              distortion=view.distortion)
        if not wires.ok:
            return _Attempt(None, wires.reason, wires)
        affine = wires.affine
        pose0 = pose_from_coarse(coarse, template, distorted(wires.projection, view.distortion))
        mask = masks[view.name] = wire_mask(view, affine, img.shape, WIRE_MASK_HALF_WIDTH_PX,
                                            distortion=view.distortion)
        # a quick first pass when a refit with better tilts follows
        # (its sigma is not used: the offsets' correlation is left to the final fit)
        settings_used = settings if final else replace(
            settings, max_iter=2,
            covariance=("scaled" if settings.covariance in ("correlated", "predicted")
                        else settings.covariance))
    else:
        wires, affine = prev.wires, prev.affine
        pose0 = prev.fit.pose
        mask = masks.get(view.name)
        if mask is None:
            mask = wire_mask(view, affine, img.shape, WIRE_MASK_HALF_WIDTH_PX,
                             distortion=view.distortion)
        settings_used = settings
    if prev is not None and not restart:   # a refit after a small tilt change: few iterations
        settings_used = replace(settings, max_iter=min(settings.max_iter, 4))
    warm = prev is not None and not restart
    fit = fit_silhouette(img, template, distorted(wires.projection, view.distortion), pose0,
                         exclude=mask,
                         settings=settings_used,
                         edge_sigma0=prev.fit.edge_sigma_px if warm else 0.9,
                         noise_coef=prev.fit.noise_coef if warm else None,
                         edge_profile0=prev.fit.edge_profile if warm else None,
                         centroid=final, tilt_step=tilt_step)
    if not fit.ok:
        return _Attempt(fit, fit.reason, wires, affine)
    warn = list(fit.warnings)
    if wires.reason:
        warn.append(wires.reason)
    for w in wires.wires:
        if not w.found:
            warn.append(w.reason or f"wire {w.name!r} not found")
        elif w.dropped_px > 0.0:
            warn.append(f"wire {w.name!r}: {w.dropped_px:.0f} px of it left out, its centres "
                        f"there off its line together (a shock or flow line along it?)")
    crossing = _wire_crossings(fit, template, wires.projection, wires)
    if crossing:
        warn.append(f"model crosses wire(s) {', '.join(repr(c) for c in crossing)}: "
                    f"{fit.n_segments} edge segments used, pixels on the wire masked")
    return _Attempt(fit, "", wires, affine, tuple(warn))


def measure_view(image, view, body_spec, *, tilt_rad: float = 0.0, roll_rad: float = 0.0,
                 settings: FitSettings | None = None, formation=None) -> ViewResult:
    """One view of one station from its image alone, in the manner of trackpy's ``locate``:
    find the model, fit the wires and the silhouette, and return the view's
    :class:`ViewResult` (pose in the view's plane with its covariance, the wires' affine).

    ``image``: a grey ``uint8``/``uint16`` array (or a float array in [0, 1]); ``view``: the
    facility's :class:`cadra.facility.reference.View`; ``body_spec``: the shot's model table
    (or a body); ``tilt_rad``: the axis' tilt out of this view's plane, which only the other
    view sees (:func:`measure_station` alternates the two views to settle it; here it is
    given, 0 by default); ``roll_rad``: a finned body's roll for its outline template;
    ``formation``: the view's wire formation fitted over several images
    (:func:`view_formation`; None: this image's own).
    """
    import time

    if view.projection == "point_source":
        raise ValueError(f"station {view.station} {view.name}: a point-source view's shadow "
                         f"depends on the model's depth, which only the station's other view "
                         f"gives; measure the station (measure_station)")
    t0 = time.perf_counter()
    settings = FitSettings() if settings is None else settings
    body = body_spec if hasattr(body_spec, "kind") else _body(body_spec)
    name = f"station {view.station} {view.name} image"
    img = np.asarray(image)
    if img.dtype.kind == "f":
        if img.shape != (view.height_px, view.width_px) or not np.all(np.isfinite(img)):
            return ViewResult(view.name, name, False, "a float image must be finite and of the "
                              f"view's size {view.width_px}x{view.height_px} px")
        img = img.astype(np.float32)
    else:
        img = station_image(img, view.width_px, view.height_px, view.bit_depth, name)
        if not isinstance(img, np.ndarray):
            return ViewResult(view.name, name, False, img.reason)
    coarse = locate_model(img, _template(body, view.name, 0.0, 256), view.optics())
    att = _measure_view(img, view, body, float(tilt_rad), settings, coarse=coarse, final=True,
                        roll=float(roll_rad), formation=formation)
    ok = att.fit is not None and att.fit.ok
    return ViewResult(view.name, name, ok, att.reason, att.fit, att.wires, att.affine,
                      float(tilt_rad), att.warnings, time.perf_counter() - t0,
                      projection=None if att.wires is None else att.wires.projection,
                      roll_rad=float(roll_rad))


def _image_name(station_id: int, view: str, source) -> str:
    """What a view's image is called in the tables: its path, or where it came from."""
    if isinstance(source, str | os.PathLike):
        return str(source)
    return f"station {station_id} {view} image (in memory)"


def _view_image(view, src, name: str):
    """A view's image as a float array (or the loader's failure, with its ``reason``)."""
    if isinstance(src, str | os.PathLike):
        return load_station_image(src, view.width_px, view.height_px, view.bit_depth)
    return station_image(src, view.width_px, view.height_px, view.bit_depth, name)


def view_formation(sources, body_spec):
    """One view's wire image formation, fitted over a few of a shot's images of it.

    ``sources``: ``(view, image)`` pairs, the facility's view of each station and its image
    (an array or a file); ``body_spec``: the shot's model table. Each image's model is
    located roughly, its wires' clean profiles are taken outside it
    (:func:`cadra.imaging.wires.fit.wire_profiles`) and all are fitted together
    (:func:`cadra.imaging.wires.formation.fit_formation`). Returns the
    :class:`~cadra.imaging.wires.profile.Formation` (``n_images`` the images used), or None
    when no image gives three wires' profiles or the fit fails: the images then fit their
    own.
    """
    from cadra.imaging.wires.fit import wire_profiles
    from cadra.imaging.wires.formation import fit_formation

    body = body_spec if hasattr(body_spec, "kind") else _body(body_spec)
    profiles, n = [], 0
    for view, src in sources:
        try:
            img = _view_image(view, src, f"station {view.station} {view.name} image")
            if not isinstance(img, np.ndarray):
                continue
            coarse = locate_model(img, _template(body, view.name, 0.0, 256), view.optics())
            if not coarse.ok:
                continue
            got = wire_profiles(img, view, exclude=_model_box(img, coarse),
                                distortion=view.distortion)
        except Exception:  # noqa: BLE001 - that image's station reports it; others serve
            continue
        if len(got) >= 3:
            profiles += got
            n += 1
    if not n:
        return None
    try:
        formation, _ = fit_formation(profiles)
    except (ValueError, np.linalg.LinAlgError):
        return None
    return replace(formation, n_images=n)


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
    body = _body(body_spec)
    station_id = station.id
    conical = point_source_station(station, body)
    image_names = {n: _image_name(station_id, n, src) for n, src in images.items()}
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
        img = _view_image(view, src, image_names[name])
        if not isinstance(img, np.ndarray):
            results[name] = ViewResult(name, image_names[name], False, img.reason)
            continue
        images[name] = img
    # first guess of each view's out-of-plane tilt from the other view's rough axis angle
    nominal = {n: distorted(v.optics(), v.distortion) for n, v in station.views.items()}
    coarse = {n: locate_model(img, _template(body, n, 0.0, 256), nominal[n])
              for n, img in images.items()}
    tilts = {"top": 0.0, "side": 0.0}
    if not sphere and all(n in coarse and coarse[n].ok for n in VIEWS):
        phi = {n: pose_from_coarse(coarse[n], _template(body, n, 0.0, 256), nominal[n])[2]
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
            a, b, phi = pose_from_coarse(coarse[n], _template(body, n, 0.0, 256), nominal[n])
            rough[n] = ViewPose(a, b, phi if math.isfinite(phi) else 0.0, 1e-4, 1e-4, 1e-3,
                                projection=nominal[n])
        pose3d = _station_pose3d(rough, sphere)
        tilts = _tilts_of(station, pose3d[1])
    fits: dict[str, ViewResult] = {}
    masks: dict[str, np.ndarray] = {}
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
            # from the template's, or slide along the axis with most segments rejected or its edge
            # width at stage A's cap: then the other start rolls are tried, and the fit with
            # an edge width below the cap that rejects least is kept
            tries = ROLL_TRIES_RAD if finned and prev is None else (roll,)
            best = None
            for view_roll in tries:
                try:
                    att = _measure_view(
                        img, station.views[name], body, tilts[name], settings, prev,
                        coarse[name], final=sphere or _round > 0, masks=masks, roll=view_roll,
                        formation=(formations or {}).get(name), pose3d=pose3d,
                        restart=prev is not None and abs(wrap_period(view_roll - prev.roll_rad))
                        > ROLL_RESTART_RAD)
                except Exception as exc:  # noqa: BLE001 - one bad image must not stop a shot
                    att = _Attempt(None, f"measurement error ({type(exc).__name__}: {exc})")
                if att.fit is not None and att.fit.ok:
                    # a try whose edge width ends at stage A's cap fitted no edges: the
                    # worst kind, whatever share of its segments it kept
                    score = (att.fit.edge_sigma_px >= 0.999 * MAX_EDGE_SIGMA_PX,
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
            tpl = (_view_templates(body, station.views[name], r.tilt_rad, r.roll_rad, pose3d,
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
        return radial_from_wires(images[name], view, _model_box(images[name], coarse[name]))

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
