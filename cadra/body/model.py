"""The :class:`Body`: a convex body of revolution described by its meridian.

A body is stored as its *meridian* in the half plane (s, r): s along the symmetry axis from the
body's **reference point** (+ toward the nose), r >= 0 the radius. The meridian is a chain of
circular arcs ordered by the angle β of their outward normal, β = 0 at the nose (normal along
+s) to β = π at the base (normal along −s); consecutive arcs are joined by straight segments
(flats: a cone flank, a flat base) where their end points differ. A corner is an arc of zero
radius. Every shape in :mod:`cadra.body` (sphere, capsule, cone) is exactly such a chain, which
is what makes the silhouette exact (:mod:`cadra.body.outline`).

Arc table columns (``Body.arcs``, one row per arc, metres / radians):
``sc`` axial position of the arc centre, ``rc`` radial position of the arc centre (the arc is
a torus of tube radius ``rho`` about a centre circle of radius ``rc``), ``rho`` arc radius,
``beta0``, ``beta1`` normal-angle range. A point of arc k at normal angle β is
``(sc + rho cos β, rc + rho sin β)``.

Body axes are Etkin's (docs/conventions.md): x along the axis toward the nose, y starboard,
z down. Geometry is given relative to the reference point, not the cg; the cg offset comes
from the shot file (see :func:`axial_offset_from_base`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Body kinds built by :mod:`cadra.body`.
KINDS = ("sphere", "capsule", "cone", "bullet")

#: Number of points in ``Body.s_m`` / ``Body.r_m``.
PROFILE_POINTS = 2001

ARC_COLUMNS = ("sc", "rc", "rho", "beta0", "beta1")


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Body:
    """A convex body of revolution (docs/bodies.md).

    Attributes
    ----------
    kind : ``"sphere"``, ``"capsule"`` or ``"cone"``.
    name : e.g. ``"M2"``.
    diameter_m : reference length d (maximum diameter), m.
    length_m : axial length nose to base, m.
    s_m : (n,) meridian axial coordinate from the reference point, + toward the nose, m;
        non-decreasing from ``base_s_m`` to ``nose_s_m`` (a flat base repeats ``base_s_m``).
    r_m : (n,) radius at ``s_m``, m (>= 0; 0 at both ends).
    nose_s_m, base_s_m : axial extent relative to the reference point, m.
    arcs : (k, 5) meridian arc table (module docstring), read-only.
    params : the defining dimensions, SI (``(("d_m", 0.0355), ...)``), as ``to_spec`` writes them.
    preset : Table 1 preset the body was built from (capsules), else None.
    oml : the resolved capsule outer mold line (:class:`~cadra.body.capsule.CapsuleOML`), else
        None. Typed ``object`` here: the capsule module builds on this one, not the reverse.

    Bodies compare by identity; compare ``to_spec()`` for equality of shape.
    """

    kind: str
    name: str
    diameter_m: float
    length_m: float
    s_m: np.ndarray
    r_m: np.ndarray
    nose_s_m: float
    base_s_m: float
    arcs: np.ndarray = field(repr=False)
    params: tuple = ()
    preset: str | None = None
    oml: object | None = field(default=None, repr=False)

    def to_spec(self) -> dict:
        """Plain-data spec in file units (cm, deg); ``body_from_spec`` rebuilds the body."""
        return spec_from_params(self.kind, self.name, self.preset, self.params)

    @property
    def param(self) -> dict:
        """``params`` as a dict (SI)."""
        return dict(self.params)


def spec_from_params(kind: str, name: str, preset: str | None, params) -> dict:
    """A body's plain-data spec in file units (cm, deg) from its constructor's SI
    ``(key, value)`` pairs (``*_m`` lengths, ``*_rad`` angles)."""
    spec: dict = {"kind": kind, "name": name}
    if preset is not None:
        spec["preset"] = preset
    for key, value in params:
        if key.endswith("_m"):
            spec[key[:-2] + "_cm"] = float(value) * 100.0
        elif key.endswith("_rad"):
            spec[key[:-4] + "_deg"] = float(np.degrees(value))
        else:  # pragma: no cover - constructors only store lengths and angles
            raise AssertionError(key)
    return spec


def arc_points(arcs: np.ndarray, k: int, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Meridian points (s, r) of arc ``k`` at normal angles ``beta``."""
    sc, rc, rho = arcs[k, 0], arcs[k, 1], arcs[k, 2]
    return sc + rho * np.cos(beta), rc + rho * np.sin(beta)


def arc_ends(arcs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 2) start and end points (s, r) of every arc."""
    sc, rc, rho, b0, b1 = arcs.T
    start = np.stack([sc + rho * np.cos(b0), rc + rho * np.sin(b0)], axis=1)
    end = np.stack([sc + rho * np.cos(b1), rc + rho * np.sin(b1)], axis=1)
    return start, end


def meridian(arcs: np.ndarray, n: int = PROFILE_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """About ``n`` meridian points (s, r), base to nose, spaced roughly evenly by arc length.

    Every junction (arc end, corner, the base centre and the nose) and the point of maximum
    radius are points, exactly; arcs are sampled uniformly in β, flats uniformly in length.
    ``s`` is non-decreasing.
    """
    arcs = np.asarray(arcs, dtype=float)
    start, end = arc_ends(arcs)
    # elements in nose -> base order: ("arc", k) and ("flat", p0, p1)
    elems: list[tuple] = []
    for k in range(len(arcs)):
        if k > 0 and np.hypot(*(start[k] - end[k - 1])) > 0.0:
            elems.append(("flat", end[k - 1], start[k]))
        elems.append(("arc", k))
    if end[-1][1] > 0.0:  # flat base down to the axis
        elems.append(("flat", end[-1], np.array([end[-1][0], 0.0])))
    lengths = np.array([arcs[e[1], 2] * (arcs[e[1], 4] - arcs[e[1], 3]) if e[0] == "arc"
                        else float(np.hypot(*(e[2] - e[1]))) for e in elems])
    total = lengths.sum()
    n_inner = max(n - len(elems) - 1, 0)
    counts = np.floor(n_inner * lengths / total).astype(int)
    s_parts, r_parts = [], []
    for e, m in zip(elems, counts, strict=True):
        if e[0] == "arc":
            k = e[1]
            beta = np.linspace(arcs[k, 3], arcs[k, 4], m + 2)[:-1]
            if arcs[k, 3] < 0.5 * np.pi < arcs[k, 4] and arcs[k, 2] > 0:
                # the maximum radius, exactly (the capsule's reference plane)
                beta = np.union1d(beta, [0.5 * np.pi])
            s, r = arc_points(arcs, k, beta)
        else:
            u = np.linspace(0.0, 1.0, m + 2)[:-1]
            s = e[1][0] + u * (e[2][0] - e[1][0])
            r = e[1][1] + u * (e[2][1] - e[1][1])
        s_parts.append(s)
        r_parts.append(r)
    last = elems[-1]
    if last[0] == "arc":
        s_end, r_end = arc_points(arcs, last[1], np.array([arcs[last[1], 4]]))
    else:
        s_end, r_end = np.array([last[2][0]]), np.array([last[2][1]])
    s = np.concatenate(s_parts + [s_end])[::-1]
    r = np.concatenate(r_parts + [r_end])[::-1]
    r = np.maximum(r, 0.0)
    r[0] = r[-1] = 0.0  # both ends on the axis (sin π is not 0 in floating point)
    s = np.maximum.accumulate(s)  # remove rounding wiggles (flat base: equal s)
    return s, r


def make_body(kind: str, name: str, arcs, params: dict, *, preset: str | None = None,
              oml=None, diameter_m: float | None = None) -> Body:
    """Build a :class:`Body` from its arc table (constructors' common tail)."""
    arcs = _ro(arcs)
    if arcs.ndim != 2 or arcs.shape[1] != 5 or len(arcs) == 0:
        raise ValueError("arc table must be (k, 5)")
    contiguous = np.all(arcs[1:, 3] == arcs[:-1, 4])
    if arcs[0, 3] != 0.0 or abs(arcs[-1, 4] - np.pi) > 1e-15 or not contiguous:
        raise ValueError("arcs must cover beta = 0..pi contiguously")
    s, r = meridian(arcs)
    d = float(2.0 * r.max()) if diameter_m is None else float(diameter_m)
    return Body(kind=kind, name=name, diameter_m=d, length_m=float(s[-1] - s[0]),
                s_m=_ro(s), r_m=_ro(r), nose_s_m=float(s[-1]), base_s_m=float(s[0]),
                arcs=arcs, params=tuple((k, float(v)) for k, v in params.items()),
                preset=preset, oml=oml)


# --------------------------------------------------------------------------- cg offsets


def axial_offset_from_base(body: Body, x_from_base_m: float) -> float:
    """Axial coordinate from the reference point (m, + toward the nose) of a point given as a
    distance from the centre of the model base toward the nose.

    Seed 004 Table 2 gives the cg as ``x_cg-b``, "axial component of cg position, from center
    of model base (aftbody)"; the body-axis cg offset from the reference point is
    ``body.base_s_m + x_cg_b``. For a sphere (no base) the "base" is the aft pole.
    """
    return float(body.base_s_m + x_from_base_m)


def cg_offset_from_table2(body: Body, x_cg_b_cm: float) -> float:
    """Seed 004 Table 2 ``x_cg-b`` (cm, from the base centre toward the nose) -> the axial cg
    offset from the body's reference point, m (+ toward the nose; usually negative for the
    capsules: the cg lies aft of the maximum-diameter plane)."""
    return axial_offset_from_base(body, float(x_cg_b_cm) * 1e-2)


__all__ = ["KINDS", "Body", "axial_offset_from_base", "cg_offset_from_table2", "make_body",
           "meridian"]
