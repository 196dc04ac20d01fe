"""Facility reference files: reading and validating (docs/facility_file.md).

The file format of :mod:`cadra.facility` -- stations, views, optics, fiducial wires -- parsed
into the facility's data objects (:class:`~cadra.facility.reference.Facility`, ``Station``,
``View``, ``Wire``, ``ReferenceMark``, which keep the geometry). Errors are
:class:`FacilityFileError` naming the key path, e.g.
``stations[3].views.top.wires[1].p0_m: expected 3 numbers``; :func:`load_facility` puts the
file's path in front. ``point_source`` views (a spark and a film, a direct shadowgraph) carry
``source_position_m`` and ``film_distance_m``, checked for a plausible layout.
"""

from __future__ import annotations

import math
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from cadra.atomic import atomic_write_text
from cadra.facility.reference import (
    REPO_ROOT,
    SCHEMA_VERSION,
    VIEW_AXES,
    Facility,
    ReferenceMark,
    Station,
    View,
    Wire,
    default_hffaf_text,
    fit_affine_to_wires,
    nominal_image_to_plane,
    sight_axis,
)
from cadra.io.toml_file import Fields, prefixed_by, read_toml
from cadra.optics.distortion import COEFFICIENTS, Distortion

#: Projections the loader knows.
PROJECTIONS_KNOWN = ("parallel", "point_source")
#: A point-source view's magnification at its station's point of the line of flight: the
#: standard layouts give 1.0-1.3 (docs/facility_file.md); beyond this bound the file is wrong.
MAX_MAGNIFICATION = 3.0
BIT_DEPTHS = (8, 16)
#: Minimum number of wires per view (an affine has 6 unknowns; each wire line gives 2).
MIN_WIRES = 3


class FacilityFileError(ValueError):
    """A facility reference file that cannot be right; the message names the key path."""


_F = Fields(FacilityFileError)
_err, _number, _positive, _integer = _F.fail, _F.number, _F.positive, _F.integer
_table, _require, _check_unknown = _F.as_table, _F.require, _F.check_unknown


def _vec(value, n: int, path: str) -> np.ndarray:
    return _F.vector(value, n, path)


_VIEW_KEYS = {"projection", "width_px", "height_px", "bit_depth", "scale_m_per_px",
              "image_to_plane", "wires", "reference_mark", "source_position_m",
              "film_distance_m", "distortion"}
_DISTORTION_KEYS = {"k1", "k2", "p1", "p2", "centre_px", "radius_px", "covariance"}
#: the largest distortion displacement the file accepts, as a fraction of the normalising
#: radius (seed 002's 0.3 deg at the corners is 0.5 %): beyond it the coefficients' units or
#: normalisation are wrong
MAX_DISTORTION_FRACTION = 0.05
_DEFAULT_KEYS = _VIEW_KEYS - {"image_to_plane", "wires", "projection"}


def _check_projection(proj, where: str) -> str:
    if not isinstance(proj, str) or proj not in PROJECTIONS_KNOWN:
        raise _err(where, f"unknown projection {proj!r}; known: {list(PROJECTIONS_KNOWN)}")
    return proj


def _point_source(merged: Mapping, key_path, vpath: str, axes: tuple[int, int], x_m: float):
    """A point-source view's spark (3,) and film distance, checked for a plausible layout:
    the spark off the line of flight along the sight axis, the film beyond that line, the
    magnification at the station's point of the line at most :data:`MAX_MAGNIFICATION`."""
    for k in ("source_position_m", "film_distance_m"):
        if k not in merged:
            raise _err(f"{vpath}{k}", "missing (a point-source view needs its spark and film; "
                                    "give it in the view or in [view_defaults])")
    S = _vec(merged["source_position_m"], 3, key_path("source_position_m"))
    if np.any(np.abs(S) > 1e4):
        raise _err(key_path("source_position_m"), f"{S.tolist()} is not a position in metres")
    film = _positive(merged["film_distance_m"], key_path("film_distance_m"), 1e2)
    sight = sight_axis(axes)
    stand_off = abs(float(S[sight]))
    if stand_off < 0.1:
        raise _err(key_path("source_position_m"),
                   f"the spark is {stand_off:.3g} m from the line of flight along the view's "
                   f"sight axis ({'xyz'[sight]}); it must stand off by at least 0.1 m")
    if film <= stand_off:
        raise _err(key_path("film_distance_m"),
                   f"{film:g} m puts the film on the spark's side of the line of flight "
                   f"(the spark stands {stand_off:g} m off it)")
    if film / stand_off > MAX_MAGNIFICATION:
        raise _err(key_path("film_distance_m"),
                   f"magnification {film / stand_off:.3g} at the line of flight (film "
                   f"{film:g} m, spark {stand_off:g} m off it) is implausible (> "
                   f"{MAX_MAGNIFICATION:g}; check the units)")
    if abs(float(S[0]) - x_m) > stand_off:
        raise _err(key_path("source_position_m"),
                   f"the spark at x = {S[0]:g} m is more than its stand-off ({stand_off:g} m) "
                   f"from its station at x = {x_m:g} m")
    return S, film


def _distortion(value, path: str, width: int, height: int) -> Distortion:
    """A view's ``distortion`` table (docs/facility_file.md, "Distortion"), checked: finite
    coefficients, a centre and a positive radius, a symmetric positive semi-definite
    covariance, a map that keeps its orientation over the image and moves no point by more
    than :data:`MAX_DISTORTION_FRACTION` of the radius."""
    table = _table(value, path)
    pre = f"{path}."
    _check_unknown(table, _DISTORTION_KEYS, pre)
    nominal = Distortion.for_image(width, height)
    coef = [_number(table.get(k, 0.0), f"{pre}{k}") for k in COEFFICIENTS]
    centre = (_vec(table["centre_px"], 2, f"{pre}centre_px") if "centre_px" in table
              else np.array(nominal.centre_px))
    radius = (_positive(table["radius_px"], f"{pre}radius_px", 1e6) if "radius_px" in table
              else nominal.radius_px)
    cov = None
    if "covariance" in table:
        raw = table["covariance"]
        if not isinstance(raw, list | tuple) or len(raw) != 4:
            raise _err(f"{pre}covariance", f"expected 4 rows of 4 numbers (k1, k2, p1, p2), "
                                           f"got {raw!r}")
        cov = np.array([_vec(r, 4, f"{pre}covariance[{i}]") for i, r in enumerate(raw)])
    try:        # the model's own checks (a symmetric, positive semi-definite covariance)
        d = Distortion(*coef, centre_px=tuple(centre), radius_px=radius, covariance=cov)
    except ValueError as exc:
        raise _err(f"{pre}covariance" if "covariance" in str(exc) else path, str(exc)) from None
    if not d.is_invertible_on(width, height):
        raise _err(path, "folds the image over (its Jacobian's determinant is not positive "
                         "everywhere on it); check the coefficients' signs and radius_px")
    moved = d.max_displacement_px(width, height)
    if moved > MAX_DISTORTION_FRACTION * radius:
        raise _err(path, f"moves image points by up to {moved:.3g} px, more than "
                         f"{MAX_DISTORTION_FRACTION:g} of radius_px = {radius:g} px "
                         f"(check the coefficients' normalisation: r in units of radius_px)")
    return d


def _reference_mark(value, path: str, width: int, height: int) -> ReferenceMark:
    mark = _table(value, path)
    _check_unknown(mark, {"u_px", "v_px", "arm_px", "width_px"}, f"{path}.")
    u = _number(_require(mark, "u_px", f"{path}."), f"{path}.u_px")
    v = _number(_require(mark, "v_px", f"{path}."), f"{path}.v_px")
    arm = _positive(_require(mark, "arm_px", f"{path}."), f"{path}.arm_px", 1e3)
    wid = _positive(_require(mark, "width_px", f"{path}."), f"{path}.width_px", 1e2)
    if not (arm <= u <= width - 1 - arm and arm <= v <= height - 1 - arm):
        raise _err(path, f"the mark at ({u:g}, {v:g}) with arm {arm:g} px is not inside the "
                         f"{width} x {height} image")
    return ReferenceMark(u_px=u, v_px=v, arm_px=arm, width_px=wid)


def _wire(value, path: str, axes: tuple[int, int]) -> Wire:
    w = _table(value, path)
    _check_unknown(w, {"name", "p0_m", "p1_m", "diameter_m"}, f"{path}.")
    name = _require(w, "name", f"{path}.")
    if not isinstance(name, str) or not name:
        raise _err(f"{path}.name", f"expected a non-empty string, got {name!r}")
    p0 = _vec(_require(w, "p0_m", f"{path}."), 3, f"{path}.p0_m")
    p1 = _vec(_require(w, "p1_m", f"{path}."), 3, f"{path}.p1_m")
    for key, p in (("p0_m", p0), ("p1_m", p1)):
        if np.any(np.abs(p) > 1e4):
            raise _err(f"{path}.{key}", f"{p.tolist()} is not a position in metres")
    dia = _positive(_require(w, "diameter_m", f"{path}."), f"{path}.diameter_m", 5e-3)
    d = (p1 - p0)[list(axes)]
    if np.hypot(d[0], d[1]) < 1e-3:
        raise _err(path, "the wire is seen end-on in this view (projected length < 1 mm)")
    return Wire(name=name, p0_m=p0, p1_m=p1, diameter_m=dia)


def _view(data, path: str, name: str, station_id: int, x_m: float, defaults: Mapping,
          facility_projection: tuple[str, str]) -> View:
    view = _table(data, path)
    vpath = f"{path}."
    _check_unknown(view, _VIEW_KEYS, vpath)
    merged = {**defaults, **view}
    if "projection" in view:
        projection = _check_projection(view["projection"], f"{vpath}projection")
    else:
        projection = _check_projection(*facility_projection)

    def key_path(k):  # where a merged key came from
        return f"{vpath}{k}" if k in view else f"view_defaults.{k}"

    def get(k):
        if k not in merged:
            raise _err(f"{vpath}{k}", "missing (give it in the view or in [view_defaults])")
        return merged[k]

    width = _integer(get("width_px"), key_path("width_px"), 16, 100_000)
    height = _integer(get("height_px"), key_path("height_px"), 16, 100_000)
    bit_depth = get("bit_depth")
    if bit_depth not in BIT_DEPTHS or isinstance(bit_depth, bool):
        raise _err(key_path("bit_depth"), f"must be one of {list(BIT_DEPTHS)}, got {bit_depth!r}")
    scale = _positive(get("scale_m_per_px"), key_path("scale_m_per_px"), 1e-2)
    if scale < 1e-9:
        raise _err(key_path("scale_m_per_px"), f"{scale:g} m/px is implausibly small "
                                               f"(< 1e-09; check the unit)")
    axes = VIEW_AXES[name]
    spark, film = None, None
    if projection == "point_source":
        spark, film = _point_source(merged, key_path, vpath, axes, x_m)
    else:
        for k in ("source_position_m", "film_distance_m"):
            if k in merged and k in view:
                raise _err(key_path(k), "given for a parallel view (a point-source view's key)")
    if "image_to_plane" in view:
        ipath = f"{vpath}image_to_plane"
        raw = view["image_to_plane"]
        if not isinstance(raw, list | tuple) or len(raw) != 2:
            raise _err(ipath, f"expected 2 rows of 3 numbers, got {raw!r}")
        M = np.array([_vec(r, 3, f"{ipath}[{i}]") for i, r in enumerate(raw)])
        for i, j in np.ndindex(2, 3):  # m/px like scale_m_per_px; the offset a position
            limit = 1e4 if j == 2 else 1e-2
            if abs(M[i, j]) > limit:
                raise _err(f"{ipath}[{i}][{j}]", f"{M[i, j]:g} is implausibly large "
                                                 f"(|value| <= {limit:g} m{'' if j == 2 else '/px'}"
                                                 f"; check the unit)")
        det = float(np.linalg.det(M[:, :2]))
        if not abs(det) > 0:
            raise _err(ipath, "the affine is singular")
        if abs(math.sqrt(abs(det)) / scale - 1.0) > 0.02:
            raise _err(ipath, f"its scale {math.sqrt(abs(det)):.6g} m/px disagrees with "
                              f"scale_m_per_px = {scale:.6g} by more than 2 %")
    else:
        M = nominal_image_to_plane(x_m, scale, width, height)
    mark = _reference_mark(get("reference_mark"), key_path("reference_mark"), width, height)
    distortion = (_distortion(merged["distortion"], key_path("distortion"), width, height)
                  if "distortion" in merged else None)
    wires_raw = get("wires")
    wpath = key_path("wires")
    if not isinstance(wires_raw, list | tuple):
        raise _err(wpath, "expected an array of wire tables")
    wires = tuple(_wire(w, f"{wpath}[{i}]", axes) for i, w in enumerate(wires_raw))
    names = [w.name for w in wires]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise _err(wpath, f"wire name {dup!r} used twice")
    if len(wires) < MIN_WIRES:
        raise _err(wpath, f"{len(wires)} wire(s); at least {MIN_WIRES} are needed to solve "
                          f"the image->plane affine")
    v = View(station=station_id, name=name, projection=projection, axes=axes, width_px=width,
             height_px=height, bit_depth=int(bit_depth), scale_m_per_px=scale,
             image_to_plane=M, wires=wires, reference_mark=mark, source_position_m=spark,
             film_distance_m=film, distortion=distortion)
    if spark is not None:
        axis_px = v.optics().to_image(np.array([x_m, 0.0, 0.0]))
        if not (0.0 <= axis_px[0] <= width - 1 and 0.0 <= axis_px[1] <= height - 1):
            raise _err(key_path("source_position_m"),
                       f"the station's point of the line of flight casts its shadow at "
                       f"({axis_px[0]:.0f}, {axis_px[1]:.0f}) px, outside the {width} x "
                       f"{height} image")
    lines = v.wire_lines_px()
    for i, seg in enumerate(lines):
        if seg is None:
            raise _err(f"{wpath}[{i}]", f"wire {wires[i].name!r} is not in the image")
    try:
        fit = fit_affine_to_wires(v, lines)
    except ValueError:
        raise _err(wpath, f"the wires {names} cannot determine the affine (need lines in two "
                          f"directions)") from None
    if fit.dof < 1:
        raise _err(wpath, "the wires determine the affine without redundancy; add a wire")
    return v


def facility_from_dict(data: Mapping, source_path: str | os.PathLike | None = None) -> Facility:
    """Validate a parsed facility file and build the :class:`Facility`."""
    data = _table(data, "facility file")
    _check_unknown(data, {"schema_version", "name", "description", "projection",
                          "view_defaults", "stations"}, "")
    version = _require(data, "schema_version", "")
    if version != SCHEMA_VERSION:
        raise _err("schema_version", f"{version!r} not supported (this CADRA reads version "
                                     f"{SCHEMA_VERSION})")
    name = _require(data, "name", "")
    if not isinstance(name, str) or not name:
        raise _err("name", f"expected a non-empty string, got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise _err("description", "expected a string")
    projection = (data.get("projection", "parallel"),
                  "projection" if "projection" in data else "projection (default)")
    if not isinstance(projection[0], str) or projection[0] not in PROJECTIONS_KNOWN:
        raise _err("projection", f"unknown projection {projection[0]!r}; known: "
                                 f"{list(PROJECTIONS_KNOWN)}")
    defaults = dict(_table(data.get("view_defaults", {}), "view_defaults"))
    _check_unknown(defaults, _DEFAULT_KEYS, "view_defaults.")
    stations_raw = _require(data, "stations", "")
    if not isinstance(stations_raw, list) or not stations_raw:
        raise _err("stations", "expected a non-empty array of [[stations]] tables")
    stations = []
    for k, st in enumerate(stations_raw):
        spath = f"stations[{k}]"
        st = _table(st, spath)
        _check_unknown(st, {"id", "x_m", "views"}, f"{spath}.")
        sid = _integer(_require(st, "id", f"{spath}."), f"{spath}.id", 1, 10_000)
        x_m = _number(_require(st, "x_m", f"{spath}."), f"{spath}.x_m")
        if abs(x_m) > 1e4:
            raise _err(f"{spath}.x_m", f"{x_m:g} is not a position in metres (|x_m| <= 1e4)")
        views_raw = _table(_require(st, "views", f"{spath}."), f"{spath}.views")
        if not views_raw:
            raise _err(f"{spath}.views", "no views")
        views = {}
        for vname, vdata in views_raw.items():
            if vname not in VIEW_AXES:
                raise _err(f"{spath}.views.{vname}", f"unknown view; known: {list(VIEW_AXES)}")
            views[vname] = _view(vdata, f"{spath}.views.{vname}", vname, sid, x_m, defaults,
                                 projection)
        stations.append(Station(id=sid, x_m=x_m, views=views))
    ids = [s.id for s in stations]
    if len(set(ids)) != len(ids):
        dup = next(i for i in ids if ids.count(i) > 1)
        raise _err(f"stations[{ids.index(dup, ids.index(dup) + 1)}].id", f"duplicate id {dup}")
    for k in range(1, len(stations)):
        if not (stations[k].id > stations[k - 1].id and stations[k].x_m > stations[k - 1].x_m):
            raise _err(f"stations[{k}]", "stations must be listed in increasing id and x_m")
    return Facility(name=name, description=description, stations=tuple(stations),
                    source_path=str(source_path) if source_path is not None else None)


def resolve_facility_path(path_or_name: str | os.PathLike) -> Path:
    """A facility file path from a path or a bare name (``"hffaf"``).

    A bare name (no directory part, no ``.toml``) is looked up as
    ``<repo>/facilities/<name>.toml``, then ``./facilities/<name>.toml``, then
    ``./<name>.toml``.
    """
    p = Path(path_or_name)
    if isinstance(path_or_name, Path) or p.suffix == ".toml" or len(p.parts) > 1:
        return p
    candidates = [REPO_ROOT / "facilities" / f"{p.name}.toml",
                  Path.cwd() / "facilities" / f"{p.name}.toml", Path.cwd() / f"{p.name}.toml"]
    for c in candidates:
        if c.is_file():
            return c
    raise FileNotFoundError(f"facility {str(path_or_name)!r} not found; looked in "
                            f"{[str(c) for c in candidates]}")


_CACHE: dict[tuple[str, int, int], Facility] = {}


def load_facility(path_or_name: str | os.PathLike) -> Facility:
    """Load and validate a facility reference file (by path or bare name, see
    :func:`resolve_facility_path`). The result is immutable and cached per file version."""
    path = resolve_facility_path(path_or_name)
    try:
        stat = path.stat()
    except OSError as exc:
        raise FileNotFoundError(f"{path}: cannot read ({exc.strerror or exc})") from None
    # the size too: two writes within one tick of the file system's clock share an mtime
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    if key in _CACHE:
        return _CACHE[key]
    data = read_toml(path, FacilityFileError, read_error=FileNotFoundError)
    with prefixed_by(path, FacilityFileError):
        fac = facility_from_dict(data, source_path=path)
    _CACHE[key] = fac
    return fac


def write_default_facility(path: str | os.PathLike | None = None,
                           overwrite: bool = False) -> Path:
    """Write :func:`~cadra.facility.reference.default_hffaf_text` to ``path`` (default
    ``<repo>/facilities/hffaf.toml``), validated first, atomically."""
    path = Path(path) if path is not None else REPO_ROOT / "facilities" / "hffaf.toml"
    facility_from_dict(tomllib.loads(default_hffaf_text()))  # validate before writing
    return atomic_write_text(path, default_hffaf_text(), overwrite=overwrite)


__all__ = [
    "BIT_DEPTHS", "MAX_MAGNIFICATION", "MIN_WIRES", "PROJECTIONS_KNOWN", "SCHEMA_VERSION",
    "FacilityFileError", "facility_from_dict", "load_facility",
    "resolve_facility_path", "write_default_facility",
]
