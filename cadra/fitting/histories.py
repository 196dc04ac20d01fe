"""The fitted trajectories a report draws, from the fit's own forward model.

:func:`fitted_histories` samples each shot's fitted trajectory through
:func:`cadra.fitting.problem.result_problem` -- the fitted model, the extras the fit used
and its integration settings -- so what the report and its plots show is what the solver
fitted (docs/fitting.md). Plain data in, tables out: :mod:`cadra.report.fit` and
:mod:`cadra.report.fit_plots` both import it (neither imports the other's module for it).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import pandas as pd

from cadra.channels import OBSERVED, from_si
from cadra.fitting.problem import result_problem
from cadra.fitting.result import FitResult
from cadra.flight.data import ShotData


def fitted_histories(result: FitResult, shots: Sequence[ShotData] | None = None,
                     n_points: int = 400, *, times=None) -> dict[str, pd.DataFrame]:
    """Each shot's fitted trajectory, densely sampled over its measured span.

    Predicted by the fit's own forward model (:func:`cadra.fitting.problem.result_problem`:
    the fitted model, the extras the fit used -- held and free physics extras on -- and the
    fit's integration settings), so the histories are the solver's predictions: at the
    station times they equal the residual table's ``fitted`` (the station extras'
    measurement terms aside: these are the trajectory, not a measurement). ``times``:
    sample there instead (one array for every shot, or ``{shot_id: array}``); default
    ``n_points`` equally spaced from the first to the last station. Returns
    ``{shot_id: DataFrame}`` with columns ``t_s``, ``x_m``, ``y_m``, ``z_m`` (reference
    point, facility frame), ``theta_deg``, ``psi_deg``, ``alpha_deg``, ``beta_deg``,
    ``sigma_deg``, ``mach``, ``p_hat``, ``q_hat``, ``r_hat`` and the cg state ``state_0`` ..
    ``state_12``.
    """
    problem = result_problem(result, shots)
    if shots is not None:
        by_id = {s.shot_id: s for s in shots}
        for sf in result.shots:
            if sf.shot_id not in by_id:
                raise ValueError(f"no ShotData given for shot {sf.shot_id!r} of the result")
    if times is None:
        times = {sd.shot_id: np.linspace(float(sd.t_s[0]), float(sd.t_s[-1]), int(n_points))
                 for sd in problem.shots}
    out = {}
    for sd, h in zip(problem.shots, problem.histories(times=times), strict=True):
        states, obs, air = h["states"], h["observed"], h["air"]
        t = problem.times_of(problem.shot_ids.index(sd.shot_id), times)
        df = pd.DataFrame({"t_s": t})
        for ch in OBSERVED:
            df[ch.display_column] = from_si(obs[ch.si_column], ch.display_unit)
        df = df.assign(
            alpha_deg=np.degrees(air["alpha_rad"]), beta_deg=np.degrees(air["beta_rad"]),
            sigma_deg=np.degrees(air["sigma_rad"]), mach=air["mach"],
            p_hat=air["p_hat"], q_hat=air["q_hat"], r_hat=air["r_hat"])
        for j in range(states.shape[1]):
            df[f"state_{j}"] = states[:, j]
        out[sd.shot_id] = df
    return out


class FlownAngles(NamedTuple):
    """The angles a fit's flights covered (:func:`flown_angles`)."""

    angle: str              # "sigma" for a total-angle model, "alpha" otherwise
    grid_rad: np.ndarray    # from the smallest to the largest angle flown
    mach: float             # the flights' mean Mach

    def path(self) -> tuple:
        """``(alpha, beta, sigma)`` along the grid, as :meth:`cadra.aero.AeroModel.evaluate`
        takes them (beta 0; sigma None for an alpha-beta model: it follows alpha)."""
        return (self.grid_rad, np.zeros_like(self.grid_rad),
                self.grid_rad if self.angle == "sigma" else None)


def flown_angles(result: FitResult, shots: Sequence[ShotData] | None = None,
                 n_points: int = 61) -> FlownAngles:
    """The angles ``result``'s flights covered (the total angle for a total-angle model,
    alpha otherwise), ``n_points`` from the smallest to the largest, and their mean Mach,
    from the fit's own histories (:func:`fitted_histories`): where seed 004 draws its
    coefficient curves (Figs. 9-14) and reads the C_mq peak."""
    angle = "sigma" if result.model.angle_plane == "sigma" else "alpha"
    h = pd.concat(list(fitted_histories(result, shots).values()), ignore_index=True)
    grid = np.radians(np.linspace(h[f"{angle}_deg"].min(), h[f"{angle}_deg"].max(), n_points))
    return FlownAngles(angle, grid, float(h["mach"].mean()))


__all__ = ["FlownAngles", "fitted_histories", "flown_angles"]
