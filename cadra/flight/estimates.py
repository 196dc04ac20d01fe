"""What linear theory reads from a shot's measurements, before any fit.

No guru needed: each shot's measurements give

- the reference point's position and velocity at the epoch (quadratic fits of x, y, z
  against time, :func:`kinematics_at_epoch`);
- the drag coefficient, from the deceleration (drag-only closed form
  ``x = x0 + ln(1 + k V0 t) / k`` with ``k = rho S C_D / 2m``);
- the pitch (and yaw) frequency and the amplitude trend, from a damped-sinusoid fit of theta
  and psi with a quadratic trend (variable projection over omega and lambda), which linear
  theory turns into C_m_alpha and C_mq + C_m_alpha_dot
  (:func:`cadra.motion.planar_coefficients`, the one home of that conversion);
- the mean and rms angle between the measured axis and the flight direction.

:class:`MotionEstimate` carries them; :mod:`cadra.flight.starts` adds the epicyclic fit's
estimates for a spinning body, and :func:`cadra.fitting.start.starting_model` maps them onto a
model's parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares, minimize

from cadra.conventions import axis_from_inclinations
from cadra.flight.data import CHANNELS, ShotData

#: the axis-inclination channels (columns of ``ShotData.meas``)
_THETA, _PSI = CHANNELS.index("theta"), CHANNELS.index("psi")


@dataclass(frozen=True)
class MotionEstimate:
    """Linear-theory estimates of one shot (SI)."""

    shot_id: str
    speed_m_s: float
    mach: float
    dynamic_pressure_pa: float
    cd: float
    omega_pitch_rad_s: float      # NaN if no angles / no oscillation found
    lambda_pitch_1_s: float
    omega_yaw_rad_s: float
    lambda_yaw_1_s: float
    sigma_mean_rad: float         # mean angle between the measured axis and the velocity
    sigma_rms_rad: float
    #: linear-theory moment coefficients found another way (per rad; NaN: none), used by
    #: :func:`starting_model` before the frequency and damping above: the epicyclic fit's
    #: arms give them for a spinning body, whose pitch frequency alone does not
    #: (:func:`cadra.flight.starts.epicyclic_estimates`)
    cm_alpha: float = math.nan
    cmq_sum: float = math.nan     # C_mq + C_m_alpha_dot
    #: the spin about the axis (rad/s; NaN: not known), which the images do not show; the
    #: epicyclic arms give it as (omega_1 + omega_2) I / I_x. The starting state spins at it
    #: (a gyroscopically stable body started without spin tumbles)
    spin_rad_s: float = math.nan
    #: the nose axis's rate of turn at the epoch, facility frame (1/s; None: from the
    #: measured angles' local slope), from the epicyclic arms when a spin put them in their
    #: frequency bands: on a spark range the fast arm turns more than once between stations,
    #: which no local slope sees (:func:`cadra.flight.starts.epicyclic_estimates`)
    axis_rate_F: tuple[float, float, float] | None = None
    #: the nose axis's inclinations (theta, psi) at the epoch from the same arms (rad; None:
    #: from the measured angles' local fit, which averages an aliased arm away)
    axis_angles: tuple[float, float] | None = None
    #: the cg's lateral position (y, z, m) and velocity (vy, vz, m/s) at the epoch from the
    #: same arms' swerve (None: from polynomials in time, which miss a swerve of millimetres
    #: and half a metre a second at the slow arm's frequency)
    cg_lateral: tuple[float, float] | None = None
    cg_lateral_velocity: tuple[float, float] | None = None
    #: the reference point's downrange speed at the epoch from a cubic in time (m/s; NaN:
    #: the quadratic's), for the same long records
    vx_m_s: float = math.nan
    #: what the start did about aliased arms ("" when nothing)
    alias_note: str = ""
    #: the lift slope C_Lα the swerve gives (per rad; NaN: none), with a known spin's arms
    cl_alpha: float = math.nan
    #: the nose axis's rate of turn at the epoch, facility frame (1/s; None: from the
    #: measured angles' local slope), from the epicyclic arms when a spin put them in their
    #: frequency bands: on a spark range the fast arm turns more than once between stations,
    #: which no local slope sees (:func:`cadra.flight.starts.epicyclic_estimates`)
    axis_rate_F: tuple[float, float, float] | None = None
    #: what the start did about aliased arms ("" when nothing)
    alias_note: str = ""


def polyfit_finite(t, v, deg, w=None):
    ok = np.isfinite(v)
    deg = min(deg, max(int(ok.sum()) - 1, 0))
    return np.polyfit(t[ok], v[ok], deg, w=None if w is None else w[ok])


def kinematics_at_epoch(shot: ShotData, cubic_x: bool = False):
    """Reference-point position and velocity at the epoch: quadratics in time; with
    ``cubic_x``, for x a cubic where the record shows one (its coefficient more than 5 sigma
    from zero: over a long record the drag changes the deceleration, and a quadratic then
    misses the speed at a mid-record epoch by half a metre a second over the spark range's
    96 m). Not the default: on a short record of a lifting body the deceleration follows the
    yaw, which a cubic does not describe either, and the quadratic starts better there."""
    t = shot.t_s
    t0 = t[shot.epoch_index]
    tt = t - t0
    if np.isfinite(shot.meas[:, 0]).sum() < 3:
        raise ValueError(f"{shot.shot_id}: fewer than 3 stations with a position: no starting "
                         "values can be estimated")
    pos = np.zeros(3)
    vel = np.zeros(3)
    for j in range(3):
        c = (_cubic_if_shown(tt, shot.meas[:, j], shot.sigma[:, j]) if j == 0 and cubic_x
             else None)
        if c is None:
            c = polyfit_finite(tt, shot.meas[:, j], 2)
        pos[j] = np.polyval(c, 0.0)
        vel[j] = np.polyval(np.polyder(c), 0.0)
    return pos, vel


def _cubic_if_shown(t, v, sigma, n_sigma: float = 5.0):
    """A cubic in ``t`` fitted to ``v`` (weights 1/sigma) when its cubic coefficient is more
    than ``n_sigma`` sigmas from zero, else None."""
    ok = np.isfinite(v) & np.isfinite(sigma) & (sigma > 0)
    if ok.sum() < 8:
        return None
    w = 1.0 / sigma[ok]
    scale = max(float(np.max(np.abs(t[ok]))), 1e-12)
    A = np.vander(t[ok] / scale, 4) * w[:, None]
    c, *_ = np.linalg.lstsq(A, v[ok] * w, rcond=None)
    cov = np.linalg.pinv(A.T @ A)
    if not abs(c[0]) > n_sigma * np.sqrt(max(cov[0, 0], 0.0)):
        return None
    return c / scale ** np.arange(3, -1, -1)


def _drag_k(shot: ShotData) -> tuple[float, float]:
    """k = rho S C_D / 2m from x(t) (drag-only closed form); returns (k, V at first station)."""
    t = shot.t_s - shot.t_s[0]
    x = shot.meas[:, 0]
    ok = np.isfinite(x)
    t, x = t[ok], x[ok]
    c = np.polyfit(t, x, 2)
    V0 = c[1]
    k0 = max(-2 * c[0] / V0**2, 1e-6)

    def res(p):
        x0, v0, k = p
        return x0 + np.log1p(k * v0 * t) / k - x

    sol = least_squares(res, [c[2], V0, k0], x_scale=[1e-3, 1.0, k0])
    return float(sol.x[2]), float(sol.x[1])


def _sine_gain(a11: float, a12: float, a22: float, b1: float, b2: float) -> float:
    """The sum of squares the least squares ``a C + b S`` removes from ``v``, from the
    products ``a11 = C.C``, ``a12 = C.S``, ``a22 = S.S``, ``b1 = C.v``, ``b2 = S.v``: the 2x2
    normal equations in closed form; a pair that is nearly one direction counts as its
    better single column."""
    det = a11 * a22 - a12 * a12
    if det > 1e-12 * (a11 + a22) ** 2:
        return (a22 * b1 * b1 - 2.0 * a12 * b1 * b2 + a11 * b2 * b2) / det
    return max(b1 * b1 / a11 if a11 > 0 else 0.0, b2 * b2 / a22 if a22 > 0 else 0.0)


def _damped_sine(t: np.ndarray, v: np.ndarray) -> tuple[float, float, float]:
    """(omega, lambda, relative residual) of ``v(t) = poly2 + e^(lambda t)(A cos + B sin)``.

    Variable projection: the quadratic is projected out once (an orthonormal basis of its
    span), and for each (omega, lambda) the sine pair's least squares is a 2x2 solve in
    closed form; omega is first found on a grid up to the sampling's Nyquist frequency (all
    of the grid at once), then refined with lambda by Nelder-Mead.
    """
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 7 or np.ptp(v) == 0:
        return math.nan, math.nan, math.nan
    t = t - t.mean()
    dt = np.median(np.diff(t))
    w_max = 0.95 * math.pi / dt
    Q, _ = np.linalg.qr(np.column_stack([np.ones_like(t), t, t * t]))

    def perp(X):
        """``X`` without its part in the quadratic's span (rows: samples)."""
        return X - Q @ (Q.T @ X)

    r0 = perp(v)
    rss0 = float(r0 @ r0)

    def cost(p):
        w, lam = p
        e = np.exp(lam * t)
        X = perp(np.column_stack([e * np.cos(w * t), e * np.sin(w * t)]))
        (a11, a12), (_, a22) = (X.T @ X).tolist()
        return max(rss0 - _sine_gain(a11, a12, a22, *(r0 @ X).tolist()), 0.0)

    span = t[-1] - t[0]
    grid = np.linspace(2 * math.pi / span, w_max, 400)
    wt = t[:, None] * grid[None, :]
    C, S = perp(np.cos(wt)), perp(np.sin(wt))
    products = zip(*(x.tolist() for x in (np.sum(C * C, axis=0), np.sum(C * S, axis=0),
                                           np.sum(S * S, axis=0), r0 @ C, r0 @ S)), strict=True)
    w0 = grid[int(np.argmax([_sine_gain(*x) for x in products]))]
    sol = minimize(cost, [w0, 0.0], method="Nelder-Mead",
                   options={"xatol": 1e-4, "fatol": 1e-14, "maxiter": 400})
    w, lam = sol.x
    rel = math.sqrt(sol.fun / max(rss0, 1e-300))
    if rel > 0.7 or not (0 < w < w_max):
        return math.nan, math.nan, rel
    return abs(float(w)), float(lam), rel


def estimate_motion(shot: ShotData) -> MotionEstimate:
    """Linear-theory estimates of one shot (see module doc)."""
    rig = shot.rigid
    if rig.mode.kind != "range":
        return _estimate_in_stream(shot)
    k, V0 = _drag_k(shot)
    pos, vel = kinematics_at_epoch(shot)
    V = float(np.linalg.norm(vel))
    qdyn = 0.5 * rig.density_kg_m3 * V * V
    cd = 2 * rig.mass_kg * k / (rig.density_kg_m3 * rig.area_m2)
    # total angle: between the measured axis and the local flight direction
    tt = shot.t_s - shot.t_s[shot.epoch_index]
    dpos = [np.polyder(polyfit_finite(tt, shot.meas[:, j], 2)) for j in range(3)]
    wp, lp, wy, ly, sig_mean, sig_rms = _angle_motion(
        shot, lambda i: np.array([np.polyval(d, tt[i]) for d in dpos]))
    return MotionEstimate(shot.shot_id, V, V / rig.speed_of_sound_m_s, qdyn, float(cd), wp, lp,
                          wy, ly, sig_mean, sig_rms)


def _angle_motion(shot: ShotData, direction):
    """Pitch and yaw frequencies and damping rates (damped sines of theta and psi), and the
    mean and rms total angle between the measured axis and ``direction(i)`` (the air's
    direction relative to the model at station i, any length). NaN rates and zero angles
    for a shot without angles."""
    wp = lp = wy = ly = math.nan
    sig_mean = sig_rms = 0.0
    if not shot.has_angles:
        return wp, lp, wy, ly, sig_mean, sig_rms
    t = shot.t_s
    wp, lp, _ = _damped_sine(t, shot.meas[:, _THETA])
    wy, ly, _ = _damped_sine(t, shot.meas[:, _PSI])
    sig = []
    for i in range(len(t)):
        th, ps = shot.meas[i, _THETA], shot.meas[i, _PSI]
        if not (np.isfinite(th) and np.isfinite(ps)):
            continue
        a = axis_from_inclinations(th, ps)
        v = direction(i)
        sig.append(math.acos(np.clip(a @ v / np.linalg.norm(v), -1, 1)))
    if sig:
        sig = np.array(sig)
        sig_mean = float(sig.mean())
        sig_rms = float(np.sqrt(np.mean(sig**2)))
    return wp, lp, wy, ly, sig_mean, sig_rms


def _estimate_in_stream(shot: ShotData) -> MotionEstimate:
    """:func:`estimate_motion` of a wind-tunnel record (cadra.dynamics.modes): the speed is
    the stream's, the drag is not estimated (a mounted model shows none; a released one
    drifts a little), the total angle is between the axis and the stream (+x)."""
    rig = shot.rigid
    V = rig.mode.stream_m_s
    qdyn = 0.5 * rig.density_kg_m3 * V * V
    stream = np.array([1.0, 0.0, 0.0])
    wp, lp, wy, ly, sig_mean, sig_rms = _angle_motion(shot, lambda i: stream)
    return MotionEstimate(shot.shot_id, V, V / rig.speed_of_sound_m_s, qdyn, math.nan, wp, lp,
                          wy, ly, sig_mean, sig_rms)


__all__ = ["MotionEstimate", "estimate_motion", "kinematics_at_epoch", "polyfit_finite"]
