"""Seed 004's steps 1 and 2 on top of the fitter: single fits and quasi-linear trends.

Seed 004 ("Data Reduction and Analysis") reduces the range data in three steps:

1. **Single fits** (:func:`single_fits`): each shot alone, with a *linear* model (bundled
   ``linear_template_sigma`` for symmetric bodies, ``linear_template_alpha_beta`` for lifting
   ones; :func:`linear_template_for`). The fitted values are quasi-linear, motion-averaged
   coefficients; each row also carries the shot's amplitude measures (alpha_rms, sigma_rms, ...)
   computed along the *fitted* trajectory (:func:`amplitude_measures`).
2. **Quasi-linear trends** (:func:`quasi_linear_summary`, :func:`plot_quasi_linear`): an average
   coefficient plotted against an amplitude measure. "If there is no nonlinearity with alpha,
   the quasi-linear data plotted versus alpha_rms will fall on a straight line"; the summary fits
   that weighted line and says, by the chi^2 p-value, whether a line is consistent with the
   points. The line's intercept is the small-amplitude value (seed 004 used it for the peak of
   C_mq at sigma = 0).
3. Multi-fits with the nonlinear forms so chosen (:func:`cadra.fitting.solver.fit`), and
   **hold-one-parameter studies** (:mod:`cadra.studies.holdone`; seed 004 "Uncertainties",
   Fig. 15).

Plots and the written folder: :mod:`cadra.report.studies`.

Everything here is a module-level function over plain data (:class:`ShotData`,
:class:`cadra.aero.AeroModel`, numbers, pandas tables), so a scheduler (Dask, a process pool)
can ship the work: :func:`single_fit` is the per-shot unit :func:`single_fits` maps over, and
:func:`hold_one_refit` the per-value unit of :func:`hold_one_study`. An ``initial_states``
callable must be picklable too (a module-level function) for that.

Angles (docs/conventions.md, classical: 0 = nose forward): alpha = atan2(w, u),
beta = asin(v / V), sigma = acos(u / V) from the air-relative velocity in body axes, as
:func:`cadra.dynamics.trajectory.truth_table` computes the truth. Tables give angles in deg,
positions in m, and parameter values in SI (radians for angle parameters such as
``alpha_ref``), as :meth:`cadra.aero.AeroModel.with_values` takes them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from cadra.aero import AeroModel, load_bundled_model
from cadra.channels import OBSERVED
from cadra.conventions import axis_from_inclinations
from cadra.dynamics.observe import air_angles, observe
from cadra.fitting.problem import FitProblem, result_problem
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import Integration
from cadra.fitting.solver import FitOptions, fit
from cadra.flight.data import CHANNELS, ShotData

#: an initial-state source: per-shot (13,) states, or ``f(shot, model) -> (13,) state``
InitialStates = Sequence[np.ndarray] | Callable[[ShotData, AeroModel], np.ndarray]

#: p-value of the straight line's chi^2 below which the quasi-linear points define a curve
LINE_P_THRESHOLD = 0.05

#: cg offset from the symmetry axis (m) above which a body counts as lifting
LIFTING_CG_OFFSET_M = 1e-6

#: channel -> (display scale from SI, display unit), from the channel registry
_CHANNEL_SCALE = {c.name: (c.display_scale, c.display_unit) for c in OBSERVED}
#: a single fit whose chi^2/nu exceeds this is flagged: its sigmas are not meaningful
SINGLE_FIT_CHI2_WARN = 10.0


# --------------------------------------------------------------------------- helpers


def linear_template_for(shot: ShotData) -> AeroModel:
    """The bundled linear single-fit model for a shot's body.

    A body whose cg lies off its symmetry axis (more than :data:`LIFTING_CG_OFFSET_M`; seed
    004's M2/M3 lifting capsules) gets ``linear_template_alpha_beta``; an axisymmetric one (M1,
    spheres, cones) ``linear_template_sigma``. Starting values are the templates' own (Table 4
    M1 M1.10 and M2 M0.70); replace them with linear-theory estimates where available.
    """
    off = np.asarray(shot.rigid.cg_from_ref_body_m, dtype=float)[1:]
    lifting = float(np.hypot(*off)) > LIFTING_CG_OFFSET_M
    return load_bundled_model("linear_template_alpha_beta" if lifting
                              else "linear_template_sigma")


def initial_state_of(initial_states: InitialStates, k: int, shot: ShotData,
                   model: AeroModel) -> np.ndarray:
    if callable(initial_states):
        y = initial_states(shot, model)
    else:
        y = initial_states[k]
    y = np.asarray(y, dtype=float)
    if y.shape != (13,):
        raise ValueError(f"initial state of shot {shot.shot_id} must have shape (13,), "
                         f"got {y.shape}")
    return y


def check_count(shots, initial_states):
    if not callable(initial_states) and len(initial_states) != len(shots):
        raise ValueError(f"{len(shots)} shots but {len(initial_states)} initial states")


def _alpha_centre(model: AeroModel) -> float:
    """Centre of alpha_rms, rad: the model's ``alpha_ref`` if it has one, else 0."""
    return model.parameter("alpha_ref").value if "alpha_ref" in model.names else 0.0


def fitted_states(shot: ShotData, model: AeroModel, state: np.ndarray, t0_s: float,
                  times_s: np.ndarray | None = None,
                  integration: Integration | None = None, extras: Sequence = ()
                  ) -> np.ndarray:
    """(n, 13) states of the trajectory through ``state`` at ``t0_s`` (a fitted shot's
    :class:`cadra.fitting.result.ShotFit` ``state``/``t0_s``: the shot's epoch) with
    ``model``'s values and the fit's ``extras`` (physics extras on at their values), at
    ``times_s`` (any order; default: the shot's spark times), predicted by the fit's forward
    model (:class:`cadra.fitting.problem.FitProblem`). (The fixed-step
    :func:`cadra.dynamics.setup.propagate_states` at the simulator's 25 us truth step is off by
    up to 2e-5 deg on M1-2366 at the kinks of Table 4's max(...) C_mq; the adaptive run agrees
    with a 1 us fixed-step run to 2e-7 deg.)
    """
    problem = _problem(shot, model, state, t0_s, integration, extras)
    return problem.states_of(0, times=shot.t_s if times_s is None else times_s)


def _problem(shot, model, state, t0_s, integration, extras) -> FitProblem:
    if float(t0_s) != float(shot.t_s[shot.epoch_index]):
        raise ValueError(f"{shot.shot_id}: t0_s = {t0_s} s is not the shot's epoch "
                         f"({shot.t_s[shot.epoch_index]} s, its middle station)")
    return FitProblem((shot,), model, (np.asarray(state, dtype=float),), tuple(extras),
                      integration=integration or Integration())


def aero_angle_history(shot: ShotData, states: np.ndarray,
                       phys: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Aerodynamic angles (rad) and Mach number along (n, 13) states of ``shot``
    (:func:`cadra.dynamics.observe.air_angles`; ``phys``: the physics the states were
    integrated with, a fit's wind extras included): ``alpha``, ``beta``, ``sigma``, ``mach``
    and ``air_dir_F`` (n, 3) unit air-relative velocity in F.
    """
    a = air_angles(states, shot.rigid, phys=phys)
    return {"alpha": a["alpha_rad"], "beta": a["beta_rad"], "sigma": a["sigma_rad"],
            "mach": a["mach"], "air_dir_F": a["air_dir_F"]}


def amplitude_measures(shot: ShotData, model: AeroModel, state: np.ndarray, t0_s: float, *,
                       samples: int | None = None,
                       integration: Integration | None = None,
                       extras: Sequence = ()) -> dict[str, float]:
    """A shot's amplitude measures along the trajectory fitted to it.

    Parameters
    ----------
    shot : the shot (its spark times, body and air).
    model : the fitted model (its values fly the trajectory; its ``alpha_ref``, if any, centres
        ``alpha_rms_deg``).
    state, t0_s : the fitted (13,) state and its epoch, s.
    samples : None (default): the angles at the shot's stations, as the range saw the motion;
        an integer: that many equally spaced times from the first to the last station (an
        rms over the motion rather than over the sparks).
    integration : integrator settings (:func:`fitted_states`).
    extras : the fit's extras (:meth:`cadra.fitting.result.FitResult.extras_at_values`):
        their physics flies the trajectory.

    Returns
    -------
    dict of
    ``alpha_rms_deg`` : rms of (alpha - alpha_c), deg, where alpha_c is the model's
        ``alpha_ref`` parameter when it has one (the lifting template's expansion point, near
        the trim; seed 004 Table 4's "sin alpha - sin alpha_ref") and 0 otherwise (the trim of a
        symmetric body, classical convention);
    ``alpha_std_deg`` : rms of alpha about its own mean, deg (the oscillation amplitude
        whatever the trim);
    ``alpha_mean_deg``, ``beta_mean_deg`` : means, deg;
    ``beta_rms_deg`` : rms of beta (about 0), deg;
    ``sigma_rms_deg`` : rms of the total angle of attack sigma (about 0), deg;
    ``sigma_max_deg`` : its maximum, deg;
    ``mach_mean`` : mean air-relative Mach number.
    """
    times = shot.t_s if samples is None else np.linspace(shot.t_s[0], shot.t_s[-1],
                                                          int(samples))
    problem = _problem(shot, model, state, t0_s, integration, extras)
    states = problem.states_of(0, times=times)
    if not np.all(np.isfinite(states)):
        return dict.fromkeys(_AMPLITUDE_KEYS, math.nan)
    h = aero_angle_history(shot, states, problem.physics(0)[0])
    a, b, s = (np.degrees(h[k]) for k in ("alpha", "beta", "sigma"))
    ac = math.degrees(_alpha_centre(model))
    return {
        "alpha_rms_deg": float(np.sqrt(np.mean((a - ac) ** 2))),
        "alpha_std_deg": float(np.std(a)),
        "alpha_mean_deg": float(np.mean(a)),
        "beta_rms_deg": float(np.sqrt(np.mean(b**2))),
        "beta_mean_deg": float(np.mean(b)),
        "sigma_rms_deg": float(np.sqrt(np.mean(s**2))),
        "sigma_max_deg": float(np.max(s)),
        "mach_mean": float(np.mean(h["mach"])),
    }


_AMPLITUDE_KEYS = ("alpha_rms_deg", "alpha_std_deg", "alpha_mean_deg", "beta_rms_deg",
                   "beta_mean_deg", "sigma_rms_deg", "sigma_max_deg", "mach_mean")


def sigma_residual_rms_deg(result: FitResult, shots: Sequence[ShotData],
                           integration: Integration | None = None) -> float:
    """Rms difference (deg) between the "experimental" and calculated total angle sigma.

    Seed 004's Fig. 15 discussion quotes "the rms difference between the calculated and
    experimental values of sigma". sigma needs the air-relative velocity, which the range does
    not measure directly: both sigmas here use the fitted trajectory's velocity direction at
    each station; the experimental one takes the measured nose axis (from theta, psi), the
    calculated one the fitted axis. NaN when no shot has angle measurements.
    """
    problem = result_problem(result, shots)
    if integration is not None:
        problem = replace(problem, integration=integration)
    theta, psi = CHANNELS.index("theta"), CHANNELS.index("psi")
    diffs = []
    for k, sd in enumerate(problem.shots):
        if not sd.has_angles:
            continue
        states = problem.states_of(k)
        if not np.all(np.isfinite(states)):
            return math.nan
        phys, ref = problem.physics(k)
        e_v = aero_angle_history(sd, states, phys)["air_dir_F"]
        axis_fit = observe(states, ref)["axis"]
        for i in range(len(sd.t_s)):
            th, ps = sd.meas[i, theta], sd.meas[i, psi]
            if not (np.isfinite(th) and np.isfinite(ps)):
                continue
            a_meas = axis_from_inclinations(th, ps)
            s_meas = math.acos(min(1.0, max(-1.0, float(a_meas @ e_v[i]))))
            s_fit = math.acos(min(1.0, max(-1.0, float(axis_fit[i] @ e_v[i]))))
            diffs.append(s_meas - s_fit)
    if not diffs:
        return math.nan
    return math.degrees(math.sqrt(float(np.mean(np.square(diffs)))))


def rms_columns(rms: dict) -> dict:
    out = {}
    for ch in CHANNELS:
        scale, unit = _CHANNEL_SCALE[ch]
        out[f"{ch}_rms_{unit}"] = rms.get(ch, math.nan) * scale
    return out


def parameter_columns(result: FitResult, exclude: str | None = None) -> dict:
    out = {}
    scaled = result.aero_sigma_scaled
    for n, v, s, ss in zip(result.aero_names, result.aero_values, result.aero_sigma, scaled,
                           strict=True):
        if n == exclude:
            continue
        out[n] = float(v)
        out[f"{n}_sigma"] = float(s)
        out[f"{n}_sigma_scaled"] = float(ss)
    return out


# --------------------------------------------------------------------------- step 1


def single_fit(shot: ShotData, model: AeroModel, initial_state: np.ndarray | None, *,
               options: FitOptions | None = None, samples: int | None = None) -> dict:
    """One shot fitted on its own (seed 004 step 1): a row of :func:`single_fits`.

    Parameters
    ----------
    shot : the shot's measurements.
    model : the (linear) model; its free parameters are fitted, starting from its values.
    initial_state : (13,) starting state at the shot's epoch ``shot.t_s[shot.epoch_index]``,
        or None: automatic starting values (:func:`cadra.fitting.fit_shots`: linear theory,
        continuation from film-level sigmas).
    options : fit options (default :class:`FitOptions`).
    samples : where the amplitude measures are taken (:func:`amplitude_measures`).

    Returns
    -------
    dict: ``shot_id``, ``status`` (:data:`cadra.fitting.solver.STATUSES`), ``converged``,
    ``message``, ``iterations``, ``chi2``, ``n_observations``, ``dof``, ``reduced_chi2``; per
    free parameter ``<name>``, ``<name>_sigma`` (covariance) and ``<name>_sigma_scaled``
    (times sqrt(reduced chi^2) when that exceeds 1), SI; residual rms per channel
    ``x_rms_m, y_rms_m, z_rms_m, theta_rms_deg, psi_rms_deg``; and the amplitude measures of
    :func:`amplitude_measures` along the fitted trajectory.
    """
    options = options or FitOptions()
    if initial_state is None:
        from cadra.fitting import fit_shots

        res, _ = fit_shots([shot], model, options=options)
    else:
        res = fit([shot], model, [np.asarray(initial_state, dtype=float)], options=options)
    sf = res.shots[0]
    row = {"shot_id": shot.shot_id, "status": res.status, "converged": bool(res),
           "message": res.message, "iterations": res.iterations, "chi2": res.chi2,
           "n_observations": res.n_observations, "dof": res.dof,
           "reduced_chi2": res.reduced_chi2}
    row.update(parameter_columns(res))
    row.update(rms_columns(sf.rms))
    row.update(amplitude_measures(shot, res.model, sf.state, sf.t0_s, samples=samples,
                                  integration=options.integration,
                                  extras=res.extras_at_values()))
    return row


def single_fits(shots: Sequence[ShotData], model: AeroModel, initial_states: InitialStates, *,
                options: FitOptions | None = None, samples: int | None = None) -> pd.DataFrame:
    """Seed 004 step 1: fit each shot on its own with a linear model.

    Parameters
    ----------
    shots : the shots.
    model : a linear model, e.g. :func:`linear_template_for` or
        ``load_bundled_model("linear_template_sigma")``; every shot starts from its values.
    initial_states : per shot a (13,) state at its epoch, or a callable
        ``(shot, model) -> (13,) state`` (module-level so it pickles), or None: automatic
        starting values per shot (:func:`single_fit`).
    options : fit options.
    samples : where the amplitude measures are taken (:func:`amplitude_measures`).

    Returns
    -------
    DataFrame, one row per shot in the given order (columns: :func:`single_fit`). Rows of fits
    that did not converge are kept, with their status, and left out by
    :func:`quasi_linear_summary`.
    """
    if initial_states is not None:
        check_count(shots, initial_states)
    rows = [single_fit(sd, model, None if initial_states is None
                       else initial_state_of(initial_states, k, sd, model),
                       options=options, samples=samples)
            for k, sd in enumerate(shots)]
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- step 2


def quasi_linear_summary(table: pd.DataFrame, coefficient: str = "Cmq_0",
                         against: str = "alpha_rms_deg", *, sigma_column: str | None = None,
                         converged_only: bool = True,
                         p_threshold: float = LINE_P_THRESHOLD) -> dict:
    """Average (quasi-linear) coefficient against an amplitude measure, with a straight line.

    The line ``y = intercept + slope x`` is a weighted least-squares fit (weights
    1 / sigma^2) of the single-fit values against ``against``; its chi^2 on n - 2 degrees of
    freedom says whether the points lie on a line (seed 004: no nonlinearity in that variable)
    or define a curve.

    Parameters
    ----------
    table : :func:`single_fits` output (any table with the columns named here).
    coefficient : the coefficient column, e.g. ``"Cmq_0"``, ``"Cm_a"``.
    against : the amplitude column, e.g. ``"alpha_rms_deg"``, ``"sigma_rms_deg"``.
    sigma_column : the coefficient's error column (default ``<coefficient>_sigma``, the
        covariance sigma; ``<coefficient>_sigma_scaled`` inflates it by each fit's
        sqrt(reduced chi^2)).
    converged_only : leave out rows whose ``status`` is not ``converged``.
    p_threshold : a line with a chi^2 p-value below this is rejected.

    Returns
    -------
    dict with ``coefficient``, ``against``, ``n``, ``shot_id``, ``x``, ``y``, ``sigma``
    (arrays of the points used), ``excluded`` (list of (shot_id, reason)), ``mean`` and
    ``mean_sigma`` (weighted average coefficient), ``slope``, ``slope_sigma``, ``intercept``
    (the value at zero amplitude), ``intercept_sigma``, ``cov_slope_intercept``, ``chi2``,
    ``dof``, ``reduced_chi2``, ``p_value`` (NaN when dof < 1), ``line_consistent`` (True /
    False; None when dof < 1).
    """
    from scipy.stats import chi2 as chi2_dist

    sigma_column = sigma_column or f"{coefficient}_sigma"
    for col in (coefficient, against, sigma_column):
        if col not in table:
            raise KeyError(f"quasi_linear_summary: no column {col!r} in the table "
                           f"(columns: {list(table.columns)})")
    ids = (table["shot_id"].astype(str).to_numpy() if "shot_id" in table
           else np.array([str(i) for i in table.index]))
    excluded = []
    keep = np.ones(len(table), dtype=bool)
    status = table["status"].to_numpy() if "status" in table else None
    x_all = table[against].to_numpy(float)
    y_all = table[coefficient].to_numpy(float)
    s_all = table[sigma_column].to_numpy(float)
    for i in range(len(table)):
        if converged_only and status is not None and status[i] != "converged":
            excluded.append((ids[i], f"fit {status[i]}"))
        elif not (np.isfinite(x_all[i]) and np.isfinite(y_all[i])):
            excluded.append((ids[i], "no value"))
        elif not (np.isfinite(s_all[i]) and s_all[i] > 0):
            excluded.append((ids[i], f"{sigma_column} = {s_all[i]} (not determined)"))
        else:
            continue
        keep[i] = False
    x, y, s = x_all[keep], y_all[keep], s_all[keep]
    n = int(x.size)
    out = {"coefficient": coefficient, "against": against, "sigma_column": sigma_column,
           "n": n, "shot_id": ids[keep], "x": x, "y": y, "sigma": s, "excluded": excluded}
    nan = math.nan
    out.update(mean=nan, mean_sigma=nan, slope=nan, slope_sigma=nan, intercept=nan,
               intercept_sigma=nan, cov_slope_intercept=nan, chi2=nan, dof=max(n - 2, 0),
               reduced_chi2=nan, p_value=nan, line_consistent=None)
    if n == 0:
        return out
    w = 1.0 / s**2
    S, Sx, Sy = w.sum(), (w * x).sum(), (w * y).sum()
    out["mean"] = float(Sy / S)
    out["mean_sigma"] = float(1.0 / math.sqrt(S))
    if n < 2:
        return out
    Sxx, Sxy = (w * x * x).sum(), (w * x * y).sum()
    det = S * Sxx - Sx * Sx
    if not det > 0:                      # every point at the same amplitude
        return out
    slope = (S * Sxy - Sx * Sy) / det
    intercept = (Sxx * Sy - Sx * Sxy) / det
    chi2 = float((w * (y - intercept - slope * x) ** 2).sum())
    dof = n - 2
    out.update(slope=float(slope), intercept=float(intercept),
               slope_sigma=math.sqrt(S / det), intercept_sigma=math.sqrt(Sxx / det),
               cov_slope_intercept=float(-Sx / det), chi2=chi2, dof=dof)
    if dof >= 1:
        p = float(chi2_dist.sf(chi2, dof))
        out.update(reduced_chi2=chi2 / dof, p_value=p, line_consistent=bool(p >= p_threshold))
    return out


@dataclass(frozen=True)
class SingleFitChecks:
    """What a :func:`single_fits` table can be used for (:func:`check_single_fits`).

    ``trends``: whether the quasi-linear trends can be computed (at least two converged
    single fits: they fit a straight line through the shots' coefficients); ``trends_note``:
    why not, in words ("" when they can); ``warnings``: per shot, fits that did not converge
    and fits whose chi^2/nu exceeds :data:`SINGLE_FIT_CHI2_WARN`."""

    trends: bool
    trends_note: str
    warnings: tuple[str, ...]

    @property
    def messages(self) -> tuple[str, ...]:
        """Every message: the trends' note first, then the shots' warnings."""
        return ((self.trends_note,) if self.trends_note else ()) + self.warnings


def check_single_fits(table: pd.DataFrame) -> SingleFitChecks:
    """Where a :func:`single_fits` table's results are meaningless (:class:`SingleFitChecks`):
    fewer than two converged shots for the quasi-linear trends, fits that did not converge,
    and fits whose chi^2/nu exceeds :data:`SINGLE_FIT_CHI2_WARN` (the model or the sigmas do
    not describe the data: the covariance sigmas mean nothing)."""
    n_ok = int((table["status"] == "converged").sum())
    note = ""
    if n_ok < 2:
        note = (f"quasi-linear trends not computed: they fit a straight line through the "
                f"shots' coefficients against their amplitude, which needs at least two "
                f"converged single fits at different amplitudes ({len(table)} shot(s) "
                f"given, {n_ok} converged); give more shots of the same case")
    out = []
    for _, row in table.iterrows():
        if row["status"] != "converged":
            out.append(f"{row['shot_id']}: fit {row['status']} ({row['message']}); its row is "
                       "not a result")
        elif math.isfinite(row["reduced_chi2"]) and row["reduced_chi2"] > SINGLE_FIT_CHI2_WARN:
            out.append(f"{row['shot_id']}: chi^2/nu = {row['reduced_chi2']:.3g}, far above 1: "
                       "the linear model or the sigmas do not describe this shot, so its "
                       "sigmas are not meaningful (the *_sigma_scaled columns inflate them by "
                       "sqrt(chi^2/nu); a nonlinear model may be needed)")
    return SingleFitChecks(n_ok >= 2, note, tuple(out))


__all__ = [
    "LINE_P_THRESHOLD",
    "SINGLE_FIT_CHI2_WARN",
    "InitialStates",
    "SingleFitChecks",
    "aero_angle_history",
    "amplitude_measures",
    "check_single_fits",
    "fitted_states",
    "linear_template_for",
    "quasi_linear_summary",
    "sigma_residual_rms_deg",
    "single_fit",
    "single_fits",
]
