"""Seed 004's hold-one-parameter study (Fig. 15; "Uncertainties").

Hold one parameter at each of several values, refit the rest on all shots, and tabulate the
fit quality and the other parameters against the held value (:func:`hold_one_study`; the plot:
:func:`cadra.report.studies.plot_hold_one`). :func:`hold_one_refit` is the per-value unit a
scheduler can ship.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

from cadra.aero import AeroModel
from cadra.fitting.result import FitResult
from cadra.fitting.solver import FitOptions, fit
from cadra.flight.data import ShotData
from cadra.studies.single import (
    InitialStates,
    check_count,
    initial_state_of,
    parameter_columns,
    rms_columns,
    sigma_residual_rms_deg,
)


def hold_one_refit(shots: Sequence[ShotData], model: AeroModel, initial_states, name: str,
                   value: float, *, options: FitOptions | None = None
                   ) -> tuple[dict, FitResult]:
    """One hold-one refit: ``name`` held at ``value`` (SI), the other free parameters and every
    shot's state refitted on all ``shots`` together.

    Returns ``(row, result)``: the row of :func:`hold_one_study` and the fit result.
    """
    options = options or FitOptions()
    m = model.with_vary({name: False}).with_values({name: float(value)})
    res = fit(list(shots), m, [np.asarray(y, dtype=float) for y in initial_states],
              options=options)
    failed = res.status == "failed"   # its chi^2 (0 or a start's) belongs to no fit
    row = {"held": name, "value": float(value), "status": res.status,
           "converged": bool(res), "iterations": res.iterations,
           "chi2": math.nan if failed else res.chi2,
           "n_observations": res.n_observations, "dof": res.dof,
           "reduced_chi2": math.nan if failed else res.reduced_chi2}
    row.update(rms_columns(res.rms()))
    row["sigma_rms_deg"] = sigma_residual_rms_deg(res, shots, options.integration)
    row.update(parameter_columns(res, exclude=name))
    return row, res


def hold_one_study(shots: Sequence[ShotData], model: AeroModel, initial_states: InitialStates,
                   name: str, values: Sequence[float], *,
                   options: FitOptions | None = None) -> pd.DataFrame:
    """Seed 004 Fig. 15: hold one parameter at each value, refit the rest on all shots.

    Parameters
    ----------
    shots : the shots of the multi-fit.
    model : the model; its free parameters other than ``name`` are refitted.
    initial_states : per shot a (13,) state at its epoch, or a callable
        ``(shot, model) -> (13,) state``.
    name : the held parameter.
    values : the values to hold it at (SI; radians for an angle parameter).
    options : fit options.

    The values are visited in increasing order. The first refit starts from ``model``'s
    values and ``initial_states``; each later one from the previous converged refit's
    parameters and states (continuation: neighbouring held values have neighbouring
    solutions). After a refit that did not converge the next starts again from the given
    start.

    Returns
    -------
    DataFrame sorted by ``value``: ``held``, ``value``, ``status``, ``converged``,
    ``iterations``, ``chi2``, ``n_observations``, ``dof``, ``reduced_chi2``, residual rms
    ``x_rms_m, y_rms_m, z_rms_m, theta_rms_deg, psi_rms_deg``, ``sigma_rms_deg``
    (:func:`sigma_residual_rms_deg`), and every other free parameter's value, ``_sigma`` and
    ``_sigma_scaled``.
    """
    if name not in model.names:
        raise KeyError(f"hold_one_study: the model has no parameter {name!r}")
    check_count(shots, initial_states)
    vals = np.asarray(values, dtype=float)
    if vals.ndim != 1 or vals.size == 0 or not np.all(np.isfinite(vals)):
        raise ValueError("hold_one_study: values must be a non-empty list of finite numbers")
    start_states = [initial_state_of(initial_states, k, sd, model) for k, sd in enumerate(shots)]
    cur_model, cur_states = model, start_states
    rows = []
    for v in np.sort(vals):
        row, res = hold_one_refit(shots, cur_model, cur_states, name, float(v),
                                  options=options)
        rows.append(row)
        if res:
            cur_model = res.model.with_vary({name: model.parameter(name).vary})
            cur_states = [sf.state for sf in res.shots]
        else:
            cur_model, cur_states = model, start_states
    return pd.DataFrame(rows).reset_index(drop=True)


def lowest_converged(table: pd.DataFrame) -> float | None:
    """The held value whose refit converged with the lowest chi^2 (None if none converged):
    a failed refit's chi^2 belongs to no fit, however low."""
    ok = table[table["converged"].astype(bool) & table["chi2"].notna()]
    return float(ok.loc[ok["chi2"].idxmin(), "value"]) if len(ok) else None


def with_linear_prediction(table: pd.DataFrame, result, name: str) -> pd.DataFrame:
    """``table`` (:func:`hold_one_study`'s) with each other free parameter's first-order
    prediction from ``result``, the fit the study started from (``<parameter>_linear``,
    :func:`cadra.fitting.consider.linear_hold_prediction`): the study is the nonlinear check
    of the consider sensitivity. ``table`` unchanged when ``result`` has no forward model."""
    from cadra.fitting.consider import linear_hold_prediction

    if getattr(result, "problem", None) is None or result.jacobian is None:
        return table
    pred = linear_hold_prediction(result, name, table["value"].to_numpy(float))
    keep = [c for c in pred.columns if c != "value" and c[:-len("_linear")] in table]
    return pd.concat([table.reset_index(drop=True), pred[keep]], axis=1)


__all__ = ["hold_one_refit", "hold_one_study", "lowest_converged", "with_linear_prediction"]
