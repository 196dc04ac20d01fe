"""Exact silhouettes of bodies of revolution under parallel (collimated) projection.

The bodies are convex, so the silhouette is the boundary of the projected body, traced by its
support function. Notation (docs/bodies.md, "Silhouette"): the view plane has orthonormal
axes (the rows of ``P_view``); the body axis ``a`` projects onto it with length σ = sin γ (γ the
angle between the axis and the line of sight) and κ = |cos γ|. Let p̂ be the projected axis
direction (toward the nose), q̂ = p̂ turned +90 deg in the view plane, and t the angle of the
outline's outward normal u = cos t p̂ + sin t q̂. The 3-D normal that projects onto u makes the
angle β with the axis, cos β = σ cos t, sin β = D(t) = sqrt(sin²t + κ² cos²t), so the outline
point with normal t is the projection of the meridian point with normal angle β, on the
azimuth facing u. For a meridian arc (centre (sc, rc), radius ρ) this is, relative to the
projected reference point,

    p(t) = σ sc p̂ + ρ u(t) + rc (κ² cos t p̂ + sin t q̂) / D(t),

a circle of radius ρ swept along the support point of the projected centre circle (an ellipse
of semi-axes rc κ along p̂ and rc along q̂). Straight edges of the outline (a cone flank, a base
seen edge-on) join consecutive arcs. Every polygon vertex is computed from this closed form: it
lies on the true outline to rounding (~1e-17 m); vertices are spaced by ∫ sqrt(ρ_v) dt (ρ_v the
outline's radius of curvature), which evens out the chord sagitta.

The area follows from ½∮ p × dp = ½∫ h (h + h'') dt with h(t) = σ sc cos t + ρ + rc D(t),
h + h'' = ρ + rc κ²/D³ on each arc, integrated in closed form (incomplete elliptic integral of
the second kind), plus the straight edges.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ellipeinc

from cadra.body.model import Body, meridian

#: Grid points per arc for the vertex-spacing quadrature.
_SPACING_GRID = 97


#: :func:`_view_geometry`: below this |sin| of the axis' angle out of the view's plane the
#: axis is taken as in the plane (docs/bodies.md)
KAP_ZERO = 1e-8


def _view_geometry(body: Body, R_FB, P_view):
    """σ, κ, p̂, q̂ of the view (module docstring), validating the inputs."""
    R = np.asarray(R_FB, dtype=float)
    P = np.asarray(P_view, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"R_FB: expected a 3x3 rotation matrix, got shape {R.shape}")
    if P.shape != (2, 3):
        raise ValueError(f"P_view: expected a (2, 3) matrix, got shape {P.shape}")
    if not np.allclose(P @ P.T, np.eye(2), atol=1e-9):
        raise ValueError("P_view: rows must be orthonormal (a parallel-projection view)")
    a = R[:, 0]
    na = np.linalg.norm(a)
    if not (np.isfinite(na) and abs(na - 1.0) < 1e-6):
        raise ValueError("R_FB: first column (the body axis) is not a unit vector")
    a = a / na
    A = P @ a
    sig = float(np.hypot(A[0], A[1]))
    kap = float(abs(np.cross(P[0], P[1]) @ a))
    n = np.hypot(sig, kap)
    sig, kap = sig / n, kap / n
    if kap < KAP_ZERO:
        # the axis in the view's plane to rounding: the end faces' ellipses are below 1e-8 of
        # the radius wide, and their vertices' float noise made the polygon fold (a template
        # 1e-15 rad out of the plane put a fit 0.5 px off); exactly in the plane they are
        # straight edges
        sig, kap = 1.0, 0.0
    ph = A / np.hypot(A[0], A[1]) if sig > 0 else np.array([1.0, 0.0])
    qh = np.array([-ph[1], ph[0]])
    return sig, kap, ph, qh


def _t_of_beta(beta: np.ndarray, sig: float) -> np.ndarray:
    """Outline normal angle t in [0, π] at which the meridian normal angle is β (clipped)."""
    c = np.cos(beta)
    inside = np.sqrt(np.clip((sig - c) * (sig + c), 0.0, None))
    return np.where(c >= sig, 0.0, np.where(c <= -sig, np.pi, np.arctan2(inside, c)))


def _visible_arcs(body: Body, sig: float):
    """Arcs whose normal range is seen on the outline, with their t ranges (upper half)."""
    arcs = body.arcs
    t0 = _t_of_beta(arcs[:, 3], sig)
    t1 = _t_of_beta(arcs[:, 4], sig)
    keep = t1 > t0
    return arcs[keep], t0[keep], t1[keep]


def _points(sc, rc, rho, t, sig, kap):
    """(X, Y) along (p̂, q̂) of the outline point with normal angle t (upper half, t in [0, π])."""
    s, c = np.sin(t), np.cos(t)
    D = np.hypot(s, kap * c)
    pos = D > 0
    inv = np.where(pos, 1.0 / np.where(pos, D, 1.0), 0.0)
    X = sig * sc + rho * c + rc * kap * kap * c * inv
    Y = rho * s + rc * np.where(pos, s * inv, 1.0)  # D = 0 only if κ = 0, t = 0: upper limit
    return X, Y


def _outline_radius(rc, rho, t, kap):
    """Radius of curvature of the outline, ρ + rc κ² / D³ (the Dirac part at D = 0 excluded)."""
    D = np.hypot(np.sin(t), kap * np.cos(t))
    pos = D > 0
    return rho + np.where(pos, rc * kap * kap / np.where(pos, D, 1.0) ** 3, 0.0)


def _upper_half(body: Body, sig: float, kap: float, n_half: int, t_must: np.ndarray):
    """Vertices (X, Y) of the upper half of the outline, t from 0 to π, on the exact outline;
    the normal angles ``t_must`` are among them."""
    arcs, t0, t1 = _visible_arcs(body, sig)
    k = len(arcs)
    # per-arc cumulative ∫ sqrt(ρ_v) dt on a grid uniform in t and in the eccentric anomaly ψ
    grids, cums = [], []
    for j in range(k):
        g = np.linspace(t0[j], t1[j], _SPACING_GRID)
        if kap < 1.0 and arcs[j, 1] > 0:
            p0 = np.arctan2(np.sin(t0[j]), kap * np.cos(t0[j]))
            p1 = np.arctan2(np.sin(t1[j]), kap * np.cos(t1[j]))
            ps = np.linspace(p0, p1, _SPACING_GRID)
            g = np.unique(np.clip(np.concatenate([g, np.arctan2(kap * np.sin(ps), np.cos(ps))]),
                                  t0[j], t1[j]))
        f = np.sqrt(_outline_radius(arcs[j, 1], arcs[j, 2], g, kap))
        cum = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(g))])
        grids.append(g)
        cums.append(cum)
    weights = np.array([c[-1] for c in cums])
    n_inner = max(n_half - 2 * k - len(t_must), 0)
    share = n_inner * weights / weights.sum() if weights.sum() > 0 else np.zeros(k)
    counts = np.floor(share).astype(int)
    counts[np.argsort(share - counts)[::-1][: n_inner - counts.sum()]] += 1
    Xs, Ys = [], []
    for j in range(k):
        m = counts[j]
        tau = cums[j][-1] * np.arange(1, m + 1) / (m + 1)
        extra = t_must[(t_must > t0[j]) & (t_must < t1[j])]
        t_mid = np.sort(np.concatenate([np.interp(tau, cums[j], grids[j]), extra]))
        t = np.concatenate([[t0[j]], t_mid, [t1[j]]])
        X, Y = _points(arcs[j, 0], arcs[j, 1], arcs[j, 2], t, sig, kap)
        Xs.append(X)
        Ys.append(Y)
    return np.concatenate(Xs), np.concatenate(Ys)


def _dedupe_closed(poly: np.ndarray, tol: float) -> np.ndarray:
    """Drop vertices within ``tol`` of their predecessor (cyclically)."""
    step = np.hypot(*(poly - np.roll(poly, 1, axis=0)).T)
    keep = step > tol
    if not keep.any():
        raise ValueError("degenerate silhouette (all vertices coincide)")
    return poly[keep]


def silhouette(body: Body, R_FB: np.ndarray, r_ref_F: np.ndarray, P_view: np.ndarray,
               n_points: int = 4096) -> np.ndarray:
    """Exact outline of ``body`` in a parallel-projection view, as a polygon.

    Parameters
    ----------
    body : the body.
    R_FB : (3, 3) rotation body -> facility (``v_F = R_FB v_B``; column 0 is the nose axis).
    r_ref_F : (3,) the body's reference point in the facility frame, m.
    P_view : (2, 3) orthonormal rows: the facility axes the view sees, e.g. top
        ``[[1, 0, 0], [0, 1, 0]]`` (x, y), side ``[[1, 0, 0], [0, 0, 1]]`` (x, z).
    n_points : vertex budget; the polygon has at most ``n_points`` vertices (a few fewer where
        vertices coincide, e.g. at a sharp apex).

    Returns
    -------
    (N, 2) closed polygon in view-plane metres (``P_view @ r_F`` coordinates),
    counter-clockwise, last vertex not repeated. Every vertex lies on the true outline (to
    rounding); straight parts of the outline are single edges; the outline's extreme points
    along both view axes and across the projected body axis (the maximum width) are vertices.
    """
    n_points = int(n_points)
    if n_points < 16:
        raise ValueError(f"n_points: need at least 16, got {n_points}")
    sig, kap, ph, qh = _view_geometry(body, R_FB, P_view)
    r = np.asarray(r_ref_F, dtype=float)
    if r.shape != (3,):
        raise ValueError(f"r_ref_F: expected shape (3,), got {r.shape}")
    origin = np.asarray(P_view, dtype=float) @ r
    # the outline's extreme points along the view axes and across the projected axis are
    # vertices, so the polygon's bounding box and width are the silhouette's
    t_axes = np.abs(np.arctan2(-ph[1] * np.array([1.0, -1.0, 0.0, 0.0])
                               + ph[0] * np.array([0.0, 0.0, 1.0, -1.0]),
                               ph[0] * np.array([1.0, -1.0, 0.0, 0.0])
                               + ph[1] * np.array([0.0, 0.0, 1.0, -1.0])))
    t_must = np.unique(np.concatenate([t_axes, [0.5 * np.pi]]))
    X, Y = _upper_half(body, sig, kap, n_points // 2, t_must)
    # lower half: mirror image in the projected axis, t from π to 2π
    Xl, Yl = X[::-1], -Y[::-1]
    XX = np.concatenate([X, Xl])
    YY = np.concatenate([Y, Yl])
    poly = origin + XX[:, None] * ph + YY[:, None] * qh
    return _dedupe_closed(poly, 1e-13 * body.diameter_m)


def _antiderivatives(t, sig, kap):
    """J2..J5 of the area integral (see silhouette_area_m2) at t in [0, π]."""
    s, c = np.sin(t), np.cos(t)
    D = np.hypot(s, kap * c)
    pos = D > 0
    inv = np.where(pos, 1.0 / np.where(pos, D, 1.0), 0.0)
    s_over_D = np.where(pos, s * inv, 1.0)          # limit from inside (0, π) when κ = 0
    m = sig * sig
    E = ellipeinc(0.5 * np.pi - t, m)
    J2 = -E                                          # ∫ D dt
    J3 = s_over_D                                    # ∫ κ² cos t / D³ dt
    J4 = -E + m * c * s_over_D                       # ∫ κ² / D³ dt
    J5 = kap * np.arctan2(s, kap * c)                # ∫ κ² / D² dt
    return J2, J3, J4, J5


def silhouette_area_m2(body: Body, R_FB: np.ndarray, P_view: np.ndarray) -> float:
    """Exact projected area of ``body`` in a parallel-projection view, m² (closed form).

    Independent of any polygon: per visible meridian arc, ½∫ h (h + h'') dt in closed form
    (module docstring), plus the straight edges between arcs and across the axis.
    """
    sig, kap, _, _ = _view_geometry(body, R_FB, P_view)
    arcs, t0, t1 = _visible_arcs(body, sig)
    sc, rc, rho = arcs[:, 0], arcs[:, 1], arcs[:, 2]
    a0 = _antiderivatives(t0, sig, kap)
    a1 = _antiderivatives(t1, sig, kap)
    dJ2, dJ3, dJ4, dJ5 = (b - a for a, b in zip(a0, a1, strict=True))
    smooth = (rho * sig * sc * (np.sin(t1) - np.sin(t0)) + rho * rho * (t1 - t0)
              + rc * rho * dJ2 + sig * sc * rc * dJ3 + rho * rc * dJ4 + rc * rc * dJ5)
    X0, Y0 = _points(sc, rc, rho, t0, sig, kap)
    X1, Y1 = _points(sc, rc, rho, t1, sig, kap)
    edges = X1[:-1] * Y0[1:] - Y1[:-1] * X0[1:]     # end of arc j -> start of arc j + 1
    upper = 0.5 * (smooth.sum() + edges.sum())
    # the two halves, plus the edges across the axis at t = 0 and t = π
    return float(2.0 * upper + X0[0] * Y0[0] - X1[-1] * Y1[-1])


def surface_points(body: Body, n_axial: int = 400, n_around: int = 256) -> np.ndarray:
    """Points on the body surface, body axes relative to the reference point (x nose,
    y starboard, z down), m.

    The meridian is sampled at about ``n_axial`` points spaced by arc length (every junction,
    the nose and the base centre included), each revolved at ``n_around`` azimuths; points on
    the axis appear once. Returns (N, 3).
    """
    s, r = meridian(body.arcs, int(n_axial))
    phi = np.linspace(0.0, 2.0 * np.pi, int(n_around), endpoint=False)
    on_axis = r == 0.0
    ring = np.stack([np.repeat(s[~on_axis], len(phi)),
                     np.outer(r[~on_axis], np.cos(phi)).ravel(),
                     np.outer(r[~on_axis], np.sin(phi)).ravel()], axis=1)
    axis = np.stack([s[on_axis], np.zeros(on_axis.sum()), np.zeros(on_axis.sum())], axis=1)
    return np.concatenate([axis, ring])


__all__ = ["silhouette", "silhouette_area_m2", "surface_points"]
