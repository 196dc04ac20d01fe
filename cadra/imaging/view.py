"""Measure one view of one station: its image -> the model's pose in the view's plane.

:func:`measure_view` locates the model (:func:`cadra.imaging.silhouette.locate.locate_model`),
finds and fits the fiducial wires with the model's box left out
(:func:`cadra.imaging.wires.fit.measure_wires`: the image->plane affine, so the view's
:class:`~cadra.optics.projection.Projection`) and fits the silhouette (method a,
:mod:`cadra.imaging.silhouette.fit`) and the area centroid (method b) with the wires masked
(docs/stage1.md). The outline templates a fit uses are made and cached here: a parallel view's
at the axis' tilt out of its plane (and a finned body's roll), a point-source view's at the
model's whole 3-D pose. :func:`view_formation` fits a view's wire image formation over several
of a shot's images. A station's two views are alternated and combined by
:mod:`cadra.imaging.station`.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, replace

import numpy as np

from cadra.body import FinnedBody
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

#: Half-width (px) of the pixel mask about each found wire that the silhouette fit ignores.
WIRE_MASK_HALF_WIDTH_PX = 4.0
#: tilt step (rad) of the outline template that gives a view's pose sensitivity to the tilt
#: (ViewFit.tilt_sensitivity; linear within 3 % up to 1 deg)
TILT_STEP_RAD = math.radians(0.3)


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


@functools.lru_cache(maxsize=8)
def _body_cached(spec_items: tuple):
    from cadra.body.spec import body_from_spec

    return body_from_spec(dict(spec_items))


def body_of(body_spec: dict):
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


def view_template(body, view_name: str, tilt_rad: float, n_points: int = 1024,
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


def view_templates(body, view, tilt_rad: float, roll_rad: float, pose3d, final: bool):
    """The view's outline template and (``final``) the pair at the tilt +- TILT_STEP_RAD that
    give the fit's tilt sensitivity. A parallel view's depends on the axis' tilt out of its
    plane; a point-source view's on the whole 3-D pose ``pose3d`` = (reference point, m; unit
    axis), the tilt stepped about the film's plane with the axis' film image kept."""
    if view.projection != "point_source":
        steps = ((view_template(body, view.name, tilt_rad + TILT_STEP_RAD, roll_rad=roll_rad),
                  view_template(body, view.name, tilt_rad - TILT_STEP_RAD, roll_rad=roll_rad),
                  TILT_STEP_RAD) if final else None)
        return view_template(body, view.name, tilt_rad, roll_rad=roll_rad), steps
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
class ViewAttempt:
    """One try at a view: the silhouette fit (or None), why it failed ("" if it did not),
    the wires found, the affine used and the warnings."""

    fit: ViewFit | None
    reason: str
    wires: object | None = None
    affine: np.ndarray | None = None
    warnings: tuple[str, ...] = ()


def model_box(img: np.ndarray, coarse, margin: int = 12) -> np.ndarray:
    """True on the model's rough bounding box (``coarse``, :func:`locate_model`) plus a
    margin: the pixels the wires' profiles must not use."""
    exclude = np.zeros(img.shape, bool)
    u0, v0, u1, v1 = coarse.bbox
    exclude[max(v0 - margin, 0):v1 + margin + 1, max(u0 - margin, 0):u1 + margin + 1] = True
    return exclude


def fit_view(img, view, body, tilt: float, settings: FitSettings, prev=None,
                  coarse=None, final: bool = True, masks: dict | None = None,
                  roll: float = 0.0, restart: bool = False, formation=None,
                  pose3d=None, first_pass=None, wires_made: dict | None = None
                  ) -> ViewAttempt:
    """Wires + silhouette of one loaded image; ``prev`` a previous ViewResult to warm-start,
    ``coarse`` the model's rough location (:func:`locate_model`); ``masks`` (view name ->
    wire mask) keeps the wire mask of the first pass for the refits (same affine);
    ``restart``: start the edge model afresh from ``prev``'s pose (a finned body whose roll,
    so template, changed much since ``prev``: its edge profile was fitted to mismatched fins);
    ``formation``: the view's wire formation shared over the shot (None: this image's own);
    ``pose3d``: a point-source view's expected 3-D pose (:func:`view_templates`);
    ``first_pass``: the wires' centroid pass made already with ``coarse``'s box
    (:class:`PreparedImage`; :func:`cadra.imaging.wires.fit.measure_wires`);
    ``wires_made`` (view name -> the wires measured with ``coarse``'s box) keeps the first
    try's wires for the station's other tries at a first fit (a finned body's start rolls,
    a restart from the rough location): the same image, box and formation. A
    distorted view's wires and silhouette are both fitted in ``img``, the recorded image,
    through its distortion."""
    from cadra.imaging.wires.fit import measure_wires
    from cadra.imaging.wires.mask import wire_mask

    masks = {} if masks is None else masks

    template, tilt_step = view_templates(body, view, tilt, roll, pose3d, final)
    if prev is None:
        if coarse is None:
            coarse = locate_model(img, template, view.optics())
        if not coarse.ok:
            return ViewAttempt(None, coarse.reason)
        wires = None if wires_made is None else wires_made.get(view.name)
        if wires is None:
            wires = measure_wires(img, view, exclude=model_box(img, coarse),
                                  formation=formation, distortion=view.distortion,
                                  first_pass=first_pass)
            if wires_made is not None:
                wires_made[view.name] = wires
        if not wires.ok:
            return ViewAttempt(None, wires.reason, wires)
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
        return ViewAttempt(fit, fit.reason, wires, affine)
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
    return ViewAttempt(fit, "", wires, affine, tuple(warn))


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
    body = body_spec if hasattr(body_spec, "kind") else body_of(body_spec)
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
    coarse = locate_model(img, view_template(body, view.name, 0.0, 256), view.optics())
    att = fit_view(img, view, body, float(tilt_rad), settings, coarse=coarse, final=True,
                        roll=float(roll_rad), formation=formation)
    ok = att.fit is not None and att.fit.ok
    return ViewResult(view.name, name, ok, att.reason, att.fit, att.wires, att.affine,
                      float(tilt_rad), att.warnings, time.perf_counter() - t0,
                      projection=None if att.wires is None else att.wires.projection,
                      roll_rad=float(roll_rad))


@dataclass(frozen=True, eq=False)
class PreparedImage:
    """A station's image the shot's formation pass has read and begun
    (:func:`view_formation`): its ``pixels`` (float32 in [0, 1]) from ``path`` (None: an
    array in memory), the model's rough location on it (``coarse``, located as the station
    locates it) and its wires' centroid pass outside that box (``first_pass``, None if none
    was made), both through the view's ``distortion`` then. A station measured in the same
    process goes on from these while its view has that distortion (not when it measures
    again with a distortion it found) instead of doing them again; it names the image by
    its file."""

    path: str | None
    pixels: np.ndarray
    coarse: object
    first_pass: object | None
    distortion: object | None = None


def image_name(station_id: int, view: str, source) -> str:
    """What a view's image is called in the tables: its path, or where it came from."""
    if isinstance(source, str | os.PathLike):
        return str(source)
    if isinstance(source, PreparedImage) and source.path is not None:
        return source.path
    return f"station {station_id} {view} image (in memory)"


def view_image(view, src, name: str):
    """A view's image as a float array (or the loader's failure, with its ``reason``)."""
    if isinstance(src, str | os.PathLike):
        return load_station_image(src, view.width_px, view.height_px, view.bit_depth)
    if isinstance(src, PreparedImage):
        return src.pixels
    return station_image(src, view.width_px, view.height_px, view.bit_depth, name)


def view_formation(sources, body_spec, prepared: dict | None = None):
    """One view's wire image formation, fitted over a few of a shot's images of it.

    ``sources``: ``(view, image)`` pairs, the facility's view of each station and its image
    (an array or a file); ``body_spec``: the shot's model table. Each image's model is
    located roughly, its wires' clean profiles are taken outside it
    (:func:`cadra.imaging.wires.fit.wire_profiles`) and all are fitted together
    (:func:`cadra.imaging.wires.formation.fit_formation`). Returns the
    :class:`~cadra.imaging.wires.profile.Formation` (``n_images`` the images used), or None
    when no image gives three wires' profiles or the fit fails: the images then fit their
    own. ``prepared``: a dict that receives each image read, as ``(station, view name) ->``
    :class:`PreparedImage`.
    """
    from cadra.imaging.wires.fit import centroid_pass
    from cadra.imaging.wires.formation import fit_formation

    body = body_spec if hasattr(body_spec, "kind") else body_of(body_spec)
    profiles, n = [], 0
    for view, src in sources:
        try:
            img = view_image(view, src, f"station {view.station} {view.name} image")
            if not isinstance(img, np.ndarray):
                continue
            # located as the station locates it (through the view's distortion), so the
            # station can go on from here
            coarse = locate_model(img, view_template(body, view.name, 0.0, 256),
                                  distorted(view.optics(), view.distortion))
            first = (centroid_pass(img, view, exclude=model_box(img, coarse),
                                   distortion=view.distortion) if coarse.ok else None)
            if prepared is not None:
                prepared[(view.station, view.name)] = PreparedImage(
                    str(src) if isinstance(src, str | os.PathLike) else None, img, coarse,
                    first, view.distortion)
            if first is None:
                continue
            got = first.profiles()
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

