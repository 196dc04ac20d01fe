"""Is a fiducial wire straight along its whole length? (step 5 of :mod:`cadra.imaging.wires.fit`)

A wire is straight, so its profile centres scatter about one line with their noise alone. A
shock wave or flow line that runs within a few pixels of a wire over hundreds of pixels moves
every centre it touches by a fraction of that noise: no single profile is rejected, yet the
line moves by many of its sigmas (a bow shock in M1 M1.10 shots: docs/stage1.md, "A bow shock
along a wire"). :func:`drop_bent_stretches` finds such a stretch from the mean residuals of
blocks of centres and leaves it out. :func:`tls_line` is the wire's line fit. Lengths in pixels.
"""

from __future__ import annotations

import math

import numpy as np

#: Profiles per block of the straightness test.
BLOCK_PROFILES = 12
#: A block's mean residual beyond this many of its sigmas: the wire is not straight there.
BLOCK_T_MAX = 4.0
#: A block's sigma also allows the centroid's sub-pixel phase bias, which a slowly drifting
#: wire keeps over a block (<= ~0.0075 px, :mod:`cadra.imaging.wires.fit` step 4), so that
#: noise-free images pass.
BLOCK_SYS_PX = 0.0075
#: ... and for the profile model's centres (:mod:`cadra.imaging.wires.profile`), which carry
#: no phase bias: their formation's error, <= ~0.0015 px on a line (docs/stage1.md).
MODEL_BLOCK_SYS_PX = 0.0015
#: Stretches left out of one wire at most (:func:`drop_bent_stretches`).
MAX_STRETCHES = 2


def tls_line(pts: np.ndarray):
    """Total least-squares line: centroid, unit direction, unit normal, signed residuals."""
    m = pts.mean(axis=0)
    q = pts - m
    suu, svv, suv = float(q[:, 0] @ q[:, 0]), float(q[:, 1] @ q[:, 1]), float(q[:, 0] @ q[:, 1])
    ang = 0.5 * math.atan2(2.0 * suv, suu - svv)  # direction of largest spread
    t = np.array([math.cos(ang), math.sin(ang)])
    if abs(t[0]) >= abs(t[1]):  # a stable sign: +u, or +v for a line running down the image
        t = t if t[0] > 0 else -t
    else:
        t = t if t[1] > 0 else -t
    n = np.array([-t[1], t[0]])
    return m, t, n, q @ n


def _block_t(q: np.ndarray, starts: np.ndarray, s: float, sys_px: float) -> np.ndarray:
    """Each block's mean residual about the total least-squares line of the centres ``q``
    (in block order, the blocks beginning at ``starts``), in its sigma; ``s`` the sigma of
    one centre, ``sys_px`` a bias a block may share."""
    *_, r = tls_line(q)
    n = np.diff(np.append(starts, len(q)))
    return np.add.reduceat(r, starts) / n / np.sqrt(s * s / n + sys_px**2)


def _best_run(q: np.ndarray, starts: np.ndarray, s: float, sys_px: float,
              cost_none: float) -> tuple[int, int]:
    """The contiguous run of blocks (first block, length; ``(0, 0)``: none) whose removal
    minimizes ``sum t^2`` of the other blocks about their own total least-squares line,
    plus 2 per block removed, at least two blocks staying; ``q`` the centres in block
    order, ``cost_none`` the cost of removing none. Every run at once, from each block's
    count, sums and second moments (prefix sums over the blocks): the line of what a run
    leaves is that of the totals less the run's, with no refit."""
    nb = len(starts)
    o = q.mean(axis=0)                       # about the centres' mean: no cancellation
    x = q - o
    n = np.diff(np.append(starts, len(q))).astype(float)
    sums = np.column_stack([np.add.reduceat(c, starts) for c in
                            (x[:, 0], x[:, 1], x[:, 0] ** 2, x[:, 1] ** 2, x[:, 0] * x[:, 1])])
    stats = np.column_stack([n, sums])       # (nb, 6): n, su, sv, suu, svv, suv
    cum = np.vstack([np.zeros(6), np.cumsum(stats, axis=0)])
    first, length = (a.ravel() for a in np.meshgrid(np.arange(nb), np.arange(1, nb - 1),
                                                    indexing="xy"))
    ok = first + length <= nb
    first, length = first[ok], length[ok]    # length-major, as the ties are broken
    left = cum[-1] - (cum[first + length] - cum[first])      # what each run leaves
    N = left[:, 0]
    m = left[:, 1:3] / N[:, None]
    suu = left[:, 3] - N * m[:, 0] ** 2
    svv = left[:, 4] - N * m[:, 1] ** 2
    suv = left[:, 5] - N * m[:, 0] * m[:, 1]
    ang = 0.5 * np.arctan2(2.0 * suv, suu - svv)
    nrm = np.column_stack([-np.sin(ang), np.cos(ang)])
    centre = stats[:, 1:3] / n[:, None]      # each block's mean centre, (nb, 2)
    t = (((centre[None, :, :] - m[:, None, :]) * nrm[:, None, :]).sum(axis=2)
         / np.sqrt(s * s / n + sys_px ** 2)[None, :])
    b = np.arange(nb)[None, :]
    gone = (b >= first[:, None]) & (b < (first + length)[:, None])
    cost = np.where(gone, 0.0, t * t).sum(axis=1) + 2.0 * length
    j = int(np.argmin(cost)) if len(cost) else -1
    if j < 0 or not cost[j] < cost_none:
        return 0, 0
    return int(first[j]), int(length[j])


def drop_bent_stretches(pts: np.ndarray, keep: np.ndarray, along: np.ndarray,
                         step_px: float, sys_px: float = BLOCK_SYS_PX
                         ) -> tuple[np.ndarray, float]:
    """Leave out the stretches of a wire whose centres stray from its line together.

    One profile's clipping cannot see a bias of a fraction of its noise that a whole stretch
    shares: a shock wave or flow line running close along the wire over hundreds of pixels
    (0.1 px over 600 px of a 1,200-px wire, 10 sigma of the line, in a supersonic shot; with
    weaker lobes either side). The kept centres, ordered along the wire, are cut into blocks
    of :data:`BLOCK_PROFILES`, each with its mean residual ``t`` in its sigma (one centre's
    noise from neighbours' differences, so blind to the shared bias, plus ``sys_px``, the
    centres' own bias a block may share: :data:`BLOCK_SYS_PX` for centroids,
    :data:`MODEL_BLOCK_SYS_PX` for the profile model's centres). When a block is beyond
    :data:`BLOCK_T_MAX`, the contiguous run of blocks is removed whose removal minimizes
    ``sum t^2`` of the rest plus 2 per block removed (a block of pure noise is worth
    keeping), at least two blocks staying; up to :data:`MAX_STRETCHES` times. A straight
    wire passes untouched (no wire cut in 24 default-realism views,
    ``tests/test_wire_shock.py``; ``tools/validate_wire_sigma.py``'s 400 renders
    unchanged). Returns the new ``keep`` and the length left out (px).
    """
    keep = keep.copy()
    dropped = 0
    for _ in range(MAX_STRETCHES):
        idx = np.flatnonzero(keep)
        idx = idx[np.argsort(along[idx])]
        nb = len(idx) // BLOCK_PROFILES
        if nb < 3:
            break
        blocks = np.array_split(idx, nb)
        starts = np.cumsum([0] + [len(b) for b in blocks[:-1]])
        _, _, nrm, _ = tls_line(pts[keep])
        s = max(1.4826 / math.sqrt(2.0) * float(np.median(np.abs(np.diff(pts[idx] @ nrm)))),
                1e-6)
        t = _block_t(pts[idx], starts, s, sys_px)
        if np.max(np.abs(t)) <= BLOCK_T_MAX:
            break
        i, length = _best_run(pts[idx], starts, s, sys_px, float(t @ t))
        if length == 0:
            break
        gone = np.concatenate(blocks[i:i + length])
        keep[gone] = False
        dropped += len(gone)
    return keep, dropped * step_px
