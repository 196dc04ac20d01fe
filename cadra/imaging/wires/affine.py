"""The wires' image->plane affine by generalized least squares, and its covariance.

:func:`solve_affine_gls` solves the affine from each found wire's two "Gauss points" (the
equations of :func:`~cadra.facility.reference.fit_affine_to_wires`, each wire's points
weighted by the inverse of their 2 x 2 covariance), with an optional similarity prior;
:func:`formation_cov` adds what the wires' fitted image formation leaves in it
(:mod:`cadra.imaging.wires.profile`); :func:`corner_sigma_px` says whether the map is
determined. The method is :mod:`cadra.imaging.wires.fit`' (steps 6 and 8); units in each name.
"""

from __future__ import annotations

import math

import numpy as np

from cadra.facility.reference import View
from cadra.imaging.wires.profile import Formation

__all__ = ["corner_sigma_px", "formation_cov", "solve_affine_gls"]

#: Prior 1-sigma of the non-similarity part (anisotropy, shear; relative) of the map from
#: the nominal image to this image, used only when the wires leave a direction undetermined.
SIMILARITY_PRIOR_REL = 2e-5


def _design(view: View, lines) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Equations ``n . (M [u, v, 1]) = n . a0`` as in :func:`fit_affine_to_wires`."""
    rows, rhs, wire_of = [], [], []
    for i, ((a0, a1), pts) in enumerate(zip(view.wire_lines_plane(), lines, strict=True)):
        if pts is None:
            continue
        d = a1 - a0
        n = np.array([-d[1], d[0]]) / math.hypot(d[0], d[1])
        for u, v in pts:
            rows.append([n[0] * u, n[0] * v, n[0], n[1] * u, n[1] * v, n[1]])
            rhs.append(float(n @ a0))
            wire_of.append(i)
    return np.array(rows).reshape(-1, 6), np.array(rhs), wire_of


def _similarity_prior(view: View) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``R`` (2, 6), rhs: ``M = M0 @ A``, A's linear part a similarity: A00 = A11 and
    A01 = -A10, expressed linearly in M's entries (``A = M0_lin^-1 M_lin``)."""
    M0 = np.asarray(view.image_to_plane, float)
    Li = np.linalg.inv(M0[:, :2])  # A_lin = Li @ M_lin, M_lin = [[m0, m1], [m3, m4]]

    def coeff(r, col):  # row vector over m (6,) giving A_lin[r, col]
        out = np.zeros(6)
        out[col] = Li[r, 0]       # M_lin[0, col] = m[col]
        out[3 + col] = Li[r, 1]   # M_lin[1, col] = m[3 + col]
        return out

    R = np.array([coeff(0, 0) - coeff(1, 1), coeff(0, 1) + coeff(1, 0)])
    return R, np.zeros(2)


def solve_affine_gls(view: View, lines, cov_m, prior: bool):
    """Generalized least squares of the affine (with the similarity prior if ``prior``).

    ``cov_m``: per wire, the (2, 2) covariance (m^2) of its two Gauss points' perpendicular
    errors (None for a wire not found); the systematic term makes the two correlated.

    Returns (M, cov, residuals per equation (m), wire index per equation) or None.
    """
    X, y, wire_of = _design(view, lines)
    wire_of = np.asarray(wire_of)
    col = np.array([1e-3, 1e-3, 1.0, 1e-3, 1e-3, 1.0])  # u, v are ~1e3 px
    Xs = X * col
    info, vec = np.zeros((6, 6)), np.zeros(6)
    for i in np.unique(wire_of):
        rows = wire_of == i
        Wi = np.linalg.inv(cov_m[i])
        info += Xs[rows].T @ Wi @ Xs[rows]
        vec += Xs[rows].T @ Wi @ y[rows]
    if prior:
        R, r0 = _similarity_prior(view)
        Rs = R * col
        wp = (1.0 / SIMILARITY_PRIOR_REL) ** 2
        info = info + wp * Rs.T @ Rs
        vec = vec + wp * Rs.T @ r0
    ev = np.linalg.eigvalsh(info)
    if not np.all(np.isfinite(ev)) or ev[0] <= 1e-12 * ev[-1]:
        return None
    cov_s = np.linalg.inv(info)
    m = (cov_s @ vec) * col
    cov = cov_s * np.outer(col, col)
    return m.reshape(2, 3), cov, X @ m - y, wire_of


def corner_sigma_px(view: View, cov: np.ndarray, scale_m: float) -> float:
    """Largest propagated 1-sigma position error (px) at the image corners."""
    W, H = view.width_px - 1.0, view.height_px - 1.0
    worst = 0.0
    for u, v in ((0, 0), (W, 0), (0, H), (W, H)):
        J = np.zeros((2, 6))
        J[0, :3] = (u, v, 1.0)
        J[1, 3:] = (u, v, 1.0)
        worst = max(worst, float(np.sqrt(np.max(np.diag(J @ cov @ J.T)))))
    return worst / scale_m


def formation_cov(view: View, fits, lines, cov_m, prior: bool, M: np.ndarray,
                   formation: Formation, sens: dict) -> np.ndarray:
    """The affine's covariance (6, 6) from the formation's: every wire's centres move
    together with the formation (``sens``: wire index -> centre shift along its profiles
    per unit of each formation parameter), which the affine follows linearly."""
    p = formation.cov.shape[0]
    G = np.zeros((6, p))
    eps = 1e-3
    for j in range(p):
        shifted = []
        for i, (f, pts) in enumerate(zip(fits, lines, strict=True)):
            if pts is None or i not in sens:
                shifted.append(pts)
                continue
            e = np.zeros(2)
            e[f.profile_axis] = 1.0
            shifted.append(pts + eps * sens[i][j] * e)
        sol = solve_affine_gls(view, shifted, cov_m, prior)
        if sol is None:
            return np.zeros((6, 6))
        G[:, j] = (sol[0] - M).ravel() / eps
    return G @ formation.cov @ G.T
