"""``cadra2 motion TRAJECTORY [...] -o OUT_DIR``: the classic angular-motion reduction of a
range shot (issue 19 part 4; docs/motion.md, "cadra2 motion").

For each shot (stage one's trajectory file and the shot file it names, read as ``cadra2 fit``
reads them, :func:`cadra.fitting.inputs.load_shots`):

1. the cg's positions (the reference point moved along the measured axis by the shot file's
   axial cg offset) are fitted with a low-order polynomial in time (default quadratic: gravity
   and drag); its derivative is the mean flight path, with the inclinations
   γ = asin(v_z/V) (+ up) and χ = asin(v_y/V) (+ port) (docs/conventions.md);
2. the angle of attack and sideslip relative to that path are α = θ − γ and β = ψ − χ (θ, ψ
   the measured axis inclinations): ξ = β + iα, the sign convention of docs/motion.md;
3. the epicyclic fit (:func:`cadra.motion.fit_epicyclic`; tricyclic with a trim arm at the
   roll rate when ``--spin`` is given) in distance or time, the Nonplanar Ratio, the lift
   slope from the swerve and the linear-theory coefficients with sigmas
   (:func:`cadra.motion.linear_coefficients`), the flight conditions from the shot file
   (mass, inertias, diameter, air density) and the trajectory (speed, C_D; as ``cadra2 fit``'s
   starting values, :func:`cadra.fitting.start.estimate_motion`);
4. when the record holds enough cycles, overlapping sectional fits in time and the
   Kryloff-Bogoliuboff reduction (:func:`cadra.motion.kb_reduction`).

Writes ``report.md``, ``angles.csv``, ``arms.csv``, ``coefficients.csv``, ``yaw_card.png``,
``arms.png`` and, with sections, ``sectional.png``; what was not computed is said, with why.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from cadra.cli._format import HelpFormatter, add_verbosity, warn
from cadra.numfmt import pm

PROG = "cadra2 motion"
#: what a refused input raises (FitDataError and bad arguments are ValueErrors)
_REFUSED = (ValueError, KeyError, FileNotFoundError)
#: sectional fits: a window spans this many cycles of the slower arm, at least MIN_WINDOW
#: points, and the K-B reduction needs at least MIN_SECTIONS windows
SECTION_CYCLES = 1.2
MIN_WINDOW = 12
MIN_SECTIONS = 5
#: ... over a record at least this many windows long (independent material for the trend)
MIN_RECORD_WINDOWS = 3
DEG = math.degrees(1.0)


@dataclass(frozen=True)
class ShotMotion:
    """One shot's reduction: the angle history relative to the mean flight path and what was
    fitted to it (None where not computed; ``notes`` says why)."""

    shot_id: str
    variable: str
    stations: np.ndarray
    t_s: np.ndarray
    x_m: np.ndarray              # the cg's downrange distance on the fitted path
    alpha: np.ndarray            # rad, relative to the mean flight path
    beta: np.ndarray
    sigma_alpha: np.ndarray
    sigma_beta: np.ndarray
    path_up: np.ndarray          # flight-path inclinations gamma (+ up), chi (+ port), rad
    path_port: np.ndarray
    fit: object                  # cadra.motion.EpicyclicFit
    conditions: object           # cadra.motion.FlightConditions (in the fit's variable)
    npr: object
    coefficients: object | None
    swerve: object | None
    sections: object | None = None
    kb: object | None = None
    kb_lift_corrected: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def s(self) -> np.ndarray:
        return self.x_m if self.variable == "distance" else self.t_s


def _path(t, pos, sig, degree):
    """Polynomials of the cg's x, y, z against time (weighted); returns (coefficients, t0)."""
    t0 = float(np.mean(t))
    return [np.polyfit(t - t0, pos[:, j], degree, w=1.0 / sig[:, j]) for j in range(3)], t0


def flight_path_angles(shot, degree: int = 2):
    """The shot's angles relative to the mean flight path (module doc, steps 1-2).

    Returns ``(keep, t, x, alpha, beta, sigma_alpha, sigma_beta, gamma, chi, cg)`` over the
    stations with both angles and a position measured; ``cg`` (n, 3) the cg positions (m).
    Approximation: α = θ − γ, β = ψ − χ are the angles between the axis and the path to first
    order (the neglected terms are products of two angles, < 0.1 % of the angle at 5°); the
    path is the polynomial's, so the swerve's oscillation stays in the angles, which changes
    the arms' amplitudes by the factor 1 + a/r_j (~1 %, a the lift's turning rate) but not
    their exponents.
    """
    from cadra.conventions import axis_from_inclinations

    m, sg = shot.meas, shot.sigma
    keep = np.all(np.isfinite(m[:, :5]), axis=1)       # x, y, z, theta, psi (not the roll)
    n = int(keep.sum())
    if n < degree + 2:
        raise ValueError(f"{shot.source.get('trajectory_file', shot.shot_id)}: {n} station(s) "
                         f"with position and both angles (theta, psi) measured; the flight "
                         f"path's degree-{degree} polynomial needs at least {degree + 2}")
    t, m, sg = shot.t_s[keep], m[keep], sg[keep]
    axes = np.array([axis_from_inclinations(th, ps) for th, ps in m[:, 3:5]])
    cg = m[:, :3] + shot.rigid.cg_from_ref_body_m[0] * axes   # on the axis: no roll needed
    coef, t0 = _path(t, cg, sg[:, :3], degree)
    v = np.array([np.polyval(np.polyder(c), t - t0) for c in coef]).T
    speed = np.linalg.norm(v, axis=1)
    gamma, chi = np.arcsin(v[:, 2] / speed), np.arcsin(v[:, 1] / speed)
    x = np.polyval(coef[0], t - t0)
    return (keep, t, x, m[:, 3] - gamma, m[:, 4] - chi, sg[:, 3], sg[:, 4], gamma, chi, cg)


def _conditions(shot, spin: float, variable: str):
    from cadra.fitting.start import estimate_motion
    from cadra.motion import FlightConditions

    est = estimate_motion(shot)
    r = shot.rigid
    inertia = r.inertia_body_kg_m2
    return FlightConditions(
        mass_kg=r.mass_kg, Ix_kg_m2=float(inertia[0, 0]),
        I_kg_m2=float(0.5 * (inertia[1, 1] + inertia[2, 2])), d_m=r.d_m,
        density_kg_m3=r.density_kg_m3, speed_m_s=est.speed_m_s, spin_rad_s=spin,
        drag_coefficient=est.cd if variable == "distance" else None), est


def _min_points(trim: bool, offset: bool) -> int:
    n_const = 8 + 2 * int(trim) + 2 * int(offset)
    return max(n_const // 2 + 2, 6)


def analyse_shot(shot, *, variable: str = "distance", spin: float | None = None,
                 offset: bool = False, nonrolling: bool = False, degree: int = 2,
                 window: int | None = None, step: int | None = None) -> ShotMotion:
    """The reduction of one :class:`cadra.fitting.data.ShotData` (module doc). Raises
    ValueError for a record that cannot be reduced (too few stations), and
    :class:`cadra.motion.MotionFitError` when the epicyclic fit does not converge."""
    from cadra.motion import (
        fit_epicyclic,
        lift_from_swerve,
        linear_coefficients,
        nonplanar_ratio_of_fit,
    )

    notes: list[str] = []
    keep, t, x, alpha, beta, sa, sb, gamma, chi, cg = flight_path_angles(shot, degree)
    need = _min_points(spin is not None, offset)
    form = "tricyclic" if spin is not None else "epicyclic"
    if t.size < need:
        raise ValueError(f"{shot.source.get('trajectory_file', shot.shot_id)}: {t.size} "
                         f"station(s) with position and both angles (theta, psi) measured; "
                         f"the {form} fit needs at least {need}")
    cond, est = _conditions(shot, spin or 0.0, variable)
    s = x if variable == "distance" else t
    per_s = cond.speed_m_s if variable == "distance" else 1.0
    trim = None if spin is None else spin / per_s
    fit = fit_epicyclic(s, alpha, beta, sa, sb, trim_rate=trim, offset=offset,
                        nonrolling=nonrolling, variable=variable)
    npr = nonplanar_ratio_of_fit(fit, float(s[0]), float(s[-1]))
    if cg[:, 0].size >= 8:
        psig = np.hypot(shot.sigma[keep, 1], shot.sigma[keep, 2]) / math.sqrt(2)
        sw = lift_from_swerve(fit, s, cg[:, 1], cg[:, 2], psig, conditions=cond,
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
    sections, kb, corrected = _sectional(t, alpha, beta, sa, sb, fit, lc, cond, spin, window,
                                         step, notes)
    return ShotMotion(shot.shot_id, variable, shot.stations[keep], t, x, alpha, beta, sa, sb,
                      gamma, chi, fit, cond, npr, lc, sw, sections, kb, corrected,
                      tuple(notes))


def epicyclic_estimates(shots) -> list:
    """Each shot's :class:`cadra.fitting.start.MotionEstimate` for ``cadra2 fit``'s starting
    values, with C_mα and C_mq + C_mα̇ from the epicyclic fit's arms (:func:`analyse_shot`:
    linear theory with the swerve's lift, docs/motion.md) where that fit converges and
    determines them (C_mα at least 3σ from zero), and the spin (ω_1 + ω_2) I/I_x where it
    is 3σ from zero (the starting state spins at it). The damped sines of θ and ψ that the
    starting values otherwise use see one frequency; a spinning body has two, and a
    gyroscopically stable one (C_mα > 0) has no pitch frequency that gives the sign.
    A shot the fit cannot reduce (a mounted record, too few stations) keeps the plain
    estimate; pure function of the shots (a campaign's scheduler can ship it). A free flight in
    a wind tunnel is fitted in time against the stream (:func:`_stream_coefficients`)."""
    from cadra.fitting.start import estimate_motion
    from cadra.motion import MotionFitError

    out = []
    for shot in shots:
        est = estimate_motion(shot)
        kind = shot.rigid.mode.kind
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


def _stream_coefficients(shot):
    """Linear-theory coefficients of a free flight in a wind tunnel (docs/dynamics.md, test
    modes): the axis angles θ, ψ are the angles to the stream (+x), the epicyclic fit runs in
    time at the rms air-relative speed over the record, and the flight path's turning by lift
    is left out (the drift across the stream is slow; first order in the lift, as on a
    gimbal)."""
    from cadra.motion import fit_epicyclic, linear_coefficients

    m, sg = shot.meas, shot.sigma
    ok = np.isfinite(m[:, 3]) & np.isfinite(m[:, 4])
    if ok.sum() < _min_points(False, False):
        raise ValueError(f"{shot.shot_id}: {int(ok.sum())} frames with both angles")
    fit = fit_epicyclic(shot.t_s[ok], m[ok, 3], m[ok, 4], sg[ok, 3], sg[ok, 4],
                        variable="time")
    cond, _ = _conditions(shot, 0.0, "time")        # the stream's speed
    # the air-relative speed w = U + v_x falls as the model drifts with the stream: the
    # frequencies follow the mean dynamic pressure, so the speed is the rms of w over the
    # record (v_x from a quadratic in time of the measured x, when positions are measured)
    hx = np.isfinite(m[:, 0])
    if hx.sum() >= 3:
        vx = np.polyval(np.polyder(np.polyfit(shot.t_s[hx], m[hx, 0], 2)), shot.t_s[ok])
        cond = replace(cond, speed_m_s=float(np.sqrt(np.mean((cond.speed_m_s + vx) ** 2))))
    return linear_coefficients(fit, cond)


def start_estimates(shots, how: str = "auto"):
    """The estimates behind ``cadra2 fit --start HOW`` (None: the fitter's own).

    ``linear``: the damped sines of θ and ψ (:func:`cadra.fitting.start.estimate_motion`);
    ``epicyclic``: :func:`epicyclic_estimates` for every shot; ``auto`` (default): the
    epicyclic estimate for a shot whose arms show a spin (3σ), the damped sines otherwise.
    Measured by ``tools/bench_starts.py`` (docs/fitting.md, "Starting values"): on a
    gyroscopically stable body the epicyclic start has the right sign of C_mα and the spin,
    and converges in half the iterations; on a non-spinning one the two starts agree."""
    if how == "linear":
        return None
    epi = epicyclic_estimates(shots)
    if how == "epicyclic":
        return epi
    if how != "auto":
        raise ValueError(f"--start {how!r}: expected auto, linear or epicyclic")
    # a shot without a spin keeps its damped sines: the estimate without the arms' fields
    return [e if np.isfinite(e.spin_rad_s)
            else replace(e, cm_alpha=math.nan, cmq_sum=math.nan, spin_rad_s=math.nan)
            for e in epi]


def _sectional(t, alpha, beta, sa, sb, fit, lc, cond, spin, window, step, notes):
    """Sectional fits in time and the K-B reduction when the record allows (else a note)."""
    from dataclasses import replace

    from cadra.motion import MotionFitError, kb_reduction, sectional_epicyclic

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
        sec = sectional_epicyclic(t, alpha, beta, sa, sb, window=window, step=step,
                                  variable="time", trim_rate=spin)
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


def add_parser(sub) -> argparse.ArgumentParser:
    """Register ``cadra2 motion`` on ``cadra2``'s subparsers."""
    p = sub.add_parser(
        "motion", help="epicyclic fit, linear-theory and K-B coefficients, yaw card",
        description="The classic angular-motion reduction of each shot: the angle of attack "
        "and sideslip relative to the mean flight path (axis inclinations minus the path's, "
        "from a polynomial fit of the cg positions), the epicyclic fit (tricyclic with "
        "--spin) with sigmas, the Nonplanar Ratio, C_L_alpha from the swerve, linear-theory "
        "C_m_alpha, C_mq + C_m_alpha_dot and C_mp_alpha with sigmas, and sectional fits with "
        "the Kryloff-Bogoliuboff reduction when the record holds enough cycles. Writes "
        "report.md, angles.csv, arms.csv, coefficients.csv and plots (yaw card, arms against "
        "distance, sectional coefficients against amplitude); docs/motion.md.",
        formatter_class=HelpFormatter)
    add_verbosity(p, top=False)
    p.set_defaults(func=run)
    p.add_argument("trajectories", nargs="+",
                   help="stage one's trajectory.csv files (or their directories)")
    p.add_argument("-o", "--output", required=True, help="output directory (must not exist)")
    p.add_argument("--shot", action="append",
                   help="shot file of each trajectory, same order (default: the one the "
                        "trajectory file names)")
    p.add_argument("--variable", choices=("distance", "time"), default="distance",
                   help="the fit's independent variable")
    p.add_argument("--spin", action="append", type=float, metavar="RAD_S",
                   help="the model's roll rate p, rad/s, right-handed about the nose (stage "
                        "one does not see roll): one value for every shot or one per "
                        "trajectory; gives the tricyclic fit (trim arm at p) and C_mp_alpha "
                        "(default: none, epicyclic fit)")
    p.add_argument("--offset", action="store_true",
                   help="fit a constant angle too (a fixed trim)")
    p.add_argument("--nonrolling", action="store_true",
                   help="seed 002's nonrolling-axis correction (docs/motion.md)")
    p.add_argument("--path-degree", type=int, default=2,
                   help="degree of the polynomials in time fitted to the cg positions for "
                        "the mean flight path")
    p.add_argument("--window", type=int, default=None,
                   help="points per sectional fit (default: 1.2 cycles of the slower arm, at "
                        "least 12)")
    p.add_argument("--step", type=int, default=None,
                   help="points between sections (default: a tenth of the window)")
    p.add_argument("--sigma-time-s", type=float, default=0.0,
                   help="spark-time sigma, s (adds V sigma_t to the x sigma)")
    p.add_argument("--min-sigma-position-m", type=float, default=0.0,
                   help="floor of the stage-one position sigmas, m")
    p.add_argument("--min-sigma-angle-deg", type=float, default=0.0,
                   help="floor of the stage-one angle sigmas, deg")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    return p


def _refused(exc: Exception) -> int:
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
    print(f"{PROG}: {msg}", file=sys.stderr)
    return 1


def _spins(args, n: int) -> list[float | None]:
    given = args.spin or []
    if len(given) not in (0, 1, n):
        raise ValueError(f"--spin: give one value for every shot or one per trajectory "
                         f"({n}), got {len(given)}")
    if any(not math.isfinite(v) for v in given):
        raise ValueError("--spin: must be finite")
    return [None] * n if not given else (given * n if len(given) == 1 else list(given))


def run(args) -> int:
    """``cadra2 motion`` (module doc); returns the exit status."""
    from tqdm import tqdm

    from cadra.fitting.inputs import load_shots
    from cadra.motion import MotionFitError

    quiet = bool(getattr(args, "quiet", False))
    verbose = bool(getattr(args, "verbose", False)) and not quiet
    out = Path(args.output)
    try:
        if args.path_degree < 1:
            raise ValueError(f"--path-degree: at least 1, got {args.path_degree}")
        shots, _ = load_shots(args.trajectories, args.shot, sigma_time_s=args.sigma_time_s,
                              min_sigma_position_m=args.min_sigma_position_m,
                              min_sigma_angle_deg=args.min_sigma_angle_deg)
        spins = _spins(args, len(shots))
        results = []
        for shot, spin in tqdm(list(zip(shots, spins, strict=True)), desc="motion",
                               disable=quiet or len(shots) < 2, file=sys.stderr, leave=False):
            if not shot.has_angles:
                raise ValueError(f"{shot.source.get('trajectory_file', shot.shot_id)}: no "
                                 "measured angles (theta, psi): nothing to reduce")
            try:
                results.append(analyse_shot(
                    shot, variable=args.variable, spin=spin, offset=args.offset,
                    nonrolling=args.nonrolling, degree=args.path_degree, window=args.window,
                    step=args.step))
            except MotionFitError as exc:
                raise ValueError(f"{shot.shot_id}: {exc}") from None
    except _REFUSED as exc:
        return _refused(exc)
    from cadra.cli._motion_output import console_lines, write_outputs

    files = write_outputs(results, out, overwrite=args.overwrite, command=vars(args))
    for r in results:
        for w in _warnings(r):
            warn(PROG, w)
    if not quiet:
        for line in console_lines(results, verbose=verbose):
            print(line)
    n_kb = sum(r.kb is not None for r in results)
    print(f"motion: {len(results)} shot(s) reduced ({results[0].fit.variable}); "
          f"linear-theory coefficients for {sum(r.coefficients is not None for r in results)}, "
          f"K-B reduction for {n_kb}")
    if not quiet:
        print(f"wrote {out}/ ({', '.join(files)})")
    return 0


def _warnings(r: ShotMotion) -> list[str]:
    out = []
    if r.fit.chi2_dof > 2.0:
        out.append(f"{r.shot_id}: chi^2/dof = {r.fit.chi2_dof:.3g} > 2: the epicyclic form or "
                   "the angle sigmas do not describe the motion (sigmas scaled by it)")
    lc, spin = r.coefficients, r.conditions.spin_rad_s
    if lc is not None and spin and abs(lc.spin_from_fit - spin) > 3 * lc.spin_from_fit_sigma:
        out.append(f"{r.shot_id}: the arms' frequencies give a spin of "
                   f"{pm(lc.spin_from_fit, lc.spin_from_fit_sigma, 'rad/s')}, not the "
                   f"{spin:g} rad/s given")
    if not np.all(np.isfinite(r.fit.sigmas)):
        out.append(f"{r.shot_id}: some fitted constants are not determined by the data "
                   "(infinite sigma)")
    return out


__all__ = ["ShotMotion", "add_parser", "analyse_shot", "flight_path_angles", "run"]
