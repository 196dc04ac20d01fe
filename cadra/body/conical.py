"""Exact silhouettes of bodies of revolution under conical projection (a point-source spark).

A point source S throws the shadow of a convex body onto a film: the shadow's outline is the
film's cut through the cone of rays from S tangent to the body. The rays touch the body along
its **contour generator**, the surface points X whose outward normal n is perpendicular to
X − S (docs/bodies.md, "Silhouette under a point source").

For a body of revolution the contour generator has a closed form per meridian arc. In body
axes relative to the reference point, let S = (S_x, S_r cos φ_S, S_r sin φ_S). The point of
arc (sc, rc, ρ) with normal angle β on azimuth φ is X = (sc + ρ cos β, r cos φ, r sin φ),
r = rc + ρ sin β, its normal n = (cos β, sin β cos φ, sin β sin φ); n·X = sc cos β + rc sin β
+ ρ does not depend on φ, so n·(X − S) = 0 reads

    cos(φ − φ_S) = f(β) = ((sc − S_x) cos β + rc sin β + ρ) / (S_r sin β),

two azimuths φ_S ± arccos f(β) wherever |f(β)| <= 1. The β where f = ±1 are the roots of
A cos β + B sin β + ρ = 0 (A = sc − S_x, B = rc ∓ S_r), in closed form; there the two
branches meet. The set of β with a solution is one interval (the contour generator of a convex
body seen from outside is one closed curve), crossed by one branch and back by the other.
A straight flank (a flat between two arcs) touches the cone along a generator: the end of one
arc and the start of the next share β and φ, so the flank is one straight edge of the shadow,
exactly (a central projection keeps lines straight). A corner (an arc of zero radius) gives
its rim's points; a sharp apex one point.

Every vertex is computed from this closed form and so lies on the true contour generator to
rounding; the caller's central projection (``to_plane``, the optics' own map) takes it to the
film. Vertices are spaced along each arc by ∫ sqrt(ds dθ) of the projected outline (s its
length, θ its tangent's direction), which evens out the chord sagitta, as the parallel
silhouette does (:mod:`cadra.body.outline`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from cadra.body.model import Body

#: Dense samples per arc for the vertex-spacing quadrature.
_SPACING_GRID = 257


def _spark_in_body(R_FB, r_ref_F, spark_m) -> tuple[float, float, float]:
    """(S_x, S_r, φ_S) of the spark in body axes relative to the reference point."""
    R = np.asarray(R_FB, dtype=float)
    if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-9):
        raise ValueError("R_FB: expected a 3x3 rotation matrix")
    r = np.asarray(r_ref_F, dtype=float)
    S = np.asarray(spark_m, dtype=float)
    if r.shape != (3,) or S.shape != (3,):
        raise ValueError("r_ref_F, spark_m: expected points (3,) in m")
    s_B = R.T @ (S - r)
    return float(s_B[0]), float(np.hypot(s_B[1], s_B[2])), float(np.arctan2(s_B[2], s_B[1]))


def _tangent_roots(A: float, B: float, rho: float) -> list[float]:
    """β in [0, π] with A cos β + B sin β + ρ = 0 (the branches' meeting points)."""
    R = np.hypot(A, B)
    if R == 0.0 or abs(rho) > R:
        return []
    delta = np.arctan2(B, A)
    half = np.arccos(np.clip(-rho / R, -1.0, 1.0))
    out = []
    for b in (delta + half, delta - half):
        b = (b + np.pi) % (2.0 * np.pi) - np.pi
        if 0.0 <= b <= np.pi:
            out.append(float(b))
    return out


def _f(arc, beta, Sx, Sr):
    sc, rc, rho = arc[0], arc[1], arc[2]
    s = np.sin(beta)
    num = (sc - Sx) * np.cos(beta) + rc * s + rho
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(s > 0.0, num / (Sr * s), np.copysign(np.inf, num))


def _pieces(body: Body, Sx: float, Sr: float) -> list[tuple[int, float, float]]:
    """(arc, β_lo, β_hi) of every arc's part on the contour generator, in β order."""
    out = []
    for k, arc in enumerate(body.arcs):
        b0, b1 = float(arc[3]), float(arc[4])
        if b1 <= b0:
            continue
        cuts = [b0, b1]
        for B in (arc[1] - Sr, arc[1] + Sr):
            cuts += [b for b in _tangent_roots(arc[0] - Sx, B, arc[2]) if b0 < b < b1]
        cuts = np.unique(cuts)
        for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
            mid = 0.5 * (lo + hi)
            if abs(_f(arc, mid, Sx, Sr)) <= 1.0:
                if out and out[-1][0] == k and out[-1][2] == lo:
                    out[-1] = (k, out[-1][1], float(hi))
                else:
                    out.append((k, float(lo), float(hi)))
    return out


def _points_B(arc, beta, Sx, Sr, phiS, sign):
    """Body-axis points of the contour generator on one branch (sign ±1) at ``beta``."""
    sc, rc, rho = arc[0], arc[1], arc[2]
    phi = phiS + sign * np.arccos(np.clip(_f(arc, beta, Sx, Sr), -1.0, 1.0))
    r = rc + rho * np.sin(beta)
    return np.stack([sc + rho * np.cos(beta), r * np.cos(phi), r * np.sin(phi)], axis=-1)


def _spacing_weights(ab: np.ndarray) -> np.ndarray:
    """∫ sqrt(ds dθ) over each interval of a dense outline ``ab`` (m, n, 2)."""
    d = np.diff(ab, axis=-2)
    ds = np.hypot(d[..., 0], d[..., 1])
    theta = np.unwrap(np.arctan2(d[..., 1], d[..., 0]), axis=-1)
    turn = np.abs(np.diff(theta, axis=-1))
    dtheta = np.concatenate([turn[..., :1], 0.5 * (turn[..., 1:] + turn[..., :-1]),
                             turn[..., -1:]], axis=-1)
    return np.sqrt(ds * dtheta).sum(axis=0)


def contour_generator(body: Body, R_FB, r_ref_F, spark_m, to_plane: Callable | None = None,
                      n_points: int = 4096) -> np.ndarray:
    """The closed curve along which the rays from ``spark_m`` touch ``body`` (module docstring).

    Parameters
    ----------
    body : the body of revolution.
    R_FB : (3, 3) rotation body -> facility (column 0 the nose axis).
    r_ref_F : (3,) the reference point in the facility frame, m.
    spark_m : (3,) the point source in the facility frame, m (outside the body).
    to_plane : the film's map of facility points (..., 3) to plane points (..., 2), used only
        to space the vertices evenly on the shadow; None spaces them on the body.
    n_points : vertex budget (about half on each branch).

    Returns
    -------
    (N, 3) facility points (m), in order around the curve, the last not repeating the first;
    every one is on the true contour generator to rounding.
    """
    n_points = int(n_points)
    if n_points < 16:
        raise ValueError(f"n_points: need at least 16, got {n_points}")
    Sx, Sr, phiS = _spark_in_body(R_FB, r_ref_F, spark_m)
    if Sr < 1e-6 * body.diameter_m:
        raise ValueError("spark_m: the point source lies on the body's axis; its shadow is a "
                         "disc this outline does not trace")
    pieces = _pieces(body, Sx, Sr)
    if not pieces:
        raise ValueError("spark_m: no ray from the point source touches the body (is the "
                         "source inside it?)")
    R = np.asarray(R_FB, dtype=float)
    r0 = np.asarray(r_ref_F, dtype=float)

    def facility(arc, beta, sign):
        return r0 + _points_B(arc, beta, Sx, Sr, phiS, sign) @ R.T

    project = to_plane if to_plane is not None else (lambda p: p)
    weights = []
    for k, lo, hi in pieces:
        g = np.linspace(lo, hi, _SPACING_GRID)
        dense = np.stack([np.asarray(project(facility(body.arcs[k], g, s)))
                          for s in (1.0, -1.0)])
        w = _spacing_weights(dense)
        weights.append((g, np.concatenate([[0.0], np.cumsum(w)])))
    total = np.array([c[-1] for _, c in weights])
    n_inner = max(n_points // 2 - 2 * len(pieces), 0)
    share = n_inner * total / total.sum() if total.sum() > 0 else np.zeros(len(pieces))
    counts = np.floor(share).astype(int)
    counts[np.argsort(share - counts)[::-1][: n_inner - counts.sum()]] += 1
    betas = []
    for (g, cum), m in zip(weights, counts, strict=True):
        tau = cum[-1] * np.arange(1, m + 1) / (m + 1)
        betas.append(np.concatenate([[g[0]], np.interp(tau, cum, g), [g[-1]]]))
    upper = np.concatenate([facility(body.arcs[k], b, 1.0)
                            for (k, _, _), b in zip(pieces, betas, strict=True)])
    lower = np.concatenate([facility(body.arcs[k], b, -1.0)
                            for (k, _, _), b in zip(pieces, betas, strict=True)])
    curve = np.concatenate([upper, lower[::-1]])
    step = np.linalg.norm(curve - np.roll(curve, 1, axis=0), axis=1)
    return curve[step > 1e-13 * body.diameter_m]


def conical_silhouette(body: Body, R_FB, r_ref_F, spark_m, to_plane: Callable,
                       n_points: int = 4096) -> np.ndarray:
    """Exact outline of ``body``'s shadow from the point source ``spark_m`` on a film whose
    map of facility points to plane points is ``to_plane`` (a central projection from
    ``spark_m``, e.g. :meth:`cadra.optics.projection.PointSourceProjection.plane_point`).

    Returns (N, 2) plane points (m), counter-clockwise, the last vertex not repeated; every
    vertex is the film's image of a point of the contour generator
    (:func:`contour_generator`), so it lies on the true outline to rounding.
    """
    poly = np.asarray(to_plane(contour_generator(body, R_FB, r_ref_F, spark_m, to_plane,
                                                 n_points)), dtype=float)
    x, y = poly[:, 0], poly[:, 1]
    area2 = np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    return poly if area2 > 0 else poly[::-1]


__all__ = ["conical_silhouette", "contour_generator"]
