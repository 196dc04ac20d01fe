"""Stage two: 6-DOF least-squares differential correction (docs/fitting.md).

Public API:

- :class:`ShotData`, :func:`load_shot_data`, :func:`shot_data_from_truth` -- the measurements;
- :func:`fit` (the solver), :class:`FitOptions`, :class:`Integration`, :class:`FitResult`;
- :func:`starting_model`, :func:`initial_states` -- linear-theory starting values;
- :func:`fit_shots` -- starting values + fit in one call (what ``cadra2 fit`` runs).
"""

from __future__ import annotations

from collections.abc import Sequence

from cadra.aero import AeroModel
from cadra.fitting.data import (
    CHANNELS,
    FILM_SIGMAS,
    FitDataError,
    ShotData,
    load_shot_data,
    shot_data_from_truth,
)
from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import LOCAL_NAMES, Integration
from cadra.fitting.solver import FitOptions, fit
from cadra.fitting.start import estimate_motion, initial_states, starting_model


def fit_shots(shots: Sequence[ShotData], model: AeroModel, *,
              options: FitOptions | None = None, auto_start: bool = True,
              initial: Sequence | None = None) -> tuple[FitResult, AeroModel]:
    """Fit ``model`` to ``shots`` from automatic starting values.

    With ``auto_start`` the free parameters first move to the linear-theory targets
    (:func:`starting_model`); each shot's initial state comes from its measurements
    (:func:`initial_states`) unless ``initial`` gives them. Returns the result and the starting
    model (for the report's "initial value" column).
    """
    options = options or FitOptions()
    shots = list(shots)
    start = starting_model(shots, model) if auto_start else model
    states = list(initial) if initial is not None else initial_states(
        shots, start, options.integration)
    return fit(shots, start, states, options=options), start


__all__ = ["CHANNELS", "FILM_SIGMAS", "LOCAL_NAMES", "FitDataError", "FitOptions",
           "FitResult", "Integration", "ShotData", "estimate_motion", "fit", "fit_shots",
           "initial_states", "load_shot_data", "shot_data_from_truth", "starting_model"]
