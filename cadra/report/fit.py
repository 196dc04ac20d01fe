"""The output layer of a stage-two fit: files, a one-page report and plots.

:func:`write_fit_outputs` writes a :class:`cadra.fitting.result.FitResult` to a directory,
atomically (everything is built in a temporary sibling directory and moved into place at the
end by :func:`cadra.atomic.atomic_output_dir`; an existing directory is refused unless
``overwrite=True``; a failure leaves nothing behind):

=============================  =================================================================
file                           contents
=============================  =================================================================
``results.json``               status, statistics, every parameter (value, sigmas, initial
                               value, held, bounds), per-shot fitted state at the epoch with
                               sigmas, residual rms per shot and channel and its noise
                               floor (docs/fitting.md), near-singular directions, warnings.
                               Plain JSON: a value that is not finite (an undetermined
                               sigma) is ``null``.
``coefficients.csv``           :meth:`FitResult.coefficient_table` (seed 004 Table 4 layout)
``covariance.csv``             (J^T W J)^-1, labelled by ``param_names`` (SI, radians)
``correlation.csv``            its correlation form
``correlation_coloured.csv``   correlation of the coloured-residual (sandwich) covariance
``residuals.csv``              one row per measured channel and station: ``measured``,
                               ``fitted``, ``residual``, ``sigma`` in the ``unit`` column's unit
                               (``m`` or ``deg``), ``normalized`` (residual / sigma) and
                               ``leverage`` (the hat matrix's diagonal)
``report.md``                  one page, lmfit-style (see :func:`report_markdown`)
``plots/*.png``                coefficients, angle histories, residuals, 3-D trajectory
=============================  =================================================================

The pure helpers (:func:`results_dict`, :func:`residuals_table`, :func:`report_markdown`,
:func:`fitted_histories`) take plain data and do no I/O; plots live in
:mod:`cadra.report.fit_plots` (matplotlib and pyvista imported lazily).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.aero import AeroModel
from cadra.channels import BY_NAME, N_CHANNELS, OBSERVED, residual
from cadra.dynamics.observe import air_angles
from cadra.fitting.histories import fitted_histories
from cadra.fitting.problem import result_problem
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import LOCAL_NAMES, apply_local, observables
from cadra.flight.data import CHANNELS, ShotData
from cadra.io.plain import plain
from cadra.numfmt import pm
from cadra.report import figures, markdown

#: results.json format tag
RESULTS_FORMAT = "cadra.fit-results/1"
#: |correlation| above which the report lists a pair
REPORT_CORRELATION = 0.9
#: plot files written by :func:`write_fit_outputs` (key -> file name under ``plots/``)
PLOT_FILES = {"coefficients": "coefficients.png", "angles": "angles.png",
              "residuals": "residuals.png", "trajectory3d": "trajectory3d.png"}
#: residual channel -> (unit in the files, factor from SI), from the channel registry
CHANNEL_OUTPUT_UNITS = {c.name: (c.display_unit, c.display_scale) for c in OBSERVED}
#: finite-difference step of the local unknowns (m, m/s, rad, rad/s) for derived sigmas;
#: the maps are linear in position and smooth in rotation (error ~ step^2 ~ 1e-12 relative)
_FD_STEP = 1e-6


# --------------------------------------------------------------------------- plain data


def _shots_by_id(shots: Sequence[ShotData]) -> dict[str, ShotData]:
    return {s.shot_id: s for s in shots}


def _epoch_observables(y: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return observables(y[None, :], ref)[0]


def shot_epoch_table(result: FitResult, shots: Sequence[ShotData]) -> list[dict]:
    """Per shot, the fitted state at the epoch in range-engineer terms, with 1-sigma.

    Reference-point position and nose-axis inclinations get their sigmas from the result's
    covariance of the shot's local unknowns (cg position and attitude correct them both),
    propagated linearly; velocity and body rates are local unknowns themselves. Held
    unknowns contribute nothing; an undetermined one (infinite sigma) makes the derived
    sigmas infinite.
    """
    by_id = _shots_by_id(shots)
    problem = result_problem(result, shots)
    rows = []
    for sf in result.shots:
        sd = by_id.get(sf.shot_id)
        if sd is None:
            raise ValueError(f"no ShotData given for shot {sf.shot_id!r} of the result")
        # the fit's physics (a cg-offset extra moves the reference point, a wind extra the air)
        phys, ref = problem.physics(problem.shot_ids.index(sf.shot_id))
        y = np.asarray(sf.state, dtype=float)
        obs0 = _epoch_observables(y, ref)
        free = list(sf.local_free_indices)
        J = np.zeros((N_CHANNELS, len(free)))
        for c, k in enumerate(free):
            u = np.zeros(len(LOCAL_NAMES))
            u[k] = _FD_STEP
            up = _epoch_observables(apply_local(y, u), ref)
            dn = _epoch_observables(apply_local(y, -u), ref)
            J[:, c] = residual(up, dn) / (2.0 * _FD_STEP)      # the roll wrapped
        idx = [result.param_names.index(f"{sf.shot_id}:{LOCAL_NAMES[k]}") for k in free]
        C = result.covariance[np.ix_(idx, idx)] if idx else np.zeros((0, 0))
        var = np.einsum("ij,jk,ik->i", J, C, J) if idx else np.zeros(N_CHANNELS)
        sig_obs = np.sqrt(np.maximum(var, 0.0))
        local_sig = np.asarray(sf.local_sigma, dtype=float)
        inf_cols = [c for c, k in enumerate(free) if math.isinf(local_sig[k])]
        for c in inf_cols:
            sig_obs[np.abs(J[:, c]) > 1e-12] = math.inf
        air = air_angles(y[None, :], sd.rigid, phys=phys)
        deg = 180.0 / math.pi
        rms = {f"{ch}_{CHANNEL_OUTPUT_UNITS[ch][0]}": sf.rms.get(ch, math.nan)
               * CHANNEL_OUTPUT_UNITS[ch][1] for ch in CHANNELS}
        rows.append({
            "shot_id": sf.shot_id,
            "t0_s": sf.t0_s,
            "epoch_station": int(sd.stations[sd.epoch_index]),
            "n_observations": sf.n_observations,
            "chi2": sf.chi2,
            "local_free": list(sf.local_free),
            "reference_point_m": obs0[:3], "reference_point_sigma_m": sig_obs[:3],
            "velocity_m_s": y[3:6], "velocity_sigma_m_s": local_sig[3:6],
            "speed_m_s": float(np.linalg.norm(y[3:6])),
            "theta_deg": obs0[3] * deg, "theta_sigma_deg": sig_obs[3] * deg,
            "psi_deg": obs0[4] * deg, "psi_sigma_deg": sig_obs[4] * deg,
            # the roll only where measured (else the fit did not determine it)
            "phi_deg": obs0[5] * deg if sd.has_roll else math.nan,
            "phi_sigma_deg": sig_obs[5] * deg if sd.has_roll else math.nan,
            "rates_rad_s": y[10:13], "rates_sigma_rad_s": local_sig[9:12],
            "alpha_deg": air["alpha_rad"][0] * deg, "beta_deg": air["beta_rad"][0] * deg,
            "sigma_deg": air["sigma_rad"][0] * deg, "mach": air["mach"][0],
            "cg_state": y, "local_sigma": dict(zip(LOCAL_NAMES, local_sig, strict=True)),
            "residual_rms": rms,
        })
    return rows


def _left_at_start(value: float, initial: float) -> bool:
    return value == initial or abs(value - initial) <= 1e-12 * max(abs(initial), 1e-300)


def _at_bound(p) -> bool:
    return bool(p.vary and (p.value <= p.min or p.value >= p.max))


def extra_warnings(result: FitResult, start_model: AeroModel | None = None) -> list[str]:
    """Warnings the report adds to the fit's own: free parameters left at their start, and
    free parameters whose sigma is not finite (not determined by the data)."""
    out = []
    if start_model is not None:
        for n in result.aero_names:
            if _left_at_start(result.value(n), start_model.parameter(n).value):
                out.append(f"{n} was left at its starting value {result.value(n):g}: the data "
                           "did not move it (check that it affects the measurements)")
    for n, s in zip(result.aero_names, result.aero_sigma, strict=True):
        if not math.isfinite(s) and not any(d["hold"] == n for d in result.near_singular):
            out.append(f"{n}: sigma is not finite (not determined by the data)")
    return [w for w in out if w not in result.warnings]


def results_dict(result: FitResult, shots: Sequence[ShotData], *,
                 start_model: AeroModel | None = None, title: str | None = None) -> dict:
    """Everything of ``result`` as plain JSON data (what ``results.json`` holds).

    Units are in the key names; model parameter values, sigmas and bounds are SI (radians for
    angle parameters; ``unit`` says how the model file writes them, ``file_value`` is the value
    in that unit). ``initial`` is the value in ``start_model`` (None if not given). Non-finite
    numbers are ``null``.
    """
    sig = dict(zip(result.aero_names, result.aero_sigma, strict=True))
    sig_c = dict(zip(result.aero_names, result.aero_sigma_coloured, strict=True))
    sig_s = dict(zip(result.aero_names, result.aero_sigma_scaled, strict=True))
    ca = result.consider
    cons = {} if ca is None else dict(zip(ca.names, ca.sigma, strict=True))
    params = {}
    for p in result.model.parameters:
        free = p.name in sig
        params[p.name] = {
            "value": p.value, "file_value": p.file_value, "unit": p.unit,
            "sigma": sig.get(p.name) if free else None,
            "sigma_coloured": sig_c.get(p.name) if free else None,
            "sigma_scaled": sig_s.get(p.name) if free else None,
            "initial": (start_model.parameter(p.name).value if start_model is not None
                        else None),
            "held": not free, "min": p.min, "max": p.max, "at_bound": _at_bound(p),
            "held_sigma": p.sigma if not free else None,
            "sigma_consider": cons.get(p.name) if free else None,
            "prior": p.prior, "prior_sigma": p.sigma if p.prior is not None else None,
        }
    out = {
        "format": RESULTS_FORMAT,
        "title": title,
        "status": result.status, "message": result.message, "converged": result.converged,
        "verdict": result.verdict, "chi2_p_value": result.chi2_p_value,
        "chi2": result.chi2, "dof": result.dof, "reduced_chi2": result.reduced_chi2,
        "n_observations": result.n_observations, "n_free": result.n_free,
        "n_priors": result.n_priors, "prior_chi2": result.prior_chi2,
        "iterations": result.iterations, "elapsed_s": result.elapsed_s,
        "chi2_history": list(result.history),
        "model": {"name": result.model.name, "angle_plane": result.model.angle_plane},
        "parameters": params,
        "shots": shot_epoch_table(result, shots),
        "residual_rms_all_shots": {f"{ch}_{CHANNEL_OUTPUT_UNITS[ch][0]}":
                                   v * CHANNEL_OUTPUT_UNITS[ch][1]
                                   for ch, v in result.rms().items()},
        # the rms a correct model would leave (sigma sqrt(1 - leverage)) and the channel's
        # share of the degrees of freedom
        "residual_noise_floor": {f"{ch}_{CHANNEL_OUTPUT_UNITS[ch][0]}":
                                 v * CHANNEL_OUTPUT_UNITS[ch][1]
                                 for ch, v in result.noise_floor().items()},
        "dof_by_channel": result.dof_by_channel(),
        "high_correlations": [{"a": a, "b": b, "r": r}
                              for a, b, r in result.high_correlations(REPORT_CORRELATION)],
        "near_singular": [dict(d) for d in result.near_singular],
        "warnings": list(result.warnings) + extra_warnings(result, start_model),
        "param_names": list(result.param_names),
        "options": result.options,
        # d(free)/d(held) of the holds with an uncertainty (SI), free parameter -> held -> value
        "consider_sensitivity": ({} if ca is None else
                                 ca.sensitivity_table(list(result.aero_names)).to_dict(
                                     orient="index")),
    }
    return plain(out)


def residuals_table(result: FitResult) -> pd.DataFrame:
    """The residuals with angles in degrees and the unit of each row named.

    Columns: ``shot_id``, ``station``, ``t_s``, ``channel``, ``unit`` (``m`` or ``deg``),
    ``measured``, ``fitted``, ``residual`` (measured - fitted), ``sigma`` (all in ``unit``) and
    ``normalized`` (residual / sigma, dimensionless), ``leverage`` (the share of the residual's
    noise the fit absorbs: a correct model leaves sigma sqrt(1 - leverage); dimensionless).
    """
    r = result.residuals
    cols = ["shot_id", "station", "t_s", "channel", "unit", "measured", "fitted", "residual",
            "sigma", "normalized", "leverage"]
    if r is None or len(r) == 0:
        return pd.DataFrame(columns=cols)
    factor = r["channel"].map(lambda c: CHANNEL_OUTPUT_UNITS[c][1]).to_numpy(float)
    out = pd.DataFrame({
        "shot_id": r["shot_id"], "station": r["station"], "t_s": r["t_s"],
        "channel": r["channel"], "unit": r["channel"].map(lambda c: CHANNEL_OUTPUT_UNITS[c][0]),
        "measured": r["measured"].to_numpy(float) * factor,
        "fitted": r["fitted"].to_numpy(float) * factor,
        "residual": r["residual"].to_numpy(float) * factor,
        "sigma": r["sigma"].to_numpy(float) * factor,
        "normalized": r["normalized"].to_numpy(float),
        "leverage": r["leverage"].to_numpy(float)})
    return out.loc[:, cols]


# --------------------------------------------------------------------------- formatting


def _pct(value: float, sigma: float) -> str:
    if not math.isfinite(sigma) or value == 0:
        return "—"
    return f"{100.0 * abs(sigma / value):.2g}%"


def coefficient_markdown(table: pd.DataFrame) -> str:
    """A :meth:`FitResult.coefficient_table` as a Markdown table: coefficient | form |
    A1 ± σ | ... | other (held values marked "(held)", unused cells blank)."""
    ks = sorted(int(c[1:]) for c in table.columns if c[0] == "A" and c[1:].isdigit())
    head = ["coefficient", "form"] + [f"A{k} ± σ" for k in ks] + ["other"]
    rows = []
    for row in table.itertuples(index=False):
        d = row._asdict()
        cells = [f"{d['coefficient']}", f"`{d['form']}`"]
        for k in ks:
            v = d.get(f"A{k}")
            if v is None or (isinstance(v, float) and math.isnan(v)):
                cells.append("")
            elif bool(d.get(f"A{k}_held")):
                cells.append(f"{v:.6g} (held)")
            else:
                cells.append(pm(float(v), float(d.get(f"A{k}_sigma"))))
        cells.append(str(d.get("other") or ""))
        rows.append(cells)
    return "\n".join(markdown.table(head, rows))


def _held_text(p) -> str:
    unit = f" {p.unit}" if p.unit else ""
    if p.sigma > 0.0:
        return f"{p.name} = {p.file_value:g} ± {p.file_sigma:g}{unit}"
    return f"{p.name} = {p.file_value:g}{unit} (exact)"


def consider_lines(ca, names: Sequence[str], at_least: float = 1.0) -> list[str]:
    """What each hold with an uncertainty does to the free parameters: the ones its own ±σ
    moves by ``at_least`` of their conditional sigmas or more, and d(free)/d(held)."""
    shift = ca.shift_per_sigma()
    idx = [ca.names.index(n) for n in names]
    out = ["### What the holds do", ""]
    for j, h in enumerate(ca.held):
        moved = sorted(((abs(shift[i, j]), ca.names[i]) for i in idx
                        if abs(shift[i, j]) >= at_least), reverse=True)
        said = (" and ".join(f"{n} by {m:.2g} σ" for m, n in moved[:4])
                + (f" (and {len(moved) - 4} more)" if len(moved) > 4 else ""))
        out.append(f"- held {h} = {ca.held_values[j]:.6g} ± {ca.held_sigma[j]:.2g} (SI) "
                   + (f"moves {said} over its ±σ: their conditional sigmas are not their "
                      "uncertainty; the consider sigmas above carry it."
                      if moved else f"moves no free parameter by {at_least:g} of its "
                      "conditional sigma over its ±σ."))
    sens = ca.sensitivity_table(list(names))
    out += ["", "d(free)/d(held), SI:", ""]
    out += markdown.table(("parameter", *ca.held),
                          ((n, *(f"{v:.4g}" for v in sens.loc[n])) for n in sens.index))
    return out


def _bounds_text(p) -> str:
    if math.isinf(p.min) and math.isinf(p.max):
        return ""
    return f"[{p.min:g}, {p.max:g}]"


def phases_note(result: FitResult) -> list[str]:
    """The report's lines on the fit's two phases (``fit_shots``' continuation), or none when
    it ran in one: the chi^2 history jumps between them because the weights change."""
    phases = result.options.get("phases") if isinstance(result.options, dict) else None
    if not phases or len(phases) != 2:
        return []
    a, b = phases
    cont = result.options.get("continuation", {})
    floor = ""
    if "position_m" in cont and "angle_rad" in cont:
        floor = (f" ({cont['position_m'] * 1e3:g} mm, "
                 f"{math.degrees(cont['angle_rad']):g} deg)")
    return [f"The fit ran in two phases (continuation, docs/cli.md): {a['iterations']} "
            f"iterations with the sigmas floored at film level{floor}, ending at χ² = "
            f"{a['chi2_end']:.4g} ({a['status']}), then {b['iterations']} with stage one's own "
            f"sigmas from that point, starting at χ² = {b['chi2_start']:.4g}. The χ² history "
            "jumps between the phases because the weights change (stage one's sigmas are "
            "much smaller), not because the fit got worse; the result is the second "
            "phase's.", ""]


def report_markdown(result: FitResult, shots: Sequence[ShotData], *,
                    start_model: AeroModel | None = None, title: str | None = None,
                    plot_files: Mapping[str, str] | None = None,
                    notes: Sequence[str] = (), reference_lines: Sequence[str] = ()) -> str:
    """The one-page fit report (Markdown), lmfit's fit report in a range engineer's units.

    Sections: status; fit statistics; free parameters (value ± sigma (%), coloured and
    scaled sigmas, initial value, bounds, flags) and held ones; the Table 4 coefficient
    table; correlations above 0.9; identifiability (near-singular directions with the
    parameter to hold) and warnings; each shot's fitted state at the epoch; residual rms per
    shot and channel (µm, deg); links to the plots (``plot_files``: key -> relative path).
    """
    name = title or f"{result.model.name}: " + ", ".join(s.shot_id for s in result.shots)
    L = [f"# Stage-two fit: {name}", ""]
    if result.converged:
        L += [f"**Status: converged** — {result.message}", ""]
    else:
        L += [f"**Status: {result.status.upper()} — NOT A RESULT.** {result.message}. The "
              "values below are the best point the fit reached; do not use them as "
              "coefficients.", ""]
    L += ["## Fit statistics", ""]
    L += markdown.table(("quantity", "value"), (
        ("χ²", f"{result.chi2:.6g}"),
        ("degrees of freedom", f"{result.dof} ({result.n_observations} measurements"
                               + (f" + {result.n_priors} Gaussian prior(s)"
                                  if result.n_priors else "")
                               + f" − {result.n_free} free unknowns)"),
        ("reduced χ²", f"{result.reduced_chi2:.4g}"),
        ("shots", len(result.shots)),
        ("iterations", result.iterations),
        ("elapsed", f"{result.elapsed_s:.2f} s")))
    L.append("")
    L += phases_note(result)
    vc = result.options.get("variance_components")
    if vc:
        L += ["### Variance components (`--variance-components`)", "",
              f"Each channel's sigmas were rescaled by the factor its own residuals ask for "
              f"({vc['rounds']} refit round(s)); χ²/ν with stage one's own sigmas was "
              f"{vc['reduced_chi2_before']:.4g}. The sigmas above include the rescaling; a "
              "scale far from 1 is a finding about the stage-one sigmas (docs/fitting.md).", ""]
        L += markdown.table(
            ("channel", "sigma scale", "variance factor", "degrees of freedom"),
            ((ch, f"×{vc['sigma_scale'][ch]:.3f}", pm(f, vc["factor_sigma"][ch]),
              f"{vc['dof'][ch]:.1f}") for ch, f in vc["factors"].items()))
        L.append("")
    if math.isfinite(result.reduced_chi2) and result.reduced_chi2 > 2.0:
        L += [f"Reduced χ² = {result.reduced_chi2:.3g} > 2: the sigmas or the model do not "
              "describe the data; use the scaled or coloured sigmas.", ""]

    # parameters
    sig = dict(zip(result.aero_names, result.aero_sigma, strict=True))
    sig_c = dict(zip(result.aero_names, result.aero_sigma_coloured, strict=True))
    sig_s = dict(zip(result.aero_names, result.aero_sigma_scaled, strict=True))
    ca = result.consider
    cons = {} if ca is None else dict(zip(ca.names, ca.sigma, strict=True))
    L += ["## Parameters", "",
          "Values SI (angles in rad); σ from (JᵀWJ)⁻¹; σ coloured: sandwich estimate for "
          "correlated residuals; σ scaled: σ·√(χ²/dof) when that exceeds 1."
          + (" The model holds parameters with an uncertainty: value ± σ is the consider "
             "sigma (the held values' own uncertainty propagated, docs/fitting.md), σ "
             "conditional the sigma with the held values taken as exact."
             if ca is not None else ""), ""]
    rows = []
    for n in result.aero_names:
        p = result.model.parameter(n)
        flags = []
        if _at_bound(p):
            flags.append("AT BOUND")
        init = "—"
        if start_model is not None:
            v0 = start_model.parameter(n).value
            init = f"{v0:.6g}"
            if _left_at_start(p.value, v0):
                flags.append("LEFT AT START")
        if not math.isfinite(sig[n]):
            flags.append("UNDETERMINED")
        if any(d["hold"] == n for d in result.near_singular):
            flags.append("hold suggested")
        main = cons.get(n, sig[n])
        rows.append((n, pm(p.value, main), _pct(p.value, main))
                    + ((f"{sig[n]:.2g}",) if ca is not None else ())
                    + (f"{sig_c[n]:.2g}", f"{sig_s[n]:.2g}", init, _bounds_text(p),
                       ", ".join(flags)))
    L += markdown.table(("parameter", "value ± σ", "σ (%)")
                        + (("σ conditional",) if ca is not None else ())
                        + ("σ coloured", "σ scaled", "initial", "bounds", "flags"), rows)
    held = [p for p in result.model.parameters if p.name not in sig]
    if held:
        L += ["", "Held: " + ", ".join(_held_text(p) for p in held) + "."]
    if ca is not None:
        L += ["", *consider_lines(ca, result.aero_names)]
    priors = [p for p in result.model.parameters if p.prior is not None]
    if priors:
        L += ["", "Gaussian priors (the Bayesian alternative to a hold with an uncertainty, "
              "docs/fitting.md; their share of χ²: " f"{result.prior_chi2:.4g}; σ above is the "
              "posterior's): " + ", ".join(f"{p.name} {pm(p.prior, p.sigma)}" for p in priors)
              + "."]
    L += ["", "## Coefficients (seed 004 Table 4 layout)", "",
          coefficient_markdown(result.coefficient_table()), ""]

    corr = result.high_correlations(REPORT_CORRELATION)
    L += [f"## Correlations (|r| ≥ {REPORT_CORRELATION})", ""]
    if corr:
        L += markdown.table(("a", "b", "r"), ((a, b, f"{r:+.4f}") for a, b, r in
                                               sorted(corr, key=lambda t: -abs(t[2]))))
    else:
        L.append("None.")
    L.append("")

    L += ["## Identifiability and warnings", ""]
    if result.near_singular:
        L += ["Directions the data do not determine (eigenvalue ratio of the normal matrix in "
              "correlation form):", ""]
        for d in result.near_singular:
            L.append(f"- **hold {d['hold']}**: {d['text']}")
        L.append("")
    near_texts = {d["text"] for d in result.near_singular}
    warns = [w for w in list(result.warnings) + extra_warnings(result, start_model)
             if w not in near_texts]
    L += [f"- {w}" for w in warns] + list(f"- note: {n}" for n in notes)
    if not (result.near_singular or warns or notes):
        L.append("None: no parameter at a bound or left at its start, no near-singular "
                 "direction.")
    L.append("")

    # per-shot states
    rows = shot_epoch_table(result, shots)
    L += ["## Fitted state at each shot's epoch", "",
          "Reference point (what the images show) in the facility frame; θ, ψ nose-axis "
          "inclinations; α, β, σ classical (0 = heat shield into the wind; CEV α = 180° − α).",
          ""]
    cells_rows = []
    for r in rows:
        x, y, z = r["reference_point_m"]
        sx, sy, sz = r["reference_point_sigma_m"]
        rates = ", ".join(pm(float(v), float(s)) if np.isfinite(s) else f"{v:.4g}"
                          for v, s in zip(r["rates_rad_s"], r["rates_sigma_rad_s"],
                                          strict=True))
        cells_rows.append((
            r["shot_id"], r["epoch_station"], f"{r['t0_s']:.6f}", pm(x, sx),
            pm(y * 1e3, sy * 1e3), pm(z * 1e3, sz * 1e3), f"{r['speed_m_s']:.3f}",
            pm(r["theta_deg"], r["theta_sigma_deg"]), pm(r["psi_deg"], r["psi_sigma_deg"]),
            rates, f"{r['alpha_deg']:.2f}, {r['beta_deg']:.2f}, {r['sigma_deg']:.2f}",
            f"{r['mach']:.4f}"))
    L += markdown.table(("shot", "station", "t0 (s)", "x (m)", "y (mm)", "z (mm)", "V (m/s)",
                         "θ (deg)", "ψ (deg)", "p, q, r (rad/s)", "α, β, σ (deg)", "Mach"),
                        cells_rows)
    L.append("")

    # one column per channel of the registry, in the order ``cells`` writes them (the roll
    # column shows "—" for a body whose roll is not measured)
    heads = [f"{BY_NAME[ch].label} ({BY_NAME[ch].residual_label})" for ch in CHANNELS]
    L += ["## Residual rms", ""]

    def cells(rms: Mapping[str, float]) -> list[str]:
        return [f"{v * BY_NAME[ch].residual_scale:.3g}" if math.isfinite(v) else "—"
                for ch in CHANNELS for v in (rms.get(ch, math.nan),)]

    rms_rows = [(sf.shot_id, sf.n_observations, f"{sf.chi2:.4g}", *cells(sf.rms))
                for sf in result.shots]
    if len(result.shots) > 1:
        rms_rows.append(("all", result.n_observations, f"{result.chi2:.4g}",
                         *cells(result.rms())))
    dof = result.dof_by_channel()
    rms_rows.append(("noise floor", f"dof {result.dof}", "—", *cells(result.noise_floor())))
    L += markdown.table(("shot", "n", "χ²", *heads), rms_rows)
    L += ["", "Noise floor: the rms a correct model leaves on noise of the stated σ, "
          "σ√(1 − leverage); the fit absorbs the rest. Degrees of freedom per channel: "
          + ", ".join(f"{ch} {v:.1f}" for ch, v in dof.items() if math.isfinite(v)) + "."]
    L.append("")
    if plot_files:
        captions = {"coefficients": "fitted coefficients vs angle with ±1σ bands",
                    "angles": "measured vs fitted θ, ψ and α (σ) vs distance",
                    "residuals": "normalized residuals per channel vs station",
                    "trajectory3d": "3-D view of the fitted flight"}
        L += ["## Plots", ""]
        for key, rel in plot_files.items():
            L.append(f"- [{captions.get(key, key)}]({rel})")
        L.append("")
        for key, rel in plot_files.items():
            L += [f"![{captions.get(key, key)}]({rel})", ""]
    L += list(reference_lines)
    L += ["Files: results.json, coefficients.csv, covariance.csv, correlation.csv, "
          "correlation_coloured.csv, residuals.csv (angles in deg, `unit` column)"
          + (", reference_pulls.csv" if reference_lines else "") + ".", ""]
    return "\n".join(L)


def reference_markdown(cmp) -> list[str]:
    """The report's section on the reference."""
    L = ["## Against the reference", "",
         f"Reference: `{cmp.label}`. Pull = (fit − reference) / √(σ_fit² + σ_ref²); "
         "σ_ref is 0 for a model file (values only).", ""]
    rows = []
    for r in cmp.table.itertuples():
        ref = pm(r.reference, r.reference_sigma) if r.reference_sigma > 0 else f"{r.reference:.6g}"
        pct = f" ({r.difference_percent:+.2f} %)" if np.isfinite(r.difference_percent) else ""
        rows.append((r.parameter, pm(r.fit, r.sigma), ref, f"{r.difference:+.4g}{pct}",
                     f"{r.pull:+.2f}"))
    L += markdown.table(("parameter", "fit", "reference", "difference", "pull"), rows)
    n = len(cmp.table)
    within = int((np.abs(cmp.table["pull"]) <= 2).sum()) if n else 0
    L += ["", f"{within} of {n} within 2σ. Joint χ² of agreement (the parameters' "
          f"correlations counted) = {cmp.chi2:.2f} for {cmp.dof} degrees of freedom, "
          f"p = {cmp.p:.3g}" + (" — **the fit and the reference disagree**"
                                if np.isfinite(cmp.p) and cmp.p < 0.01 else "") + ".", ""]
    if cmp.not_compared:
        L += ["Not in the reference (not compared): " + ", ".join(cmp.not_compared), ""]
    return L


# --------------------------------------------------------------------------- writer


def _matrix_csv(M: np.ndarray, names: Sequence[str], path: Path) -> None:
    pd.DataFrame(np.asarray(M, dtype=float), index=list(names), columns=list(names)) \
        .to_csv(path, index_label="parameter")


def write_fit_outputs(result: FitResult, shots: Sequence[ShotData], out_dir: str | os.PathLike,
                      *, overwrite: bool = False, plots: bool = True, title: str | None = None,
                      start_model: AeroModel | None = None, bodies: Mapping | None = None,
                      reference_model: AeroModel | None = None,
                      reference=None,
                      extra_files: Mapping[str, str] | None = None,
                      notes: Sequence[str] = ()) -> Path:
    """Write a fit's files, report and plots to ``out_dir`` (module doc), atomically.

    Parameters
    ----------
    result : the fit (a failed fit is written too; the report says it is not a result).
    shots : the :class:`ShotData` the fit used (matched to ``result.shots`` by shot id).
    out_dir : the directory to create.
    overwrite : replace an existing ``out_dir`` (default: :class:`FileExistsError`).
    plots : write ``plots/*.png`` (matplotlib; pyvista for the 3-D view, with a matplotlib
        fallback when off-screen rendering is unavailable, noted in the report).
    title : report title (default: model name and shot ids).
    start_model : the model the fit started from (its values are the "initial" column).
    bodies : optional ``{shot_id: cadra.body.Body}`` for the 3-D view (default: rebuilt from
        ``shot.source["shot_file"]``, else a generic body of the shot's kind).
    reference_model : optional model drawn beside the fitted coefficients (e.g. the truth of
        a synthetic shot).
    reference : optional :class:`cadra.fitting.reference.Reference` (``cadra2 fit
        --reference``): a pulls table and joint chi^2 against it in the report,
        ``reference_pulls.csv``, a ``reference`` block in results.json, and its model drawn
        on the coefficient plots (unless ``reference_model`` is given).
    extra_files : ``{file name: text}`` written in the same atomic step (the CLI's fitted
        model file and run configuration).
    notes : lines the report lists under its warnings (e.g. the station bias table applied).

    Returns
    -------
    The output directory. On any error nothing is left at ``out_dir`` (an existing directory
    being replaced is kept unchanged).
    """
    from cadra.atomic import atomic_output_dir

    out_dir = Path(out_dir)
    shots = list(shots)
    missing = [sf.shot_id for sf in result.shots if sf.shot_id not in _shots_by_id(shots)]
    if missing:
        raise ValueError(f"write_fit_outputs: no ShotData for shot(s) {missing}")
    cmp = None
    if reference is not None:
        from cadra.fitting.reference import compare_with_reference

        na = len(result.aero_names)
        cmp = compare_with_reference(result.aero_names, result.aero_values,
                                     result.covariance[:na, :na], reference)
        if reference_model is None:
            reference_model = reference.model
    with atomic_output_dir(out_dir, overwrite=overwrite,
                           kind="fit") as tmp:
        data = results_dict(result, shots, start_model=start_model, title=title)
        reference_lines: list[str] = []
        if cmp is not None:
            cmp.table.to_csv(tmp / "reference_pulls.csv", index=False, float_format="%.10g")
            data["reference"] = plain({"label": cmp.label, "chi2": cmp.chi2, "dof": cmp.dof,
                                        "p": cmp.p, "not_compared": list(cmp.not_compared),
                                        "pulls": cmp.table.to_dict(orient="records")})
            reference_lines = reference_markdown(cmp)
        (tmp / "results.json").write_text(json.dumps(data, indent=2, allow_nan=False) + "\n",
                                          encoding="utf-8")
        result.coefficient_table().to_csv(tmp / "coefficients.csv", index=False)
        names = result.param_names
        _matrix_csv(result.covariance, names, tmp / "covariance.csv")
        _matrix_csv(result.correlation(), names, tmp / "correlation.csv")
        _matrix_csv(result.correlation(coloured=True), names, tmp / "correlation_coloured.csv")
        residuals_table(result).to_csv(tmp / "residuals.csv", index=False)
        for name, text in (extra_files or {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
        plot_files: dict[str, str] = {}
        notes = list(notes)
        if plots:
            plot_files, plot_notes = _write_plots(result, shots, tmp / "plots", bodies=bodies,
                                                  reference_model=reference_model, title=title)
            notes += plot_notes
        (tmp / "report.md").write_text(
            report_markdown(result, shots, start_model=start_model, title=title,
                            plot_files=plot_files, notes=notes,
                            reference_lines=reference_lines), encoding="utf-8")
    return out_dir


def _write_plots(result, shots, plot_dir: Path, *, bodies, reference_model, title):
    from cadra.report import fit_plots as P

    plot_dir.mkdir()
    files: dict[str, str] = {}
    notes: list[str] = []

    def save(key, fig):
        figures.save(fig, plot_dir / PLOT_FILES[key])
        files[key] = f"plots/{PLOT_FILES[key]}"

    histories = fitted_histories(result, shots)
    save("coefficients", P.plot_coefficients(result, shots, histories=histories,
                                             reference_model=reference_model))
    save("angles", P.plot_angle_histories(result, shots, histories=histories))
    save("residuals", P.plot_residuals(result))
    path3d = plot_dir / PLOT_FILES["trajectory3d"]
    try:
        P.render_trajectory_3d(result, shots, path3d, bodies=bodies, histories=histories,
                               title=title)
    except P.RenderingUnavailable as exc:
        save("trajectory3d", P.trajectory_3d_matplotlib(result, shots, bodies=bodies,
                                                        histories=histories, title=title))
        notes.append(f"the 3-D view was drawn with matplotlib: {exc}")
    files["trajectory3d"] = f"plots/{PLOT_FILES['trajectory3d']}"
    return files, notes


__all__ = ["CHANNEL_OUTPUT_UNITS", "PLOT_FILES", "RESULTS_FORMAT",
           "coefficient_markdown", "fitted_histories", "reference_markdown", "report_markdown",
           "residuals_table",
           "results_dict", "shot_epoch_table", "write_fit_outputs"]
