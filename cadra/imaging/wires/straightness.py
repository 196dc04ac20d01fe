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


def _block_t(pts: np.ndarray, mask: np.ndarray, order: np.ndarray, starts: np.ndarray,
             s: float, sys_px: float) -> np.ndarray:
    """Each block's mean residual about the total least-squares line of ``pts[mask]``, in
    its sigma, for the blocks inside ``mask``; the blocks are ``order``'s runs beginning at
    ``starts`` (a block is wholly in or out); ``s`` the sigma of one centre, ``sys_px`` a
    bias a block may share."""
    m, _, nrm, _ = tls_line(pts[mask])
    r = (pts[order] - m) @ nrm
    n = np.diff(np.append(starts, len(order)))
    inside = mask[order[starts]]
    mean = np.add.reduceat(r, starts)[inside] / n[inside]
    return mean / np.sqrt(s * s / n[inside] + sys_px**2)


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
        t = _block_t(pts, keep, idx, starts, s, sys_px)
        if np.max(np.abs(t)) <= BLOCK_T_MAX:
            break
        best = (float(t @ t), 0, 0)  # (cost, first block, length)
        for length in range(1, nb - 1):
            for i in range(nb - length + 1):
                mask = keep.copy()
                mask[np.concatenate(blocks[i:i + length])] = False
                t = _block_t(pts, mask, idx, starts, s, sys_px)
                cost = float(t @ t) + 2.0 * length
                if cost < best[0]:
                    best = (cost, i, length)
        _, i, length = best
        if length == 0:
            break
        gone = np.concatenate(blocks[i:i + length])
        keep[gone] = False
        dropped += len(gone)
    return keep, dropped * step_px
