"""Facility reference file: stations, views, optics, fiducial wires (docs/facility_file.md).

A facility reference file (TOML) describes the range in the facility frame F (docs/
conventions.md: origin station 1 on the centreline, x downrange, y port, z up; metres). Each
station has a top view (sees x, y) and a side view (sees x, z). A *parallel* (collimated)
view maps its two facility coordinates affinely to pixels: ``[a, b] = M @ [u, v, 1]`` with
``M = image_to_plane`` (2x3), pixels (u, v) = (column, row) from the centre of the top-left
pixel. Fiducial wires -- straight, with surveyed 3-D end points -- let stage one re-solve that
affine per image (:func:`fit_affine_to_wires`). A *point-source* view (a direct shadowgraph)
has a spark and a film beyond the line of flight: a point reaches the film along the ray from
the spark (:class:`~cadra.optics.projection.PointSourceProjection`), and the affine maps pixels
to the film's points; the wires (straight lines, still straight on the film) solve it the same
way.

This module holds the facility's geometry and data objects; reading and validating the file
(``load_facility``, ``FacilityFileError`` naming the key path) is
:mod:`cadra.io.facility_file`, whose names are importable from here too.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cadra.geometry import affine_inverse, apply_affine  # the 2x3 affines' one home

#: Facility-file schema version this CADRA reads and :func:`default_hffaf_text` writes.
SCHEMA_VERSION = 1
#: Facility axes (0 = x, 1 = y, 2 = z) each view sees, in view-plane order (a, b).
VIEW_AXES = {"top": (0, 1), "side": (0, 2)}

REPO_ROOT = Path(__file__).resolve().parents[2]

#: The file format (reading, validation, errors) is :mod:`cadra.io.facility_file`.


# --------------------------------------------------------------------------- affine helpers


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def nominal_image_to_plane(x_station_m: float, scale_m_per_px: float, width_px: int,
                           height_px: int) -> np.ndarray:
    """The default image->view-plane affine (docs/conventions.md, "Images and pixels").

    The image centre ``((W-1)/2, (H-1)/2)`` sees ``(x_station, 0)``; x increases to the right
    (+u); the view's second coordinate (y port for top, z up for side) increases upward (-v).
    """
    s = float(scale_m_per_px)
    cu, cv = (width_px - 1) / 2.0, (height_px - 1) / 2.0
    return np.array([[s, 0.0, x_station_m - s * cu], [0.0, -s, s * cv]])


def sight_axis(axes: tuple[int, int]) -> int:
    """The facility axis a view seeing ``axes`` looks along: z (2) for top, y (1) for side."""
    return ({0, 1, 2} - set(axes)).pop()


def _clip_segment(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Liang-Barsky clip of segment p0-p1 to the box [lo, hi]; None if outside."""
    d = p1 - p0
    t0, t1 = 0.0, 1.0
    for k in range(2):
        for p, q in ((-d[k], p0[k] - lo[k]), (d[k], hi[k] - p0[k])):
            if p == 0.0:
                if q < 0.0:
                    return None
                continue
            r = q / p
            if p < 0.0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
    if t0 > t1:
        return None
    return p0 + t0 * d, p0 + t1 * d


# --------------------------------------------------------------------------- data model


@dataclass(frozen=True, eq=False)
class Wire:
    """A straight fiducial wire: surveyed end points in F (m) and diameter (m)."""

    name: str
    p0_m: np.ndarray
    p1_m: np.ndarray
    diameter_m: float

    def __post_init__(self):
        object.__setattr__(self, "p0_m", _ro(np.reshape(self.p0_m, 3)))
        object.__setattr__(self, "p1_m", _ro(np.reshape(self.p1_m, 3)))
        object.__setattr__(self, "diameter_m", float(self.diameter_m))


@dataclass(frozen=True)
class ReferenceMark:
    """The scanner reference mark: a cross drawn on the film/scan at pixel (u, v).

    ``arm_px`` is the half-length of each arm from the centre, ``width_px`` the line width.
    """

    u_px: float
    v_px: float
    arm_px: float
    width_px: float


@dataclass(frozen=True, eq=False)
class View:
    """One camera view of one station (see module doc).

    Attributes
    ----------
    station : station id.
    name : ``"top"`` (sees x, y) or ``"side"`` (sees x, z).
    projection : ``"parallel"`` or ``"point_source"``.
    axes : facility axis indices seen, (0, 1) for top, (0, 2) for side.
    width_px, height_px : image size.
    bit_depth : 8 or 16.
    scale_m_per_px : nominal scale, m per pixel.
    image_to_plane : (2, 3) nominal affine ``[a, b] = M @ [u, v, 1]`` (view-plane metres in F).
    wires : the fiducial wires seen in this view.
    reference_mark : the scanner reference mark.
    source_position_m : a point-source view's spark (3,), m in F; None for a parallel view.
    film_distance_m : a point-source view's distance from the spark to the film, m, along
        the view's sight axis (z for top, y for side); the film lies beyond the line of
        flight, perpendicular to that axis, and ``image_to_plane`` maps pixels to its
        points' facility coordinates along the view's axes (docs/facility_file.md).
    distortion : the image's calibrated distortion
        (:class:`~cadra.optics.distortion.Distortion`), or None (none). Every other map of
        the view (``image_to_plane``, the wires' lines, :meth:`optics`) is of the *ideal*
        image; the recorded image is the ideal one distorted.
    """

    station: int
    name: str
    projection: str
    axes: tuple[int, int]
    width_px: int
    height_px: int
    bit_depth: int
    scale_m_per_px: float
    image_to_plane: np.ndarray
    wires: tuple[Wire, ...]
    reference_mark: ReferenceMark
    source_position_m: np.ndarray | None = None
    film_distance_m: float | None = None
    distortion: object | None = None

    def __post_init__(self):
        object.__setattr__(self, "image_to_plane", _ro(np.reshape(self.image_to_plane, (2, 3))))
        if self.source_position_m is not None:
            object.__setattr__(self, "source_position_m",
                               _ro(np.reshape(self.source_position_m, 3)))
        object.__setattr__(self, "wires", tuple(self.wires))
        object.__setattr__(self, "axes", tuple(int(a) for a in self.axes))

    @property
    def P_view(self) -> np.ndarray:
        """(2, 3) selection matrix: view-plane coordinates ``ab = P_view @ r_F``."""
        P = np.zeros((2, 3))
        P[0, self.axes[0]] = 1.0
        P[1, self.axes[1]] = 1.0
        return P

    @property
    def sight_axis(self) -> int:
        """The facility axis the view looks along (the one it does not see): z for top."""
        return sight_axis(self.axes)

    @property
    def film_origin_m(self) -> np.ndarray:
        """A point-source view's film point with view-plane coordinates (0, 0), m in F: on
        the sight axis, ``film_distance_m`` from the spark, beyond the line of flight."""
        if self.source_position_m is None:
            raise ValueError(f"station {self.station} {self.name}: a parallel view has no film")
        k = self.sight_axis
        S = self.source_position_m[k]
        origin = np.zeros(3)
        origin[k] = S - np.copysign(float(self.film_distance_m), S)
        return origin

    @property
    def plane_to_image(self) -> np.ndarray:
        """(2, 3) inverse of :attr:`image_to_plane`: ``[u, v] = M_inv @ [a, b, 1]``."""
        return affine_inverse(self.image_to_plane)

    @property
    def image_centre_px(self) -> np.ndarray:
        """Pixel coordinates of the image centre, ``((W-1)/2, (H-1)/2)``."""
        return np.array([(self.width_px - 1) / 2.0, (self.height_px - 1) / 2.0])

    def optics(self, affine: np.ndarray | None = None):
        """This view's :class:`~cadra.optics.projection.Projection` (docs/conventions.md,
        "Projections"): a ``ParallelProjection``, or a ``PointSourceProjection`` from the spark
        onto the film, with the nominal image->plane affine (made once per view: projections
        are immutable) or ``affine`` (e.g. the one solved from the image's wires)."""
        if affine is None:
            return self._nominal_optics
        return self._make_optics(affine)

    @functools.cached_property
    def _nominal_optics(self):
        return self._make_optics(self.image_to_plane)

    def _make_optics(self, affine):
        from cadra.optics.projection import ParallelProjection, PointSourceProjection

        if self.projection == "point_source":
            return PointSourceProjection(
                spark_m=self.source_position_m, film_origin_m=self.film_origin_m,
                plane_basis=self.P_view, image_to_plane=affine)
        return ParallelProjection.from_view(self, affine)

    def project_points(self, r_F: np.ndarray) -> np.ndarray:
        """View-plane points (m) of facility points ``(N, 3)`` (or ``(3,)``): where the view's
        ray through each meets the view plane (for a parallel view, the two coordinates it
        sees)."""
        r_F = np.asarray(r_F, dtype=float)
        if self.projection == "point_source":
            return self.optics().plane_point(r_F)
        return r_F[..., list(self.axes)]

    def plane_to_pixels(self, ab: np.ndarray, affine: np.ndarray | None = None) -> np.ndarray:
        """View-plane points ``(N, 2)`` (m) to pixels ``(N, 2)`` (u, v).

        ``affine`` is an image->plane map (2x3) to use instead of the nominal one (e.g. the
        affine solved from this image's wires).
        """
        M = self.image_to_plane if affine is None else np.asarray(affine, dtype=float)
        return apply_affine(affine_inverse(M), ab)

    def pixels_to_plane(self, uv: np.ndarray, affine: np.ndarray | None = None) -> np.ndarray:
        """Pixels ``(N, 2)`` (u, v) to view-plane points ``(N, 2)`` (m)."""
        M = self.image_to_plane if affine is None else np.asarray(affine, dtype=float)
        return apply_affine(M, uv)

    def wire_width_px(self, wire: Wire) -> float:
        """The width of ``wire``'s image, px: its diameter at the view's magnification at its
        middle (1 for parallel light; a point source's shadow is wider than the wire) over
        the nominal scale."""
        mid = 0.5 * (np.asarray(wire.p0_m) + np.asarray(wire.p1_m))
        return wire.diameter_m * float(self.optics().magnification(mid)) / self.scale_m_per_px

    def wire_lines_plane(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each wire's projected end points in the view plane (m), in :attr:`wires` order."""
        return [(self.project_points(w.p0_m), self.project_points(w.p1_m)) for w in self.wires]

    def wire_lines_px(self, affine: np.ndarray | None = None, margin_px: float = 0.0):
        """Each wire's image segment ``((u0, v0), (u1, v1))``, clipped to the image.

        One entry per wire, in :attr:`wires` order; ``None`` for a wire whose image misses
        the (margin-expanded) picture (never for a valid facility file with the nominal
        affine). The surveyed end points reach the image through :meth:`optics` (with
        ``affine``, or the nominal one). The image extends to the outer pixel edges,
        ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``; ``margin_px`` > 0 expands that box (a renderer
        wants the wire to run on past the border so blur does not fade it at the edge; the
        surveyed end points lie far enough outside the picture in the default facility).
        """
        lo = np.array([-0.5, -0.5]) - margin_px
        hi = np.array([self.width_px - 0.5, self.height_px - 0.5]) + margin_px
        projection = self.optics(affine)
        out = []
        for w in self.wires:
            uv = projection.to_image(np.array([w.p0_m, w.p1_m]))
            seg = _clip_segment(uv[0], uv[1], lo, hi)
            out.append(None if seg is None else
                       ((float(seg[0][0]), float(seg[0][1])), (float(seg[1][0]),
                                                                float(seg[1][1]))))
        return out


@dataclass(frozen=True, eq=False)
class Station:
    """An optical station: id, surveyed x (m, in F) and its views by name."""

    id: int
    x_m: float
    views: dict[str, View]


@dataclass(frozen=True, eq=False)
class Facility:
    """A loaded facility reference file."""

    name: str
    description: str
    stations: tuple[Station, ...]
    source_path: str | None = None

    def station(self, station_id: int) -> Station:
        """The station with id ``station_id`` (KeyError if none)."""
        for s in self.stations:
            if s.id == station_id:
                return s
        raise KeyError(f"facility {self.name}: no station {station_id}")

    def view(self, station_id: int, name: str) -> View:
        """View ``name`` of station ``station_id``."""
        st = self.station(station_id)
        if name not in st.views:
            raise KeyError(f"facility {self.name}: station {station_id} has no {name!r} view")
        return st.views[name]

    @property
    def station_ids(self) -> tuple[int, ...]:
        return tuple(s.id for s in self.stations)

    @property
    def station_x_m(self) -> np.ndarray:
        return np.array([s.x_m for s in self.stations])


# --------------------------------------------------------------------------- wire affine fit


@dataclass(frozen=True, eq=False)
class AffineFit:
    """Image->plane affine solved from fiducial-wire lines.

    ``residuals_m`` are the distances (m, in the view plane) of the mapped image points from
    their wires' surveyed lines; ``rms_m`` their rms; ``dof`` = equations - 6.
    """

    affine: np.ndarray
    residuals_m: np.ndarray
    rms_m: float
    dof: int
    wires_used: tuple[str, ...]


def fit_affine_to_wires(view: View, lines_px, weights=None) -> AffineFit:
    """Solve the image->plane affine of ``view`` from measured wire lines (least squares).

    Parameters
    ----------
    view : the view whose wires (surveyed, from the reference file) were measured.
    lines_px : one entry per wire of ``view.wires`` (same order): points ``(k, 2)`` (u, v)
        on that wire's image -- e.g. a segment ``((u0, v0), (u1, v1))`` as
        :meth:`View.wire_lines_px` returns, or many edge points -- or None if not measured.
    weights : optional per-wire weights (default 1).

    Each point gives one linear equation ``n . (M [u, v, 1]) = n . a0``, with ``n`` the unit
    normal of the wire's projected line through ``a0``. With the four wires of the default
    facility (two across, two along the range) the 6 unknowns are over-determined.
    """
    if len(lines_px) != len(view.wires):
        raise ValueError(f"lines_px has {len(lines_px)} entries for {len(view.wires)} wires")
    rows, rhs, w_rows, used = [], [], [], []
    for i, ((a0, a1), pts) in enumerate(zip(view.wire_lines_plane(), lines_px, strict=True)):
        if pts is None:
            continue
        pts = np.atleast_2d(np.asarray(pts, dtype=float))
        d = a1 - a0
        n = np.array([-d[1], d[0]]) / np.hypot(d[0], d[1])
        wi = 1.0 if weights is None else float(weights[i])
        for u, v in pts:
            rows.append(np.concatenate([n[0] * np.array([u, v, 1.0]),
                                        n[1] * np.array([u, v, 1.0])]))
            rhs.append(n @ a0)
            w_rows.append(wi)
        used.append(view.wires[i].name)
    A, b = np.array(rows).reshape(-1, 6), np.array(rhs)
    # scale columns for conditioning: u, v are ~1e3 px
    col = np.array([1e-3, 1e-3, 1.0, 1e-3, 1e-3, 1.0])
    sv = np.linalg.svd(A * col, compute_uv=False) if len(rows) >= 6 else np.zeros(1)
    if len(rows) < 6 or sv[-1] < 1e-6 * sv[0]:
        raise ValueError(f"station {view.station} {view.name}: wires {used} cannot determine "
                         f"the affine (need lines in two directions, >= 3 wires)")
    sw = np.sqrt(np.array(w_rows))
    m, *_ = np.linalg.lstsq((A * col) * sw[:, None], b * sw, rcond=None)
    m = m * col
    M = m.reshape(2, 3)
    res = A @ m - b
    return AffineFit(affine=M, residuals_m=res, rms_m=float(np.sqrt(np.mean(res ** 2))),
                     dof=len(rows) - 6, wires_used=tuple(used))


# --------------------------------------------------------------------------- default HFFAF


def _survey_offsets(n: int, seed: int = 2009, half_range_m: float = 1.0e-3) -> list[float]:
    """Deterministic pseudo-random survey offsets, uniform in +-half_range, 0.01 mm steps.

    A 32-bit linear congruential generator (Numerical Recipes constants) so the default
    facility file can be regenerated bit-for-bit on any platform and numpy version.
    """
    state, out = seed & 0xFFFFFFFF, []
    for _ in range(n):
        state = (1664525 * state + 1013904223) & 0xFFFFFFFF
        u = state / 2.0**32 * 2.0 - 1.0
        out.append(round(u * half_range_m, 5))
    return out


def default_hffaf_text() -> str:
    """TOML text of ``facilities/hffaf.toml`` (the file is this function's output).

    16 stations 1.524 m apart; top and side view each 1600 x 1200 px at 1.27e-4 m/px; per view
    two wires across the range at x_station -+ 0.080 m and two along it at -+ 0.069 m in the
    view's second coordinate, placed out of the other view's picture (top-view wires at
    z = -0.12 m, side-view wires at y = -0.12 m), each end point offset by a deterministic
    "survey" error of up to 1 mm.
    """
    return _range_text(
        "hffaf",
        "Default facility modelled on the NASA Ames HFFAF (seed 004): 16 shadowgraph stations "
        "1.524 m apart, collimated (parallel-projection) top and side views, 4 surveyed "
        "fiducial wires per view.",
        spacing=1.524, n_st=16, survey_seed=2009)


def small_arms_range_text() -> str:
    """TOML text of ``facilities/small_arms.toml`` (the file is this function's output).

    A notional small-arms aerodynamics range for the 7.62 mm M-80 (docs/m80.md): 30 stations
    0.9144 m (3 ft) apart, 26.5 m in all -- about 1.5 cycles of the bullet's slow yaw arm
    (17 m) and 2.6 stations per cycle of its fast arm (2.3 m), so neither arm aliases. Views,
    pixels and wires as the HFFAF's (:func:`default_hffaf_text`); survey errors from another
    seed.
    """
    return _range_text(
        "small_arms",
        "Notional small-arms aerodynamics range for the 7.62 mm M-80 (docs/m80.md): 30 "
        "shadowgraph stations 0.9144 m (3 ft) apart, collimated top and side views as the "
        "HFFAF's (1600 x 1200 px at 0.127 mm/px), 4 surveyed fiducial wires per view.",
        spacing=0.9144, n_st=30, survey_seed=1833)


def spark_range_text() -> str:
    """TOML text of ``facilities/spark_range.toml`` (the file is this function's output).

    A BRL-like spark range for small-arms bullets (docs/spark_range.md): 25 stations 4.0 m
    apart, 96 m in all, as the long spark ranges that give the classic bullet data are laid
    out. At 830 m/s the M-80's fast yaw arm (about 2240 rad/s, 2.3 m a cycle) turns 1.7 times
    between stations: the stations alias it, which the fit's start resolves from the gun's
    twist (docs/spark_range.md). The slow arm (16 m a cycle) is sampled 4 times a cycle and
    the record shows about 6 slow cycles. Views are collimated, as the HFFAF's
    (:func:`default_hffaf_text`); real spark ranges are direct shadowgraphs (a point source),
    which this facility does not model.
    """
    return _range_text(
        "spark_range",
        "BRL-like small-arms spark range (docs/spark_range.md): 25 shadowgraph stations "
        "4.0 m apart (96 m), collimated top and side views as the HFFAF's (1600 x 1200 px at "
        "0.127 mm/px), 4 surveyed fiducial wires per view. Real spark ranges use point-source "
        "shadowgraphs; these views are parallel.",
        spacing=4.0, n_st=25, survey_seed=1880)


#: The BRL-like point-source range's layout (docs/facility_file.md): the spark's stand-off
#: from the line of flight and its distance to the film, m (magnification 1.2 at the line).
BRL_SPARK_STANDOFF_M, BRL_FILM_DISTANCE_M = 1.5, 1.8


def brl_spark_text() -> str:
    """TOML text of ``facilities/brl_spark.toml`` (the file is this function's output).

    A BRL-like small-arms spark range with direct shadowgraphs (docs/facility_file.md, "The
    point-source range"): 25 stations 0.9144 m (3 ft) apart, each view a spark 1.5 m from
    the line of flight (above it for the top view, to port for the side view) throwing the
    shadow onto a film 0.3 m beyond the line (1.8 m from the spark): magnification 1.2 at
    the line of flight, in the 1.0-1.3 of the standard method. Film scanned at 0.127 mm/px
    (1600 x 1200 px). Per view two wires across the range (0.07 m either side of the
    station) 0.12 m beyond the line of flight, toward the film, and two along it 0.20 m
    beyond: two depths, so that the wires' images also carry the spark's position. The wires
    are 0.225 mm and 0.236 mm thick, so that their shadows are as wide as the other ranges'
    0.25 mm wires at unit magnification (stage one's wire tests are tuned to images about
    2 px wide: docs/stage1.md, "Wires"). Survey errors as the other ranges', from another
    seed.
    """
    return _range_text(
        "brl_spark",
        "BRL-like small-arms spark range (docs/facility_file.md): 25 direct-shadowgraph "
        "stations 0.9144 m (3 ft) apart, point-source sparks 1.5 m from the line of flight "
        "and films 0.3 m beyond it (magnification 1.2), films scanned at 0.127 mm/px "
        "(1600 x 1200 px), 4 surveyed fiducial wires per view at two depths.",
        spacing=0.9144, n_st=25, survey_seed=900,
        point_source=(BRL_SPARK_STANDOFF_M, BRL_FILM_DISTANCE_M))


_GENERATOR = {"hffaf": "default_hffaf_text", "small_arms": "small_arms_range_text",
              "spark_range": "spark_range_text", "brl_spark": "brl_spark_text"}


def _range_text(name: str, description: str, *, spacing: float, n_st: int,
                survey_seed: int, point_source: tuple[float, float] | None = None) -> str:
    """TOML text of a range of ``n_st`` HFFAF-like stations ``spacing`` metres apart;
    ``point_source`` = (spark stand-off, spark-to-film distance) for direct shadowgraphs."""
    w, h, s = 1600, 1200, 1.27e-4
    across, along, off, half = 0.080, 0.069, 0.12, 0.15
    off_along = off     # the depth of the wires along the range
    if point_source is not None:
        across, along, off_along = 0.070, 0.062, 0.20   # clear of the mark when magnified
    offs = iter(_survey_offsets(n_st * 2 * 4 * 6, seed=survey_seed))

    def f(x):
        return repr(round(float(x), 8))

    def vec(p):
        return "[" + ", ".join(f(v) for v in p) + "]"

    lines = [
        "# CADRA facility reference file (docs/facility_file.md). Facility frame F: origin",
        "# station 1 on the range centreline, x downrange, y port, z up; metres. Pixels (u, v)",
        "# = (column, row) from the centre of the top-left pixel.",
        f"# Generated by cadra.facility.reference.{_GENERATOR[name]}(); regenerate, don't edit.",
        f"schema_version = {SCHEMA_VERSION}",
        f'name = "{name}"',
        f'description = "{description}"',
        f'projection = "{"parallel" if point_source is None else "point_source"}"',
        "",
        "[view_defaults]",
        f"width_px = {w}",
        f"height_px = {h}",
        "bit_depth = 8",
        f"scale_m_per_px = {s!r}",
        "reference_mark = { u_px = 100.0, v_px = 130.0, arm_px = 24.0, width_px = 3.0 }",
    ]
    if point_source is not None:
        lines.append(f"film_distance_m = {f(point_source[1])}")
    for k in range(1, n_st + 1):
        xs = round((k - 1) * spacing, 6)
        lines += ["", "[[stations]]", f"id = {k}", f"x_m = {f(xs)}"]
        for view in ("top", "side"):
            M = nominal_image_to_plane(xs, s, w, h)
            oa = off_along
            if view == "top":   # wires in horizontal planes below the flight line (z = -off)
                nominal = [
                    ("x-", (xs - across, -half, -off), (xs - across, half, -off)),
                    ("x+", (xs + across, -half, -off), (xs + across, half, -off)),
                    ("y-", (xs - half, -along, -oa), (xs + half, -along, -oa)),
                    ("y+", (xs - half, along, -oa), (xs + half, along, -oa)),
                ]
                spark = (xs, 0.0, None if point_source is None else point_source[0])
            else:               # wires in the vertical plane y = -off (starboard window)
                top = off - 0.01  # vertical wires stop short of the top-view wires' plane
                nominal = [
                    ("x-", (xs - across, -off, -top), (xs - across, -off, top)),
                    ("x+", (xs + across, -off, -top), (xs + across, -off, top)),
                    ("z-", (xs - half, -oa, -along), (xs + half, -oa, -along)),
                    ("z+", (xs - half, -oa, along), (xs + half, -oa, along)),
                ]
                spark = (xs, None if point_source is None else point_source[0], 0.0)
            lines += ["", f"[stations.views.{view}]"]
            if point_source is not None:
                lines.append(f"source_position_m = {vec(spark)}")
            lines += [f"image_to_plane = [{vec(M[0])}, {vec(M[1])}]", "wires = ["]
            for name, p0, p1 in nominal:
                q0 = [p + next(offs) for p in p0]
                q1 = [p + next(offs) for p in p1]
                dia = 0.00025
                if point_source is not None:   # its shadow as wide as the others' wires
                    depth = off if name in ("x-", "x+") else off_along
                    dia = round(dia * (point_source[0] + depth) / point_source[1], 6)
                lines.append(f'    {{ name = "{name}", p0_m = {vec(q0)}, p1_m = {vec(q1)}, '
                             f"diameter_m = {dia!r} }},")
            lines.append("]")
    return "\n".join(lines) + "\n"


__all__ = [
    "VIEW_AXES", "AffineFit", "Facility", "ReferenceMark", "Station", "View", "Wire",
    "brl_spark_text", "default_hffaf_text", "fit_affine_to_wires", "small_arms_range_text",
    "spark_range_text",
    "nominal_image_to_plane", "sight_axis", "SCHEMA_VERSION",
]
