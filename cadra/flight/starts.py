"""Starting estimates for the 6-DOF fit: which linear theory a fit starts from.

:func:`start_estimates` is what ``cadra2 fit --start`` and :func:`cadra.fit` use: the damped
sines of theta and psi (:func:`cadra.flight.estimates.estimate_motion`) or the epicyclic
fit's arms (:func:`epicyclic_estimates`, through the classic reduction
:func:`cadra.flight.classic.analyse_shot`), which see both arms of a spinning body and the
sign of C_m_alpha of a gyroscopically stable one. Measured by ``tools/bench_starts.py``
(docs/fitting.md, "Starting values").
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from cadra.flight.classic import analyse_shot, conditions_of, min_points
from cadra.flight.data import CHANNELS, launch_spin
from cadra.flight.estimates import MotionEstimate, estimate_motion, kinematics_at_epoch
from cadra.motion import MotionFitError, fit_epicyclic, linear_coefficients

_THETA = CHANNELS.index("theta")
#: stations with angles from which a known spin's start uses the 12-constant form
CURVATURE_STATIONS = 16
#: the choices of :func:`start_estimates`
START_CHOICES = ("auto", "linear", "epicyclic")


def epicyclic_estimates(shots, cm_alpha_guess: float | None = None) -> list[MotionEstimate]:
    """Each shot's :class:`~cadra.flight.estimates.MotionEstimate` for ``cadra2 fit``'s starting
    values, with C_mα and C_mq + C_mα̇ from the epicyclic fit's arms (:func:`analyse_shot`:
    linear theory with the swerve's lift, docs/motion.md) where that fit converges and
    determines them (C_mα at least 3σ from zero), and the spin (ω_1 + ω_2) I/I_x where it
    is 3σ from zero (the starting state spins at it). The damped sines of θ and ψ that the
    starting values otherwise use see one frequency; a spinning body has two, and a
    gyroscopically stable one (C_mα > 0) has no pitch frequency that gives the sign.
    A shot the fit cannot reduce (a mounted record, too few stations) keeps the plain
    estimate; pure function of the shots (a campaign's scheduler can ship it). A free flight in
    a wind tunnel is fitted in time against the stream (:func:`_stream_coefficients`).

    A shot whose spin is known (its gun's twist, :func:`cadra.flight.data.launch_spin`) is
    reduced with that spin: the arms go into the frequency bands gyroscopic theory gives for
    it (``cm_alpha_guess``, the starting model's C_mα, tells apart bands of equal sum), the
    estimate spins at it, and the axis's rate at the epoch comes from those arms
    (:func:`_spinning_estimate`)."""
    out = []
    for shot in shots:
        est = estimate_motion(shot)
        kind = shot.rigid.mode.kind
        spin = launch_spin(shot, est.speed_m_s)
        if kind == "range" and shot.has_angles and np.isfinite(spin):
            out.append(_spinning_estimate(shot, est, spin, cm_alpha_guess))
            continue
        if kind in ("range", "tunnel") and shot.has_angles:
            try:
                lc = (analyse_shot(shot, window=None).coefficients if kind == "range"
                      else _stream_coefficients(shot))
            except (ValueError, MotionFitError, np.linalg.LinAlgError, FloatingPointError):
                lc = None
            if (lc is not None and np.isfinite(lc.Cm_alpha)
                    and abs(lc.Cm_alpha) > 3.0 * lc.Cm_alpha_sigma):
                spin = lc.spin_from_fit
                est = replace(est, cm_alpha=float(lc.Cm_alpha),
                              cmq_sum=float(lc.Cmq_sum) if np.isfinite(lc.Cmq_sum)
                              else math.nan,
                              spin_rad_s=float(spin) if abs(spin) > 3.0 * lc.spin_from_fit_sigma
                              else math.nan)
        out.append(est)
    return out


def _spinning_estimate(shot, est: MotionEstimate, spin: float,
                       cm_alpha_guess: float | None) -> MotionEstimate:
    """``est`` with what the classic reduction at a known spin gives (no trim arm: a body of
    revolution has none): C_mα, C_mq + C_mα̇ and the axis's rate at the epoch from the
    de-aliased arms; the spin itself. A record of :data:`CURVATURE_STATIONS` or more is
    reduced in the 12-constant form (p/V, and with it the arms' frequencies, changes along a
    long record, which biases the 10-constant C_mα; docs/spark_range.md). A reduction that
    fails keeps the spin only."""
    failed = None
    for curvature in ((True, False) if np.isfinite(shot.meas[:, _THETA]).sum()
                      >= CURVATURE_STATIONS else (False,)):
        try:
            motion = analyse_shot(shot, window=None, spin=spin, trim=False,
                                  curvature=curvature, cm_alpha_guess=cm_alpha_guess)
            break
        except (ValueError, MotionFitError, np.linalg.LinAlgError, FloatingPointError) as exc:
            failed = exc
    else:
        return replace(est, spin_rad_s=float(spin), alias_note=f"no epicyclic start ({failed})")
    lc = motion.coefficients
    t0 = shot.t_s[shot.epoch_index]
    s0 = float(np.interp(t0, motion.t_s, motion.s))
    per_s = motion.conditions.speed_m_s if motion.variable == "distance" else 1.0
    dxi = complex(np.asarray(motion.fit.predict([s0], derivative=True))[0]) * per_s
    xi0 = complex(np.asarray(motion.fit.predict([s0]))[0])
    # theta = alpha + gamma, psi = beta + chi (the angles are relative to the mean path)
    angles = (xi0.imag + float(np.interp(t0, motion.t_s, motion.path_up)),
              xi0.real + float(np.interp(t0, motion.t_s, motion.path_port)))
    note = motion.alias.note() if motion.alias is not None else next(
        (n for n in motion.notes if n.startswith("the arms could not")), "")
    ok = motion.alias is not None and lc is not None and np.isfinite(lc.Cm_alpha)
    lateral = lateral_v = None
    if ok and motion.swerve is not None:
        Z, dZ = motion.swerve.lateral(motion.fit, s0)
        lateral, lateral_v = (Z.real, Z.imag), (dZ.real * per_s, dZ.imag * per_s)
    vx = float(kinematics_at_epoch(shot, cubic_x=True)[1][0])
    return replace(
        est, spin_rad_s=float(spin), cg_lateral=lateral, cg_lateral_velocity=lateral_v,
        vx_m_s=vx,
        cm_alpha=float(lc.Cm_alpha) if ok else math.nan,
        cmq_sum=float(lc.Cmq_sum) if ok and np.isfinite(lc.Cmq_sum) else math.nan,
        axis_rate_F=(0.0, dxi.real, dxi.imag) if ok else None, alias_note=note,
        axis_angles=angles if ok else None,
        cl_alpha=float(lc.C_L_alpha) if ok and lc.C_L_alpha is not None
        and np.isfinite(lc.C_L_alpha) and abs(lc.C_L_alpha) > 3 * lc.C_L_alpha_sigma
        else math.nan)


def _stream_coefficients(shot):
    """Linear-theory coefficients of a free flight in a wind tunnel (docs/dynamics.md, test
    modes): the axis angles θ, ψ are the angles to the stream (+x), the epicyclic fit runs in
    time at the rms air-relative speed over the record, and the flight path's turning by lift
    is left out (the drift across the stream is slow; first order in the lift, as on a
    gimbal)."""
    m, sg = shot.meas, shot.sigma
    ok = np.isfinite(m[:, 3]) & np.isfinite(m[:, 4])
    if ok.sum() < min_points(False, False):
        raise ValueError(f"{shot.shot_id}: {int(ok.sum())} frames with both angles")
    fit = fit_epicyclic(shot.t_s[ok], m[ok, 3], m[ok, 4], sg[ok, 3], sg[ok, 4],
                        variable="time")
    cond, _ = conditions_of(shot, 0.0, "time")        # the stream's speed
    # the air-relative speed w = U + v_x falls as the model drifts with the stream: the
    # frequencies follow the mean dynamic pressure, so the speed is the rms of w over the
    # record (v_x from a quadratic in time of the measured x, when positions are measured)
    hx = np.isfinite(m[:, 0])
    if hx.sum() >= 3:
        vx = np.polyval(np.polyder(np.polyfit(shot.t_s[hx], m[hx, 0], 2)), shot.t_s[ok])
        cond = replace(cond, speed_m_s=float(np.sqrt(np.mean((cond.speed_m_s + vx) ** 2))))
    return linear_coefficients(fit, cond)


def start_estimates(shots, how: str = "auto", model=None):
    """The estimates behind ``cadra2 fit --start HOW`` (None: the fitter's own).

    ``linear``: the damped sines of θ and ψ (:func:`~cadra.flight.estimates.estimate_motion`);
    ``epicyclic``: :func:`epicyclic_estimates` for every shot; ``auto`` (default): the
    epicyclic estimate for a shot whose arms show a spin (3σ), the damped sines otherwise.
    Measured by ``tools/bench_starts.py`` (docs/fitting.md, "Starting values"): on a
    gyroscopically stable body the epicyclic start has the right sign of C_mα and the spin,
    and converges in half the iterations; on a non-spinning one the two starts agree."""
    if how not in START_CHOICES:
        raise ValueError(f"start {how!r}: expected auto, linear or epicyclic")
    if how == "linear":
        return None
    epi = epicyclic_estimates(shots, None if model is None else cm_alpha_of(model))
    if how == "epicyclic":
        return epi
    # a shot without a spin keeps its damped sines: the estimate without the arms' fields
    return [e if np.isfinite(e.spin_rad_s)
            else replace(e, cm_alpha=math.nan, cmq_sum=math.nan, spin_rad_s=math.nan)
            for e in epi]


def cm_alpha_of(model, sigma_deg: float = 2.0) -> float:
    """A total-angle model's C_mα at its current values: C_m(σ) / sin σ at a small σ (NaN
    for a model without C_m)."""
    if "Cm" not in model.coefficients:
        return math.nan
    sig = math.radians(sigma_deg)
    c = model.evaluate(sig, 0.0, sig, 1.0)
    return float(c["Cm"]) / math.sin(sig)


__all__ = ["START_CHOICES", "cm_alpha_of", "epicyclic_estimates", "start_estimates"]
