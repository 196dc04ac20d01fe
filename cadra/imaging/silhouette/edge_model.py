"""Stage A's edge model and its least squares, compiled (docs/stage1.md, step 3).

Each band pixel ``j`` of segment ``q`` is modelled as ``m = L (1 - g) + D g + a L h`` with
``g = Phi((delta - d) / s)`` and the fringe ``h`` (:func:`_edge_profile`); the unknowns are
each segment's bright level ``L``, dark level ``D`` (or, tied, ``D = r L + c`` image-wide) and
edge offset ``delta``, and the image's edge profile ``(s0, a0, s4, a4)`` (segment q's width
``s0 + s4 c4[q]``, fringe amplitude ``a0 + a4 c4[q]``; ``c4`` the cos 4 theta of its normal's
angle to the pixel grid) with the tied level's ``(r, c)``.

:func:`_segment_fit` solves them jointly by Levenberg-Marquardt: the normal equations are
block-arrowhead (each segment's 3 unknowns couple only to the image-wide ones), so a step
costs one pass over the pixels and the Schur complement of the segments' 3x3 blocks
(:func:`_joint_solve`), and it converges in a few steps to a tolerance instead of settling
the profile by alternation. The weights are the image's noise model, refitted to the
residuals (:func:`_noise_weights`) once the fit has converged. All lengths in pixels.
"""

from __future__ import annotations

import math

import numba
import numpy as np

SQRT2PI = math.sqrt(2.0 * math.pi)

#: Largest edge width (the profile's sigma, px) stage A fits. A fit that ends there is not
#: following edges (a template far from the outline, a finned body at a wrong roll): real
#: optics at this scale blur to about 1 px.
MAX_EDGE_SIGMA_PX = 5.0

#: Normalization of the fringe profile: ``h`` peaks at +-1 (at one fringe width from the edge).
PHI1 = math.exp(-0.5) / SQRT2PI

#: Bounds on the profile's cos(4 theta) terms (the pixel's footprint: a box or a triangle of
#: one variance, so small): |s4| <= S4_MAX s0, |a4| <= max(|a0|, A4_FLOOR). Looser, sharp
#: optics fell into a false minimum (docs/stage1.md, "Sharp optics").
S4_MAX = 0.05
A4_FLOOR = 0.02
#: A step of the edge profile is bounded to this factor of the width either way: a strong
#: fringe is nearly the shape of a width change, and one step could throw the width (and
#: every offset) far off before the damping sees it.
WIDTH_STEP_FACTOR = 1.25
#: A segment's offset moves at most this far (px) in one step.
MAX_OFFSET_STEP_PX = 1.5


@numba.njit(cache=True)
def _edge_profile(x, s, ratio):
    """The edge model's shape at ``x = delta - d`` (px) for edge width ``s``: the step
    ``g = Phi(x / s)``, its derivative ``p = phi(x / s)`` (per unit x / s), the fringe
    ``h = -z_f phi(z_f) / phi(1)`` with ``z_f = x / (ratio s)`` (+1 at one fringe width
    outside the edge, -1 inside: the second derivative of a blurred step, scaled), and
    ``hp = dh / dz_f``."""
    z = x / s
    g = 0.5 * math.erfc(-z / math.sqrt(2.0))
    p = math.exp(-0.5 * z * z) / SQRT2PI
    zf = z / ratio
    pf = math.exp(-0.5 * zf * zf) / SQRT2PI
    return g, p, -zf * pf / PHI1, -(1.0 - zf * zf) * pf / PHI1


@numba.njit(cache=True)
def gn_workspace(K, tied):
    """The arrays :func:`_gn_accumulate` fills: per-segment normal equations ``A, b``, their
    coupling ``C`` to the image-wide unknowns, and those unknowns' ``Hg, bg`` (6 with a tied
    dark level, else the profile's 4)."""
    ng = 6 if tied else 4
    return (np.empty((K, 3, 3)), np.empty((K, 3)), np.empty((K, 3, ng)), np.empty((ng, ng)),
            np.empty(ng))


@numba.njit(cache=True)
def pixel_terms(Lk, Dk, g, p, h, hp, a, s, ratio, tied, r):
    """One pixel's edge model ``m = L (1 - g) + D g + a L h`` and its derivatives
    ``(c0, c1, c2)`` by the segment's L, D and offset (``tied``: D = r L + c is no unknown,
    ``c1 = 0``); ``g, p, h, hp`` from :func:`_edge_profile` at width ``s``."""
    c0 = 1.0 - g + a * h
    c1 = g
    if tied:
        c0 += r * g
        c1 = 0.0
    c2 = ((Dk - Lk) * p + a * Lk * hp / ratio) / s
    return Lk * (1.0 - g) + Dk * g + a * Lk * h, c0, c1, c2


@numba.njit(cache=True)
def _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, C, Hg, bg, want_global,
                   tied, rc, lref):
    """Gauss-Newton normal equations per segment for (L, D, delta) into ``A, b``, and (with
    ``want_global``) their coupling ``C`` (K, 3, ng) to the image-wide unknowns and those
    unknowns' own ``Hg, bg``: the edge profile ``prof = (s0, a0, s4, a4)`` and, ``tied``, the
    dark level's ``D = rc[0] L + rc[1]`` (then the D row of each segment's system is left
    empty), its ratio's column taken about the bright level ``lref`` (``D = r (L - lref) +
    c'``: every segment's L is near the beam's, and about 0 the ratio and the offset are
    nearly one direction, which a damped step crawls along). Returns sum w r^2.

    Every image-wide column is a segment's constant times one of three pixel columns
    (``d/ds = -c2 x / s``, the fringe's ``h``, the step's ``g``; times 1 or ``c4[q]``, ``L``,
    ``L - lref``): the pixels fill each segment's products of those three, and the segments
    then fill ``C``, ``Hg`` and ``bg``."""
    A[:] = 0.0
    b[:] = 0.0
    C[:] = 0.0
    Hg[:] = 0.0
    bg[:] = 0.0
    K = A.shape[0]
    ng = Hg.shape[0]
    U = np.zeros((K, 3, 3))     # sum w u u^T, u = (d m/d s, h, g)
    Ur = np.zeros((K, 3))       # sum w u r
    Uc = np.zeros((K, 3, 3))    # sum w u_i c_j (c = d m / d (L, D, delta))
    chi2 = 0.0
    for j in range(I.shape[0]):
        kk = k[j]
        s = prof[0] + prof[2] * c4[kk]
        a = prof[1] + prof[3] * c4[kk]
        x = delta[kk] - d[j]
        g, p, h, hp = _edge_profile(x, s, ratio)
        mj, c0, c1, c2 = pixel_terms(L[kk], D[kk], g, p, h, hp, a, s, ratio, tied, rc[0])
        r = I[j] - mj
        ww = w[j]
        A[kk, 0, 0] += ww * c0 * c0
        A[kk, 0, 1] += ww * c0 * c1
        A[kk, 0, 2] += ww * c0 * c2
        A[kk, 1, 1] += ww * c1 * c1
        A[kk, 1, 2] += ww * c1 * c2
        A[kk, 2, 2] += ww * c2 * c2
        b[kk, 0] += ww * c0 * r
        b[kk, 1] += ww * c1 * r
        b[kk, 2] += ww * c2 * r
        chi2 += ww * r * r
        if not want_global:
            continue
        uu = (-c2 * x / s, h, g)
        wu = (ww * uu[0], ww * h, ww * g)
        cc = (c0, c1, c2)
        for i0 in range(3):
            Ur[kk, i0] += wu[i0] * r
            for i1 in range(3):
                Uc[kk, i0, i1] += wu[i0] * cc[i1]
            for i1 in range(i0, 3):
                U[kk, i0, i1] += wu[i0] * uu[i1]
    for kk in range(K):
        if tied:
            A[kk, 1, 1] = 1.0   # D is no segment unknown: its step solves to 0
        A[kk, 1, 0] = A[kk, 0, 1]
        A[kk, 2, 0] = A[kk, 0, 2]
        A[kk, 2, 1] = A[kk, 1, 2]
    if not want_global:
        return chi2
    src = np.array([0, 1, 0, 1, 2, 2])[:ng]   # each image-wide column's pixel column
    sc = np.empty(ng)
    for kk in range(K):
        U[kk, 1, 0] = U[kk, 0, 1]
        U[kk, 2, 0] = U[kk, 0, 2]
        U[kk, 2, 1] = U[kk, 1, 2]
        Lk = L[kk]
        sc[0] = 1.0
        sc[1] = Lk
        sc[2] = c4[kk]
        sc[3] = Lk * c4[kk]
        if ng == 6:
            sc[4] = Lk - lref
            sc[5] = 1.0
        for i0 in range(ng):
            u_i = src[i0]
            bg[i0] += sc[i0] * Ur[kk, u_i]
            for c in range(3):
                C[kk, c, i0] = sc[i0] * Uc[kk, u_i, c]
            for i1 in range(i0, ng):
                Hg[i0, i1] += sc[i0] * sc[i1] * U[kk, u_i, src[i1]]
    for i0 in range(ng):
        for i1 in range(i0):
            Hg[i0, i1] = Hg[i1, i0]
    return chi2


@numba.njit(cache=True)
def _inv3_ridge(A):
    """Inverse of a symmetric 3x3 matrix (Cramer's rule) with a tiny relative ridge: a
    one-sided segment keeps its unseen level instead of making the system singular."""
    r = 1e-9 * (A[0, 0] + A[1, 1] + A[2, 2]) + 1e-15
    a00, a11, a22 = A[0, 0] + r, A[1, 1] + r, A[2, 2] + r
    a01, a02, a12 = A[0, 1], A[0, 2], A[1, 2]
    out = np.empty((3, 3))
    out[0, 0] = a11 * a22 - a12 * a12
    out[0, 1] = a02 * a12 - a01 * a22
    out[0, 2] = a01 * a12 - a02 * a11
    out[1, 1] = a00 * a22 - a02 * a02
    out[1, 2] = a01 * a02 - a00 * a12
    out[2, 2] = a00 * a11 - a01 * a01
    det = a00 * out[0, 0] + a01 * out[0, 1] + a02 * out[0, 2]
    for i in range(3):
        for j in range(i, 3):
            out[i, j] /= det
            out[j, i] = out[i, j]
    return out


@numba.njit(cache=True)
def _solve3_ridge(A, b):
    """Solve a symmetric 3x3 system with :func:`_inv3_ridge`'s ridge."""
    Ai = _inv3_ridge(A)
    out = np.empty(3)
    for i in range(3):
        out[i] = Ai[i, 0] * b[0] + Ai[i, 1] * b[1] + Ai[i, 2] * b[2]
    return out


@numba.njit(cache=True)
def _joint_solve(A, b, C, Hg, bg, lam, Y, z, free):
    """One Levenberg-Marquardt step of the joint normal equations (each diagonal times
    ``1 + lam``), by the Schur complement of the segments' 3x3 blocks: returns the step of
    the image-wide unknowns; ``z`` (K, 3) and ``Y`` (K, 3, ng) receive each block's
    ``A^-1 b`` and ``A^-1 C``, whose difference ``z - Y dg`` is the segments' step for an
    image-wide step ``dg`` (:func:`_take_step`). An image-wide unknown not ``free`` is held
    (its step 0)."""
    ng = Hg.shape[0]
    S = Hg.copy()
    t = bg.copy()
    for i in range(ng):
        S[i, i] += lam * Hg[i, i]
    Ad = np.empty((3, 3))
    for q in range(A.shape[0]):
        Ad[:] = A[q]
        for i in range(3):
            Ad[i, i] += lam * A[q, i, i]
        Ai = _inv3_ridge(Ad)
        for i in range(3):
            z[q, i] = Ai[i, 0] * b[q, 0] + Ai[i, 1] * b[q, 1] + Ai[i, 2] * b[q, 2]
            for g in range(ng):
                Y[q, i, g] = Ai[i, 0] * C[q, 0, g] + Ai[i, 1] * C[q, 1, g] + Ai[i, 2] * C[q, 2, g]
        for g0 in range(ng):
            t[g0] -= C[q, 0, g0] * z[q, 0] + C[q, 1, g0] * z[q, 1] + C[q, 2, g0] * z[q, 2]
            for g1 in range(ng):
                S[g0, g1] -= (C[q, 0, g0] * Y[q, 0, g1] + C[q, 1, g0] * Y[q, 1, g1]
                              + C[q, 2, g0] * Y[q, 2, g1])
    for i in range(ng):
        if not free[i]:
            S[i, :] = 0.0
            S[:, i] = 0.0
            S[i, i] = 1.0
            t[i] = 0.0
    tr = 0.0
    for i in range(ng):
        tr += abs(S[i, i])
    for i in range(ng):
        S[i, i] += 1e-9 * tr + 1e-15
    return np.linalg.solve(S, t)


@numba.njit(cache=True)
def _take_step(dg, z, Y, L, D, delta, prof, rc, tied, lref):
    """Apply a joint step in place: the image-wide part ``dg`` within its bounds (width by
    at most :data:`WIDTH_STEP_FACTOR`, fringe amplitude |a0| <= 0.5, the cos 4 theta terms by
    :data:`S4_MAX` and :data:`A4_FLOOR`, the tied level's ratio and offset in [-0.5, 0.95]),
    then each segment's part for the image-wide step actually taken (offsets by at most
    :data:`MAX_OFFSET_STEP_PX`); the tied level's step is in ``(r, c')`` about ``lref``
    (:func:`_gn_accumulate`). Returns the largest move of an offset or the width (px)."""
    ng = dg.shape[0]
    old = prof.copy()
    s = prof[0]
    prof[0] = min(max(s + dg[0], max(s / WIDTH_STEP_FACTOR, 0.2)),
                  min(WIDTH_STEP_FACTOR * s, MAX_EDGE_SIGMA_PX))
    prof[1] = min(max(prof[1] + dg[1], -0.5), 0.5)
    prof[2] = min(max(prof[2] + dg[2], -S4_MAX * prof[0]), S4_MAX * prof[0])
    a4 = max(abs(prof[1]), A4_FLOOR)
    prof[3] = min(max(prof[3] + dg[3], -a4), a4)
    taken = np.empty(ng)
    taken[:4] = prof - old
    if tied:
        # (r, c') about lref: r by dr, c = c' - r lref by dc' - dr lref
        r_new = min(max(rc[0] + dg[4], -0.5), 0.95)
        c_new = min(max(rc[1] + dg[5] - (r_new - rc[0]) * lref, -0.5), 0.95)
        taken[4] = r_new - rc[0]
        taken[5] = c_new - rc[1] + taken[4] * lref
        rc[0] = r_new
        rc[1] = c_new
    move = abs(taken[0])
    for q in range(L.shape[0]):
        st = z[q].copy()
        for i in range(3):
            for g in range(ng):
                st[i] -= Y[q, i, g] * taken[g]
        dd = min(max(st[2], -MAX_OFFSET_STEP_PX), MAX_OFFSET_STEP_PX)
        L[q] += st[0]
        D[q] = rc[0] * L[q] + rc[1] if tied else D[q] + st[1]
        delta[q] += dd
        move = max(move, abs(dd))
    return move


@numba.njit(cache=True)
def _model_intensities(d, k, L, D, delta, prof, c4, ratio):
    """Every pixel's model intensity ``m = L (1 - g) + D g + a L h`` at the current state
    (as :func:`pixel_terms` gives it)."""
    m = np.empty(d.shape[0])
    for j in range(d.shape[0]):
        kk = k[j]
        s = prof[0] + prof[2] * c4[kk]
        a = prof[1] + prof[3] * c4[kk]
        g, _, h, _ = _edge_profile(delta[kk] - d[j], s, ratio)
        m[j] = L[kk] * (1.0 - g) + D[kk] * g + a * L[kk] * h
    return m


@numba.njit(cache=True)
def _noise_weights(I, d, k, L, D, delta, prof, c4, ratio, w):
    """The noise model ``var = v0 + v1 m + v2 m^2`` (m the model intensity) fitted to the
    squared residuals at the current state; ``w`` receives the weights ``1 / var``, floored
    so that no pixel weighs more than 5x the average. Returns ``(v0, v1, v2)``."""
    n = I.shape[0]
    N = np.zeros((3, 3))
    rhs = np.zeros(3)
    m = _model_intensities(d, k, L, D, delta, prof, c4, ratio)
    mean_r2 = 0.0
    for j in range(n):
        mj = m[j]
        r2 = (I[j] - mj) ** 2
        mean_r2 += r2
        x = (1.0, mj, mj * mj)
        for i0 in range(3):
            rhs[i0] += x[i0] * r2
            for i1 in range(i0, 3):
                N[i0, i1] += x[i0] * x[i1]
    N[1, 0] = N[0, 1]
    N[2, 0] = N[0, 2]
    N[2, 1] = N[1, 2]
    coef = _solve3_ridge(N, rhs)
    floor = max(0.2 * mean_r2 / n, 1e-12)
    for j in range(n):
        w[j] = 1.0 / max(coef[0] + coef[1] * m[j] + coef[2] * m[j] * m[j], floor)
    return coef


@numba.njit(cache=True)
def _segment_fit(I, d, k, K, c4, prof0, ratio, coef_in, has_coef, max_iter, tol, L0, D0,
                 tied):
    """Stage A's least squares in one compiled loop (see
    :func:`cadra.imaging.silhouette.edges.stage_a`): every segment's levels and offset and
    the image-wide edge profile (and tied level), jointly by Levenberg-Marquardt
    (:func:`_joint_solve`) until no offset nor the width moves by ``tol`` px (at most
    ``max_iter`` steps), then the noise model refitted to the residuals and its weights
    (:func:`_noise_weights`). From a cold start (``has_coef`` False) the first fit is
    unweighted, with the fringe held, and two weighted ones with it free follow, each with
    the weights of the fit before; a warm start (``coef_in``, the previous pose's noise
    model) fits once, weighted. Returns the levels, offsets, each offset's
    formal variance (image-wide unknowns held), the profile, the noise model, the weights,
    the weighted chi^2 and the tied level's ``(r, c)``."""
    n = I.shape[0]
    L = np.full(K, L0)
    D = np.full(K, D0)
    cntL = np.zeros(K)
    cntD = np.zeros(K)
    sumL = np.zeros(K)
    sumD = np.zeros(K)
    for j in range(n):
        if d[j] > 2.0:
            sumL[k[j]] += I[j]
            cntL[k[j]] += 1.0
        elif d[j] < -2.0:
            sumD[k[j]] += I[j]
            cntD[k[j]] += 1.0
    for q in range(K):
        if cntL[q] > 0:
            L[q] = sumL[q] / cntL[q]
        if cntD[q] > 0:
            D[q] = sumD[q] / cntD[q]
    rc = np.array([D0 / L0 if L0 > 0.0 else 0.0, 0.0])
    if tied:
        for q in range(K):
            D[q] = rc[0] * L[q] + rc[1]
    delta = np.zeros(K)
    prof = prof0.copy()
    w = np.ones(n)
    coef = coef_in.copy()
    if has_coef:
        # warm start: the noise model at the starting state's model intensities (not the
        # pixels' own: a weight that follows a pixel's noise biases the fit), floored at a
        # fifth of the mean variance, as in the noise pass (its quadratic can dip below 0
        # mid-range: docs/stage1.md, "A strong fringe")
        m = _model_intensities(d, k, L, D, delta, prof, c4, ratio)
        vbar = 0.0
        for j in range(n):
            w[j] = coef[0] + coef[1] * m[j] + coef[2] * m[j] * m[j]
            vbar += w[j] / n
        for j in range(n):
            w[j] = 1.0 / max(w[j], 0.2 * vbar, 1e-12)
    A, b, C, Hg, bg = gn_workspace(K, tied)
    A0, b0, C0, Hg0, bg0 = gn_workspace(K, tied)
    ng = Hg.shape[0]
    Y = np.empty((K, 3, ng))
    z = np.empty((K, 3))
    free = np.ones(ng, np.bool_)
    # a cold start fits the width first, unweighted, with the fringe held: from a width far
    # off (a 2 px blur started at 0.9 px), a fringe of the wrong sign (-0.1) mimicking the
    # missing width is a nearby false minimum. That fit is only a start (to 100 tol); the
    # weights then follow the residuals twice (the second fit to 10 tol): the weighted fit's
    # answer depends on its weights, and one round of them left the width 0.0012 px from
    # where further rounds settle (0.0000 after two). Freeing the fringe makes a long first
    # step, damped from the start.
    phases = 1 if has_coef else 3
    for phase in range(phases):
        free[1] = free[3] = has_coef or phase > 0
        lam = 1e-5 if has_coef else (1e-3 if phase == 0 else 1e-2 if phase == 1 else 1e-5)
        tol_phase = tol * (1.0 if has_coef or phase == 2 else 100.0 if phase == 0 else 10.0)
        chi2 = _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, C, Hg, bg,
                              True, tied, rc, L0)
        for _ in range(max_iter):
            dg = _joint_solve(A, b, C, Hg, bg, lam, Y, z, free)
            finite = True
            for i in range(ng):
                finite = finite and math.isfinite(dg[i])
            if not finite:
                break
            Ls, Ds, ds, ps, rs = L.copy(), D.copy(), delta.copy(), prof.copy(), rc.copy()
            A0[:] = A
            b0[:] = b
            C0[:] = C
            Hg0[:] = Hg
            bg0[:] = bg
            move = _take_step(dg, z, Y, L, D, delta, prof, rc, tied, L0)
            chi2_new = _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, C, Hg,
                                      bg, True, tied, rc, L0)
            if move < tol_phase:     # converged (a step this small is taken whatever its chi^2)
                chi2 = chi2_new
                break
            if chi2_new <= chi2:
                chi2 = chi2_new
                lam = lam * 0.1 if lam > 1e-9 else 0.0
            else:                # worse: back to the last state, a shorter step
                L[:] = Ls
                D[:] = Ds
                delta[:] = ds
                prof[:] = ps
                rc[:] = rs
                A[:] = A0
                b[:] = b0
                C[:] = C0
                Hg[:] = Hg0
                bg[:] = bg0
                lam = max(10.0 * lam, 1e-4)
                if lam > 1e8:
                    break
        coef = _noise_weights(I, d, k, L, D, delta, prof, c4, ratio, w)
    chi2 = _gn_accumulate(I, d, k, w, L, D, delta, prof, c4, ratio, A, b, C, Hg, bg, False,
                          tied, rc, L0)
    scale = chi2 / max(n - (2 * K + 6 if tied else 3 * K), 1)
    var_delta = np.empty(K)
    contrast = np.abs(L - D)
    typical = np.median(contrast)
    for q in range(K):
        var_delta[q] = _inv3_ridge(A[q])[2, 2] * scale
        # a segment whose edge ran off or lost its contrast carries no information
        if abs(delta[q]) > 2.0 or contrast[q] < 0.3 * typical or not var_delta[q] > 0.0:
            var_delta[q] = np.inf
    return L, D, delta, var_delta, prof, coef, w, chi2, rc
