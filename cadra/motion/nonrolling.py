"""Seed 002's angle corrections: fixed-plane angles from the horizontal and vertical angles
(eqs. 6-7) and the fixed-plane → nonrolling-axes rotation (eq. 8).

Fixed-plane axes turn with the body axis by a yaw about the fixed vertical then a pitch
(their lateral axis stays horizontal); nonrolling axes turn with the body axis with no
angular velocity along it. With ``zeta = sin beta + i sin alpha`` in each, the two differ by
a rotation about the body axis, ``zeta_NR = exp(i phi_hat) zeta_F``, with

    phi_hat(s) = ∫_{s0}^{s} sin alpha_F  d(sin beta_F)/ds / (1 - sin² beta_F) ds     (eq. 8)

(= ∫ sin theta dpsi for the yaw-then-pitch angles; tests/test_motion_nonrolling.py checks
the sign and the value against a numerically parallel-transported frame).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import cumulative_trapezoid

from cadra.motion import _checks


def fixed_plane_angles(theta_v, theta_h) -> tuple[np.ndarray, np.ndarray]:
    """(alpha_F, beta_F) from the vertical and horizontal (side- and top-view projected)
    angles, seed 002 eqs. 6-7: sin alpha_F = cos θ_H sin(atan(tan θ_V cos θ_H)),
    sin beta_F = sin θ_H. In CADRA's terms θ_V = θ_p (side view), θ_H = ψ_p (top view),
    docs/conventions.md, for a stream along +x."""
    tv = np.asarray(theta_v, float)
    th = np.asarray(theta_h, float)
    if tv.shape != th.shape:
        raise ValueError(f"theta_h: shape {th.shape} does not match theta_v's {tv.shape}")
    if not (np.all(np.isfinite(tv)) and np.all(np.isfinite(th))):
        raise ValueError("theta_v, theta_h: non-finite value")
    sa = np.cos(th) * np.sin(np.arctan(np.tan(tv) * np.cos(th)))
    return np.arcsin(sa), th.copy()


def nonrolling_angle(s, xi_f, dxi_f, s0: float | None = None) -> np.ndarray:
    """phi_hat(s) of seed 002 eq. 8 from a fixed-plane history.

    Parameters
    ----------
    s : (N,) increasing time or distance
    xi_f : (N,) complex fixed-plane angle beta_F + i alpha_F (rad), e.g. a fit's prediction
    dxi_f : (N,) its derivative with respect to ``s``
    s0 : where phi_hat = 0 (default ``s[0]``); the integral is taken on a 16x finer grid when
        ``xi_f`` and ``dxi_f`` are callables, else by the trapezoid rule on ``s``.
    """
    s = _checks.abscissa("s", s, min_points=2)
    if callable(xi_f):
        fine = np.linspace(s[0], s[-1], 16 * (s.size - 1) + 1)
        x, dx = xi_f(fine), dxi_f(fine)
        phi_f = _integral(fine, x, dx)
        phi = np.interp(s, fine, phi_f)
    else:
        x = np.asarray(xi_f, complex)
        dx = np.asarray(dxi_f, complex)
        if x.shape != s.shape or dx.shape != s.shape:
            raise ValueError("xi_f, dxi_f: lengths must match s")
        phi = _integral(s, x, dx)
    if s0 is not None:
        phi = phi - np.interp(s0, s, phi)
    return phi


def nonrolling_rate(xi_f, dxi_f) -> np.ndarray:
    """d(phi_hat)/ds, the integrand of seed 002 eq. 8, from beta_F + i alpha_F and its
    derivative."""
    b, a = np.real(xi_f), np.imag(xi_f)
    sb = np.sin(b)
    return np.sin(a) * np.cos(b) * np.real(dxi_f) / (1.0 - sb * sb)


def _integral(s, x, dx):
    return cumulative_trapezoid(nonrolling_rate(x, dx), s, initial=0.0)
