"""The two arms of a simulated yaw history by Prony's method: an independent reading of the
fast and slow modes that the tests set beside linear theory (McCoy, *Modern Exterior
Ballistics*, ch. 10), without :mod:`cadra.motion`'s epicyclic fit.

A two-arm linear motion sampled at a constant step obeys the two-term recurrence
``xi[n+2] = c1 xi[n+1] + c0 xi[n]``; its characteristic roots are ``exp(lambda_j ds)``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["fit_two_arms"]


def fit_two_arms(xi: np.ndarray, ds: float) -> tuple[np.ndarray, np.ndarray]:
    """Roots (fast, slow) per unit of the abscissa of ``xi[n+2] = c1 xi[n+1] + c0 xi[n]``
    (Prony, least squares over the whole history sampled every ``ds``) and the arms' complex
    amplitudes at the first sample: ``xi(s) = sum_j K_j exp(lambda_j s)``. Damping rate = real
    part, frequency = imaginary part; the fast arm (larger frequency) first."""
    xi = np.asarray(xi, dtype=complex)
    c = np.linalg.lstsq(np.stack([xi[1:-1], xi[:-2]], 1), xi[2:], rcond=None)[0]
    lam = np.log(np.roots([1.0, -c[0], -c[1]]).astype(complex)) / ds
    lam = lam[np.argsort(-lam.imag)]
    s = np.arange(xi.size) * ds
    K = np.linalg.lstsq(np.exp(np.outer(s, lam)), xi, rcond=None)[0]
    return lam, K
