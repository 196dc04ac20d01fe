"""Stage one's trajectory file made from a truth, without images.

The tests and tools that exercise stage two (``cadra2 fit``, ``calibrate``, the parsers'
fuzzer) need a trajectory file (:mod:`cadra.io.trajectory`) that stage one would have
written: here it is made from a simulator's exact truth (a simulated shot's ``truth`` table or
a sample shot's ``truth.csv``), optionally with seeded Gaussian noise of the stated sigmas.

:func:`trajectory_table` makes the table, :func:`write_trajectory_file` writes it;
:func:`sphere_trajectory` is the sphere sample's stage-one folder the command-line tests share.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from cadra.facility.reference import REPO_ROOT
from cadra.io.trajectory import COLUMNS, write_trajectory

#: the sample shots (shot files, truth tables, specs)
SAMPLE_SHOTS = REPO_ROOT / "sample_shots"
#: the sphere sample's shot file (its truth beside it)
SPHERE_SHOT = SAMPLE_SHOTS / "sphere_1" / "shot.toml"
#: the truth's columns a trajectory file carries (file units)
TRUTH_COLUMNS = ("station", "t_s", "x_m", "y_m", "z_m", "theta_deg", "psi_deg")


def _truth(source) -> tuple[pd.DataFrame, str | None]:
    """(truth table, shot id or None) of a simulated shot, a table or a truth CSV file."""
    if isinstance(source, pd.DataFrame):
        return source, None
    if isinstance(source, str | os.PathLike):
        return pd.read_csv(source), None
    return source.truth, source.spec.shot_id


def trajectory_table(source, rng: np.random.Generator | None = None, *,
                     sigma_position_m: float = 1e-4, sigma_angle_deg: float = 0.1,
                     rows=None, status: str | Sequence[str] = "ok",
                     x_top_minus_side_m: float = 0.0,
                     x_consistency: float = 0.0) -> pd.DataFrame:
    """A stage-one table (:data:`~cadra.io.trajectory.COLUMNS`, file units) from a truth.

    ``source``: a simulated shot (:class:`~cadra.synthetic.simulate.SimulatedShot`: its
    ``truth``), a truth table, or the path of a truth CSV file. ``rng``: draws Gaussian noise
    of the stated sigmas on the positions and angles (x, y, z, theta, psi, in that order);
    ``None``: the exact truth. ``rows``: the truth's rows to keep (positions, as ``iloc``;
    default all). ``status``: each station's status (one for all, or one per row); the
    two-view consistency columns are constants."""
    t, _ = _truth(source)
    t = t if rows is None else t.iloc[rows]
    if rng is None:
        table = t[list(TRUTH_COLUMNS)].copy()
    else:
        n = len(t)
        sp, sa = sigma_position_m, sigma_angle_deg
        table = pd.DataFrame({
            "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(),
            "x_m": t["x_m"] + rng.normal(0, sp, n), "y_m": t["y_m"] + rng.normal(0, sp, n),
            "z_m": t["z_m"] + rng.normal(0, sp, n),
            "theta_deg": t["theta_deg"] + rng.normal(0, sa, n),
            "psi_deg": t["psi_deg"] + rng.normal(0, sa, n)})
    table["status"] = status if isinstance(status, str) else list(status)
    for c, v in (("sigma_x_m", sigma_position_m), ("sigma_y_m", sigma_position_m),
                 ("sigma_z_m", sigma_position_m), ("sigma_theta_deg", sigma_angle_deg),
                 ("sigma_psi_deg", sigma_angle_deg)):
        table[c] = v
    table["x_top_minus_side_m"], table["x_consistency"] = x_top_minus_side_m, x_consistency
    table["reason"], table["warnings"] = "", ""
    return table[list(COLUMNS)]


def write_trajectory_file(source, shot_file: str | os.PathLike | None,
                          path: str | os.PathLike, rng: np.random.Generator | None = None, *,
                          shot_id: str | None = None,
                          edit: Callable[[pd.DataFrame], None] | None = None,
                          **table_options) -> Path:
    """Write the trajectory file of :func:`trajectory_table` (``source``, ``rng`` and
    ``table_options`` as there) at ``path`` (refusing to overwrite); returns the path.

    Metadata: ``shot_file`` as an absolute path (stage two finds the shot through it; None:
    not named, the shot is then given with the file) and ``shot_id`` (default: the simulated
    shot's). ``edit``: changes the table in place (file units, cells as Python objects: text
    may go in, and floats are written at full precision) before it is written."""
    t = trajectory_table(source, rng, **table_options)
    if edit is not None:
        t = t.astype(object)
        edit(t)
    meta = {"shot_id": shot_id if shot_id is not None else _truth(source)[1]}
    if shot_file is not None:
        meta["shot_file"] = str(Path(shot_file).resolve())
    return write_trajectory(path, t, meta)


def sphere_trajectory(folder: str | os.PathLike, shot_file: str | os.PathLike = SPHERE_SHOT,
                      shot_id: str = "SPH-1") -> Path:
    """A stage-one folder for the sphere sample: ``folder/trajectory.csv`` from its exact
    truth (no noise; sigmas 0.1 mm and 0.1 deg) naming ``shot_file``; returns the file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return write_trajectory_file(SPHERE_SHOT.parent / "truth.csv", shot_file,
                                 folder / "trajectory.csv", shot_id=shot_id)


__all__ = ["SAMPLE_SHOTS", "SPHERE_SHOT", "sphere_trajectory", "trajectory_table",
           "write_trajectory_file"]
