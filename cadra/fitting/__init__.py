"""Stage two: 6-DOF least-squares differential correction (docs/fitting.md).

Public API (the measurements it fits, :class:`~cadra.flight.data.ShotData`, are
:mod:`cadra.flight`'s):

- :func:`fit` (the solver), :class:`FitOptions`, :class:`Integration`, :class:`FitResult`;
- :class:`FitProblem` (the forward model behind every prediction), :func:`result_problem`;
- :func:`starting_model`, :func:`initial_states` -- linear-theory starting values;
- :func:`fit_shots` -- starting values + fit in one call (what ``cadra2 fit`` runs).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from cadra.aero import AeroModel
from cadra.channels import ANGLE, POSITION
from cadra.fitting.problem import FitProblem, check_one_body, result_problem
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import LOCAL_NAMES, Integration
from cadra.fitting.solver import FitOptions, fit
from cadra.fitting.start import initial_states, starting_model
from cadra.flight.data import FILM_SIGMAS, ShotData, floor_sigmas

#: the progress-bar labels of :func:`fit_shots`' two phases (continuation)
PHASE_LABELS = ("fit (film-level sigmas)", "fit (stage-one sigmas)")


def fit_shots(shots: Sequence[ShotData], model: AeroModel, *,
              options: FitOptions | None = None, auto_start: bool = True,
              initial: Sequence | None = None,
              continuation: dict | None = FILM_SIGMAS, local_free=None,
              extras: Sequence = (),
              variance_components: bool = False,
              estimates: Sequence | None = None) -> tuple[FitResult, AeroModel]:
    """Fit ``model`` to ``shots`` from automatic starting values.

    With ``auto_start`` the free parameters first move to the linear-theory targets
    (:func:`starting_model`); each shot's initial state comes from its measurements
    (:func:`initial_states`) unless ``initial`` gives them.

    ``continuation`` (default: the film-range sigmas, 0.1 mm and 0.1 deg): when the
    measurements are more precise than that, the fit first converges with the sigmas floored
    at these values and then refines with the real ones from there. From a rough start the
    very steep chi^2 of micrometre data can otherwise walk into a region where a term of a
    ``max(...)`` form never acts (its parameter then has no effect and cannot come back);
    ``None`` fits with the real sigmas at once.

    ``local_free`` and ``extras`` are passed to :func:`cadra.fitting.solver.fit` (each
    stage; the second starts the extras at the first's values).

    ``variance_components``: after convergence, rescale each channel's sigmas by the factor
    its own residuals ask for and refit (:func:`cadra.fitting.variance.fit_variance_components`;
    the factors are in ``result.options["variance_components"]``, the rescaled shots in
    ``result.problem.shots``).

    ``estimates``: each shot's :class:`~cadra.flight.estimates.MotionEstimate` for the
    starting values, in place of :func:`~cadra.flight.estimates.estimate_motion`'s (e.g. the
    epicyclic fit's, ``cadra.flight.starts.epicyclic_estimates``).

    Returns the result and the starting model (for the report's "initial value" column).
    """
    result, start = _fit_shots(shots, model, options=options, auto_start=auto_start,
                               initial=initial, continuation=continuation,
                               local_free=local_free, extras=extras, estimates=estimates)
    if variance_components and result.converged:
        from cadra.fitting.variance import fit_variance_components

        result, _ = fit_variance_components(list(shots), result, options or FitOptions(),
                                            local_free=local_free)
    return result, start


def _finest(shot: ShotData, channels) -> float:
    """The smallest sigma of the measured entries of ``channels`` (inf: none measured);
    a channel the shot does not measure has no sigma and is not looked at."""
    sig = shot.sigma[:, channels][shot.mask[:, channels]]
    return float(sig.min()) if sig.size else math.inf


def _fit_shots(shots, model, *, options, auto_start, initial, continuation, local_free,
               extras, estimates=None):
    """:func:`fit_shots` without the variance components."""
    options = options or FitOptions()
    shots = list(shots)
    check_one_body(shots)          # at once, not after the starting values
    staged = continuation is not None and any(
        _finest(s, POSITION) < continuation["position_m"]
        or _finest(s, ANGLE) < continuation["angle_rad"] for s in shots)
    # starting values (and the roll grid's chi^2) under the weights of the first stage
    first_shots = [floor_sigmas(s, continuation) for s in shots] if staged else shots
    if auto_start and initial is None and estimates is None and any(
            np.isfinite(s.launch_spin_rad_s) or np.isfinite(s.twist_m_per_turn) for s in shots):
        from cadra.flight.starts import start_estimates

        # a known spin always starts the arms in its bands (docs/spark_range.md)
        estimates = start_estimates(shots, "auto", model)
    start = starting_model(first_shots, model, estimates) if auto_start else model
    states = list(initial) if initial is not None else initial_states(
        first_shots, start, options.integration, estimates)
    extras = list(extras)
    if staged:
        first = fit(first_shots, start, states, local_free=local_free, extras=extras,
                    options=replace(options, progress_label=PHASE_LABELS[0]))
        if first.status in ("converged", "max_iterations", "stalled") and np.all(
                np.isfinite(first.aero_values)):
            result = fit(shots, first.model, [sf.state for sf in first.shots],
                         options=replace(options, progress_label=PHASE_LABELS[1]),
                         local_free=local_free, extras=first.extras_at_values())
            # the report says there were two phases and why chi^2 jumps between them
            phases = [{"label": PHASE_LABELS[k], "status": r.status,
                       "iterations": r.iterations,
                       "chi2_start": r.history[0] if r.history else float("nan"),
                       "chi2_end": r.chi2, "history_points": len(r.history)}
                      for k, r in enumerate((first, result))]
            return replace(result, iterations=first.iterations + result.iterations,
                           elapsed_s=first.elapsed_s + result.elapsed_s,
                           history=first.history + result.history,
                           initial_values=first.initial_values,
                           options={**result.options, "phases": phases,
                                    "continuation": dict(continuation)}), start
    return fit(shots, start, states, options=options, local_free=local_free,
               extras=extras), start


__all__ = ["LOCAL_NAMES", "PHASE_LABELS", "FitOptions", "FitProblem", "FitResult",
           "Integration", "fit", "fit_shots", "initial_states", "result_problem",
           "starting_model"]
