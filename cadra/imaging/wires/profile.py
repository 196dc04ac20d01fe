"""A wire's cross-section modelled as the image forms it: the centres without a phase bias.

A wire's centroid (:func:`cadra.imaging.wires.line._centroids`) needs no model of the profile, but
it errs by a periodic function of the wire's sub-pixel phase (up to ~0.007 px for a 2 px wire)
and its darkness weights carry the noise of every sample in its window. This module fits each
profile, sampled through pixel centres along an image axis, with a model of how the image was
formed, so the sampling is modelled rather than averaged:

``I(x) = b0 + b1 x + b2 x^2 / 2 + A O(x - c) + F L(x - c)``, in the profile's coordinate
``x`` (px), with

* ``O = g_d * [box_1 * box_t * G_c * band_h]`` the wire's opacity: a band of half-width ``h``
  blurred by a continuous Gaussian ``G_c`` (sigma ``sigma_c``: optics, film, anything before
  the pixel integrates the light), integrated over the pixel (``box_1``) and over the wire's
  drift across the pixel's other side (``box_t``, ``t`` the wire's slope against the profile
  axis; 3-point Gauss-Legendre, above |t| = 0.02), then blurred by a discrete Gaussian ``g_d``
  (sigma ``sigma_d``) on the pixel grid (a scanner's or a renderer's filter of the sampled
  image);
* ``L`` the second difference of ``O`` blurred by a discrete Gaussian of sigma ``fringe_w``
  (the diffraction fringe, a Laplacian of the blurred shadow);
* the background ``b0, b1, b2`` (the beam's slope and mottle), ``A`` and ``F`` linear per
  profile, ``c`` the centre, nonlinear per profile (Gauss-Newton from the centroid, compiled
  with numba). Samples darker than :data:`CLIP_FRACTION` of the bright level are left out (a
  fringe deeper than the shadow is clipped at zero transmission).

The order matters: the same total blur applied before or after the pixel integration gives
profiles whose centres differ by up to ~0.035 px at some phases. The image formation
(``sigma_c``, ``sigma_d``, ``fringe_w``) and each wire's half-width are fitted from the
profiles (:mod:`cadra.imaging.wires.formation`: once per view of a shot, or per image), then
every profile's centre is fitted with them (:func:`fit_centres`). The formation's covariance
and each wire's centre shift per unit of each parameter come with it, so the caller can carry
the formation's uncertainty into the lines (:func:`cadra.imaging.wires.affine.formation_cov`).

Measured (``tests/test_wire_profile.py``): on the renderer's own wires (coverage, then a
discrete PSF) and on wires formed in the physical order (PSF, then the pixel), noise-free,
lines within 5e-4 px at every phase; a model of the wrong order errs by up to 0.035 px; with
the default noise the centres scatter ~2.7x less than the centroid's. At 0.4 px optics blur a
few per cent error of the fitted blur moved lines by several sigma, so sharp wires are left to
the centroid (:data:`cadra.imaging.wires.fit.MIN_MODEL_BLUR_PX`). All lengths in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numba
import numpy as np

__all__ = ["Formation", "WireProfiles", "fit_centres"]

_INV_SQRT2PI = 1.0 / math.sqrt(2.0 * math.pi)
_INV_SQRT2 = 1.0 / math.sqrt(2.0)
#: Bounds of the formation's blurs (px).
SIGMA_MAX = 4.0
FRINGE_W_MIN = 0.05
#: Most Gauss-Newton iterations of each profile's centre (from the centroid, ~0.05 px off;
#: a sharp wire's profile needs up to ~5; each profile stops at :data:`CENTRE_TOL_PX`).
CENTRE_ITERATIONS = 8
#: A profile's centre has converged when Gauss-Newton's step is below this (px); the step is
#: then taken, leaving an error of a few per cent of it (Gauss-Newton's linear rate at the
#: profiles' noise): a shot's stations move by < 4e-7 deg and 2e-10 m against a tolerance of
#: 1e-7 px with the step not taken, a fifth of the centres' time saved. The centres' finite
#: differences in the formation (:func:`cadra.imaging.wires.formation`'s sensitivities, steps
#: of 1e-3) shift them by ~1e-4 px: those use :data:`SENS_TOL_PX` (an error ~5e-8 px, 5e-5 of a
#: unit sensitivity; the tolerance above gave sensitivities of mostly rounding, 1e-3).
CENTRE_TOL_PX = 1e-4
SENS_TOL_PX = 1e-6
#: A profile's centre is rejected when it moves more than this (px) from its start.
MAX_CENTRE_SHIFT_PX = 1.0


@dataclass(frozen=True, eq=False)
class Formation:
    """How one image formed its wires (px): blur before the pixel integration (continuous),
    after it (discrete, on the pixel grid), the fringe's width; the fit's rms residual
    (fraction of the background); the covariance ``cov`` of ``(sigma_c^2, sigma_d^2,
    fringe_w, h_1..h_m)`` and ``sens`` (m, 3 + m), each wire's mean centre shift (px along
    its profiles) per unit of each (None for a formation not fitted); ``shared``: the three
    formation values are the view's, fitted over several images of a shot
    (:mod:`cadra.imaging.wires.formation`), not this image's own; ``n_images``: how many
    images the three were fitted from."""

    sigma_c: float
    sigma_d: float
    fringe_w: float
    rms: float = math.nan
    cov: np.ndarray | None = None
    sens: np.ndarray | None = None
    shared: bool = False
    n_images: int = 1


@dataclass(frozen=True, eq=False)
class WireProfiles:
    """One wire's profiles: intensities ``P`` (n, k) at consecutive integer positions starting
    at ``s0`` (n,) along the profile axis, start centres ``c0`` (n,), the wire's half-width
    ``h`` along the profile, its slope ``t`` against the profile axis (d profile coordinate per
    pixel along the other axis) and ``cos_t`` (cosine of its angle to the other axis)."""

    P: np.ndarray
    s0: np.ndarray
    c0: np.ndarray
    h: float
    t: float
    cos_t: float


def _kernel(sigma: float) -> np.ndarray:
    if sigma < 1e-3:
        return np.ones(1)
    half = int(math.ceil(4.0 * sigma))
    x = np.arange(-half, half + 1)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


#: Gauss-Legendre nodes and weights on [-1/2, 1/2] for the drift box.
_GL_X = np.array([-math.sqrt(0.15), 0.0, math.sqrt(0.15)])
_GL_W = np.array([5.0, 8.0, 5.0]) / 18.0
#: Below this slope the drift box (variance t^2 / 12) is left out.
_DRIFT_MIN = 0.02
#: Samples darker than this fraction of the profile's bright level are left out: a fringe
#: deeper than the shadow is clipped at zero transmission there, which no linear term models.
CLIP_FRACTION = 0.03


@dataclass(frozen=True, eq=False)
class _Rows:
    """Profiles of one or more wires stacked, with their per-row geometry and sample mask."""

    P: np.ndarray      # (n, k), masked samples zeroed
    s0: np.ndarray     # (n,)
    c0: np.ndarray     # (n,)
    t: np.ndarray      # (n,)
    cos_t: np.ndarray  # (n,)
    m: np.ndarray      # (n, k) 1 used, 0 clipped
    wire: np.ndarray   # (n,) index of the wire each row belongs to

    @staticmethod
    def of(wires: list[WireProfiles], picks=None) -> _Rows:
        picks = [slice(None)] * len(wires) if picks is None else picks
        P = np.concatenate([w.P[p] for w, p in zip(wires, picks, strict=True)]).astype(float)
        m = (P > CLIP_FRACTION * np.max(P, axis=1, keepdims=True)).astype(float)
        n = [len(w.P[p]) for w, p in zip(wires, picks, strict=True)]

        def col(name):   # a per-profile array, or one value per wire
            return np.concatenate([
                np.broadcast_to(np.asarray(getattr(w, name), float), (len(w.P),))[p]
                for w, p in zip(wires, picks, strict=True)])
        return _Rows(np.ascontiguousarray(P * m), col("s0"), col("c0"), col("t"), col("cos_t"), m,
                     np.repeat(np.arange(len(wires)), n))


#: Beyond this many sigmas from an edge the blurred edge is a step to rounding (the normal
#: tail there is < 1e-23): a pixel wholly beyond it is exactly in (1) or out (0) of the
#: half-line, and no ``erfc`` is evaluated for it.
_U_SAT = 10.0


@numba.njit(cache=True)
def _pixel_profile(x0, ne, h, s, cov, dcov, F, N):
    """``cov[j]``: the band ``|y| < h`` blurred by N(0, s^2) and integrated over the pixel
    ``[x0 + j - 1/2, x0 + j + 1/2]``, ``dcov[j]`` its derivative in ``x0``, j < ne (added to
    the arrays). Each edge's antiderivative is evaluated once per pixel boundary (``F``,
    ``N`` scratch of ne + 1), and only within :data:`_U_SAT` sigmas of the edge: a pixel
    wholly beyond adds exactly 1 (past the edge) or 0 (before it)."""
    for sg, e in ((1.0, h), (-1.0, -h)):
        past = ne + 1   # the first boundary beyond the edge's tail (u grows with j)
        before = -1     # the last boundary short of it
        for j in range(ne + 1):
            u = (x0 + j - 0.5 + e) / s
            if u > _U_SAT:
                past = min(past, j)
            elif u < -_U_SAT:
                before = j
            else:
                N[j] = 0.5 * math.erfc(-u * _INV_SQRT2)
                F[j] = u * N[j] + math.exp(-0.5 * u * u) * _INV_SQRT2PI
        for j in range(max(before, 0), min(past, ne)):
            # a pixel with a boundary in the tails: that boundary's N and F exactly
            n0, f0 = (0.0, 0.0) if j <= before else (N[j], F[j])
            n1, f1 = ((1.0, (x0 + j + 0.5 + e) / s) if j + 1 >= past
                      else (N[j + 1], F[j + 1]))
            cov[j] += sg * s * (f1 - f0)
            dcov[j] += sg * (n1 - n0)
        for j in range(past, ne):
            cov[j] += sg        # s (u_{j+1} - u_j) = 1, without its rounding


@numba.njit(cache=True)
def _row_basis(s0i, c, h, sc, at, mrow, kd, kw, A, O, dO, G, dG, cov, dcov, F, Nb, cov_g,
               dcov_g):
    """Fill ``A[:, :5]`` with one profile's basis at centre ``c`` (and ``dO``, ``dG`` with the
    opacity's and the blurred opacity's derivatives in ``c``); ``cov_g``, ``dcov_g`` are
    scratch of ``cov``'s length."""
    k = A.shape[0]
    hd = (kd.shape[0] - 1) // 2
    hw = (kw.shape[0] - 1) // 2
    pad = hd + hw + 1
    ne = k + 2 * pad
    cov[:] = 0.0
    dcov[:] = 0.0
    x0 = s0i - pad - c
    if at > _DRIFT_MIN:
        for g in range(3):
            cov_g[:] = 0.0
            dcov_g[:] = 0.0
            _pixel_profile(x0 + _GL_X[g] * at, ne, h, sc, cov_g, dcov_g, F, Nb)
            wg = _GL_W[g]
            for j in range(ne):
                cov[j] += wg * cov_g[j]
                dcov[j] += wg * dcov_g[j]
    else:
        _pixel_profile(x0, ne, h, sc, cov, dcov, F, Nb)
    # the band's pixels: cov and dcov are exactly 0 outside [lo, hi] (see _pixel_profile)
    lo = 0
    while lo < ne and cov[lo] == 0.0 and dcov[lo] == 0.0:
        lo += 1
    hi = ne - 1
    while hi > lo and cov[hi] == 0.0 and dcov[hi] == 0.0:
        hi -= 1
    for j in range(hd, ne - hd):  # discrete blur after the pixel (zero terms skipped)
        o = 0.0
        do = 0.0
        for q in range(max(-hd, lo - j), min(hd, hi - j) + 1):
            o += kd[q + hd] * cov[j + q]
            do -= kd[q + hd] * dcov[j + q]
        O[j] = o
        dO[j] = do
    for j in range(pad - 1, pad + k + 1):  # the fringe's blur
        g_ = 0.0
        dg = 0.0
        for q in range(-hw, hw + 1):
            g_ += kw[q + hw] * O[j + q]
            dg += kw[q + hw] * dO[j + q]
        G[j] = g_
        dG[j] = dg
    for j in range(k):
        x = s0i + j - c
        jj = j + pad
        w = mrow[j]
        A[j, 0] = w
        A[j, 1] = w * x
        A[j, 2] = w * 0.5 * x * x
        A[j, 3] = w * O[jj]
        A[j, 4] = w * (G[jj - 1] - 2.0 * G[jj] + G[jj + 1])


@numba.njit(cache=True)
def _linear_rss(Prow, A, M, rhs, r):
    """Least squares of the profile on the basis; residuals into ``r``; returns beta, rss."""
    beta = _normal_solve(A, Prow, 5, M, rhs)
    rss = 0.0
    for j in range(A.shape[0]):
        acc = Prow[j]
        for q in range(5):
            acc -= A[j, q] * beta[q]
        r[j] = acc
        rss += acc * acc
    return beta, rss


#: Start offsets (px) scanned about the centroid when the formation is sharp (total blur
#: below :data:`SCAN_BLUR_PX`): a sharp profile's least squares has minima a fraction of a
#: pixel apart, and Gauss-Newton from the centroid can land in the wrong one.
_SCAN = np.array([-0.4, -0.2, 0.0, 0.2, 0.4])
SCAN_BLUR_PX = 0.6


@numba.njit(cache=True)
def _fit_rows(P, m, s0, t, cos_t, h, c0, sigma_c, sigma_d, kd, kw, n_iter, want_r, scan,
              tol, out_c, out_r):
    """Per profile: Gauss-Newton of the centre with the linear terms (background 1, x,
    x^2 / 2; opacity O; fringe L), ``n_iter`` steps from ``c0`` (0: the linear fit at ``c0``;
    ``scan``: from the best of ``c0 +`` :data:`_SCAN`). Writes the centres to ``out_c`` and,
    if ``want_r``, the residuals at them (masked samples 0) to ``out_r``."""
    n, k = P.shape
    hd = (kd.shape[0] - 1) // 2
    hw = (kw.shape[0] - 1) // 2
    pad = hd + hw + 1
    ne = k + 2 * pad
    cov = np.empty(ne)
    dcov = np.empty(ne)
    cov_g = np.empty(ne)
    dcov_g = np.empty(ne)
    F = np.empty(ne + 1)
    Nb = np.empty(ne + 1)
    O = np.zeros(ne)
    dO = np.zeros(ne)
    G = np.zeros(ne)
    dG = np.zeros(ne)
    A = np.empty((k, 6))
    M = np.empty((6, 6))
    rhs = np.empty(6)
    r = np.empty(k)
    for i in range(n):
        sc = max(math.hypot(sigma_c / cos_t[i], sigma_d * t[i]), 1e-3)
        at = abs(t[i])
        c = c0[i]
        if scan and n_iter > 0:
            best = np.inf
            for d in _SCAN:
                _row_basis(s0[i], c0[i] + d, h[i], sc, at, m[i], kd, kw, A, O, dO, G, dG,
                           cov, dcov, F, Nb, cov_g, dcov_g)
                _, rss = _linear_rss(P[i], A, M, rhs, r)
                if rss < best:
                    best = rss
                    c = c0[i] + d
        for it in range(n_iter + 1):
            _row_basis(s0[i], c, h[i], sc, at, m[i], kd, kw, A, O, dO, G, dG, cov, dcov, F,
                       Nb, cov_g, dcov_g)
            beta, _ = _linear_rss(P[i], A, M, rhs, r)
            if it == n_iter:
                out_r[i, :] = r
                break
            for j in range(k):
                x = s0[i] + j - c
                jj = j + pad
                A[j, 5] = m[i, j] * (-beta[1] - beta[2] * x + beta[3] * dO[jj]
                                     + beta[4] * (dG[jj - 1] - 2.0 * dG[jj] + dG[jj + 1]))
            step = _normal_solve(A, r, 6, M, rhs)
            if abs(step[5]) < tol:   # converged: r is the residual at c
                out_r[i, :] = r
                if not want_r:
                    c += step[5]   # taken: a few per cent of it left (CENTRE_TOL_PX)
                break
            c += min(max(step[5], -0.5), 0.5)
            if it == n_iter - 1 and not want_r:
                break
        out_c[i] = c


@numba.njit(cache=True)
def _normal_solve(A, y, p, M, rhs):
    """Least squares of ``y`` on the first ``p`` columns of ``A`` by the normal equations
    (a tiny ridge keeps an all-zero column solvable)."""
    k = A.shape[0]
    for a in range(p):
        acc = 0.0
        for j in range(k):
            acc += A[j, a] * y[j]
        rhs[a] = acc
        for b in range(a, p):
            acc = 0.0
            for j in range(k):
                acc += A[j, a] * A[j, b]
            M[a, b] = acc
            M[b, a] = acc
        M[a, a] += 1e-12 * (M[a, a] + 1.0)
    # Cholesky in place (M symmetric positive definite), then the two triangular solves
    for a in range(p):
        d = M[a, a]
        for q in range(a):
            d -= M[a, q] * M[a, q]
        d = math.sqrt(max(d, 1e-300))
        M[a, a] = d
        for b in range(a + 1, p):
            acc = M[b, a]
            for q in range(a):
                acc -= M[b, q] * M[a, q]
            M[b, a] = acc / d
    z = np.empty(p)
    for a in range(p):
        acc = rhs[a]
        for q in range(a):
            acc -= M[a, q] * z[q]
        z[a] = acc / M[a, a]
    for a in range(p - 1, -1, -1):
        acc = z[a]
        for q in range(a + 1, p):
            acc -= M[q, a] * z[q]
        z[a] = acc / M[a, a]
    return z


def _fit(rows: _Rows, h: np.ndarray, f: Formation, n_iter: int = CENTRE_ITERATIONS,
         want_r: bool = True, tol: float = CENTRE_TOL_PX):
    """Gauss-Newton fit of each profile's centre (and linear terms) from ``rows.c0``, each
    stopping at a step below ``tol`` (px); returns the centres and (if ``want_r``) the
    residuals (n, k) at them."""
    c = np.empty(len(rows.c0))
    r = np.zeros(rows.P.shape)
    _fit_rows(rows.P, rows.m, rows.s0, rows.t, rows.cos_t, np.asarray(h, float), rows.c0,
              f.sigma_c, f.sigma_d, _kernel(f.sigma_d), _kernel(f.fringe_w), n_iter,
              want_r or n_iter == 0, math.hypot(f.sigma_c, f.sigma_d) < SCAN_BLUR_PX, tol,
              c, r)
    return c, r


def _linear_resid(rows: _Rows, c: np.ndarray, h: np.ndarray, f: Formation) -> np.ndarray:
    """Residuals (n, k) of each profile's linear least squares at fixed centres ``c``."""
    return _fit(replace(rows, c0=c), h, f, 0)[1]


def fit_centres(wp: WireProfiles, h: float, f: Formation) -> np.ndarray:
    """Each profile's centre (profile coordinate, px) under formation ``f``; NaN where the
    fit fails or moves more than :data:`MAX_CENTRE_SHIFT_PX` from the start."""
    c, _ = _fit(_Rows.of([wp]), np.full(len(wp.c0), h), f, want_r=False)
    bad = ~np.isfinite(c) | (np.abs(c - wp.c0) > MAX_CENTRE_SHIFT_PX)
    c[bad] = np.nan
    return c
