"""Starting values of the 6-DOF fit, from linear theory and the measurements themselves.

No guru needed: :mod:`cadra.flight.estimates` reads each shot's frequency, damping, drag and
mean angle from its measurements (or :mod:`cadra.flight.starts` from its epicyclic arms), and

- :func:`starting_model` maps these *targets* onto whatever parameters the model file has: it
  finds the smallest change of the free parameters (relative to the file's values) for which
  the model reproduces the targets at the shots' mean flight condition (C_D, slope of C_m,
  C_m = 0 at the mean angle for a trimmed lifting body, C_mq, and the yaw slope of C_n for
  alpha-beta models). Parameters the targets do not touch keep the file's values.
- :func:`initial_states` gives each shot's state at its epoch: position and velocity from
  quadratic fits of x, y, z against time, the attitude and transverse angular velocity from
  local quadratic fits of the measured axis direction; the roll about the axis, which the
  images do not show, is chosen from a grid by the chi^2 of the starting trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares

from cadra.aero import AeroModel
from cadra.channels import residual
from cadra.conventions import axis_from_inclinations, body_to_facility_matrix, quat_from_axis_roll
from cadra.dynamics.setup import state_from_reference
from cadra.fitting.problem import FitProblem, default_local_free
from cadra.fitting.sensitivity import LOCAL_NAMES, Integration
from cadra.flight.data import CHANNELS, FitDataError, ShotData
from cadra.flight.estimates import (
    MotionEstimate,
    estimate_motion,
    kinematics_at_epoch,
    polyfit_finite,
)
from cadra.motion import FlightConditions, planar_coefficients

#: roll angles (deg) tried for a shot whose roll the images do not show
ROLL_GRID_DEG = tuple(range(0, 360, 30))
#: relative spins a known spin's start tries (-6 % to +6 % of the spin given, 0.25 % apart:
#: a step moves the spark range's fast arm by under half a radian over the record). The
#: muzzle's spin is a few per cent above the range's; a spin from the twist at the speed
#: measured in the range, a few per cent below
SPIN_SCAN = np.arange(-0.06, 0.06 + 1e-9, 0.0025)
#: the axis-inclination channels (columns of ``ShotData.meas``)
_THETA, _PSI = CHANNELS.index("theta"), CHANNELS.index("psi")
_PHI = CHANNELS.index("phi")


def _slope(model: AeroModel, coef: str, var: str, point: dict, params: np.ndarray) -> float:
    """d coef / d var at ``point`` by complex step (var: alpha, beta or sigma)."""
    h = 1e-20
    pt = dict(point)
    pt[var] = pt[var] + 1j * h
    if model.angle_plane == "sigma" and var == "sigma":
        pt["alpha"] = pt["sigma"]
    return float(np.imag(model.evaluate(**pt, params=params.astype(complex))[coef]) / h)


def starting_model(shots: Sequence[ShotData], model: AeroModel,
                   estimates: Sequence[MotionEstimate] | None = None) -> AeroModel:
    """``model`` with its free parameters moved to match the linear-theory targets.

    The targets (see module doc) are averaged over the shots; the change of the free
    parameters is the smallest (relative to a scale of max(|value|, 0.1)) that meets them, found
    by a regularised least-squares solve. Parameters the targets cannot move keep their values.
    """
    est = list(estimates) if estimates is not None else [estimate_motion(s) for s in shots]
    free = model.free_indices()
    if free.size == 0:
        return model
    p0 = model.values()
    rig = shots[0].rigid
    I_yy = float(rig.inertia_body_kg_m2[1, 1])
    I_zz = float(rig.inertia_body_kg_m2[2, 2])
    # a mount turns the body about its pivot: the inertia about it, and the lift's arm
    # (cadra.dynamics.modes); free flight: l = 0
    l_pivot = float(rig.mode.pivot_from_cg_body_m[0]) if rig.mode.mounted else 0.0
    I_yy += rig.mass_kg * l_pivot**2
    I_zz += rig.mass_kg * l_pivot**2
    d, rho = rig.d_m, rig.density_kg_m3
    V = float(np.mean([e.speed_m_s for e in est]))
    mach = float(np.mean([e.mach for e in est]))
    sig = float(np.mean([e.sigma_mean_rad for e in est]))
    sig_rms = float(np.mean([e.sigma_rms_rad for e in est]))
    sigma_plane = model.angle_plane == "sigma"

    def planar(omega: float, lam: float, inertia: float) -> tuple[float, float]:
        """(C_m_alpha, C_mq + C_m_alpha_dot) of a planar oscillation at the mean speed
        (linear theory's one home, :func:`cadra.motion.planar_coefficients`)."""
        cond = FlightConditions(mass_kg=rig.mass_kg, Ix_kg_m2=float(rig.inertia_body_kg_m2[0, 0]),
                                I_kg_m2=inertia, d_m=d, density_kg_m3=rho, speed_m_s=V)
        return planar_coefficients(omega, lam if np.isfinite(lam) else 0.0, cond)

    angle = max(sig_rms, math.radians(0.5)) if sigma_plane else sig
    point = {"alpha": angle, "beta": 0.0, "sigma": angle, "mach": mach}
    targets = []   # (function of params, target value, tolerance)
    cd = float(np.mean([e.cd for e in est]))
    if np.isfinite(cd):
        targets.append((lambda p: float(model.evaluate(**point, params=p)["CD"]), cd, 0.02))

    def mean_finite(vals):
        vals = [v for v in vals if np.isfinite(v)]
        return float(np.mean(vals)) if vals else math.nan

    # pitch plane: the theta channel for a lifting body rolled near 0/180 deg; for a symmetric
    # body both channels see the same frequency
    wp = mean_finite([e.omega_pitch_rad_s for e in est] + (
        [e.omega_yaw_rad_s for e in est] if sigma_plane else []))
    lp = mean_finite([e.lambda_pitch_1_s for e in est] + (
        [e.lambda_yaw_1_s for e in est] if sigma_plane else []))
    var = "sigma" if sigma_plane else "alpha"
    cma_given = mean_finite([e.cm_alpha for e in est])
    cmq_given = mean_finite([e.cmq_sum for e in est])
    if "Cm" in model.coefficients and (np.isfinite(wp) or np.isfinite(cma_given)):
        cma = cma_given if np.isfinite(cma_given) else planar(wp, lp, I_yy)[0]
        if l_pivot and not np.isfinite(cma_given) and "CL" in model.coefficients:
            # about a pivot l ahead of the cg the lift adds -l/d C_L_alpha to the slope
            cla = _slope(model, "CL", var, point, p0)
            cma += l_pivot / d * cla
        if sigma_plane:
            # effective (secant) slope over the motion: Cm(sigma) / sigma at the rms angle
            targets.append((lambda p: float(model.evaluate(**point, params=p)["Cm"]) / angle,
                            cma, 0.2 * abs(cma) + 1e-3))
        else:
            targets.append((lambda p: _slope(model, "Cm", var, point, p), cma,
                            0.2 * abs(cma) + 1e-3))
            targets.append((lambda p: float(model.evaluate(**point, params=p)["Cm"]), 0.0,
                            0.05 * abs(cma) + 1e-4))
    cla_given = mean_finite([e.cl_alpha for e in est])
    if "CL" in model.coefficients and np.isfinite(cla_given) and sigma_plane:
        # the swerve's lift slope (a known spin's arms, epicyclic_estimates): secant slope
        targets.append((lambda p: float(model.evaluate(**point, params=p)["CL"]) / angle,
                        cla_given, 0.1 * abs(cla_given) + 1e-3))
    if "Cmq" in model.coefficients and (np.isfinite(lp) or np.isfinite(cmq_given)):
        cmq = float(np.clip(cmq_given if np.isfinite(cmq_given)
                            else planar(0.0, lp, I_yy)[1], -20, 20))
        targets.append((lambda p: float(model.evaluate(**point, params=p)["Cmq"]), cmq,
                        0.5 * abs(cmq) + 0.5))
    if not sigma_plane and "Cn" in model.coefficients:
        wy = mean_finite([e.omega_yaw_rad_s for e in est])
        if np.isfinite(wy):
            cnb = planar(wy, mean_finite([e.lambda_yaw_1_s for e in est]), I_zz)[0]
            targets.append((lambda p: _slope(model, "Cn", "beta", point, p), cnb,
                            0.2 * abs(cnb) + 1e-3))
    scale = np.maximum(np.abs(p0[free]), 0.1)

    def residuals(x):
        p = p0.copy()
        p[free] = p0[free] + x * scale
        r = [(f(p) - target) / tol for f, target, tol in targets]
        return np.concatenate([np.array(r), 0.1 * x])

    lo = np.array([(model.parameters[i].min - p0[i]) / s for i, s in zip(free, scale,
                                                                          strict=True)])
    hi = np.array([(model.parameters[i].max - p0[i]) / s for i, s in zip(free, scale,
                                                                          strict=True)])
    # a start on a bound (a C_D_0 >= 0 started at 0) stalls the bounded solver's scaled
    # step at x = 0 for every parameter: start just inside
    x0 = np.clip(np.zeros(free.size), np.where(np.isfinite(lo), lo + 1e-3, -np.inf),
                 np.where(np.isfinite(hi), hi - 1e-3, np.inf))
    try:
        sol = least_squares(residuals, x0, bounds=(lo, hi), max_nfev=200)
        x = sol.x
    except (ValueError, FloatingPointError):
        return model
    values = {model.parameters[i].name: float(p0[i] + xi * s)
              for i, xi, s in zip(free, x, scale, strict=True)}
    return model.with_values(values)


def _axis_and_rate(shot: ShotData):
    """Measured nose axis and its time derivative at the epoch (local quadratic fits)."""
    t = shot.t_s
    k = shot.epoch_index
    lo, hi = max(0, k - 3), min(len(t), k + 4)
    tt = t[lo:hi] - t[k]
    axes = []
    for i in range(lo, hi):
        th, ps = shot.meas[i, _THETA], shot.meas[i, _PSI]
        axes.append(axis_from_inclinations(th, ps) if np.isfinite(th) and np.isfinite(ps)
                    else np.full(3, np.nan))
    axes = np.array(axes)
    a = np.zeros(3)
    adot = np.zeros(3)
    for j in range(3):
        c = polyfit_finite(tt, axes[:, j], 2)
        a[j] = np.polyval(c, 0.0)
        adot[j] = np.polyval(np.polyder(c), 0.0) if len(c) > 1 else 0.0
    a /= np.linalg.norm(a)
    return a, adot


def _roll_and_rate(shot: ShotData) -> tuple[float, float]:
    """The measured roll angle phi (rad) and its rate (rad/s) at the epoch: a local quadratic
    fit of phi unwrapped along the shot (whole turns between samples are not seen: a roll
    sampled more coarsely than half a turn per station aliases)."""
    ok = np.isfinite(shot.meas[:, _PHI])
    t, phi = shot.t_s[ok], np.unwrap(shot.meas[ok, _PHI])
    if t.size == 1:
        return float(phi[0]), 0.0
    k = int(np.argmin(np.abs(t - shot.t_s[shot.epoch_index])))
    lo, hi = max(0, k - 3), min(t.size, k + 4)
    if hi - lo < 3:
        lo, hi = 0, t.size
    c = np.polyfit(t[lo:hi] - shot.t_s[shot.epoch_index], phi[lo:hi], min(2, hi - lo - 1))
    return float(np.polyval(c, 0.0)), float(np.polyval(np.polyder(c), 0.0))


def state_candidates(shot: ShotData, roll_grid_deg=ROLL_GRID_DEG,
                     spin_rad_s: float = 0.0, axis_rate_F=None,
                     axis_angles=None, cg_lateral=None) -> list[np.ndarray]:
    """Starting states at the epoch for each roll angle of the grid (one if no angles),
    spinning at ``spin_rad_s`` about the measured axis (stage one does not see roll: 0 unless
    an estimate gives it, :class:`MotionEstimate`). ``axis_rate_F`` (facility frame, 1/s)
    replaces the measured angles' local slope as the axis's rate of turn (an estimate's
    :attr:`MotionEstimate.axis_rate_F`, from arms a local slope cannot follow), and
    ``axis_angles`` (theta, psi, rad) the axis itself (the local fit would average an arm
    that turns between stations away). ``cg_lateral`` ((y, z) m, (vy, vz) m/s, vx m/s or NaN)
    replaces the polynomials' lateral cg position and velocity at the epoch (a swerve fitted
    with the arms: a spinning bullet's slow arm swerves it by millimetres at half a metre a
    second), and the downrange speed when given.

    A shot that measures its roll angle (``phi``: a finned body) starts at its measured roll
    and at the roll rate phi's slope gives, in place of the grid and ``spin_rad_s``. A mounted
    record that measures the roll but not the axis (theta, psi) cannot place the axis: pass
    its starting state (``fit_shots(initial=...)``).

    A mounted wind-tunnel record (cadra.dynamics.modes) may have no positions: the pivot is
    then put at the facility origin (nothing observed depends on where it is), and the
    velocity is the mount's (the integration sets it from the rates)."""
    mode = shot.rigid.mode
    if mode.mounted and np.isfinite(shot.meas[:, 0]).sum() < 3:
        pos, vel = np.zeros(3), np.zeros(3)
    else:
        pos, vel = kinematics_at_epoch(shot)
    if mode.mounted:
        vel = np.zeros(3)
    ref = shot.rigid.ref_from_cg_body_m()
    if not shot.has_angles and shot.has_roll:
        raise FitDataError(f"{shot.shot_id}: the roll angle is measured but the nose axis "
                           "(theta, psi) is not, so no starting attitude can be made: measure "
                           "theta and psi, or give the starting state")
    if not shot.has_angles:
        a = vel / np.linalg.norm(vel)
        q = quat_from_axis_roll(a, 0.0)
        return [state_from_reference(pos, vel, q, np.zeros(3), ref)]
    a, adot = _axis_and_rate(shot)
    if axis_angles is not None and np.all(np.isfinite(axis_angles)):
        a = axis_from_inclinations(*axis_angles)
    if axis_rate_F is not None and np.all(np.isfinite(axis_rate_F)):
        adot = np.asarray(axis_rate_F, dtype=float)
        adot = adot - (adot @ a) * a
    w_F = np.cross(a, adot)                # transverse angular velocity, facility frame
    if shot.has_roll:
        phi0, phi_dot = _roll_and_rate(shot)
        roll_grid_deg = (math.degrees(phi0),)
        # phi' = p + (q sin phi + r cos phi) tan theta (3-2-1 Euler kinematics); q, r from the
        # axis's swing, which cross(a, a') gives without a part along the axis
        w_B = body_to_facility_matrix(quat_from_axis_roll(a, phi0)).T @ w_F
        theta = math.asin(float(np.clip(a[2], -1.0, 1.0)))
        spin_rad_s = phi_dot - (w_B[1] * math.sin(phi0) + w_B[2] * math.cos(phi0)) * math.tan(theta)
        if mode.kind != "pitch_pivot":
            w_F = w_F + spin_rad_s * a
    elif np.isfinite(spin_rad_s) and not mode.mounted:
        w_F = w_F + spin_rad_s * a
    if mode.kind == "pitch_pivot" and not shot.has_roll:
        roll_grid_deg = _pivot_rolls(shot, a)
    out = []
    for roll in roll_grid_deg:
        q = quat_from_axis_roll(a, math.radians(roll))
        R = body_to_facility_matrix(q)
        y = state_from_reference(pos, vel, q, R.T @ w_F, ref)
        if cg_lateral is not None:
            y[1:3], y[4:6] = cg_lateral[0], cg_lateral[1]
            if np.isfinite(cg_lateral[2]):
                y[3] = cg_lateral[2]
        out.append(y)
    return out


def _pivot_rolls(shot: ShotData, a: np.ndarray) -> tuple[float, float]:
    """The two roll angles (deg) that put a pitch pivot's axis (body y) normal to the plane
    the measured nose axis swings in: the mount turns the body about body y only, so the
    roll grid's other angles are motions it cannot make."""
    ok = np.isfinite(shot.meas[:, _THETA]) & np.isfinite(shot.meas[:, _PSI])
    axes = np.array([axis_from_inclinations(th, ps)
                     for th, ps in shot.meas[ok][:, [_THETA, _PSI]]])
    swing = np.linalg.svd(axes - axes.mean(axis=0), full_matrices=False)[2][0]
    n = np.cross(a, swing)
    n /= np.linalg.norm(n)
    R0 = body_to_facility_matrix(quat_from_axis_roll(a, 0.0))
    phi = math.degrees(math.atan2(n @ R0[:, 2], n @ R0[:, 1]))
    if body_to_facility_matrix(quat_from_axis_roll(a, math.radians(phi)))[:, 1] @ n < 0:
        phi = -phi
    return (phi, phi + 180.0)


def initial_state(shot: ShotData, model: AeroModel,
                  integ: Integration | None = None, spin_rad_s: float = 0.0,
                  axis_rate_F=None, axis_angles=None, cg_lateral=None) -> np.ndarray:
    """The best starting state of ``shot`` under ``model``: the roll-grid candidate whose
    predicted trajectory is closest to the measurements (chi^2).

    With a known spin's arms (``axis_rate_F`` given) the spin is scanned too, over
    :data:`SPIN_SCAN` of ``spin_rad_s``: the twist gives the muzzle spin, and the spin at the
    epoch is a per cent or two lower (it decays, and the muzzle is not where the record
    starts), which on a spark range is radians of the fast arm's phase by the record's ends;
    without a muzzle velocity the twist's spin at the range's speed is low instead.
    Such a body, when the fit does not use its roll (:func:`default_local_free`), skips the
    roll grid: turning it about its axis changes nothing measured."""
    integ = integ or Integration()
    grid, spins = ROLL_GRID_DEG, [spin_rad_s]
    if axis_rate_F is not None and np.isfinite(spin_rad_s) and spin_rad_s != 0:
        spins = list(spin_rad_s * (1.0 + SPIN_SCAN))
        if LOCAL_NAMES.index("rot_x_rad") not in default_local_free(shot, model):
            grid = (0.0,)
    cands = [y for p in spins for y in state_candidates(
        shot, grid, spin_rad_s=p, axis_rate_F=axis_rate_F, axis_angles=axis_angles,
        cg_lateral=cg_lateral)]
    if len(cands) == 1:
        return cands[0]
    # the fit's forward model (cadra.fitting.problem), as the solver will predict
    problem = FitProblem((shot,), model, (cands[0],), integration=integ)
    params = model.values()
    best, best_chi2 = cands[0], math.inf
    mask = shot.mask
    for y in cands:
        pred = problem.predict_from(params, np.zeros(0), [y])[0]
        r = (residual(shot.meas, pred) / shot.sigma)[mask]
        chi2 = float(r @ r) if np.all(np.isfinite(r)) else math.inf
        if chi2 < best_chi2:
            best, best_chi2 = y, chi2
    return best


def initial_states(shots: Sequence[ShotData], model: AeroModel,
                   integ: Integration | None = None,
                   estimates: Sequence[MotionEstimate] | None = None) -> list[np.ndarray]:
    """:func:`initial_state` of every shot, spinning at its estimate's spin where given."""
    est = list(estimates) if estimates is not None else [None] * len(shots)
    spins = [0.0 if e is None or not np.isfinite(e.spin_rad_s) else e.spin_rad_s for e in est]
    return [initial_state(s, model, integ, p, None if e is None else e.axis_rate_F,
                          None if e is None else e.axis_angles, _lateral(e))
            for s, p, e in zip(shots, spins, est, strict=True)]


def _lateral(e):
    """An estimate's swerve at the epoch as :func:`state_candidates` takes it, or None."""
    if e is None or e.cg_lateral is None or e.cg_lateral_velocity is None:
        return None
    return (np.asarray(e.cg_lateral, dtype=float), np.asarray(e.cg_lateral_velocity, dtype=float),
            e.vx_m_s)


__all__ = ["ROLL_GRID_DEG", "initial_state", "initial_states", "starting_model",
           "state_candidates"]
