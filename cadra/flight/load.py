"""Stage two's inputs as a user names them: stage-one folders or trajectory files and their
shot files.

What ``cadra2`` does with its file arguments before fitting, as library functions
(docs/fitting.md)::

    shots, paths = load_shots(["out/m2_2429/cadra1"], sigma_time_s=1e-7)
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from cadra.flight.data import FitDataError, ShotData, load_shot_data
from cadra.units import deg_to_rad

#: stage one's trajectory file in its output folder
TRAJECTORY_FILE = "trajectory.csv"


def trajectory_and_shot(item: str | os.PathLike, shot: str | os.PathLike | None = None
                        ) -> tuple[Path, Path]:
    """The trajectory file and shot file of one shot.

    ``item`` is stage one's ``trajectory.csv`` or its output folder; ``shot`` the shot file,
    by default the one the trajectory file names (its ``shot_file`` metadata; a relative one
    from the trajectory file's folder first, then the working folder's). Raises
    :class:`FitDataError` saying what is missing.
    """
    from cadra.io.trajectory import TrajectoryFileError, load_trajectory

    traj = Path(item)
    if traj.is_dir():
        traj = traj / TRAJECTORY_FILE
    if not traj.is_file():
        raise FitDataError(f"{item}: no trajectory file (give stage one's {TRAJECTORY_FILE} "
                           "or its output directory)")
    if shot is not None:
        return traj, Path(shot)
    try:
        meta = load_trajectory(traj).meta
    except TrajectoryFileError as exc:
        raise FitDataError(str(exc)) from None
    if not meta.get("shot_file"):
        raise FitDataError(f"{traj}: names no shot file; pass it with --shot")
    named = Path(meta["shot_file"])
    if named.is_absolute():
        return traj, named
    # a relative name is the trajectory file's folder's (a record carried with its shot
    # file), then the working folder's (as earlier CADRA read it)
    beside = traj.parent / named
    if beside.is_file() or named.is_file():
        return traj, beside if beside.is_file() else named
    raise FitDataError(f"{traj}: its shot file {named} is neither beside it ({beside}) nor in "
                       f"the working folder ({Path.cwd()}); pass it with --shot")


def load_shots(trajectories: Sequence[str | os.PathLike],
               shots: Sequence[str | os.PathLike] | None = None, *, sigma_time_s: float = 0.0,
               min_sigma_position_m: float = 0.0, min_sigma_angle_deg: float = 0.0
               ) -> tuple[list[ShotData], list[Path]]:
    """The measurements of each shot (:func:`load_shot_data`) and its trajectory file.

    ``shots`` gives the shot file of each trajectory, same order (default: the ones the
    trajectory files name, :func:`trajectory_and_shot`); ``sigma_time_s`` the spark-time
    sigma (s); the ``min_sigma_*`` floors of the stage-one sigmas (m, deg). A model larger
    than half its facility's field of view (a size in the wrong unit) raises
    :class:`FitDataError` naming the shot file's key, as stage one refuses it.
    """
    if shots and len(shots) != len(trajectories):
        raise ValueError("give one --shot per trajectory file (same order), or none")
    min_sigma = {"position_m": min_sigma_position_m,
                 "angle_rad": deg_to_rad(min_sigma_angle_deg)}
    data, paths = [], []
    for k, item in enumerate(trajectories):
        traj, shot_path = trajectory_and_shot(item, shots[k] if shots else None)
        data.append(load_shot_data(shot_path, traj, sigma_t_s=sigma_time_s,
                                   min_sigma=min_sigma))
        _check_model_size(shot_path)
        paths.append(traj)
    return data, paths


def _check_model_size(shot_path: str | os.PathLike) -> None:
    """The shot's model against its facility's field of view, as stage one checks it
    (:func:`cadra.io.shot_check.check_model_size`: a size in the wrong unit). A facility that
    cannot be loaded is left alone: the fit does not need it, and without it there is no
    image scale to compare with."""
    from cadra.io.facility_file import load_facility
    from cadra.io.shot_check import check_model_size
    from cadra.io.shotfile import ShotFileError, load_shot

    shot = load_shot(shot_path)   # already validated by load_shot_data
    try:
        facility = load_facility(shot.facility)
    except (ValueError, OSError):
        return
    try:
        check_model_size(shot, facility)
    except ShotFileError as exc:
        raise FitDataError(str(exc)) from None


__all__ = ["TRAJECTORY_FILE", "load_shots", "trajectory_and_shot"]
