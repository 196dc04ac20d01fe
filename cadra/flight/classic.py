"""The classic angular-motion reduction of a range shot (docs/motion.md, "cadra2 motion").

For each shot (a :class:`~cadra.flight.data.ShotData`, from files or from memory):

1. the cg's positions (the reference point moved along the measured axis by the shot's
   axial cg offset) are fitted with a low-order polynomial in time (default quadratic:
   gravity and drag); its derivative is the mean flight path, with the inclinations
   γ = asin(v_z/V) (+ up) and χ = asin(v_y/V) (+ port) (docs/conventions.md;
   :func:`flight_path_angles`);
2. the angle of attack and sideslip relative to that path are α = θ − γ and β = ψ − χ (θ, ψ
   the measured axis inclinations): ξ = β + iα, the sign convention of docs/motion.md;
3. the epicyclic fit (:func:`cadra.motion.fit_epicyclic`; tricyclic with a trim arm at the
   roll rate when a spin is given) in distance or time, the Nonplanar Ratio, the lift slope
   from the swerve and the linear-theory coefficients with sigmas
   (:func:`cadra.motion.linear_coefficients`), the flight conditions from the shot (mass,
   inertias, diameter, air density) and the trajectory (speed, C_D; as the fit's starting
   values, :func:`cadra.flight.estimates.estimate_motion`);
4. when the record holds enough cycles, overlapping sectional fits in time and the
   Kryloff-Bogoliuboff reduction (:func:`cadra.motion.kb_reduction`), with the flight path's
   turning by lift taken out of its damping and Magnus terms.

:func:`analyse_shot` returns a :class:`ShotMotion`; :mod:`cadra.report.motion` writes and
prints it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from cadra.conventions import axis_from_inclinations
from cadra.flight.data import ShotData
from cadra.flight.estimates import MotionEstimate, estimate_motion
from cadra.motion import (
    Dealiased,
    EpicyclicFit,
    FlightConditions,
    KBResult,
    LinearCoefficients,
    MotionFitError,
    NonplanarRatio,
    Sections,
    SwerveFit,
    dealias_arms,
    fit_epicyclic,
    kb_reduction,
    lift_from_swerve,
    linear_coefficients,
    nonplanar_ratio_of_fit,
    sectional_epicyclic,
)
from cadra.numfmt import pm
from cadra.stats import POOR_MINIMUM_P as POOR_P

#: sectional fits: a window spans this many cycles of the slower arm, at least MIN_WINDOW
#: points, and the K-B reduction needs at least MIN_SECTIONS windows
SECTION_CYCLES = 1.2
MIN_WINDOW = 12
MIN_SECTIONS = 5
#: ... over a record at least this many windows long (independent material for the trend)
MIN_RECORD_WINDOWS = 3


@dataclass(frozen=True)
class ShotMotion:
    """One shot's reduction: the angle history relative to the mean flight path and what was
    fitted to it (None where not computed; ``notes`` says why)."""

    shot_id: str
    variable: str                # "distance" or "time": the fit's independent variable
    stations: np.ndarray
    t_s: np.ndarray
    x_m: np.ndarray              # the cg's downrange distance on the fitted path
    alpha: np.ndarray            # rad, relative to the mean flight path
    beta: np.ndarray
    sigma_alpha: np.ndarray
    sigma_beta: np.ndarray
    path_up: np.ndarray          # flight-path inclinations gamma (+ up), chi (+ port), rad
    path_port: np.ndarray
    fit: EpicyclicFit
    conditions: FlightConditions  # in the fit's variable
    npr: NonplanarRatio
    coefficients: LinearCoefficients | None
    swerve: SwerveFit | None
    sections: Sections | None = None
    kb: KBResult | None = None
    kb_lift_corrected: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)
    #: the arms' frequency bands from the spin (None: no spin given)
    alias: Dealiased | None = None

    @property
    def s(self) -> np.ndarray:
        """The fit's independent variable at the stations: x (m) or t (s)."""
        return self.x_m if self.variable == "distance" else self.t_s

    @property
    def warnings(self) -> list[str]:
        """Where this reduction is not to be trusted: a chi^2/dof above 2 (the epicyclic form
        or the angle sigmas do not describe the motion), arms whose frequencies disagree with
        the spin given, constants the data do not determine."""
        out = []
        if self.fit.chi2_dof > 2.0:
            out.append(f"{self.shot_id}: chi^2/dof = {self.fit.chi2_dof:.3g} > 2: the "
                       "epicyclic form or the angle sigmas do not describe the motion (sigmas "
                       "scaled by it)")
        lc, spin = self.coefficients, self.conditions.spin_rad_s
        if (lc is not None and spin
                and abs(lc.spin_from_fit - spin) > 3 * lc.spin_from_fit_sigma):
            out.append(f"{self.shot_id}: the arms' frequencies give a spin of "
                       f"{pm(lc.spin_from_fit, lc.spin_from_fit_sigma, 'rad/s')}, not the "
                       f"{spin:g} rad/s given")
        if self.fit.chi2_p_value < POOR_P:
            fit = self.fit.predict(self.s)
            if self.fit.nonrolling is not None:
                fit = fit * np.exp(-1j * self.fit.nonrolling)
            z = np.hypot((self.beta - fit.real) / self.sigma_beta,
                         (self.alpha - fit.imag) / self.sigma_alpha)
            k = int(np.argmax(z))
            out.append(f"{self.shot_id}: converged to a poor minimum, p(chi^2) = "
                       f"{self.fit.chi2_p_value:.2g} < {POOR_P:g}: the largest residual is "
                       f"{z[k]:.1f} sigma at station {int(self.stations[k])}; an arm in the "
                       "wrong alias band (give the spin: --spin or --twist) or a motion the "
                       "epicyclic form does not describe")
        if not np.all(np.isfinite(self.fit.sigmas)):
            out.append(f"{self.shot_id}: some fitted constants are not determined by the data "
                       "(infinite sigma)")
        return out


@dataclass(frozen=True)
class FlightPathAngles:
    """A shot's angles relative to its mean flight path (:func:`flight_path_angles`), over the
    stations ``keep`` selects (position and both angles measured); SI."""

    keep: np.ndarray             # (n_all,) bool: the stations used
    t_s: np.ndarray              # (n,) spark times
    x_m: np.ndarray              # (n,) the cg's downrange distance on the fitted path
    alpha: np.ndarray            # (n,) θ − γ, rad
    beta: np.ndarray             # (n,) ψ − χ, rad
    sigma_alpha: np.ndarray
    sigma_beta: np.ndarray
    gamma: np.ndarray            # (n,) path inclination, + up, rad
    chi: np.ndarray              # (n,) path inclination, + port, rad
    cg_m: np.ndarray             # (n, 3) the cg's positions


def _path(t, pos, sig, degree):
    """Polynomials of the cg's x, y, z against time (weighted); returns (coefficients, t0)."""
    t0 = float(np.mean(t))
    return [np.polyfit(t - t0, pos[:, j], degree, w=1.0 / sig[:, j]) for j in range(3)], t0


def _name(shot: ShotData) -> str:
    return shot.source.get("trajectory_file", shot.shot_id)


def flight_path_angles(shot: ShotData, degree: int = 2) -> FlightPathAngles:
    """The shot's angles relative to the mean flight path (module doc, steps 1-2), over the
    stations with both angles and a position measured.

    Approximation: α = θ − γ, β = ψ − χ are the angles between the axis and the path to first
    order (the neglected terms are products of two angles, < 0.1 % of the angle at 5°); the
    path is the polynomial's, so the swerve's oscillation stays in the angles, which changes
    the arms' amplitudes by the factor 1 + a/r_j (~1 %, a the lift's turning rate) but not
    their exponents.
    """
    m, sg = shot.meas, shot.sigma
    keep = np.all(np.isfinite(m[:, :5]), axis=1)       # x, y, z, theta, psi (not the roll)
    n = int(keep.sum())
    if n < degree + 2:
        raise ValueError(f"{_name(shot)}: {n} station(s) with position and both angles "
                         f"(theta, psi) measured; the flight path's degree-{degree} "
                         f"polynomial needs at least {degree + 2}")
    t, m, sg = shot.t_s[keep], m[keep], sg[keep]
    axes = np.array([axis_from_inclinations(th, ps) for th, ps in m[:, 3:5]])
    cg = m[:, :3] + shot.rigid.cg_from_ref_body_m[0] * axes   # on the axis: no roll needed
    coef, t0 = _path(t, cg, sg[:, :3], degree)
    v = np.array([np.polyval(np.polyder(c), t - t0) for c in coef]).T
    speed = np.linalg.norm(v, axis=1)
    gamma, chi = np.arcsin(v[:, 2] / speed), np.arcsin(v[:, 1] / speed)
    x = np.polyval(coef[0], t - t0)
    return FlightPathAngles(keep, t, x, m[:, 3] - gamma, m[:, 4] - chi, sg[:, 3], sg[:, 4],
                            gamma, chi, cg)


def conditions_of(shot: ShotData, spin: float, variable: str
                  ) -> tuple[FlightConditions, MotionEstimate]:
    """The shot's body and stream for a coefficient reduction in ``variable`` (the speed and,
    in distance, C_D from :func:`~cadra.flight.estimates.estimate_motion`), and that
    estimate."""
    est = estimate_motion(shot)
    r = shot.rigid
    inertia = r.inertia_body_kg_m2
    return FlightConditions(
        mass_kg=r.mass_kg, Ix_kg_m2=float(inertia[0, 0]),
        I_kg_m2=float(0.5 * (inertia[1, 1] + inertia[2, 2])), d_m=r.d_m,
        density_kg_m3=r.density_kg_m3, speed_m_s=est.speed_m_s, spin_rad_s=spin,
        drag_coefficient=est.cd if variable == "distance" else None), est


def min_points(trim: bool, offset: bool) -> int:
    """Fewest stations an epicyclic fit (8 constants, + 2 for a trim arm, + 2 for an offset)
    is tried on."""
    n_const = 8 + 2 * int(trim) + 2 * int(offset)
    return max(n_const // 2 + 2, 6)


#: a record whose angles scatter about their mean by less than this many of their own sigmas
#: holds no angular motion above its noise: nothing to reduce (constant angles gave
#: coefficients with tiny sigmas from the noise alone)
MIN_MOTION_SIGMAS = 3.0


def _check_motion(shot: ShotData, fp) -> None:
    """Refuse (``ValueError``) a record with no angular motion above its noise."""
    rms = math.hypot(float(np.std(fp.alpha)), float(np.std(fp.beta))) / math.sqrt(2.0)
    sigma = float(np.median(np.hypot(fp.sigma_alpha, fp.sigma_beta))) / math.sqrt(2.0)
    if not rms > MIN_MOTION_SIGMAS * sigma:
        raise ValueError(f"{_name(shot)}: the angles scatter {math.degrees(rms):.3g} deg rms "
                         f"about their mean, {rms / max(sigma, 1e-300):.2g} of their sigma "
                         f"({math.degrees(sigma):.3g} deg): no angular motion above the noise, "
                         "nothing to reduce")


def analyse_shot(shot: ShotData, *, variable: str = "distance", spin: float | None = None,
                 offset: bool = False, nonrolling: bool = False, degree: int = 2,
                 window: int | None = None, step: int | None = None,
                 trim: bool | None = None, curvature: bool = False,
                 cm_alpha_guess: float | None = None) -> ShotMotion:
    """The classic reduction of one shot (module doc).

    ``variable``: the epicyclic fit's independent variable, ``"distance"`` or ``"time"``;
    ``spin`` (rad/s, right-handed about the nose): gives the tricyclic fit (a trim arm at the
    roll rate) and C_mpα; ``offset``: fit a constant angle too; ``nonrolling``: seed 002's
    nonrolling-axis correction; ``degree``: of the flight path's polynomials;
    ``window``, ``step``: points per sectional fit and between sections (default: 1.2 cycles
    of the slower arm, at least 12; a tenth of the window). ``trim``: the tricyclic trim arm
    at the spin (default: whenever a spin is given; a gun-launched body of revolution has
    none, and on a spark range its arm aliases onto the others). ``curvature``: the
    12-constant form (each arm's frequency changing linearly, as p/V does along a long
    record). With a spin, the arms are put into the frequency bands gyroscopic theory gives
    for it (:func:`cadra.motion.alias.dealias_arms`; ``cm_alpha_guess`` tells apart bands of
    equal sum), and :attr:`ShotMotion.alias` says what was moved.

    Raises ValueError for a record that cannot be reduced (too few stations), and
    :class:`cadra.motion.MotionFitError` when the epicyclic fit does not converge.
    """
    notes: list[str] = []
    fp = flight_path_angles(shot, degree)
    t = fp.t_s
    trim = spin is not None if trim is None else bool(trim)
    if trim and spin is None:
        raise ValueError("trim: the trim arm turns at the spin; give the spin")
    need = min_points(trim, offset)
    form = "tricyclic" if trim else "epicyclic"
    if t.size < need:
        raise ValueError(f"{_name(shot)}: {t.size} station(s) with position and both angles "
                         f"(theta, psi) measured; the {form} fit needs at least {need}")
    _check_motion(shot, fp)
    cond, _ = conditions_of(shot, spin or 0.0, variable)
    s = fp.x_m if variable == "distance" else t
    per_s = cond.speed_m_s if variable == "distance" else 1.0
    # the 12-constant form refers its frequencies to the record's middle: the coefficients
    # are then those of the middle, not extrapolated along omega-dot to the first station
    fit = fit_epicyclic(s, fp.alpha, fp.beta, fp.sigma_alpha, fp.sigma_beta,
                        trim_rate=spin / per_s if trim else None, offset=offset,
                        curvature=curvature, nonrolling=nonrolling, variable=variable,
                        s_ref=0.5 * (s[0] + s[-1]) if curvature else None)
    alias = None
    if spin:
        s_m, _, ix_over_i = cond.scales()
        guess = None
        if cm_alpha_guess is not None and np.isfinite(cm_alpha_guess):
            guess = cm_alpha_guess / (s_m * per_s**2)
        try:
            alias = dealias_arms(fit, s, fp.alpha, fp.beta, fp.sigma_alpha, fp.sigma_beta,
                                 expected_sum=ix_over_i * spin / per_s, expected_product=guess)
            fit = alias.fit
            if alias.aliased:
                notes.append(alias.note("m" if variable == "distance" else "s"))
        except ValueError as exc:
            notes.append(f"the arms could not be put in the spin's bands: {exc}")
    npr = nonplanar_ratio_of_fit(fit, float(s[0]), float(s[-1]))
    if fp.cg_m[:, 0].size >= 8:
        psig = np.hypot(shot.sigma[fp.keep, 1], shot.sigma[fp.keep, 2]) / math.sqrt(2)
        sw = lift_from_swerve(fit, s, fp.cg_m[:, 1], fp.cg_m[:, 2], psig, conditions=cond,
                              gravity=shot.rigid.gravity_m_s2)
        lc = linear_coefficients(fit, cond, lift=(sw.C_L_alpha, sw.C_L_alpha_sigma))
    else:
        lc, sw = linear_coefficients(fit, cond), None
        notes.append("C_Lα from the swerve: not computed (fewer than 8 stations); the "
                     "coefficients neglect the flight path's turning by lift")
    if spin is None:
        notes.append("C_mpα (Magnus): not computed, the spin is not measured by stage one "
                     "(give --spin RAD_S); the tricyclic trim arm needs it too")
    if np.any(np.abs(shot.rigid.cg_from_ref_body_m[1:]) > 0):
        notes.append("the cg's offset from the axis is not applied to the positions (it needs "
                     "the roll angle, which the images do not show)")
    sections, kb, corrected = _sectional(fp, fit, lc, cond, spin, window, step, notes, trim)
    return ShotMotion(shot.shot_id, variable, shot.stations[fp.keep], t, fp.x_m, fp.alpha,
                      fp.beta, fp.sigma_alpha, fp.sigma_beta, fp.gamma, fp.chi, fit, cond, npr,
                      lc, sw, sections, kb, corrected, tuple(notes), alias)


def _sectional(fp: FlightPathAngles, fit, lc, cond, spin, window, step, notes, trim=True):
    """Sectional fits in time and the K-B reduction when the record allows (else a note);
    returns (sections, K-B result, whether the K-B terms were corrected for the lift)."""
    t = fp.t_s
    slow = min(abs(fit.arm(1).omega), abs(fit.arm(2).omega))
    if fit.variable == "distance":
        slow *= cond.speed_m_s            # rad/m -> rad/s
    cycles = slow * (t[-1] - t[0]) / (2 * math.pi)
    per_cycle = (t.size - 1) / cycles if cycles > 0 else float("inf")
    if window is None:
        window = max(MIN_WINDOW, math.ceil(SECTION_CYCLES * per_cycle))
    if step is None:
        step = max(1, window // 10)
    n_sec = (t.size - window) // step + 1 if t.size >= window else 0
    if n_sec < MIN_SECTIONS or t.size < MIN_RECORD_WINDOWS * window:
        notes.append(f"sectional fits and the Kryloff-Bogoliuboff reduction: not computed, the "
                     f"record holds {cycles:.1f} cycles of the slower arm in {t.size} stations; "
                     f"they need sections of ≥ {SECTION_CYCLES} cycles and ≥ {MIN_WINDOW} "
                     f"points ({window} here), at least {MIN_SECTIONS} of them, over a record "
                     f"of ≥ {MIN_RECORD_WINDOWS} sections' length (the amplitude must change "
                     "between sections)")
        return None, None, False
    try:
        sec = sectional_epicyclic(t, fp.alpha, fp.beta, fp.sigma_alpha, fp.sigma_beta,
                                  window=window, step=step, variable="time",
                                  trim_rate=spin if trim else None)
    except (MotionFitError, ValueError) as exc:
        notes.append(f"sectional fits: not computed ({exc})")
        return None, None, False
    cond_t = replace(cond, drag_coefficient=None)
    spin_fit = lc.spin_from_fit if lc is not None else 0.0
    if spin is None and lc is not None and abs(spin_fit) > 3 * lc.spin_from_fit_sigma:
        notes.append(f"Kryloff-Bogoliuboff reduction: not computed, the arms show a spin of "
                     f"{pm(spin_fit, lc.spin_from_fit_sigma, 'rad/s')} and none was given "
                     "(--spin)")
        return sec, None, False
    if spin is None:
        notes.append("Kryloff-Bogoliuboff reduction: no spin given, taken as 0 (the arms' "
                     "frequencies are consistent with none)")
    try:
        kb = kb_reduction(sec, cond_t)
    except ValueError as exc:
        notes.append(f"Kryloff-Bogoliuboff reduction: not computed ({exc})")
        return sec, None, False
    if lc is None or lc.C_L_alpha is None:
        notes.append("Kryloff-Bogoliuboff damping and Magnus terms include the flight path's "
                     "turning by lift (no C_Lα from the swerve)")
        return sec, kb, False
    # free flight: the sections' damping is D - a and their Magnus term T + P a (docs/motion.md)
    a = cond.density_kg_m3 * cond.S * cond.speed_m_s * lc.C_L_alpha / (2 * cond.mass_kg)
    _, s_d, ix_i = cond.scales()
    lift = {"Cmq_sum0": kb.Cmq_sum0 + a * s_d}
    if spin:
        lift["Cm_p_alpha0"] = kb.Cm_p_alpha0 - ix_i * a * s_d     # P a s_d / p
    return sec, replace(kb, **lift), True


__all__ = ["FlightPathAngles", "ShotMotion", "analyse_shot", "conditions_of",
           "flight_path_angles", "min_points"]
