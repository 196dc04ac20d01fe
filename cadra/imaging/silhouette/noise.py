"""Stage one's sigma when the image noise is correlated between nearby pixels (film grain,
a scanner's MTF): the noise's autocovariance measured beside the outline, and the covariance
it gives the edge segments' offsets (docs/stage1.md, step 5, "correlated").

Neighbouring segments share the grain at their common end; a pose fit, which sums every
offset, sees that correlation, and the offsets' residuals cannot show it (the pose absorbs
it). :func:`noise_autocovariance` measures the noise, :func:`offset_covariance` propagates it
through each pixel's influence on its segment's offset (``EdgeSegments.pixels``, kept by
:func:`cadra.imaging.silhouette.edges.stage_a`); :func:`segment_covariance` applies it to a
stage-A result and :func:`segment_correlation` normalizes that.
Pure functions of arrays (picklable inputs).
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from cadra.imaging.silhouette.edge_model import (
    _edge_profile,
    _gn_accumulate,
    _solve3_ridge,
    gn_workspace,
    pixel_terms,
)
from cadra.imaging.silhouette.edges import EdgeSegments, Outline, band_pixels, outline_geometry

__all__ = ["noise_autocovariance", "noise_lags", "offset_covariance", "segment_correlation",
           "segment_covariance"]


#: :func:`noise_autocovariance`: pixel differences beyond this many of their sigmas are
#: clutter, not noise (a Gaussian difference exceeds it with probability 2e-9)
CLIP_SIGMA = 6.0


#: :func:`noise_autocovariance`: lags (px) at which film grain and scanner blur are
#: uncorrelated, for the local mean's share
FAR_LAGS = [(9, 0), (0, 9), (6, 6), (-6, 6), (9, 3), (-3, 9)]


@numba.njit(cache=True)
def _lag_sums(res, ok, lags):
    """For each lag ``(du, dv)``: the sum of ``res[p] res[p + lag]`` and the number of pairs
    with both pixels ``ok``, over the ``ok`` pixels ``p``."""
    H, W = res.shape
    prod = np.zeros(lags.shape[0])
    cnt = np.zeros(lags.shape[0])
    for r in range(H):
        for c in range(W):
            if not ok[r, c]:
                continue
            x = res[r, c]
            for q in range(lags.shape[0]):
                r1 = r + lags[q, 1]
                c1 = c + lags[q, 0]
                if 0 <= r1 < H and 0 <= c1 < W and ok[r1, c1]:
                    prod[q] += x * res[r1, c1]
                    cnt[q] += 1.0
    return prod, cnt


def noise_lags(max_lag: int) -> list[tuple[int, int]]:
    """The pixel lags ``(du, dv)`` of a half plane with ``0 < |lag| <= max_lag``."""
    return [(du, dv) for dv in range(max_lag + 1) for du in range(-max_lag, max_lag + 1)
            if (dv > 0 or du > 0) and du * du + dv * dv <= max_lag * max_lag]


def noise_autocovariance(img: np.ndarray, geo: Outline, exclude, noise_coef,
                         max_lag: int, inner_px: float = 5.0, outer_px: float = 20.0,
                         smooth_px: float = 10.0):
    """The image noise's autocovariance at lags up to ``max_lag`` px, as
    ``acov(lag; m) = alpha + beta m^2`` (m the mean intensity), from the flat image on both
    sides of the outline (``inner_px``-``outer_px`` px outside it: the beam; as far inside:
    the shadow). Docs/stage1.md, step 5.

    Per side: the pixels minus their local mean (a ``2 smooth_px + 1`` px box over that
    side's pixels only: illumination and mottle out, the noise in), those beyond ``CLIP_SIGMA``
    robust sigmas left out (dust, scratches, flow lines); their correlation at each lag,
    less that at ``FAR_LAGS`` (the local mean removes a nearly even share of the noise's
    covariance at every short lag, ~0.02 in correlation for a 1.2 px grain, which summed over
    the lags matters), times the fitted noise model's variance at the side's median level.
    Additive correlated noise (a scanner's MTF) gives ``beta = 0``; film grain, which
    modulates the beam, ``alpha = 0``. Returns ``(lags, alpha, beta)``, or None where a side
    has too few pixels or where the fit implies a correlation beyond 1 at an intensity between
    black and the brighter side's level (the noise is then taken as white).
    """
    H, W = img.shape
    # the ring needs no precision: every 8th vertex of the outline is 8x faster
    step = max(len(geo.p0) // 128, 1)
    ring_geo = outline_geometry(geo.p0[::step]) if step > 1 else geo
    lin, d, _, _ = band_pixels(ring_geo, outer_px, img.shape)
    keep = np.abs(d) >= inner_px
    if exclude is not None:
        keep &= ~exclude.ravel()[lin]
    lags = noise_lags(max_lag)
    v0, v1, v2 = (float(x) for x in noise_coef)
    pad = max_lag + 1
    out = []
    for side in (d > 0, d < 0):
        sel = lin[keep & side]
        if len(sel) < 400:
            return None
        u, v = sel % W, sel // W
        u0, v0_ = max(u.min() - pad, 0), max(v.min() - pad, 0)
        roi = (slice(v0_, min(v.max() + pad + 1, H)), slice(u0, min(u.max() + pad + 1, W)))
        M = np.zeros(img[roi].shape, np.float32)
        M[v - v0_, u - u0] = 1.0
        Iroi = img[roi].astype(np.float32)
        k = 2 * int(round(smooth_px)) + 1
        both = cv2.boxFilter(np.dstack([Iroi * M, M]), -1, (k, k),
                             borderType=cv2.BORDER_CONSTANT)
        res = np.where(M > 0, Iroi - both[..., 0] / np.maximum(both[..., 1], 1e-6),
                       0.0).astype(np.float64)
        rv = res[M > 0]
        mad = 1.4826 * float(np.median(np.abs(rv)))
        ok = (M > 0) & (np.abs(res) <= CLIP_SIGMA * max(mad, 1e-12))
        res = np.where(ok, res, 0.0)
        var0 = float(np.sum(res**2)) / max(int(ok.sum()), 1)
        if var0 <= 0.0:
            return None
        all_lags = np.array(lags + FAR_LAGS, np.int64)
        prod, cnt = _lag_sums(res, ok, all_lags)
        if cnt.min() < 200:
            return None
        ac = list(prod / cnt / var0)
        # the local mean took a nearly constant share of every short lag's covariance: the
        # far lags, where the noise itself is uncorrelated, show it
        far = float(np.mean(ac[len(lags):]))
        rho = (np.array(ac[:len(lags)]) - far) / (1.0 - far)
        lev = float(np.median(img.ravel()[sel]))
        out.append((lev, rho * (v0 + v1 * lev + v2 * lev * lev)))
    (mb, ab), (md, ad) = out
    if mb * mb - md * md <= 1e-6:
        return None
    beta = (ab - ad) / (mb * mb - md * md)
    alpha = ad - beta * md * md
    # the line through two levels holds between them; where they are close (a faint shadow,
    # a blurred edge) its slope is mostly their noise, and extrapolated to the other
    # intensities of the outline's pixels it can exceed the noise's own variance: a
    # correlation beyond 1, no covariance at all (a segment's offset variance comes out
    # negative). Such an estimate is not used.
    m = np.linspace(0.0, max(mb, md), 33)[:, None]
    var = np.maximum(v0 + v1 * m + v2 * m * m, 1e-300)
    if np.any(np.abs(alpha + beta * m * m) > var):
        return None
    return lags, alpha, beta


def segment_covariance(seg: EdgeSegments, width: int, acov, pixel_var=None) -> np.ndarray:
    """(K, K) covariance of ``seg``'s offset errors (:func:`offset_covariance`) under the
    noise autocovariance ``acov`` (:func:`noise_autocovariance`; None: white noise), from
    stage A's final state (``seg.pixels["state"]``, kept when ``FitSettings.covariance`` is
    "correlated"). ``pixel_var(m)``: the pixels' noise variance at model intensity ``m``
    (default: the fitted noise model, ``1 / w``)."""
    st = seg.pixels["state"]
    K = len(seg.delta_px)
    infl, m = _offset_influence(*st.kernel_args())
    w_noise = st.w if pixel_var is None else 1.0 / pixel_var(m)
    return offset_covariance(st.lin, width, st.k, K, infl, w_noise, m, acov)


def segment_correlation(seg: EdgeSegments, width: int, acov) -> np.ndarray:
    """(K, K) correlation of ``seg``'s offset errors under the noise autocovariance ``acov``
    (:func:`noise_autocovariance`; None: white noise, the identity)."""
    K = len(seg.delta_px)
    if acov is None or "state" not in seg.pixels:
        return np.eye(K)
    cov = segment_covariance(seg, width, acov)
    dg = np.sqrt(np.maximum(np.diag(cov), 1e-300))
    corr = cov / np.outer(dg, dg)
    np.fill_diagonal(corr, 1.0)
    return corr


@numba.njit(cache=True)
def _offset_influence(I, d, k, K, w, L, D, delta, prof, c4, ratio, tied, rc):
    """Each pixel's influence on its segment's offset at the final state of
    :func:`_segment_fit`: ``d delta_q / d I_j`` (the offset row of the segment's Gauss-Newton
    solve, image-wide unknowns held), and the model's intensity ``m_j`` there.
    """
    n = I.shape[0]
    A, b, C, Hg, bg = gn_workspace(K, tied)
    _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, C, Hg, bg, False, tied, rc,
                   0.0)
    rows = np.empty((K, 3))
    for q in range(K):
        for i in range(3):
            e = np.zeros(3)
            e[i] = 1.0
            rows[q, i] = _solve3_ridge(A[q], e)[2]   # A symmetric: row 2 of A^-1
    infl = np.empty(n)
    m = np.empty(n)
    for j in range(n):
        kk = k[j]
        s = prof[0] + prof[2] * c4[kk]
        a = prof[1] + prof[3] * c4[kk]
        g, p, h, hp = _edge_profile(delta[kk] - d[j], s, ratio)
        m[j], c0, c1, c2 = pixel_terms(L[kk], D[kk], g, p, h, hp, a, s, ratio, tied, rc[0])
        infl[j] = w[j] * (rows[kk, 0] * c0 + rows[kk, 1] * c1 + rows[kk, 2] * c2)
    return infl, m


@numba.njit(cache=True)
def _pair_sums(u, v, k, K, infl, m, index, du, dv, alpha, beta):
    """Each pixel pair at the lags ``(du, dv)`` (offset by the index image's origin) once:
    ``sum infl_j infl_j' (alpha + beta m_j m_j')`` into (segment of j, segment of j')."""
    pairs = np.zeros((K, K))
    for j in range(u.shape[0]):
        for q in range(du.shape[0]):
            j1 = index[v[j] + dv[q], u[j] + du[q]]
            if j1 >= 0:
                pairs[k[j], k[j1]] += infl[j] * infl[j1] * (alpha[q] + beta[q] * m[j] * m[j1])
    return pairs


def offset_covariance(lin: np.ndarray, width: int, k: np.ndarray, K: int,
                      infl: np.ndarray, w: np.ndarray, m: np.ndarray, acov) -> np.ndarray:
    """Covariance (K, K) of the segment offsets' errors when the image noise is correlated
    between nearby pixels (film grain, a scanner's MTF): docs/stage1.md, step 5.

    ``acov = (lags, alpha, beta)`` (:func:`noise_autocovariance`): pixels ``j, j'`` at lag
    ``j' - j`` have noise covariance ``alpha + beta m_j m_j'``; a pixel's variance is
    ``1 / w_j`` (the fitted noise model). With ``infl`` each pixel's influence on its
    segment's offset, ``cov(delta_q, delta_r) = sum_j sum_j' infl_j infl_j' C_jj'`` over the
    pixels of q and r (``lin`` their flat indices in an image ``width`` px wide). Segments
    next to each other share the grain at their common end; a pose fit sums that.
    """
    K = int(K)
    lin = np.asarray(lin, np.int64)
    u, v = lin % width, lin // width
    white = np.diag(np.bincount(k, infl * infl / np.maximum(w, 1e-300), minlength=K))
    if acov is None or len(lin) == 0:
        return white
    lags = acov[0]
    pad = max(max(abs(du), abs(dv)) for du, dv in lags)
    u0, v0 = u.min() - pad, v.min() - pad
    index = np.full((v.max() - v0 + pad + 1, u.max() - u0 + pad + 1), -1, np.int64)
    index[v - v0, u - u0] = np.arange(len(lin))
    du = np.array([a for a, _ in lags], np.int64) - u0
    dv = np.array([b for _, b in lags], np.int64) - v0
    pairs = _pair_sums(u, v, np.asarray(k, np.int64), K, np.asarray(infl, float),
                       np.asarray(m, float), index, du, dv, np.asarray(acov[1], float),
                       np.asarray(acov[2], float))
    return white + pairs + pairs.T
