"""Refits of a fit with candidate effects: from its solution (:func:`refit_with`), from
automatic starting values (:func:`fresh_fit`), continued with more budget
(:func:`continue_fit`; extra unknowns: ``refit_with(..., extras=...)``), and profile
intervals.

Every refit is the solver's own fit (:func:`cadra.fitting.solver.fit`) with the candidate's
terms added: the model's forms (aero), a freed held parameter (held), or extra unknowns
(:mod:`cadra.fitting.extras`: a body or air effect per shot or shared by the set, a station
term); so each prediction comes from the fit problem the solver used.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

from scipy import stats

from cadra.aero import AeroModel
from cadra.fitting.extras import Extra
from cadra.fitting.profile import profile_parameter
from cadra.fitting.result import FitResult
from cadra.fitting.solver import FitOptions
from cadra.flight.data import ShotData
from cadra.gap.candidates import Candidate, augmented_model

#: iteration budget a fit short of convergence is continued with before it is diagnosed
#: (a strong effect, chi^2/dof 50-200, takes a base fit well past the default 60)
CONTINUE_ITERATIONS = 200

#: convergence control of the station candidates' refits (linear effects: they settle fast)
REFIT_OPTIONS = FitOptions(max_iterations=25)


#: a fit from scratch with a candidate that stays above the noise floor at this p-value is
#: restarted once with the candidate's parameters at its values (:func:`fresh_fit`)
FRESH_RESTART_P = 0.01


#: an added effect whose refit did not converge gets a profile likelihood interval
#: (:mod:`cadra.fitting.profile`) for each of its parameters when it has at most this many
#: (each profile costs ~10-20 refits)
PROFILE_MAX_PARAMS = 2


def profiles(rf: FitResult, shots: Sequence[ShotData], names) -> list:
    """Two-sigma profile-likelihood intervals ``(lower, upper, settled)`` of ``names`` in
    ``rf`` (``settled``: every held fit converged; None where a profile could not be run)."""
    out = []
    for n in names:
        try:
            p = profile_parameter(rf, shots, n)
        except ValueError:
            out.append(None)
            continue
        out.append((p.lower, p.upper, p.n_unsettled == 0))
    return out




def param_names(c: Candidate, shot_ids: Sequence[str]) -> tuple[str, ...]:
    """The candidate's parameter names in a fit of ``shot_ids``: a dynamics (body or
    atmosphere) effect has its own parameters per shot (``name@shot`` when there are
    several shots) unless its scope is the set; aero, held and station effects are
    shared."""
    if c.kind != "dynamics" or len(shot_ids) == 1 or c.scope == "set":
        return c.params
    return tuple(f"{p}@{sid}" for sid in shot_ids for p in c.params)




def candidate_extras(c: Candidate, shot_ids: Sequence[str]) -> list[Extra]:
    """The extra unknowns (started at 0) a dynamics or measurement candidate adds to a fit of
    ``shot_ids`` (none for an aero or held one: those change the model)."""
    if c.kind == "dynamics" and c.scope == "set":
        return [Extra(p, phys_direction=tuple(d), shots=tuple(shot_ids))
                for p, d in zip(c.params, c.phys_dirs, strict=True)]
    if c.kind == "dynamics":
        out = []
        for sid in shot_ids:
            for p, d in zip(c.params, c.phys_dirs, strict=True):
                out.append(Extra(p if len(shot_ids) == 1 else f"{p}@{sid}",
                                 phys_direction=tuple(d), shots=(sid,)))
        return out
    if c.kind == "measurement" and c.responses:
        return [Extra(p, station=c.station, measure=c.measure, response=g)
                for p, g in zip(c.params, c.responses, strict=True)]
    if c.kind == "measurement":
        return [Extra(c.params[0], station=c.station, measure=c.measure, response=c.response)]
    return []




def refit_with(result: FitResult, shots: Sequence[ShotData], cands: Sequence[Candidate],
               options=None, extras: Sequence[Extra] = ()) -> FitResult | None:
    """``result``'s fit redone with the candidates' terms and ``extras`` added (their
    parameters free, started at 0 / their values; the fit's own extras kept, started at
    their values), from the fitted states; None if the refit raises. The fit's free local
    unknowns stay as they are: a body asymmetry is a pair that turns with the roll and spans
    every orientation about the axis by itself (:mod:`cadra.gap.candidates`), so the roll of
    a body of revolution is not freed with it (that would add a direction with a saddle
    where it has no gradient; docs/gap.md)."""
    from cadra.fitting.solver import fit

    by_id = {s.shot_id: s for s in shots}
    ids = [sf.shot_id for sf in result.shots]
    model = result.model
    more: list[Extra] = result.extras_at_values() + list(extras)
    for c in cands:
        if c.kind in ("aero", "held"):
            model = augmented_model(model, c)
        else:
            more += candidate_extras(c, ids)
    try:
        return fit([by_id[i] for i in ids], model, [sf.state for sf in result.shots],
                   options=options or REFIT_OPTIONS,
                   local_free=[sf.local_free_indices for sf in result.shots],
                   extras=more)
    except (ValueError, FloatingPointError):
        return None




def fresh_fit(result: FitResult, shots: Sequence[ShotData], cand: Candidate,
              start: AeroModel | None = None) -> FitResult | None:
    """``result``'s fit with ``cand`` added, redone from automatic starting values (not from
    ``result``'s solution): its aero model and extras (started at 0) plus the candidate's
    terms; None if it fails. ``start``: the model as first given to the fit; its values
    are the automatic start's starting point (the linear-theory targets move only the
    parameters they constrain: the rest would otherwise start where ``result`` left them).
    The fit without an effect may sit in a basin (a ``max(...)`` branch, terms bent to
    mimic the missing one) that a refit from there cannot leave.

    The automatic start knows nothing of the candidate (its parameters start at 0), so a
    large effect can still leave the aero terms in a wrong basin while the candidate's own
    parameters come out right (a 0.27 mm cg offset on M2-2429: z to 0.03 %, chi^2/dof
    1289); when the fit stays above the noise floor it is redone once more from automatic
    starting values with the candidate's parameters started at that fit's values (there:
    chi^2/dof 1.13), and the better of the two is returned."""
    from cadra.fitting import fit_shots

    by_id = {s.shot_id: s for s in shots}
    ids = [sf.shot_id for sf in result.shots]
    data = [by_id[i] for i in ids]
    local_free = [sf.local_free_indices for sf in result.shots]
    base = result.model
    if start is not None:
        base = base.with_values({n: start.parameter(n).value for n in start.names
                                 if n in base.names})
    model = augmented_model(base, cand) if cand.kind in ("aero", "held") else base
    extras = [replace(e, value=0.0) for e in result.extras]
    if cand.kind not in ("aero", "held"):
        extras += candidate_extras(cand, ids)

    def run(model, extras):
        try:
            res, _ = fit_shots(data, model, local_free=local_free, extras=extras)
        except (ValueError, FloatingPointError):
            return None
        return res if res.status != "failed" and math.isfinite(res.chi2) else None

    res = run(model, extras)
    if res is None or stats.chi2.sf(res.chi2, max(res.dof, 1)) >= FRESH_RESTART_P:
        return res
    names = param_names(cand, ids)
    if cand.kind in ("aero", "held"):
        again = run(model.with_values({n: res.value(n) for n in names}), extras)
    else:
        again = run(model, [replace(e, value=res.value(e.name)) if e.name in names else e
                            for e in extras])
    return again if again is not None and again.chi2 < res.chi2 else res


def continue_fit(result: FitResult, shots: Sequence[ShotData],
                 max_iterations: int = CONTINUE_ITERATIONS) -> FitResult:
    """A fit short of convergence continued from where it stopped with ``max_iterations``
    more; the better of the two (the continued one when it is no worse)."""
    if result.status == "converged":
        return result
    more = refit_with(result, shots, [], FitOptions(max_iterations=max_iterations))
    if more is not None and math.isfinite(more.chi2) and more.chi2 <= result.chi2:
        return more
    return result


def above_floor(fit_res: FitResult, p: float) -> bool:
    """The fit's chi^2 is above the noise floor at level ``p``."""
    return bool(stats.chi2.sf(fit_res.chi2, max(fit_res.dof, 1)) < p)


__all__ = ["CONTINUE_ITERATIONS", "FRESH_RESTART_P", "PROFILE_MAX_PARAMS", "REFIT_OPTIONS",
           "above_floor", "candidate_extras", "continue_fit", "fresh_fit", "param_names",
           "profiles", "refit_with"]
