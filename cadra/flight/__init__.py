"""A shot's measured flight: the data stage two and the classic methods read.

- :class:`ShotData` (:mod:`cadra.flight.data`): one shot's measurements with its body, mass
  properties and air, SI; built in memory from stage one's trajectory
  (:func:`shot_data_from_trajectory`), from files (:func:`load_shot_data`,
  :func:`~cadra.flight.load.load_shots`) or from a simulated truth
  (:func:`shot_data_from_truth`);
- what linear theory reads from it before any fit (:mod:`cadra.flight.estimates`), the
  classic angular-motion reduction of a range shot (:mod:`cadra.flight.classic`) and the
  starting estimates a fit takes (:mod:`cadra.flight.starts`).
"""

from cadra.flight.data import (
    CHANNELS,
    FILM_SIGMAS,
    FitDataError,
    ShotData,
    floor_sigmas,
    load_shot_data,
    shot_data_from_trajectory,
    shot_data_from_truth,
)
from cadra.flight.estimates import MotionEstimate, estimate_motion
from cadra.flight.load import load_shots

__all__ = ["CHANNELS", "FILM_SIGMAS", "FitDataError", "MotionEstimate", "ShotData",
           "estimate_motion", "floor_sigmas", "load_shot_data", "load_shots",
           "shot_data_from_trajectory", "shot_data_from_truth"]
