"""Find the fiducial wires in one shadowgraph and solve the image->plane affine from them.

Each wire of the view (facility reference file) is predicted in the image with the nominal
affine; intensity profiles across it are sampled every ``step_px`` along its length within
``+-search_px`` (bilinear, cv2.remap); in each profile the wire's dark line is located by a
least-squares fit of a symmetric dip ``bg + slope (s - c) - A exp(-(s - c)^2 / 2 w^2)`` (all
profiles of a wire at once, vectorized Gauss-Newton). A symmetric model fitted to a symmetric
line is unbiased whatever the line's true shape. Profiles that touch the ``exclude`` mask (the
model), that lack contrast (gaps, a missing wire) or that disagree with the others (dust,
scratches: iterative 3.5-sigma clipping of a total-least-squares line) are dropped.

The affine ``[a, b] = M [u, v, 1]`` then follows by weighted least squares from the fitted
lines' end points inside the image (two equations per wire: each mapped end point lies on the
surveyed line, :func:`cadra.facility.reference.fit_affine_to_wires`), with its covariance from
the lines' offset sigmas, so the position of any image point carries the affine's uncertainty.

Pure functions of plain arrays; results are frozen dataclasses (picklable).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numba
import numpy as np

from cadra.facility.reference import View, apply_affine

#: Fewest clean profiles for a wire to count as found.
MIN_PROFILES = 10
#: A found wire's profile centres scatter less than this about its line (px) ...
MAX_LINE_RMS_PX = 0.25
#: ... and agree over at least this fraction of its profiles inside the image.
MIN_USED_FRACTION = 0.15


@dataclass(frozen=True)
class WireFit:
    """One wire: found or not (with the reason), its fitted image line and figures."""

    name: str
    found: bool
    reason: str = ""
    point_px: tuple[float, float] = (math.nan, math.nan)      # a point on the line (mid)
    direction_px: tuple[float, float] = (math.nan, math.nan)  # unit direction
    ends_px: tuple = ()                                       # the line's ends inside the image
    n_used: int = 0
    n_rejected: int = 0
    rms_px: float = math.nan           # rms of the profile centres about the line
    sigma_offset_px: float = math.nan  # 1-sigma of the line's offset at its mid point
    residual_px: float = math.nan      # mean distance of its mapped ends from the surveyed line
    residual_m: float = math.nan


@dataclass(frozen=True, eq=False)
class WireMeasurement:
    """All wires of one image and the affine solved from them."""

    ok: bool
    reason: str
    affine: np.ndarray | None
    affine_cov: np.ndarray | None     # 6x6 covariance of the affine's entries (row-major)
    wires: tuple[WireFit, ...]
    affine_rms_m: float
    affine_rms_px: float
    n_found: int

    def position_sigma_m(self, uv) -> np.ndarray:
        """1-sigma (a, b) in metres of the affine's image of pixel ``uv`` from its uncertainty."""
        if self.affine_cov is None:
            return np.full(2, np.nan)
        u, v = float(uv[0]), float(uv[1])
        J = np.zeros((2, 6))
        J[0, :3] = (u, v, 1.0)
        J[1, 3:] = (u, v, 1.0)
        return np.sqrt(np.diag(J @ self.affine_cov @ J.T))


@numba.njit(cache=True)
def _dip_kernel(P, S, c, w, bg, b1, A, h, n_iter):
    """Per-row Gauss-Newton (Levenberg-damped) of the bar model; updates c, w, bg, b1, A in
    place and returns the residual rms per row."""
    n, k = P.shape
    r2 = math.sqrt(2.0)
    r2pi = 1.0 / math.sqrt(2.0 * math.pi)
    J = np.empty(5)
    JtJ = np.empty((5, 5))
    Jtr = np.empty(5)
    r = np.empty(k)
    rms = np.empty(n)
    for i in range(n):
        for it in range(n_iter + 1):
            ss = 0.0
            JtJ[:] = 0.0
            Jtr[:] = 0.0
            for j in range(k):
                x = S[i, j] - c[i]
                zp = (x + h) / w[i]
                zm = (x - h) / w[i]
                e = 0.5 * (math.erfc(-zp / r2) - math.erfc(-zm / r2))
                gp = r2pi * math.exp(-0.5 * zp * zp)
                gm = r2pi * math.exp(-0.5 * zm * zm)
                r[j] = P[i, j] - (bg[i] + b1[i] * x - A[i] * e)
                ss += r[j] * r[j]
                aw = A[i] / w[i]
                J[0] = 1.0
                J[1] = x
                J[2] = -e
                J[3] = -b1[i] + aw * (gp - gm)
                J[4] = aw * (gp * zp - gm * zm)
                for a in range(5):
                    Jtr[a] += J[a] * r[j]
                    for b in range(a, 5):
                        JtJ[a, b] += J[a] * J[b]
            rms[i] = math.sqrt(ss / k)
            if it == n_iter:
                break
            for a in range(5):
                JtJ[a, a] += 1e-6 * JtJ[a, a] + 1e-12
                for b in range(a):
                    JtJ[a, b] = JtJ[b, a]
            step = np.linalg.solve(JtJ, Jtr)
            bg[i] += step[0]
            b1[i] += step[1]
            A[i] += step[2]
            c[i] += min(max(step[3], -1.0), 1.0)
            w[i] = min(max(w[i] + step[4], 0.2), 4.0)
    return rms


def _fit_dips(P: np.ndarray, s: np.ndarray, c0: np.ndarray, half_width: float,
              n_iter: int = 6):
    """Gauss-Newton fit of a blurred opaque bar on a sloped background to each row of P::

        bg + b1 (s - c) - A [Phi((s - c + h) / w) - Phi((s - c - h) / w)]

    with the bar's half-width h known (the surveyed wire diameter) and the blur w fitted
    (``s`` per row: (n, k) sample positions). Returns c, A, w, bg, rms, ok."""
    P = np.ascontiguousarray(P, dtype=np.float64)
    S = np.ascontiguousarray(s, dtype=np.float64)
    n = len(P)
    c = np.asarray(c0, dtype=np.float64).copy()
    w = np.full(n, 0.8)
    bg = 0.5 * (P[:, :2].mean(axis=1) + P[:, -2:].mean(axis=1))
    b1 = np.zeros(n)
    A = np.maximum(bg - P.min(axis=1), 1e-3)
    rms = _dip_kernel(P, S, c, w, bg, b1, A, float(half_width), int(n_iter))
    ok = (np.isfinite(c) & np.isfinite(A) & np.isfinite(bg) & np.isfinite(rms)
          & (np.abs(c - c0) < 3.0) & (w < 3.9))
    return c, A, w, bg, rms, ok


def _tls_line(pts: np.ndarray):
    m = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - m, full_matrices=False)
    t = vt[0]
    n = np.array([-t[1], t[0]])
    return m, t, n, (pts - m) @ n


def _measure_one(img32, wire_name, seg, shape, exclude, search_px, step_px, half_window,
                 wire_width_px):
    H, W = shape
    p0, p1 = np.asarray(seg[0], float), np.asarray(seg[1], float)
    length = float(np.hypot(*(p1 - p0)))
    t = (p1 - p0) / length
    n = np.array([-t[1], t[0]])
    margin = 6.0
    along = np.arange(margin, length - margin, step_px)
    if len(along) < MIN_PROFILES:
        return WireFit(wire_name, False, f"wire {wire_name!r} not found: its predicted path "
                                         f"crosses only {length:.0f} px of the image")
    # profiles along the image axis closest to the wire's normal, through pixel centres: no
    # interpolation (bilinear sampling across a 2-px line biases its centre by ~0.02 px)
    s = np.arange(-round(search_px), round(search_px) + 1, 1.0)
    ax = 0 if abs(n[0]) >= abs(n[1]) else 1          # 0: profiles along u (a near-vertical wire)
    other = 1 - ax
    pts_along = p0 + along[:, None] * t
    fixed = np.rint(pts_along[:, other])
    limit = (H if other == 1 else W) - 1
    fixed = np.unique(fixed[(fixed >= 0) & (fixed <= limit)])
    # predicted crossing of the wire with each fixed row/column
    pred = p0[ax] + (fixed - p0[other]) * (t[ax] / t[other])
    base = np.rint(pred)
    centres = np.empty((len(fixed), 2))
    centres[:, ax] = base
    centres[:, other] = fixed
    n = np.zeros(2)
    n[ax] = 1.0
    grid = centres[:, None, :] + s[None, :, None] * n
    gi = np.clip(np.rint(grid).astype(int), 0, [W - 1, H - 1])
    prof = img32[gi[..., 1], gi[..., 0]]
    inside = ((grid[..., 0] >= 0) & (grid[..., 0] <= W - 1) & (grid[..., 1] >= 0)
              & (grid[..., 1] <= H - 1)).all(axis=1)
    # coarse: smoothed minimum, then the wire's common offset (median) to reject strays
    sm = (np.roll(prof, 1, axis=1) + 2 * prof + np.roll(prof, -1, axis=1)) / 4.0
    imin = np.argmin(sm[:, 2:-2], axis=1) + 2
    bgp = np.partition(prof, int(0.8 * prof.shape[1]), axis=1)[:, int(0.8 * prof.shape[1])]
    depth = bgp - sm[np.arange(len(sm)), imin]
    strong = depth > 0.5 * np.median(depth[inside]) if inside.any() else depth > 0
    if strong.sum() >= MIN_PROFILES:
        off = float(np.median(s[imin[strong]]))
    else:
        off = 0.0
    # coarse line through the profiles' minima (robust), then a window of +-half_window px
    # centred on it in every profile, so the window sits symmetrically about the line
    rows = np.arange(len(prof))
    sel = strong & inside if (strong & inside).sum() >= MIN_PROFILES else inside
    coarse = s[imin]
    q = np.polyfit(centres[sel, 1 - ax], coarse[sel], 1) if sel.sum() >= 3 else (0.0, off)
    for _ in range(3):
        pred_c = np.polyval(q, centres[:, 1 - ax])
        good = sel & (np.abs(coarse - pred_c) < 2.0)
        if good.sum() < 3:
            break
        q = np.polyfit(centres[good, 1 - ax], coarse[good], 1)
    pred_c = np.polyval(q, centres[:, 1 - ax])
    k0 = np.clip(np.rint(pred_c - s[0]).astype(int), half_window, len(s) - half_window - 1)
    idx = k0[:, None] + np.arange(-half_window, half_window + 1)[None, :]
    P = prof[rows[:, None], idx]
    S = s[idx]
    half_w = 0.5 * wire_width_px
    c, A, w, bg, rms, ok = _fit_dips(P, S, pred_c, half_w)
    off = float(np.median(pred_c))
    contrast_ok = (A > 0.25 * np.maximum(bg, 1e-3)) & (A < 1.5 * np.maximum(bg, 1e-3))
    use = ok & inside & contrast_ok
    if exclude is not None:
        offs = off + np.arange(-half_window - 1.0, half_window + 1.5, 1.0)
        ends = np.rint(centres[:, None, :] + offs[None, :, None] * n).astype(int)
        ends[..., 0] = np.clip(ends[..., 0], 0, W - 1)
        ends[..., 1] = np.clip(ends[..., 1], 0, H - 1)
        touched = exclude[ends[..., 1], ends[..., 0]].any(axis=1)
        use &= ~touched
    n_bad_contrast = int((inside & ~contrast_ok).sum())
    if use.sum() < MIN_PROFILES:
        frac = n_bad_contrast / max(int(inside.sum()), 1)
        return WireFit(wire_name, False, f"wire {wire_name!r} not found: too few clean "
                                         f"profiles ({int(use.sum())} < {MIN_PROFILES}; no "
                                         f"dark line along {frac:.0%} of its predicted path)",
                       n_rejected=int(len(use) - use.sum()))
    pts = centres + c[:, None] * n
    keep = use.copy()
    for _ in range(5):
        m, tt, nn, res = _tls_line(pts[keep])
        full = (pts - m) @ nn
        mad = 1.4826 * np.median(np.abs(res - np.median(res)))
        new = use & (np.abs(full) <= 3.5 * max(mad, 1e-4))
        if new.sum() == keep.sum() and np.all(new == keep):
            break
        if new.sum() < MIN_PROFILES:
            break
        keep = new
    m, tt, nn, res = _tls_line(pts[keep])
    k = int(keep.sum())
    rms_px = float(np.sqrt(np.mean(res ** 2)))
    n_inside = max(int(inside.sum()), 1)
    if rms_px > MAX_LINE_RMS_PX or k < MIN_USED_FRACTION * n_inside:
        return WireFit(wire_name, False, f"wire {wire_name!r} not found: no straight dark "
                                         f"line along its predicted path ({k} of {n_inside} "
                                         f"profiles agree, scatter {rms_px:.2f} px)",
                       n_rejected=int(len(use) - k))
    # offset sigma at the mid point: Newey-West over the profiles in order along the wire
    # (lags up to ~60 px), since the illumination's mottle correlates neighbouring profiles
    order = np.argsort((pts[keep] - m) @ tt)
    rr = res[order]
    lags = min(10, k - 2)
    s_nw = float(rr @ rr)
    for lag in range(1, lags + 1):
        s_nw += 2.0 * (1.0 - lag / (lags + 1.0)) * float(rr[:-lag] @ rr[lag:])
    sigma_off = math.sqrt(max(s_nw, float(rr @ rr)) / max(k - 2, 1) / k)
    # the fitted line's ends inside the image (along the predicted path)
    a0 = (centres[keep][0] - m) @ tt
    a1 = (centres[keep][-1] - m) @ tt
    ends = (tuple(m + a0 * tt), tuple(m + a1 * tt))
    return WireFit(wire_name, True, "", (float(m[0]), float(m[1])),
                   (float(tt[0]), float(tt[1])), ends, k, int(len(use) - k), rms_px, sigma_off)


def measure_wires(image: np.ndarray, view: View, exclude: np.ndarray | None = None,
                  search_px: float = 30.0, step_px: float = 12.0,
                  half_window: int = 6) -> WireMeasurement:
    """Find every wire of ``view`` in ``image`` and solve the affine (module docstring).

    ``image``: float (H, W) in [0, 1]. ``exclude``: True where pixels must not be used (the
    model). Never raises for bad data: a wire not found carries its reason, and fewer than
    three wires (or wires in one direction only) give ``ok = False`` with the reason.
    """
    img32 = np.ascontiguousarray(image, dtype=np.float32)
    shape = img32.shape
    fits = []
    for w, seg in zip(view.wires, view.wire_lines_px(), strict=True):
        if seg is None:
            fits.append(WireFit(w.name, False, f"wire {w.name!r} is not in this view's image"))
            continue
        fits.append(_measure_one(img32, w.name, seg, shape, exclude, search_px, step_px,
                                 half_window, w.diameter_m / view.scale_m_per_px))
    found = [f for f in fits if f.found]
    if len(found) < 3:
        missing = ", ".join(repr(f.name) for f in fits if not f.found)
        return WireMeasurement(False, f"only {len(found)} of {len(fits)} wires found "
                                      f"(missing {missing}); at least 3 are needed for the "
                                      f"image->plane map", None, None, tuple(fits), math.nan,
                               math.nan, len(found))
    M, cov, under = _solve_affine(view, fits)
    if M is None:
        return WireMeasurement(False, "wires cannot determine the image->plane map", None,
                               None, tuple(fits), math.nan, math.nan, len(found))
    scale = math.sqrt(abs(np.linalg.det(M[:, :2])))
    updated = []
    k = 0
    for (a0, a1), f in zip(view.wire_lines_plane(), fits, strict=True):
        if not f.found:
            updated.append(f)
            continue
        d = a1 - a0
        nrm = np.array([-d[1], d[0]]) / np.hypot(d[0], d[1])
        ab = apply_affine(M, np.array(f.ends_px))
        r = float(np.mean((ab - a0) @ nrm))
        updated.append(WireFit(**{**f.__dict__, "residual_m": r, "residual_px": r / scale}))
        k += 1
    rms_m = float(np.sqrt(np.mean(np.array([u.residual_m for u in updated if u.found]) ** 2)))
    reason = ""
    if under:
        reason = (f"only one wire across the {under}: that scale comes from the facility's "
                  f"nominal map (prior), positions in metres are less certain")
    return WireMeasurement(True, reason, M, cov, tuple(updated), rms_m, rms_m / scale,
                           len(found))


#: Prior 1-sigma of the image->plane map about the facility's nominal one, for directions the
#: wires leave undetermined: relative scale / rotation of the linear part, and shift in px.
PRIOR_LINEAR_REL = 2e-3
PRIOR_SHIFT_PX = 12.0


def _solve_affine(view: View, fits):
    """Weighted least squares of the affine from the found wires' end points, with a weak
    prior toward the nominal map (it only matters where the wires leave a direction free,
    e.g. a single wire across the range). Returns (M, cov 6x6, name of an under-determined
    direction or "")."""
    M0 = np.asarray(view.image_to_plane, float)
    s = view.scale_m_per_px
    rows, rhs, wts = [], [], []
    dirs = {0: 0, 1: 0}
    for (a0, a1), f in zip(view.wire_lines_plane(), fits, strict=True):
        if not f.found:
            continue
        d = a1 - a0
        nrm = np.array([-d[1], d[0]]) / np.hypot(d[0], d[1])
        dirs[int(abs(nrm[1]) > abs(nrm[0]))] += 1
        for (u, v) in f.ends_px:
            rows.append(np.concatenate([nrm[0] * np.array([u, v, 1.0]),
                                        nrm[1] * np.array([u, v, 1.0])]))
            rhs.append(nrm @ a0)
            # the two ends share the line's offset error (and the slope error): sqrt(2) x
            wts.append(1.0 / (math.sqrt(2.0) * max(f.sigma_offset_px, 1e-4) * s) ** 2)
    if not rows:
        return None, None, ""
    X, y, Wt = np.array(rows), np.array(rhs), np.array(wts)
    prior_sd = np.array([PRIOR_LINEAR_REL * s, PRIOR_LINEAR_REL * s, PRIOR_SHIFT_PX * s] * 2)
    m0 = M0.reshape(-1)
    col = np.array([1e-3, 1e-3, 1.0, 1e-3, 1e-3, 1.0])
    Xs = X * col
    info = Xs.T @ (Xs * Wt[:, None]) + np.diag((col / prior_sd) ** 2)
    rhs_vec = Xs.T @ (Wt * y) + (col / prior_sd) ** 2 * (m0 / col)
    try:
        ms = np.linalg.solve(info, rhs_vec)
    except np.linalg.LinAlgError:
        return None, None, ""
    M = (ms * col).reshape(2, 3)
    cov = np.linalg.inv(info) * np.outer(col, col)
    under = []
    if dirs[0] < 2:
        under.append("range (x scale)")
    if dirs[1] < 2:
        under.append("view's second axis (its scale)")
    return M, cov, " and ".join(under)


def wire_mask(view: View, affine: np.ndarray, shape: tuple[int, int],
              half_width_px: float = 4.0) -> np.ndarray:
    """True on pixels within ``half_width_px`` of any wire's image (through ``affine``)."""
    mask = np.zeros(shape, np.uint8)
    for seg, w in zip(view.wire_lines_px(affine=affine, margin_px=10.0), view.wires,
                      strict=True):
        if seg is None:
            continue
        half = half_width_px + 0.5 * w.diameter_m / view.scale_m_per_px
        p0, p1 = np.array(seg[0]), np.array(seg[1])
        t = (p1 - p0) / np.hypot(*(p1 - p0))
        n = np.array([-t[1], t[0]]) * half
        poly = np.array([p0 + n, p1 + n, p1 - n, p0 - n])
        cv2.fillConvexPoly(mask, np.rint(poly * 16).astype(np.int32), 1, cv2.LINE_8, 4)
    return mask.astype(bool)
