"""Gaussian priors on aerodynamic parameters: the Bayesian alternative to a hold with an
uncertainty (docs/fitting.md, "Held values with an uncertainty").

A parameter with a prior (:attr:`cadra.aero.Parameter.prior`, the prior's mean, and its
``sigma``) is fitted with one more term in chi^2, ``((value - prior) / sigma)^2``: a
pseudo-measurement of the parameter itself. The solver adds its information ``1 / sigma^2`` to
the normal equations and its residual to the gradient; the covariance the fit reports is then
the posterior's (linearised), and the prior counts as one observation in the degrees of
freedom. A held parameter with a prior (a profile-likelihood point, for instance) adds its
term at the held value, so chi^2 differences along a profile stay right.

Against the consider covariance of the same hold (:mod:`cadra.fitting.consider`): the data
here may move the parameter, and it may narrow it; the two agree where the data carry
little information on it (its data-only sigma far above the prior's) and the problem is
near-linear over the prior's width.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from cadra.aero import AeroModel

__all__ = ["holds_as_priors", "prior_chi2", "prior_names", "prior_rows", "prior_terms"]


def prior_names(model: AeroModel) -> tuple[str, ...]:
    """The parameters of ``model`` that carry a Gaussian prior."""
    return tuple(p.name for p in model.parameters if p.prior is not None)


def prior_terms(model: AeroModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indices into model.values(), means, sigmas)`` of the model's priors (SI)."""
    idx = [i for i, p in enumerate(model.parameters) if p.prior is not None]
    return (np.array(idx, dtype=int),
            np.array([model.parameters[i].prior for i in idx], dtype=float),
            np.array([model.parameters[i].sigma for i in idx], dtype=float))


def prior_chi2(model: AeroModel, params: np.ndarray) -> float:
    """The priors' share of chi^2 at the full parameter vector ``params`` (SI)."""
    idx, mean, sig = prior_terms(model)
    if not idx.size:
        return 0.0
    z = (np.asarray(params, dtype=float)[idx] - mean) / sig
    return float(z @ z)


def prior_rows(model: AeroModel, names: Sequence[str]) -> np.ndarray:
    """The priors of the free parameters among ``names`` as weighted Jacobian rows
    (k, len(names)): ``1 / sigma`` in the parameter's column (what a pseudo-measurement of
    the parameter adds to ``J``)."""
    cols = {n: j for j, n in enumerate(names)}
    rows = [(cols[p.name], 1.0 / p.sigma) for p in model.parameters
            if p.prior is not None and p.vary and p.name in cols]
    out = np.zeros((len(rows), len(names)))
    for r, (j, w) in enumerate(rows):
        out[r, j] = w
    return out


def holds_as_priors(model: AeroModel, names: Iterable[str] | None = None) -> AeroModel:
    """``model`` with its held parameters that carry an uncertainty (or ``names``) freed,
    each with a Gaussian prior at its held value and with its sigma: the Bayesian
    alternative to their consider covariance. A named parameter without a sigma raises
    ``ValueError``."""
    if names is None:
        names = [p.name for p in model.parameters
                 if not p.vary and p.sigma > 0.0 and p.prior is None]
    priors = {}
    for n in names:
        p = model.parameter(n)
        if not p.sigma > 0.0:
            raise ValueError(f"{n}: a prior needs an uncertainty; give it as "
                             f"{n}=VALUE+-SIGMA")
        priors[n] = (p.value, p.sigma)
    return model.with_priors(priors)
