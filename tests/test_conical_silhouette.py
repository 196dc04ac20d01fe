"""The exact shadow of a body under a point source (cadra.body.conical, through
PointSourceProjection.outline), against geometry computed independently here.

- A sphere's shadow: every vertex's ray from the spark makes the tangent cone's half-angle
  asin(a / |C - S|) with the line to the centre, to 1e-12 rad.
- Every body, the finned one included: the outline is ray-traced. From a point inside the
  shadow, along directions on the film, the boundary is bisected between rays that hit the
  body and rays that miss it. A ray's hit test reads the body's radius profile R(s) (arcs
  as explicit circles, flats as lines) and the fins' boxes (a slab test), nothing of the
  tangency condition the outline is built from. The polygon agrees with the traced boundary
  to far below 0.01 px (1e-4 px of a 0.127 mm pixel is the bound asserted).
- A spark far away gives the parallel silhouette.
- A spark on the body's axis is refused.
"""

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from cadra.body import (
    FinnedBody,
    bullet_preset,
    capsule,
    finner_preset,
    outline_polygon,
    sphere,
)
from cadra.body.finner import fin_frames
from cadra.conventions import axis_from_inclinations, quat_from_axis_roll, quat_to_matrix
from cadra.optics import PointSourceProjection

SCALE = 1.27e-4   # m per px on the film


def view(spark=(0.04, -0.03, 2.5)):
    """A BRL-like top view: the spark 2.5 m above the line of flight, the film 0.35 m below."""
    return PointSourceProjection(spark_m=spark, film_origin_m=[0.0, 0.0, -0.35],
                                 plane_basis=[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                                 image_to_plane=[[SCALE, 0.0, -0.1], [0.0, -SCALE, 0.08]])


def attitude(theta_deg, psi_deg, roll_deg=0.0):
    a = axis_from_inclinations(np.radians(theta_deg), np.radians(psi_deg))
    return quat_to_matrix(quat_from_axis_roll(a, np.radians(roll_deg)))


def radius_profile(arcs, s):
    """The body's radius at axial position s (None off the body): arcs as explicit circles
    r = rc + sqrt(rho^2 - (s - sc)^2), flats as straight lines between arc ends."""
    sc, rc, rho, b0, b1 = np.asarray(arcs).T
    s_hi, s_lo = sc + rho * np.cos(b0), sc + rho * np.cos(b1)      # arcs run nose to base
    r_hi, r_lo = rc + rho * np.sin(b0), rc + rho * np.sin(b1)
    for k in range(len(sc)):
        if rho[k] > 0 and s_lo[k] <= s <= s_hi[k]:
            return rc[k] + np.sqrt(max(rho[k] ** 2 - (s - sc[k]) ** 2, 0.0))
        if k + 1 < len(sc) and s_hi[k + 1] <= s <= s_lo[k] and s_lo[k] > s_hi[k + 1]:
            t = (s - s_hi[k + 1]) / (s_lo[k] - s_hi[k + 1])
            return r_hi[k + 1] + t * (r_lo[k] - r_hi[k + 1])
    return None


def ray_hits_body(arcs, R, r_ref, S, d):
    """Whether the line S + t d passes through the body of revolution (its radius profile)."""
    sc, rc, rho, b0, b1 = np.asarray(arcs).T
    s_min = float(np.min(sc + rho * np.cos(b1)))
    s_max = float(np.max(sc + rho * np.cos(b0)))

    def g(t):   # <= 0 exactly inside the body: a continuous max of the three conditions
        y = R.T @ (S + t * d - r_ref)
        s = float(np.clip(y[0], s_min, s_max))
        return max(np.hypot(y[1], y[2]) - radius_profile(arcs, s), s_min - y[0], y[0] - s_max)

    t_c = float((r_ref - S) @ d)
    half = s_max - s_min + float(np.max(rc + rho))
    ts = np.linspace(t_c - half, t_c + half, 301)
    vals = np.array([g(t) for t in ts])
    i = int(np.argmin(vals))
    if vals[i] < 0.0:
        return True
    lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, len(ts) - 1)]
    res = minimize_scalar(g, bounds=(lo, hi), method="bounded", options={"xatol": 1e-15})
    return res.fun < 0.0


def ray_hits_box(origin, axes, lo, hi, S, d):
    """Slab test of the line S + t d against the box lo <= axes @ (x - origin) <= hi."""
    p, q = axes @ (S - origin), axes @ d
    with np.errstate(divide="ignore"):
        t1, t2 = (lo - p) / q, (hi - p) / q
    return np.max(np.minimum(t1, t2)) <= np.min(np.maximum(t1, t2))


def traced_hit(body, R, r_ref, S, d):
    if isinstance(body, FinnedBody):
        if ray_hits_body(body.body.arcs, R, r_ref, S, d):
            return True
        lo = np.array([0.0, 0.0, -0.5 * body.fin_thickness_m])
        hi = np.array([body.fin_chord_m, body.fin_tip_radius_m, 0.5 * body.fin_thickness_m])
        return any(ray_hits_box(r_ref, frame, lo, hi, S, d) for frame in fin_frames(body, R))
    return ray_hits_body(body.arcs, R, r_ref, S, d)


def polygon_reach(poly, c, e):
    """Distance from c along the unit direction e to the polygon's boundary (c inside)."""
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    den = e[0] * ab[:, 1] - e[1] * ab[:, 0]
    ac = a - c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ac[:, 0] * ab[:, 1] - ac[:, 1] * ab[:, 0]) / den
        u = (ac[:, 0] * e[1] - ac[:, 1] * e[0]) / den
    ok = (den != 0) & (u >= 0) & (u <= 1) & (t > 0)
    return float(np.min(t[ok]))


def traced_reach(proj, body, R, r_ref, c, e, q_in, q_out):
    """Bisect the traced boundary between q_in (a hit) and q_out (a miss) along c + q e."""
    S = proj.spark_m
    for _ in range(40):
        q = 0.5 * (q_in + q_out)
        origin, d = proj.plane_ray(c + q * e)
        if traced_hit(body, R, r_ref, S, (origin - S) / np.linalg.norm(origin - S)):
            q_in = q
        else:
            q_out = q
    return 0.5 * (q_in + q_out)


def test_sphere_shadow_is_the_tangent_cone():
    a = 0.0125
    C = np.array([0.01, 0.03, -0.02])
    proj = view()
    poly = proj.outline(sphere(2 * a), np.eye(3), C)
    film = proj.film_origin_m + poly @ proj.plane_basis
    rays = film - proj.spark_m
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    axis = (C - proj.spark_m) / np.linalg.norm(C - proj.spark_m)
    half = np.arcsin(a / np.linalg.norm(C - proj.spark_m))
    assert len(poly) > 2000
    assert np.max(np.abs(np.arccos(np.clip(rays @ axis, -1, 1)) - half)) < 1e-12
    # the shadow is larger than the parallel one by about the magnification
    lam = float(proj.magnification(C))
    area = 0.5 * np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    assert area == pytest.approx(np.pi * a * a * lam * lam, rel=2e-3)


CASES = {
    "M80 bullet": (lambda: bullet_preset("M80"), (4.0, -3.0, 0.0), (-0.01, 0.02, 0.015)),
    "M2 capsule": (lambda: capsule("M2"), (12.0, 7.0, 0.0), (0.02, -0.01, 0.0)),
    "finner": (lambda: finner_preset(d_m=0.02), (6.0, 3.0, 22.0), (-0.05, 0.01, 0.03)),
}


@pytest.mark.parametrize("name", list(CASES))
def test_outline_agrees_with_a_ray_traced_shadow(name):
    make, angles, r_ref = CASES[name]
    body = make()
    R = attitude(*angles)
    r_ref = np.array(r_ref)
    proj = view()
    poly = proj.outline(body, R, r_ref)
    c = poly.mean(axis=0)
    misses = []
    for ang in np.linspace(0.0, 2 * np.pi, 16, endpoint=False) + 0.1:
        e = np.array([np.cos(ang), np.sin(ang)])
        q = polygon_reach(poly, c, e)
        traced = traced_reach(proj, body, R, r_ref, c, e, 0.9 * q, 1.1 * q)
        misses.append(abs(traced - q))
    assert max(misses) / SCALE < 1e-4, f"{max(misses) / SCALE:.2e} px"


def test_far_spark_is_the_parallel_silhouette():
    body = bullet_preset("M80")
    R = attitude(5.0, -2.0)
    r_ref = np.array([0.0, 0.01, 0.0])
    far = view(spark=(0.0, 0.0, 1e7))
    poly = far.outline(body, R, r_ref)
    par = outline_polygon(body, R, r_ref, far.plane_basis)
    lam = float(far.magnification(r_ref))
    # the far spark's shadow is the parallel one scaled by its magnification (1 + 3.5e-8)
    # about the spark's foot; compare the two by their areas and bounding boxes
    area = [0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
            for p in (poly, par)]
    assert area[0] == pytest.approx(area[1] * lam * lam, rel=1e-6)
    assert np.allclose(poly.min(axis=0), par.min(axis=0), atol=1e-8)
    assert np.allclose(poly.max(axis=0), par.max(axis=0), atol=1e-8)


def test_spark_on_the_axis_is_refused():
    proj = view(spark=(0.0, 0.0, 2.5))
    with pytest.raises(ValueError, match="on the body's axis"):
        proj.outline(bullet_preset("M80"), np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),
                     np.zeros(3))
