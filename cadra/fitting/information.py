"""The Fisher information a fit problem's measurements carry about its shared unknowns
(docs/design.md).

Each shot's weighted Jacobian (:meth:`cadra.fitting.problem.FitProblem.jacobian`, the
solver's own sensitivities, rows divided by the measurements' sigmas) gives that shot's
information ``J^T J`` over its free local unknowns and the shared ones (free aero parameters,
free extras). The local unknowns (the shot's own initial state) are nuisance parameters: a
shot's information about the shared unknowns is the Schur complement ``C - B^T A^+ B`` of its
local block ``A`` -- what is left once its own state is fitted too. Shots are independent, so
their shares add; a Gaussian prior adds ``1 / sigma^2`` on its parameter's diagonal
(:mod:`cadra.fitting.priors`). The inverse of the sum is the covariance the solver reports for
the shared unknowns (at the same point: a test checks it), and adding a candidate shot's share
predicts the covariance after it is fired.

Directions the information does not reach (an eigenvalue below ``rcond`` times the largest)
have an infinite variance: :func:`covariance_sigmas` says so instead of returning the
pseudo-inverse's zero.
"""

from __future__ import annotations

import numpy as np

from cadra.fitting.priors import prior_rows
from cadra.fitting.problem import FitProblem
from cadra.fitting.solver import FitOptions, _psolve

__all__ = ["RCOND", "covariance_sigmas", "problem_information", "shot_information"]

#: relative eigenvalue cut-off: directions with less information are "not determined" (the
#: solver's own)
RCOND = FitOptions.rcond


def shot_information(jac: np.ndarray, sigma: np.ndarray, mask: np.ndarray,
                     n_local: int) -> np.ndarray:
    """One shot's (n_shared, n_shared) information about the shared unknowns.

    ``jac``: the shot's (n, N_CHANNELS, n_local + n_shared) Jacobian (its locals first, as
    :meth:`FitProblem.jacobian` gives it); ``sigma``, ``mask``: its (n, N_CHANNELS) sigmas and
    measured entries. The locals are profiled out (module doc)."""
    w = 1.0 / sigma[mask]
    J = jac[mask] * w[:, None]
    Jl, Js = J[:, :n_local], J[:, n_local:]
    C = Js.T @ Js
    if not n_local:
        return C
    A, B = Jl.T @ Jl, Jl.T @ Js
    return C - B.T @ _psolve(A, B, RCOND)


def problem_information(problem: FitProblem, jacobians=None) -> np.ndarray:
    """The (n_shared, n_shared) information of all of ``problem``'s shots and of its model's
    priors about its shared unknowns (``problem.param_names[:problem.n_shared]``), at the
    problem's point. ``jacobians``: the per-shot Jacobians when already computed."""
    jacs = problem.jacobian() if jacobians is None else jacobians
    ns = problem.n_shared
    info = np.zeros((ns, ns))
    for sd, lf, jac in zip(problem.shots, problem.local_free, jacs, strict=True):
        info += shot_information(jac, sd.sigma, sd.mask, lf.size)
    names = list(problem.param_names[:ns])
    rows = prior_rows(problem.model, names)
    return info + rows.T @ rows


def covariance_sigmas(info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(covariance, sigmas) from an information matrix: the pseudo-inverse, with the sigma of
    any unknown that a not-determined direction reaches set to ``inf`` (module doc)."""
    n = info.shape[0]
    if n == 0:
        return np.zeros((0, 0)), np.zeros(0)
    d = np.sqrt(np.maximum(np.diag(info), 0.0))
    d[d == 0] = 1.0
    S = info / np.outer(d, d)                  # scaled: the cut-off is scale-free
    w, V = np.linalg.eigh(0.5 * (S + S.T))
    top = max(float(w[-1]), 0.0)
    keep = w > RCOND * top if top > 0 else np.zeros(n, dtype=bool)
    # the solver's pseudo-inverse (cadra.fitting.result), with the eigenvectors it drops kept
    # here: an unknown with a share in one of them is one no data reach
    cov = (V[:, keep] / w[keep]) @ V[:, keep].T / np.outer(d, d)
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    reached = (np.abs(V[:, ~keep]) > 1e-6).any(axis=1) if (~keep).any() else np.zeros(n, bool)
    sig[reached] = np.inf
    return cov, sig
