"""The wire centroid's sub-pixel phase bias: its size in one image, and what it leaves in a line.

:mod:`cadra.imaging.wires.fit` centres each profile across a wire by the centroid of its
darkness. Sampled on the pixel grid, that centroid errs by a periodic function ``beta(phi)``
of the sub-pixel phase ``phi`` of the wire's centre (pixel centres at integers), zero on
average over a phase. Along a wire whose image sweeps several pixels across the grid the
errors average out of its fitted line; a wire parallel to the grid to within a pixel keeps
one phase, and its whole line is off by ``beta(phi)`` (up to ~0.007 px for a 2 px wire,
against ~0.004 px from the profile noise). Left out of the line's sigma, this made the
affine's error at the model ~1.15 of its reported sigma (docs/stage1.md, "Where the x
channel's excess comes from").

Method (lengths in pixels):

1. **Shape.** The centroid of a sharp band of width ``w`` sampled by pixel coverage errs by
   ``[b(1 - b) - a(1 - a)] / (2 w)`` (end fractions a, b): :func:`sampling_bias_px`. A
   normalized blur applied after the sampling (a scanner's digital filter, the renderer's
   discrete PSF) leaves it unchanged: a discrete convolution adds its kernel's centroid (0)
   to the samples' centroid. A PSF acting before the pixel integration reduces it: by Poisson
   summation the centroid of samples ``f(k - phi)`` errs by ``sum_{m != 0} i F'(m)
   exp(-2 pi i m phi) / (2 pi F(0))``, and for the band ``F(nu) = sinc(nu) w sinc(w nu) G(nu)``
   with ``G`` the PSF's transfer, so each harmonic is scaled by ``G(m)`` (``sinc(m) = 0``
   leaves ``F'(m) = (-1)^m w sinc(w m) G(m) / m``).
2. **Size in this image.** So the image's bias is modelled as ``g * sampling_bias_px(phi)``,
   ``g`` in [0, 1] (1: all blur after the sampling; ~0: an optical blur of >= 0.5 px before
   it), the same for all wires of one image (one image formation). Wires that sweep pixel
   phases show it in their residuals about their lines; :func:`phase_gain` regresses them
   on the predicted bias, over all wires at once, each wire's own offset and slope projected
   out. The phase is the fitted line's at each profile, not the noisy centre's (noise of
   ~0.05 px would blur the jump of ``beta`` where the wire's edges cross pixel boundaries and
   attenuate the regression). With ~0.05 px per centre the estimate is noisy (sigma ~0.3);
   ``g^2`` is used as its mean under a uniform prior on [0, 1] (no tuning: the physical
   range of ``g``, 1/3 if the image shows nothing).
3. **In a line.** Where a wire sits on the pixel grid is random (the film's placement), so
   the line's systematic error is treated as random over a uniform sub-pixel shift of all
   its centres: :func:`systematic_cov` gives the covariance of the errors of the line's two
   Gauss points (the points the affine is solved from), which it adds to their noise
   variance; it is close to ``g^2 beta_rms^2`` for a wire at one phase (~0.004 px for a
   2 px wire, g = 1) and vanishes for one sweeping many.

On default-realism renders of ``tests/test_wires.py``'s views (``tools/validate_wire_sigma.py``)
the regression finds g = 0.82 (noise-free renders: 0.83 +- 0.03): the renderer blurs after
the sampling, and its discrete kernel and the centroid window make the bias ~0.8 of the
sharp band's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["line_phases", "phase_gain", "sampling_bias_px", "systematic_cov"]


def sampling_bias_px(phi, width_px: float) -> np.ndarray:
    """Error (px) of the centroid of a sharp band ``width_px`` wide, centred at sub-pixel
    phase ``phi`` (pixel centres at integers), sampled by pixel coverage (method step 1).

    Each fully covered pixel weighs its centre correctly; a partly covered one (covered
    fraction ``a``) puts weight ``a`` at its centre instead of at its covered part's centroid,
    ``(1 - a) / 2`` away: the error is ``[b(1 - b) - a(1 - a)] / (2 w)`` for end fractions a
    (low side), b (high side). A function of the phase of period 1 px and zero mean, up to
    ~0.0075 px for a 2 px wire.
    """
    phi = np.asarray(phi, float)
    k = np.arange(-math.ceil(width_px) - 1, math.ceil(width_px) + 2, dtype=float)
    lo = np.maximum(k - 0.5, phi[..., None] - 0.5 * width_px)
    hi = np.minimum(k + 0.5, phi[..., None] + 0.5 * width_px)
    cov = np.clip(hi - lo, 0.0, None)
    return (cov * k).sum(axis=-1) / cov.sum(axis=-1) - phi


def line_phases(centres_px, point_px, direction_px, profile_axis: int):
    """Per centre of a fitted wire line: the sub-pixel phase along the profile axis (in
    [0, 1)) of the line's crossing of that profile, the position along the line (px, about
    ``point_px``), the centre's residual along the profile axis (px); and the line's unit
    normal's component along that axis (signed: a shift along the profile axis moves the line
    by that times it).

    ``profile_axis``: 0 if the profiles ran along rows (sampling u), 1 along columns.
    """
    c = np.asarray(centres_px, float)
    t = np.asarray(direction_px, float)
    nrm = np.array([-t[1], t[0]])
    q = c - np.asarray(point_px, float)
    cos_n = float(nrm[profile_axis])
    r = (q @ nrm) / cos_n
    x = c[:, profile_axis] - r
    return x - np.floor(x), q @ t, r, cos_n


def phase_gain(lines, width_px) -> tuple[float, float, float]:
    """How much ``g`` of the sharp band's sampling bias the image shows (method step 2).

    ``lines``: per wire, :func:`line_phases`'s ``(phi, s, r, cos_n)`` plus the rms of its
    centres about the line (px) as a fifth entry, or None (not found); ``width_px``: per
    wire, its diameter in pixels. Each wire's residuals along the profile axis are weighted
    ``cos_n^2 / rms^2``.

    Returns (g_hat, sigma of g_hat, mean of g^2 under a uniform prior on [0, 1]);
    (NaN, inf, 1/3) when no wire shows the bias.
    """
    hh, hr = 0.0, 0.0
    for line, w_px in zip(lines, width_px, strict=True):
        if line is None:
            continue
        phi, s, r, cos_n, rms = line
        h = sampling_bias_px(phi, w_px / abs(cos_n))
        A = np.column_stack([np.ones_like(s), s])
        h = h - A @ np.linalg.lstsq(A, h, rcond=None)[0]
        wt = (cos_n / max(rms, 1e-6)) ** 2
        hh += wt * float(h @ h)
        hr += wt * float(h @ r)
    if not hh > 0.0:
        return math.nan, math.inf, 1.0 / 3.0
    g_hat, sd = hr / hh, 1.0 / math.sqrt(hh)
    g = np.linspace(0.0, 1.0, 201)
    like = np.exp(-0.5 * ((g - g_hat) / sd) ** 2)
    if not like.sum() > 0.0:  # far outside [0, 1]: the nearer end
        return g_hat, sd, float(g_hat > 0.5)
    return g_hat, sd, float((g * g * like).sum() / like.sum())


def systematic_cov(phi, s, cos_n: float, width_px: float, g2: float,
                   n_shift: int = 64) -> np.ndarray:
    """(2, 2) covariance (px^2) of the errors the phase bias gives a line's two Gauss points
    (perpendicular to the line; at ``-S``, ``+S`` along it, ``S`` the rms of ``s``), for a
    bias ``g * sampling_bias_px`` with ``g^2`` of mean ``g2`` (method step 3).

    The least-squares line through centres erring by ``beta(phi_i)`` errs at ``s = +-S`` by
    ``mean[(1 +- s_i / S) beta(phi_i)]``. Over a uniform sub-pixel shift ``delta`` of all the
    line's centres (``n_shift`` steps) these errors have covariance ``g^2 mean_delta(e e^T)``.
    ``phi``, ``s``, ``cos_n`` as from :func:`line_phases`.
    """
    phi, s = np.asarray(phi, float), np.asarray(s, float)
    S = math.sqrt(float(np.mean(s ** 2)))
    w = width_px / abs(cos_n)
    k = np.arange(-math.ceil(w) - 1, math.ceil(w) + 2, dtype=float)
    e = _shift_errors(phi, s / S, w, k, n_shift)
    return g2 * (e.T @ e) / n_shift * cos_n ** 2


@numba.njit(cache=True)
def _shift_errors(phi, u, w, k, n_shift):
    """(n_shift, 2) errors ``mean[(1 -+ u_i) beta(phi_i + delta)]`` of a line's two Gauss
    points over the shifts ``delta`` (:func:`systematic_cov`; ``beta`` as
    :func:`sampling_bias_px`, summed over the pixels ``k`` in the same order)."""
    n = phi.shape[0]
    e = np.zeros((n_shift, 2))
    for a in range(n_shift):
        delta = (a + 0.5) / n_shift
        e0 = 0.0
        e1 = 0.0
        for i in range(n):
            x = phi[i] + delta
            num = 0.0
            den = 0.0
            for kk in k:
                c = min(kk + 0.5, x + 0.5 * w) - max(kk - 0.5, x - 0.5 * w)
                if c > 0.0:
                    num += c * kk
                    den += c
            beta = num / den - x
            e0 += (1.0 - u[i]) * beta
            e1 += (1.0 + u[i]) * beta
        e[a, 0] = e0 / n
        e[a, 1] = e1 / n
    return e
