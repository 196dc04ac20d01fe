"""A cruciform finned missile: cone-cylinder body plus four thin rectangular fins (docs/bodies.md).

The Basic Finner of seed 001 (Nicolaides et al., AFATL-TR-68-32). Its Fig. 1 ("Schematic of
Basic Finner") did not survive the OCR: the seed gives no dimension. The preset takes the
classic Basic Finner as the literature describes it, in calibres d (docs/bodies.md, "Basic
Finner", gives the source of every number):

* a sharp 10 deg half-angle conical nose, 0.5 / tan 10 deg = 2.8356 d long;
* a cylinder of diameter d to the flat base, 10 d overall;
* four flat-plate rectangular fins (seed 001: "flat plate fins"), chord 1 d, exposed span 1 d
  from the body surface (3 d tip to tip), thickness 0.08 d, trailing edges flush with the base.

Reference point: the centre of the base plane, as for the cone and the bullet (s + toward the
nose). Body axes x nose, y starboard, z down (docs/conventions.md).

**Roll convention.** Fin k (k = 0..3) lies in the half-plane from the axis along
``e_k = cos(phi_k) z_b + sin(phi_k) y_b`` with ``phi_k = k pi/2``: at zero roll the fins lie in
the body's x-z plane (fins 0 and 2, along +z_b and -z_b) and x-y plane (fins 1 and 3, along
+y_b and -y_b), the "+" attitude of conventions.md's aerodynamic roll angle, measured like it
from z_b toward y_b. The body's roll is carried by ``R_FB`` (``conventions.quat_from_axis_roll``
roll: about the nose axis, 0 = z_b in the vertical plane pointing down); rolling the body by
+gamma rotates every fin by +gamma about x_b, so the shape repeats every 90 deg of roll.

**Silhouette.** :func:`finner_silhouette` is the union of the body of revolution's exact
outline (:func:`cadra.body.outline.silhouette`) and the four fins' projections. Each fin is
taken as the box ``0 <= s <= chord``, ``0 <= u <= d/2 + span``, ``|w| <= t/2`` (u along e_k,
w across it): from the axis, so the part inside the body changes nothing and every piece
contains the axis segment ``0 <= s <= chord``. A box's parallel projection is the convex hull of
its 8 projected corners, exact. The union is shapely's (GEOS), exact to rounding; as every
piece is convex and contains one common point (the projected axis point at s = chord / 2), the
union is star-shaped about it, hence one simple polygon without holes.

**Mass properties.** :func:`finner_mass_properties` of a uniform-density solid: the body of
revolution by :func:`cadra.body.mass.solid_properties`, each fin as the box
``0 <= s <= chord, d/2 <= u <= d/2 + span, |w| <= t/2`` (root on the cylinder; the sliver
between the flat root faces and the curved surface, t^3 / (24 a) per unit chord, 5e-4 of the
fin, is left out), by the box's inertia rotated into body axes and moved by the parallel-axis
theorem.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cadra.body.conical import conical_silhouette
from cadra.body.mass import solid_properties
from cadra.body.model import Body, make_body, spec_from_params
from cadra.body.outline import silhouette

#: Body kind of :func:`finner`.
KIND = "finner"

#: Fin roll positions phi_k at zero body roll, rad (module docstring: from z_b toward y_b).
FIN_PHI_RAD = (0.0, 0.5 * np.pi, np.pi, 1.5 * np.pi)

#: The Basic Finner in calibres (``half_angle_deg`` in degrees); docs/bodies.md gives the source
#: of each number (seed 001's Fig. 1 is lost to the OCR).
BASIC_FINNER_CAL: dict[str, float] = {
    "length": 10.0, "half_angle_deg": 10.0, "fin_chord": 1.0, "fin_span": 1.0,
    "fin_thickness": 0.08,
}
#: The preset's diameter, m (a free scale: every dimension is in calibres; docs/bodies.md).
BASIC_FINNER_D_M = 0.030

#: Presets: ``preset -> (d_m, dimensions in calibres)``.
PRESETS: dict[str, tuple[float, dict[str, float]]] = {
    "basic_finner": (BASIC_FINNER_D_M, BASIC_FINNER_CAL),
}

#: Default fin thickness without a preset, calibres.
DEFAULT_FIN_THICKNESS_CAL = 0.08


@dataclass(frozen=True, eq=False)
class FinnedBody:
    """A cone-cylinder body of revolution with four thin rectangular fins at its base.

    Attributes
    ----------
    kind : ``"finner"``.
    name : e.g. ``"basic_finner"``.
    body : the body of revolution (cone-cylinder, reference point at the base-plane centre);
        its outline alone is :func:`cadra.body.silhouette`, the fins' are not in it.
    fin_chord_m : axial chord of each fin; the trailing edge is in the base plane (s = 0), the
        leading edge at s = chord, m.
    fin_span_m : exposed span of each fin, from the body surface (r = d/2) to the tip, m.
    fin_thickness_m : plate thickness, m.
    fin_phi_rad : (4,) roll positions of the fins at zero body roll (module docstring).
    params : defining dimensions, SI, as ``to_spec`` writes them.
    preset : the preset the body was built from, or None.

    ``diameter_m``, ``length_m``, ``nose_s_m``, ``base_s_m`` are the body of revolution's. No
    ``arcs``: :func:`cadra.body.silhouette` refuses a finned body rather than drop its fins; use
    :func:`finner_silhouette` (or :func:`outline_polygon` for any body).
    """

    kind: str
    name: str
    body: Body = field(repr=False)
    fin_chord_m: float
    fin_span_m: float
    fin_thickness_m: float
    fin_phi_rad: tuple = FIN_PHI_RAD
    params: tuple = ()
    preset: str | None = None

    @property
    def diameter_m(self) -> float:
        return self.body.diameter_m

    @property
    def length_m(self) -> float:
        return self.body.length_m

    @property
    def nose_s_m(self) -> float:
        return self.body.nose_s_m

    @property
    def base_s_m(self) -> float:
        return self.body.base_s_m

    @property
    def param(self) -> dict:
        """``params`` as a dict (SI)."""
        return dict(self.params)

    @property
    def fin_tip_radius_m(self) -> float:
        """Distance of the fin tips from the axis, d/2 + span, m."""
        return 0.5 * self.diameter_m + self.fin_span_m

    def to_spec(self) -> dict:
        """Plain-data spec in file units (cm, deg); ``body_from_spec`` rebuilds the body."""
        return spec_from_params(self.kind, self.name, self.preset, self.params)


def _positive(name: str, value) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name}: must be a positive length, got {value!r}")
    return v


def cone_cylinder(d_m: float, length_m: float, half_angle_rad: float, *,
                  name: str = KIND) -> Body:
    """Sharp cone on a cylinder, flat base; reference point at the centre of the base plane.

    The meridian, nose to base: the apex (a corner on the axis), the cone flank (a flat), the
    shoulder (a corner at s = L - a / tan θ, r = a), the cylinder (a flat), the base rim (a
    corner at s = 0) and the flat base; a = d/2, θ the half-angle.
    """
    d = _positive("d_m", d_m)
    length = _positive("length_m", length_m)
    th = float(half_angle_rad)
    if not (np.isfinite(th) and 0.0 < th < 0.5 * np.pi):
        raise ValueError(f"half_angle_rad: must lie in (0, pi/2), got {half_angle_rad!r}")
    a = 0.5 * d
    nose = a / np.tan(th)
    if nose > length:
        raise ValueError(f"length_m: a {np.degrees(th):.3f} deg cone on d = {d} m is {nose} m "
                         f"long, longer than the body ({length} m)")
    beta_flank = 0.5 * np.pi - th
    rows = [[length, 0.0, 0.0, 0.0, beta_flank]]             # apex (corner)
    # (flat: the flank)
    if nose < length:
        rows.append([length - nose, a, 0.0, beta_flank, 0.5 * np.pi])   # shoulder (corner)
        # (flat: the cylinder)
        rows.append([0.0, a, 0.0, 0.5 * np.pi, np.pi])                 # base rim (corner)
    else:
        rows.append([0.0, a, 0.0, beta_flank, np.pi])                  # a plain cone
    # (flat: the base disc)
    params = {"d_m": d, "length_m": length, "half_angle_rad": th}
    return make_body(KIND, name, np.array(rows), params, diameter_m=d)


def finner(d_m: float, length_m: float, half_angle_rad: float, fin_chord_m: float,
           fin_span_m: float, fin_thickness_m: float | None = None, *, name: str = KIND,
           preset: str | None = None) -> FinnedBody:
    """Cone-cylinder with four rectangular fins at the base (module docstring).

    Parameters
    ----------
    d_m : body diameter, the reference length d, m.
    length_m : overall length, apex to base, m.
    half_angle_rad : nose-cone half-angle, 0 < θ < 90 deg; the cone is a / tan θ long.
    fin_chord_m : axial chord of each fin (trailing edge in the base plane), m; at most the
        cylinder's length.
    fin_span_m : exposed span of each fin from the body surface to the tip, m.
    fin_thickness_m : plate thickness, m; None: 0.08 d. Less than d / 2.
    name, preset : recorded in the spec.

    Raises ValueError naming the argument for dimensions that cannot make the body.
    """
    body = cone_cylinder(d_m, length_m, half_angle_rad, name=name)
    d = body.diameter_m
    chord = _positive("fin_chord_m", fin_chord_m)
    span = _positive("fin_span_m", fin_span_m)
    t = DEFAULT_FIN_THICKNESS_CAL * d if fin_thickness_m is None else _positive(
        "fin_thickness_m", fin_thickness_m)
    cylinder = body.length_m - 0.5 * d / np.tan(float(half_angle_rad))
    if chord > cylinder * (1.0 + 1e-12):
        raise ValueError(f"fin_chord_m: the fins ({chord} m) are longer than the cylinder "
                         f"({cylinder} m): a fin root would leave the body on the cone")
    if t >= 0.5 * d:
        raise ValueError(f"fin_thickness_m: {t} m is not less than d/2 = {0.5 * d} m")
    params = dict(body.params) | {"fin_chord_m": chord, "fin_span_m": span,
                                  "fin_thickness_m": t}
    return FinnedBody(kind=KIND, name=name, body=body, fin_chord_m=chord, fin_span_m=span,
                      fin_thickness_m=t, params=tuple(params.items()), preset=preset)


def finner_preset(preset: str = "basic_finner", *, name: str | None = None,
                  d_m: float | None = None, **overrides) -> FinnedBody:
    """The preset's body (:data:`PRESETS`): its calibre dimensions times ``d_m`` (default: the
    preset's d), then any :func:`finner` keyword in ``overrides`` (SI) replacing its value."""
    if preset not in PRESETS:
        raise ValueError(f"preset: {preset!r} is not one of {list(PRESETS)}")
    d0, cal = PRESETS[preset]
    d = d0 if d_m is None else _positive("d_m", d_m)
    kw = {"d_m": d, "length_m": cal["length"] * d,
          "half_angle_rad": float(np.radians(cal["half_angle_deg"])),
          "fin_chord_m": cal["fin_chord"] * d, "fin_span_m": cal["fin_span"] * d,
          "fin_thickness_m": cal["fin_thickness"] * d}
    kw |= {k: v for k, v in overrides.items() if v is not None}
    return finner(name=name or preset, preset=preset, **kw)


# --------------------------------------------------------------------------- outline


def fin_frames(fb: FinnedBody, R_FB=None) -> np.ndarray:
    """(4, 3, 3) per fin the unit vectors (x_b, e_k, w_k) as rows: the axis, the span direction
    and the thickness direction (e_k turned +90 deg about x_b), in body axes, or in the
    facility frame if ``R_FB`` is given."""
    out = np.empty((len(fb.fin_phi_rad), 3, 3))
    for k, phi in enumerate(fb.fin_phi_rad):
        c, s = np.cos(phi), np.sin(phi)
        out[k] = [[1.0, 0.0, 0.0], [0.0, s, c], [0.0, -c, s]]   # w_k = x_b × e_k
    if R_FB is not None:
        out = out @ np.asarray(R_FB, dtype=float).T
    return out


def fin_corners(fb: FinnedBody, R_FB, r_ref_F, *, from_axis: bool = True) -> np.ndarray:
    """(4, 8, 3) corners of the fin boxes in the facility frame, m.

    ``from_axis``: the boxes start on the axis (u >= 0, the outline's boxes); else at the
    body surface (u >= d/2, the solid fins of the mass properties).
    """
    frames = fin_frames(fb, R_FB)
    r0 = np.asarray(r_ref_F, dtype=float)
    u0 = 0.0 if from_axis else 0.5 * fb.diameter_m
    ss = np.array([0.0, fb.fin_chord_m])
    uu = np.array([u0, fb.fin_tip_radius_m])
    ww = 0.5 * fb.fin_thickness_m * np.array([-1.0, 1.0])
    grid = np.array([[s, u, w] for s in ss for u in uu for w in ww])     # (8, 3)
    return r0 + np.einsum("cj,kjd->kcd", grid, frames)


def fin_polygons(fb: FinnedBody, R_FB, r_ref_F, P_view=None, *,
                 to_plane=None) -> list[np.ndarray]:
    """The four fins' projected outlines: each the convex hull of its box's 8 projected
    corners, (M, 2) counter-clockwise in view-plane metres (``P_view @ r_F``, or
    ``to_plane(r_F)`` for a central projection, which also maps a box to the hull of its
    corners' images)."""
    from scipy.spatial import ConvexHull

    if to_plane is None:
        P = _check_view(P_view)

        def to_plane(r):
            return r @ P.T
    polys = []
    for corners in fin_corners(fb, _check_rotation(R_FB), r_ref_F):
        pts = np.asarray(to_plane(corners), dtype=float)
        polys.append(pts[ConvexHull(pts).vertices])      # counter-clockwise in 2-D
    return polys


def _check_view(P_view) -> np.ndarray:
    P = np.asarray(P_view, dtype=float)
    if P.shape != (2, 3):
        raise ValueError(f"P_view: expected a (2, 3) matrix, got shape {P.shape}")
    return P


def _check_rotation(R_FB) -> np.ndarray:
    R = np.asarray(R_FB, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
        raise ValueError("R_FB: expected a 3x3 rotation matrix")
    return R


def _union(pieces: list[np.ndarray]):
    """shapely union of (N, 2) polygons, counter-clockwise exterior."""
    import shapely
    from shapely.geometry.polygon import orient

    shape = shapely.union_all([shapely.Polygon(p) for p in pieces])
    if shape.geom_type != "Polygon" or len(shape.interiors) > 0:  # pragma: no cover
        # cannot happen: every piece is convex and contains the projected axis point at
        # s = chord / 2 (module docstring)
        raise AssertionError(f"finned outline is a {shape.geom_type} with holes or parts")
    return orient(shape, 1.0)


def finner_silhouette(fb: FinnedBody, R_FB, r_ref_F, P_view,
                      n_points: int = 4096) -> np.ndarray:
    """Exact outline of the finned body in a parallel-projection view, as one polygon.

    Same arguments and result as :func:`cadra.body.silhouette`: ``R_FB`` (3, 3) body ->
    facility (column 0 the nose axis; its roll about that axis places the fins, module
    docstring), ``r_ref_F`` (3,) the reference point (base-plane centre) in the facility frame,
    m, ``P_view`` (2, 3) orthonormal rows. ``n_points`` is the vertex budget of the body of
    revolution's outline; the union adds the fins' corners and the intersection points.

    Returns
    -------
    (N, 2) closed simple polygon in view-plane metres, counter-clockwise, last vertex not
    repeated: the union of the body's outline and the fins' projections (module docstring).
    Vertices lie on the true outline to rounding (the body's are on its exact outline, the
    fins' are projected corners or edge intersections).
    """
    R = _check_rotation(R_FB)
    pieces = [silhouette(fb.body, R, r_ref_F, P_view, n_points=n_points),
              *fin_polygons(fb, R, r_ref_F, P_view)]
    return np.asarray(_union(pieces).exterior.coords)[:-1]


def finner_silhouette_area_m2(fb: FinnedBody, R_FB, P_view, n_points: int = 4096) -> float:
    """Area of :func:`finner_silhouette`, m² (the polygon's: the body's part is inscribed,
    short of the exact area by O(n_points⁻²), e.g. 6e-8 relative at 4096 for a capsule; a
    cone-cylinder seen side-on is a polygon, exact)."""
    R = _check_rotation(R_FB)
    pieces = [silhouette(fb.body, R, np.zeros(3), P_view, n_points=n_points),
              *fin_polygons(fb, R, np.zeros(3), P_view)]
    return float(_union(pieces).area)


def outline_polygon(body, R_FB, r_ref_F, P_view, n_points: int = 4096) -> np.ndarray:
    """The outline of any body (:class:`~cadra.body.model.Body` or :class:`FinnedBody`): the
    one call a renderer or a template needs (:func:`cadra.body.silhouette`'s contract)."""
    if isinstance(body, FinnedBody):
        return finner_silhouette(body, R_FB, r_ref_F, P_view, n_points=n_points)
    return silhouette(body, R_FB, r_ref_F, P_view, n_points=n_points)


def conical_outline_polygon(body, R_FB, r_ref_F, spark_m, to_plane,
                            n_points: int = 4096) -> np.ndarray:
    """The outline of any body's shadow from a point source ``spark_m`` on a film mapped by
    ``to_plane`` (:func:`cadra.body.conical.conical_silhouette`'s contract); a finned body's
    is the union of its body's shadow and its fins' (each the hull of its corners' images:
    a central projection keeps a box convex and every piece still contains the axis point
    at s = chord / 2)."""
    if isinstance(body, FinnedBody):
        R = _check_rotation(R_FB)
        pieces = [conical_silhouette(body.body, R, r_ref_F, spark_m, to_plane, n_points),
                  *fin_polygons(body, R, r_ref_F, to_plane=to_plane)]
        return np.asarray(_union(pieces).exterior.coords)[:-1]
    return conical_silhouette(body, R_FB, r_ref_F, spark_m, to_plane, n_points)


# --------------------------------------------------------------------------- mass


@dataclass(frozen=True)
class FinnedMassProperties:
    """Uniform-density mass properties of a finned body; axial positions from the reference
    point (+ nose), inertias about the cg in body axes (x nose, y starboard, z down).

    Attributes
    ----------
    density_kg_m3 : the uniform density.
    body_volume_m3, fin_volume_m3 : volume of the body of revolution, of one fin.
    mass_kg : total mass.
    cg_s_m : axial cg position (on the axis: the cruciform is symmetric).
    inertia_kg_m2 : (3, 3) inertia tensor about the cg, body axes (diagonal at zero roll).
    """

    density_kg_m3: float
    body_volume_m3: float
    fin_volume_m3: float
    mass_kg: float
    cg_s_m: float
    inertia_kg_m2: np.ndarray

    @property
    def ixx_kg_m2(self) -> float:
        """Axial moment of inertia."""
        return float(self.inertia_kg_m2[0, 0])

    @property
    def itrans_kg_m2(self) -> float:
        """Transverse moment of inertia about the cg (I_yy = I_zz for a cruciform)."""
        return float(self.inertia_kg_m2[1, 1])


def box_inertia(mass_kg: float, lengths_m) -> np.ndarray:
    """(3, 3) inertia tensor of a uniform box about its centroid in its own axes:
    ``m (l_j² + l_k²) / 12`` on the diagonal."""
    sq = np.asarray(lengths_m, dtype=float) ** 2
    return mass_kg / 12.0 * np.diag([sq[1] + sq[2], sq[0] + sq[2], sq[0] + sq[1]])


def finner_mass_properties(fb: FinnedBody, density_kg_m3: float) -> FinnedMassProperties:
    """Mass, cg and inertia tensor of ``fb`` as a uniform solid of ``density_kg_m3``.

    Body of revolution: :func:`cadra.body.mass.solid_properties`. Fin k: the box
    chord × span × thickness with its root on the cylinder (module docstring), centroid at
    s = chord / 2, u = d/2 + span/2 on e_k; its own inertia :func:`box_inertia` in the fin's
    axes (x_b, e_k, w_k), rotated into body axes, then moved to the cg by the parallel-axis
    theorem ``I += m (|r|² 1 − r rᵀ)``.
    """
    rho = float(density_kg_m3)
    if not (np.isfinite(rho) and rho > 0):
        raise ValueError(f"density_kg_m3: must be positive, got {density_kg_m3!r}")
    sp = solid_properties(fb.body, rho)
    c, b, t = fb.fin_chord_m, fb.fin_span_m, fb.fin_thickness_m
    v_fin = c * b * t
    m_fin = rho * v_fin
    u_c = 0.5 * fb.diameter_m + 0.5 * b
    frames = fin_frames(fb)                              # rows: x_b, e_k, w_k in body axes
    cents = np.array([[0.5 * c, 0.0, 0.0] + u_c * f[1] for f in frames])
    n = len(frames)
    mass = sp.mass_kg + n * m_fin
    cg = (sp.mass_kg * sp.centroid_s_m + m_fin * cents[:, 0].sum()) / mass
    I = np.diag([sp.ixx_kg_m2, sp.itrans_kg_m2, sp.itrans_kg_m2])
    I = I + sp.mass_kg * (sp.centroid_s_m - cg) ** 2 * np.diag([0.0, 1.0, 1.0])
    own = box_inertia(m_fin, (c, b, t))
    for f, r in zip(frames, cents, strict=True):
        r = r - np.array([cg, 0.0, 0.0])
        I = I + f.T @ own @ f + m_fin * (r @ r * np.eye(3) - np.outer(r, r))
    I = 0.5 * (I + I.T)
    I.setflags(write=False)
    return FinnedMassProperties(density_kg_m3=rho, body_volume_m3=sp.volume_m3,
                                fin_volume_m3=v_fin, mass_kg=mass, cg_s_m=float(cg),
                                inertia_kg_m2=I)


__all__ = ["BASIC_FINNER_CAL", "BASIC_FINNER_D_M", "FIN_PHI_RAD", "KIND", "PRESETS",
           "FinnedBody", "FinnedMassProperties", "box_inertia", "cone_cylinder",
           "fin_corners", "fin_frames", "fin_polygons", "finner", "finner_mass_properties",
           "finner_preset", "finner_silhouette", "finner_silhouette_area_m2",
           "outline_polygon"]
