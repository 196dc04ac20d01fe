"""A fit's text report, as :meth:`FitResult.report` gives it and ``cadra2 fit`` prints it.

lmfit's ``fit_report`` in a range engineer's terms: the status line (status, why, chi^2/nu,
iterations per phase, time), the fit's statistics, every free parameter as ``value ± sigma``
(the one format of :func:`cadra.numfmt.pm`) with its share of the value and its start, the
held ones, the correlations above a threshold, the two phases of a continuation and the
warnings. It only reads what the fit stored. The written report (``report.md``, files,
plots) is :mod:`cadra.report.fit`.
"""

from __future__ import annotations

import math

from cadra.channels import BY_NAME
from cadra.numfmt import pm
from cadra.stats import POOR_MINIMUM_P

#: |correlation| above which the report lists a pair of free aerodynamic parameters
REPORT_CORRELATION = 0.9


def status_line(result) -> str:
    """The fit's one status line: status, why, chi^2/nu, iterations (per phase), time. The
    solver's message may start with its status (``converged: ...``); it is not repeated."""
    detail = result.message
    if detail.lower().startswith(f"{result.status}:"):
        detail = detail[len(result.status) + 1:].strip()
    phases = result.options.get("phases") if isinstance(result.options, dict) else None
    its = f"{result.iterations} iterations"
    if phases:
        its += " (" + " + ".join(f"{p['iterations']} {p['label'][5:-1]}" for p in phases) + ")"
    line = (f"{result.status}: {detail}; chi^2/nu = {result.chi2:.4g}/{result.dof} = "
            f"{result.reduced_chi2:.3g}, {its}, {result.elapsed_s:.2f} s")
    if result.poor_minimum:
        line = (f"poor_minimum: converged to a poor minimum (p(chi^2) = "
                f"{result.chi2_p_value:.2g} < {POOR_MINIMUM_P:g}: the residuals are far "
                f"above the noise; {result.worst_residual()}); {line}")
    return line


def phase_lines(result) -> list[str]:
    """Two lines on the fit's two phases (continuation), or none: why chi^2 jumps."""
    phases = result.options.get("phases") if isinstance(result.options, dict) else None
    if not phases:
        return []
    a, b = phases
    return [f"two phases: {a['label']}: {a['iterations']} iterations, chi^2 -> "
            f"{a['chi2_end']:.4g} ({a['status']}); {b['label']}: {b['iterations']} iterations, "
            f"chi^2 {b['chi2_start']:.4g} -> {b['chi2_end']:.4g}",
            "  (stage one's sigmas are finer than film level: the fit first converges with "
            "them floored, then refines; chi^2 jumps between the phases because the weights "
            "change, not because the fit got worse; docs/cli.md)"]


def _share(value: float, sigma: float | None) -> str:
    if sigma is None or not math.isfinite(sigma) or value == 0:
        return ""
    return f" ({100.0 * abs(sigma / value):.2g}%)"


def fit_report(result, *, verbose: bool = False, status: bool = True,
               warnings: bool = True, correlation: float = REPORT_CORRELATION) -> str:
    """The report (module doc). ``status``: begin with the status line; ``warnings``: end
    with the fit's warnings (``cadra2 fit`` prints both itself, on stdout or stderr by the
    outcome); ``verbose``: add the coloured and scaled sigmas, the chi^2 history and each
    shot's residual rms; ``correlation``: the threshold of the listed correlations."""
    lines = [status_line(result)] if status else []
    shots = ", ".join(sf.shot_id for sf in result.shots)
    n_local = sum(len(sf.local_free) for sf in result.shots)
    lines += [f"shots: {shots}; {result.n_observations} observations, {result.n_free} "
              f"unknowns ({len(result.aero_names)} aerodynamic, {len(result.extras)} extra, "
              f"{n_local} initial-state), "
              + (f"{result.n_priors} prior(s), " if result.n_priors else "")
              + f"{result.dof} degrees of freedom"]
    vc = result.options.get("variance_components") if isinstance(result.options, dict) else None
    if vc:
        lines.append("variance components: sigma scale " + ", ".join(
            f"{ch} ×{v:.3f}" for ch, v in vc["sigma_scale"].items())
            + f" (chi^2/nu with stage one's sigmas {vc['reduced_chi2_before']:.3f})")
    params = result.params
    ca = result.consider
    cons = {} if ca is None else dict(zip(ca.names, ca.sigma, strict=True))
    if cons:
        lines.append("value ± sigma: the consider sigma, the held values' own uncertainty "
                     "included (docs/fitting.md); conditional: with them taken as exact")
    head = f"{'parameter':12s} {'value ± sigma':>24s}"
    lines.append(head + (f" {'sigma coloured':>15s} {'sigma scaled':>13s}" if verbose else ""))
    coloured = dict(zip(result.aero_names, result.aero_sigma_coloured, strict=True))
    scaled = dict(zip(result.aero_names, result.aero_sigma_scaled, strict=True))
    for name in result.aero_names:
        p = params[name]
        sigma = cons.get(name, p.stderr)
        row = f"{name:12s} {pm(p.value, sigma):>24s}"
        if verbose:
            row += f" {coloured[name]:>15.2g} {scaled[name]:>13.2g}"
        init = "" if p.init_value is None else f", init {p.init_value:.6g}"
        cond = f", conditional {p.stderr:.2g}" if name in cons else ""
        lines.append(row + f"  {_share(p.value, sigma).strip()}{init}{cond}".rstrip())
    for name in result.extra_names:
        p = params[name]
        lines.append(f"{name:12s} {pm(p.value, p.stderr):>24s}  (extra unknown)")
    held = [p for p in params.values() if p.kind == "aero" and not p.vary]
    if held:
        sig = {q.name: q.sigma for q in result.model.parameters}
        lines.append("held: " + ", ".join(
            f"{p.name} = {p.value:.6g}" + (f" ± {sig[p.name]:.3g}" if sig.get(p.name) else "")
            for p in held))
    priors = [q for q in result.model.parameters if q.prior is not None]
    if priors:
        lines.append("Gaussian priors (their share of chi^2 "
                     f"{result.prior_chi2:.3g}; the sigmas above are the posterior's): "
                     + ", ".join(f"{q.name} {pm(q.prior, q.sigma)}" for q in priors))
    pairs = [(a, b, r) for a, b, r in result.high_correlations(correlation)
             if a in result.aero_names and b in result.aero_names]
    if pairs:
        lines.append(f"correlations |r| >= {correlation:g}: " + ", ".join(
            f"{a}–{b} {r:+.3f}" for a, b, r in pairs))
    lines += phase_lines(result)
    if verbose:
        lines.append("chi^2 history: " + ", ".join(f"{c:.4g}" for c in result.history))
        for sf in result.shots:
            lines.append(f"{sf.shot_id}: residual rms " + ", ".join(
                f"{ch} {v * BY_NAME[ch].residual_scale:.3g} {BY_NAME[ch].residual_label}"
                for ch, v in sf.rms.items() if math.isfinite(v)))
    if warnings:
        lines += [f"warning: {w}" for w in result.warnings]
    return "\n".join(lines)


__all__ = ["REPORT_CORRELATION", "fit_report", "phase_lines", "status_line"]
