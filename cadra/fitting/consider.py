"""Held values with an uncertainty: the consider covariance of a fit.

A parameter the fit holds (``vary = false``) at a value known only to ``sigma``
(:attr:`cadra.aero.Parameter.sigma`, ``--hold NAME=VALUE+-SIGMA``) is a *consider*
parameter in the sense of orbit determination (Schmidt; Tapley, Schutz & Born, *Statistical
Orbit Determination*, ch. 6): it is not estimated, but its uncertainty moves the estimated
ones. To first order the fitted unknowns theta move with the held values c as

    S = d theta / d c = -(J^T J)^-1 J^T C

(J the fit's own weighted Jacobian in theta, ``FitResult.jacobian``; C its weighted columns in
c, one complex-step run per held value and shot of the fit's own forward model at the
fitted point, :func:`cadra.fitting.problem.result_problem`), and
their covariance becomes

    P_consider = P + S diag(sigma_c^2) S^T,

P the fit's own (conditional) covariance. Per free unknown, the held parameter that adds
most to its variance is the one that dominates the difference. The linear prediction is
what a hold study's refits (:func:`cadra.studies.holdone.hold_one_study`) check: a held
value moved by d moves theta by ``S d`` while the data stay near-linear in it
(docs/fitting.md, "Held values with an uncertainty").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from cadra.fitting.priors import prior_rows
from cadra.fitting.problem import result_problem
from cadra.fitting.sensitivity import predict_with_jacobian


@dataclass(frozen=True, eq=False)
class ConsiderAnalysis:
    """The consider covariance of one fit (module doc).

    ``held``: the held parameters with an uncertainty, ``held_values`` and ``held_sigma``
    (SI); ``names``: the fit's unknowns (``FitResult.param_names``); ``sensitivity``
    (len(names), len(held)): d(unknown) / d(held value), SI; ``conditional`` and
    ``covariance``: the fit's own covariance and the consider covariance."""

    held: tuple[str, ...]
    held_values: np.ndarray
    held_sigma: np.ndarray
    names: tuple[str, ...]
    values: np.ndarray
    sensitivity: np.ndarray
    conditional: np.ndarray
    covariance: np.ndarray

    @property
    def sigma_conditional(self) -> np.ndarray:
        return np.sqrt(np.maximum(np.diag(self.conditional), 0.0))

    @property
    def sigma(self) -> np.ndarray:
        """Each unknown's consider sigma (its uncertainty with the holds' own)."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))

    def shift_per_sigma(self) -> np.ndarray:
        """(len(names), len(held)): how far each held value moved by its own sigma moves
        each unknown, in the unknown's conditional sigmas."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.sensitivity * self.held_sigma[None, :] / self.sigma_conditional[:, None]

    def table(self, names: Sequence[str] | None = None) -> pd.DataFrame:
        """Per unknown (default: the shared ones, not the shots' own states): ``value``,
        ``sigma_conditional``, ``sigma_consider``, their ``ratio``, the held parameter that
        adds most to its variance (``dominant_held``) and how far that hold, moved by its
        own sigma, moves it in conditional sigmas (``dominant_shift_sigma``, signed)."""
        names = [n for n in self.names if ":" not in n] if names is None else list(names)
        idx = [self.names.index(n) for n in names]
        shift = self.shift_per_sigma()
        rows = []
        for i in idx:
            j = int(np.argmax(np.abs(shift[i]))) if self.held else -1
            rows.append({"parameter": self.names[i], "value": float(self.values[i]),
                         "sigma_conditional": float(self.sigma_conditional[i]),
                         "sigma_consider": float(self.sigma[i]),
                         "ratio": float(self.sigma[i] / self.sigma_conditional[i])
                         if self.sigma_conditional[i] > 0 else float("nan"),
                         "dominant_held": self.held[j] if j >= 0 else "",
                         "dominant_shift_sigma": float(shift[i, j]) if j >= 0 else 0.0})
        return pd.DataFrame(rows)

    def sensitivity_table(self, names: Sequence[str] | None = None) -> pd.DataFrame:
        """d(unknown) / d(held value) (SI), rows the unknowns (default: the shared ones),
        columns the held parameters."""
        names = [n for n in self.names if ":" not in n] if names is None else list(names)
        idx = [self.names.index(n) for n in names]
        return pd.DataFrame(self.sensitivity[idx], index=pd.Index(names, name="parameter"),
                            columns=list(self.held))


def held_with_sigma(model) -> tuple[str, ...]:
    """The parameters ``model`` holds with an uncertainty (sigma > 0; a held parameter with
    a Gaussian prior is a profile's point, not a consider parameter)."""
    return tuple(p.name for p in model.parameters
                 if not p.vary and p.sigma > 0.0 and p.prior is None)


def held_columns(problem, held: Sequence[str]) -> np.ndarray:
    """The weighted Jacobian columns of the held parameters ``held`` at the problem's own
    point, rows the shots' used measurements in order (as ``FitResult.jacobian``'s): one
    complex-step run per held parameter and shot, the fit's own forward model."""
    model = problem.model
    idx = np.array([model.index(h) for h in held], dtype=int)
    program, params = model.compile(), model.values()
    xv = np.array([e.value for e in problem.free_extras], dtype=float)
    blocks = []
    for k, sd in enumerate(problem.shots):
        phys, ref = problem.physics(k, xv)
        _, jac = predict_with_jacobian(problem.epoch_states[k], problem.epochs[k], sd.t_s,
                                       phys, program, params, ref, [], idx,
                                       problem.integration)
        blocks.append(jac[sd.mask] / sd.sigma[sd.mask][:, None])
    return np.vstack(blocks)


def consider(result, shots=None, held: Sequence[str] | None = None
             ) -> ConsiderAnalysis | None:
    """The consider covariance of ``result`` (a :class:`cadra.fitting.result.FitResult`)
    for the parameters its model holds with an uncertainty; None when it holds none.
    ``held``: these held parameters instead (their sensitivity, whatever their sigma);
    ``shots``: the fit's shots when the result carries no fit problem."""
    held = held_with_sigma(result.model) if held is None else tuple(held)
    if not held:
        return None
    free = [h for h in held if result.model.parameter(h).vary]
    if free:
        raise ValueError(f"consider: {free[0]} is free in this fit, not held")
    if result.jacobian is None:
        raise ValueError("consider: the fit has no Jacobian (its start did not predict)")
    problem = result_problem(result, shots)
    J = result.jacobian.toarray()           # the fit's own, at its final point
    C = held_columns(problem, held)
    if C.shape[0] != J.shape[0]:
        raise ValueError(f"consider: {C.shape[0]} measurements against the fit's "
                         f"{J.shape[0]}: give the shots the fit used")
    # the free parameters' Gaussian priors are measurements too (the held values move none)
    Jp = prior_rows(result.model, result.param_names)
    J = np.vstack([J, Jp])
    C = np.vstack([C, np.zeros((Jp.shape[0], C.shape[1]))])
    # S = -(J^T J)^-1 J^T C by least squares (the same solution, better conditioned)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0.0] = 1.0
    S = -np.linalg.lstsq(J / scale, C, rcond=None)[0] / scale[:, None]
    sig = np.array([result.model.parameter(h).sigma for h in held])
    P = np.asarray(result.covariance, dtype=float)
    cov = P + (S * sig[None, :] ** 2) @ S.T
    return ConsiderAnalysis(held=held,
                            held_values=np.array([result.model.parameter(h).value
                                                  for h in held]),
                            held_sigma=sig, names=tuple(result.param_names),
                            values=problem.theta0, sensitivity=S,
                            conditional=P, covariance=cov)


def linear_hold_prediction(result, name: str, values: Sequence[float], shots=None
                           ) -> pd.DataFrame:
    """The free aerodynamic parameters, to first order, with ``name`` held at each of
    ``values`` (SI): what a hold-one study's refits (seed 004 Fig. 15) should give where the
    data are near-linear in the held value, from ``result`` alone. Held in ``result``: its
    consider sensitivity (theta + S (v - held value)); free in it: the regression of the
    others on it in the fit's covariance (theta + P_op / P_pp (v - its value)), the same
    first-order answer. Columns ``value`` and ``<parameter>_linear``."""
    values = np.asarray(values, dtype=float)
    names = list(result.aero_names)
    if not result.model.parameter(name).vary:
        ca = consider(result, shots, held=(name,))
        idx = [ca.names.index(n) for n in names]
        base, slope = ca.values[idx], ca.sensitivity[idx, 0]
        at = ca.held_values[0]
    else:
        i = list(result.param_names).index(name)
        P = np.asarray(result.covariance, dtype=float)
        idx = [list(result.param_names).index(n) for n in names]
        base, slope = np.asarray(result.aero_values, dtype=float), P[idx, i] / P[i, i]
        at = float(result.model.parameter(name).value)
    out = {"value": values}
    for k, n in enumerate(names):
        if n != name:
            out[f"{n}_linear"] = base[k] + slope[k] * (values - at)
    return pd.DataFrame(out)


__all__ = ["ConsiderAnalysis", "consider", "held_columns", "held_with_sigma",
           "linear_hold_prediction"]
