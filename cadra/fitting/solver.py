"""Least-squares differential correction: Levenberg-Marquardt on the block-arrow normal equations.

Unknowns: the free aerodynamic parameters (shared by every shot of a multi-fit) and each shot's
free local unknowns (corrections to its state at the epoch; :mod:`cadra.fitting.sensitivity`).
The Jacobian of a multi-shot fit is block-arrow shaped (seed 003's global fit): shot k's
residuals depend on its own local unknowns and on the shared ones only, so the normal matrix is

    [ A_1           B_1 ]     A_k = J_k^T J_k      (local x local, 12 x 12)
    [      A_2      B_2 ]     B_k = J_k^T G_k      (local x shared)
    [           ... ... ]     C   = sum G_k^T G_k  (shared x shared)
    [ B_1^T B_2^T ... C ]

and each step is solved through the Schur complement ``S = C - sum B_k^T A_k^-1 B_k`` (cost
linear in the number of shots). Columns are scaled to unit norm (Marquardt's scaling) and the
damping is ``lambda I`` in scaled space. Every solve goes through an eigen-decomposition with
a relative cut-off, so a singular matrix (parameters the data cannot separate) never raises:
the step leaves those directions alone and the result names them
(:mod:`cadra.fitting.result`).

Pure function over plain data: :func:`fit` takes :class:`cadra.flight.data.ShotData` s and an
:class:`cadra.aero.AeroModel` and returns a :class:`cadra.fitting.result.FitResult`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from cadra.aero import AeroModel
from cadra.channels import residual
from cadra.dynamics.integrate import EVALS_PER_SECOND, MAX_ADAPTIVE_EVALS
from cadra.fitting.extras import Extra
from cadra.fitting.priors import prior_chi2, prior_terms
from cadra.fitting.problem import FitProblem, default_local_free
from cadra.fitting.sensitivity import LOCAL_NAMES, N_LOCAL, Integration, apply_local
from cadra.flight.data import ShotData

#: statuses of a fit; only the first counts as a result
STATUSES = ("converged", "max_iterations", "stalled", "failed")

#: the damping's floor (scaled space)
LAMBDA_MIN = 1e-12

#: environment variable that chooses the damping schedule of every fit of a process:
#: ``search`` (default: an accepted step is also tried less damped while the linear model
#: predicts its gain) or ``classic`` (Marquardt's: one trial per damping, divided by ten after
#: each accepted step; what the fit did before, kept for the speed A/B); docs/fitting.md,
#: "Solver"
DAMPING_ENV = "CADRA_DAMPING"
DAMPINGS = ("search", "classic")


def damping() -> str:
    """The damping schedule this process's fits use (:data:`DAMPING_ENV`)."""
    chosen = os.environ.get(DAMPING_ENV, "search").strip().lower() or "search"
    if chosen not in DAMPINGS:
        raise ValueError(f"{DAMPING_ENV} must be one of {DAMPINGS}, got {chosen!r}")
    return chosen


@dataclass(frozen=True)
class FitOptions:
    """Convergence control of :func:`fit`.

    A fit has converged when the Gauss-Newton step it would still take changes the parameters
    by less than ``step_tol_sigma`` of their standard deviations (that is, chi^2 by less than
    ``step_tol_sigma**2``, scaled by the reduced chi^2 when that exceeds 1).
    """

    max_iterations: int = 60
    step_tol_sigma: float = 1e-2
    noise_tol_sigma: float = 0.1         # see the "stalled" rule in :func:`fit`
    lambda_start: float = 1e-3
    lambda_max: float = 1e12
    rcond: float = 1e-12                 # eigenvalue cut-off of every solve (relative)
    integration: Integration = field(default_factory=Integration)
    progress: bool = False
    progress_label: str = "cadra2 fit"   # the progress bar's label (fit_shots names its phases)


@dataclass
class _ShotState:
    data: ShotData
    y_nom: np.ndarray            # (13,) state at the epoch
    local_free: np.ndarray       # indices into LOCAL_NAMES
    t0: float
    phys: np.ndarray             # the shot's physics with the held extras on
    ref: np.ndarray              # its reference point from the cg, body axes
    mask: np.ndarray             # (n, N_CHANNELS)
    pred: np.ndarray | None = None
    jac: np.ndarray | None = None


def _frame_note(problem) -> str:
    """Why a fast-spinning shot's steps are short: it integrates in its body frame (its roll
    measured or fitted, or physics the non-rolling frame cannot carry), or ""."""
    from cadra.dynamics.setup import non_rolling_obstacle

    for sd, y, frame in zip(problem.shots, problem.epoch_states, problem.frames, strict=True):
        if frame == "body" and abs(y[10]) * problem.integration.h_max_s > 1.0:
            why = (non_rolling_obstacle(sd.rigid.phys(), problem.model.compile(), (),
                                        sd.rigid.ref_from_cg_body_m())
                   or "its roll is measured or fitted")
            return (f" (shot {sd.shot_id} spins at {y[10]:.4g} rad/s and is integrated in "
                    f"its body frame because {why}, so its spin sets the step)")
    return ""


def _weighted(st: _ShotState, pred: np.ndarray) -> np.ndarray:
    r = residual(st.data.meas, pred) / st.data.sigma
    return r[st.mask]


def _chi2(states: list[_ShotState], preds: list[np.ndarray]) -> float:
    total = 0.0
    for st, p in zip(states, preds, strict=True):
        r = _weighted(st, p)
        if not np.all(np.isfinite(r)):
            return math.inf
        total += float(r @ r)
    return total


def _psolve(M: np.ndarray, b: np.ndarray, rcond: float) -> np.ndarray:
    """Solve the symmetric system M x = b by eigen-decomposition, dropping directions whose
    eigenvalue is below ``rcond`` times the largest (never raises on a singular matrix)."""
    if M.size == 0:
        return np.zeros_like(b)
    w, V = np.linalg.eigh(0.5 * (M + M.T))
    top = max(float(w[-1]), 0.0)
    keep = w > rcond * top if top > 0 else np.zeros_like(w, dtype=bool)
    inv = np.zeros_like(w)
    inv[keep] = 1.0 / w[keep]
    return V @ ((V.T @ b) * inv[:, None] if b.ndim == 2 else (V.T @ b) * inv)


def _blocks(states, aero_free_count):
    """Scaled weighted Jacobian blocks and residuals of every shot."""
    out = []
    for st in states:
        w = 1.0 / st.data.sigma[st.mask]                          # (m,)
        J = st.jac[st.mask] * w[:, None]                          # (m, nl + na)
        r = _weighted(st, st.pred)
        nl = st.local_free.size
        out.append((J[:, :nl], J[:, nl:nl + aero_free_count], r))
    return out


def _normal_equations(blocks, na):
    """Per-shot (A_k, B_k, g_k), the shared C and g_a, and the column scales."""
    Ca = np.zeros((na, na))
    ga = np.zeros(na)
    per = []
    for Js, Ja, r in blocks:
        per.append((Js.T @ Js, Js.T @ Ja, Js.T @ r))
        Ca += Ja.T @ Ja
        ga += Ja.T @ r
    return per, Ca, ga


def _scales(per, Ca):
    da = np.sqrt(np.maximum(np.diag(Ca), 0.0))
    da[da == 0] = 1.0
    ds = []
    for A, _, _ in per:
        d = np.sqrt(np.maximum(np.diag(A), 0.0))
        d[d == 0] = 1.0
        ds.append(d)
    return ds, da


def _step(per, Ca, ga, ds, da, lam, rcond):
    """Damped Gauss-Newton step through the Schur complement (scaled space).

    Returns (local steps per shot, shared step, predicted chi^2 decrease)."""
    na = Ca.shape[0]
    S = Ca / np.outer(da, da) + lam * np.eye(na)
    rhs = ga / da
    solves = []
    for (A, B, g), d in zip(per, ds, strict=True):
        As = A / np.outer(d, d) + lam * np.eye(d.size)
        Bs = B / np.outer(d, da)
        gs = g / d
        X = _psolve(As, np.column_stack([Bs, gs]), rcond) if d.size else np.zeros((0, na + 1))
        S -= Bs.T @ X[:, :na]
        rhs -= Bs.T @ X[:, na]
        solves.append((X, Bs))
    delta_a_s = _psolve(S, rhs, rcond) if na else np.zeros(0)
    local_steps = []
    decrease = 0.0
    for (X, _), (_, _, g), d in zip(solves, per, ds, strict=True):
        dls = X[:, na] - X[:, :na] @ delta_a_s
        local_steps.append(dls / d)
        decrease += float((g / d) @ dls)
    decrease += float((ga / da) @ delta_a_s)
    return local_steps, delta_a_s / da, decrease


def _stop_rule(accepted: bool, decrease: float, chi2: float, gn_decrease: float,
               gradient: float, scale: float, options: FitOptions) -> tuple[str, str] | None:
    """Whether an iteration ends the fit, after its Levenberg-Marquardt trials: ``(status,
    message)``, or None to go on. ``accepted``: a trial reduced chi^2 (by ``decrease``);
    ``gn_decrease``: what the full Gauss-Newton step predicts; ``gradient``: the scaled
    gradient's share of chi^2, ``sum (g_j / |J_j|)^2`` (what a small step along each unknown's
    own direction can gain); ``scale``: max(1, chi^2 / dof). The fit stops:

    1. accepted, but gaining less than the convergence tolerance with the Gauss-Newton step
       inside the noise floor: converged (the trial, a prediction, and the Jacobian run
       integrate on different step sequences and differ by ~1e-5 in chi^2, so a heavily
       damped step can "win" on that difference alone, for ever: seen, 60 such iterations);
    2. no step, or no worthwhile one, and the gradient within the noise while the
       Gauss-Newton step still promises more: converged to a stationary point, the promise
       lying along near-degenerate directions where chi^2 is far from quadratic (a ridge of
       correlated parameters bent by a ``max(...)`` form's kink: the M1 M1.10 C_mq peak freed
       on stage-one data, scaled gradient 1e-6 against a promise of 0.47);
    3. no step, the Gauss-Newton step inside the noise floor (the adaptive integrator's step
       choices, ~1e-6 in chi^2, hide it): converged;
    4. no step at all otherwise: stalled.
    """
    noise = options.noise_tol_sigma**2 * scale
    small_gain = not accepted or decrease <= options.step_tol_sigma**2 * scale

    def sig(x):
        return math.sqrt(max(x / scale, 0.0))

    if accepted and gn_decrease <= noise and small_gain:
        return "converged", (f"converged to the integration noise floor: the remaining "
                             f"Gauss-Newton step, {sig(gn_decrease):.1e} sigma, no longer "
                             "reduces chi^2 beyond its numerical noise")
    if small_gain and gradient <= noise < gn_decrease:
        return "converged", (f"converged to a stationary point: no step reduces chi^2 beyond "
                             f"its numerical noise and its scaled gradient is "
                             f"{sig(gradient):.1e} sigma; the Gauss-Newton step's "
                             f"{sig(gn_decrease):.1e} sigma lies along near-degenerate "
                             "directions where chi^2 is not quadratic")
    if not accepted and gn_decrease <= noise:
        return "converged", (f"converged to the integration noise floor: the remaining "
                             f"Gauss-Newton step, {sig(gn_decrease):.1e} sigma, reduces chi^2 "
                             "by less than its numerical noise")
    if not accepted:
        return "stalled", (f"stalled at chi^2 = {chi2:.6g}: no step reduces it (the remaining "
                           f"Gauss-Newton step is {math.sqrt(max(gn_decrease, 0)):.2e} in chi "
                           "units); the model may not describe the data")
    return None


def fit(shots: Sequence[ShotData], model: AeroModel, initial_states: Sequence[np.ndarray], *,
        options: FitOptions = FitOptions(), local_free: Sequence[np.ndarray] | None = None,
        extras: Sequence[Extra] = ()):
    """Fit the free parameters of ``model`` and each shot's initial state to the measurements.

    Parameters
    ----------
    shots : the shots (one for a single fit, several for a multi-fit).
    model : the aerodynamic model; its values are the starting point, ``vary`` says which are
        free, ``min``/``max`` bound them.
    initial_states : per shot, the (13,) starting state at the shot's epoch
        (``shot.t_s[shot.epoch_index]``), e.g. from :func:`cadra.fitting.start.initial_state`.
    options : convergence control and integration settings.
    local_free : per shot, indices into :data:`LOCAL_NAMES` to fit (default
        :func:`default_local_free`).
    extras : further shared unknowns, started at their ``value`` (unmodelled effects made
        free: physics directions and station terms, :mod:`cadra.fitting.extras`); they sit
        beside the free aero parameters in the shared block. A ``held`` extra acts at its
        value and is not fitted (the result lists it in ``held_extras``).

    Returns
    -------
    :class:`cadra.fitting.result.FitResult` -- also when the fit did not converge (its
    ``status`` says so and it holds the best point reached).
    """
    from cadra.fitting.result import build_result

    t_start = time.perf_counter()
    # the forward model: every prediction of the fit goes through it (cadra.fitting.problem)
    problem = FitProblem(tuple(shots), model, tuple(initial_states), tuple(extras),
                         None if local_free is None else tuple(local_free),
                         options.integration)
    params = model.values()
    aero_idx = problem.aero_indices
    extras = problem.free_extras
    xvals = np.array([e.value for e in extras], dtype=float)
    ne = len(extras)
    na = aero_idx.size
    ns = na + ne                # shared unknowns: free aero parameters, then the extras
    lo = np.array([model.parameters[i].min for i in aero_idx])
    hi = np.array([model.parameters[i].max for i in aero_idx])
    states = [_ShotState(sd, y0.copy(), lf, t0, *problem.held_physics(k), sd.mask)
              for k, (sd, y0, lf, t0) in enumerate(zip(problem.shots, problem.epoch_states,
                                                       problem.local_free, problem.epochs,
                                                       strict=True))]
    # Gaussian priors (cadra.fitting.priors): one pseudo-measurement each; a free one's
    # information and residual enter the shared block at its column
    p_idx, p_mean, p_sig = prior_terms(model)
    shared_at = {int(i): k for k, i in enumerate(aero_idx)}
    p_col = np.array([shared_at.get(int(i), -1) for i in p_idx], dtype=int)

    def with_priors(Ca, ga, p, blocked=None):
        for c, i, m, s in zip(p_col, p_idx, p_mean, p_sig, strict=True):
            if c >= 0 and (blocked is None or not blocked[c]):
                Ca[c, c] += 1.0 / s**2
                ga[c] += (m - p[i]) / s**2
        return Ca, ga

    n_obs = sum(st.mask.sum() for st in states) + p_idx.size
    n_free = ns + sum(st.local_free.size for st in states)
    warnings: list[str] = []
    message = ""
    if n_obs < n_free:
        message = (f"{n_obs} measurements for {n_free} free unknowns: too few stations for the "
                   "free parameters (hold some, or add stations or shots); not fitted")
        warnings.append(message)

    def evaluate_jac(p, xv):
        """chi^2 at (p, xv) and the states' predictions and Jacobians there; inf when either
        is not finite (no linearisation to step from)."""
        try:
            preds, jacs = problem.jacobian_from(p, xv, [st.y_nom for st in states])
        except (FloatingPointError, ZeroDivisionError):
            for st in states:
                st.pred = st.jac = None
            return math.inf
        for st, pred, jac in zip(states, preds, jacs, strict=True):
            st.pred, st.jac = pred, jac
        if not all(np.all(np.isfinite(st.jac[st.mask])) for st in states):
            return math.inf
        return _chi2(states, [st.pred for st in states]) + prior_chi2(model, p)

    def evaluate(p, xv, ys):
        return problem.predict_from(p, xv, ys)

    search = damping() == "search"
    history = []
    status = "failed"
    lam = options.lambda_start
    iterations = 0
    bar = None
    if options.progress:
        from tqdm import tqdm

        bar = tqdm(total=options.max_iterations, desc=options.progress_label, unit="it",
                   leave=False)
    try:
        chi2 = evaluate_jac(params, xvals)
        if n_obs < n_free:
            history.append(chi2)
            return build_result(problem, params, states, "failed", message, history,
                                warnings, iterations, t_start, options, lam, xvals)
        if not math.isfinite(chi2):
            message = ("the starting point gives a non-finite prediction or Jacobian: the "
                       "trajectory diverges or tumbles, or a run needs more derivative "
                       f"evaluations than its budget ({MAX_ADAPTIVE_EVALS:,}, or "
                       f"{EVALS_PER_SECOND:,} per second of the record if more), i.e. steps "
                       "far below the motion's time scales"
                       + _frame_note(problem) + "; better starting values are needed"
                       + model.nonfinite_note(params))
            return build_result(problem, params, states, status, message, history,
                                warnings, iterations, t_start, options, lam, xvals)
        history.append(chi2)
        while True:
            if iterations >= options.max_iterations:
                status = "max_iterations"
                message = (f"not converged after {iterations} iterations (chi^2 = {chi2:.6g})"
                           "; the best point reached is reported")
                break
            iterations += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(chi2=f"{chi2:.4g}", lam=f"{lam:.1e}")
            blocks = _blocks(states, ns)
            per, Ca, ga = _normal_equations(blocks, ns)
            Ca, ga = with_priors(Ca, ga, params)
            ds, da = _scales(per, Ca)
            # Gauss-Newton step size (lambda ~ 0): the convergence test
            _, gn_a, gn_decrease = _step(per, Ca, ga, ds, da, 1e-14, options.rcond)
            # active set: a parameter at a bound whose step points outward is frozen for
            # this iteration (its column is dropped), so neither the step nor the convergence
            # test pushes against the bound (the extras are unbounded)
            pa = params[aero_idx]
            blocked = np.zeros(ns, dtype=bool)
            blocked[:na] = ((pa <= lo) & (gn_a[:na] < 0)) | ((pa >= hi) & (gn_a[:na] > 0))
            if blocked.any():
                blocks = [(Js, np.where(blocked, 0.0, Ja), r) for Js, Ja, r in blocks]
                per, Ca, ga = _normal_equations(blocks, ns)
                Ca, ga = with_priors(Ca, ga, params, blocked)
                ds, da = _scales(per, Ca)
                _, _, gn_decrease = _step(per, Ca, ga, ds, da, 1e-14, options.rcond)
            dof = max(n_obs - n_free, 1)
            scale = max(1.0, chi2 / dof)
            # the scaled gradient's share of chi^2: what a small step along each unknown's
            # own direction can gain (first-order optimality, insensitive to the
            # ill-conditioning that can make the Gauss-Newton step promise much more)
            gradient = float(sum(np.sum((g / d) ** 2) for (_, _, g), d in zip(per, ds,
                                                                          strict=True))
                             + np.sum((ga / da) ** 2))
            if gn_decrease <= options.step_tol_sigma**2 * scale:
                status = "converged"
                message = (f"converged: the remaining Gauss-Newton step is "
                           f"{math.sqrt(max(gn_decrease / scale, 0.0)):.1e} sigma")
                break
            accepted = False

            def trial(lam, per=per, Ca=Ca, ga=ga, ds=ds, da=da, params=params, xvals=xvals):
                """The step damped by ``lam``: (chi^2 there, its predicted decrease,
                parameters, extras, epoch states)."""
                dls, dap, predicted = _step(per, Ca, ga, ds, da, lam, options.rcond)
                p_try = params.copy()
                p_try[aero_idx] = np.clip(params[aero_idx] + dap[:na], lo, hi)
                x_try = xvals + dap[na:]
                ys = []
                for st, dl in zip(states, dls, strict=True):
                    u = np.zeros(N_LOCAL)
                    u[st.local_free] = dl
                    ys.append(apply_local(st.y_nom, u))
                try:
                    chi2_try = _chi2(states, evaluate(p_try, x_try, ys)) + prior_chi2(model, p_try)
                except (FloatingPointError, ZeroDivisionError):
                    chi2_try = math.inf
                return chi2_try, predicted, p_try, x_try, ys

            while lam <= options.lambda_max:
                chi2_try, predicted, p_try, x_try, ys = trial(lam)
                if chi2_try < chi2 and search:
                    # the lambda search: while the linear model predicts the gain (half of
                    # it at least), the step damped ten times less is tried too, and the best
                    # kept; a trial costs a prediction, a Jacobian a dozen or more
                    while (lam > LAMBDA_MIN and chi2 - chi2_try >= 0.5 * predicted
                           and predicted > options.noise_tol_sigma**2 * scale):
                        less = trial(lam / 10.0)
                        if not less[0] < chi2_try:
                            break
                        lam /= 10.0
                        chi2_try, predicted, p_try, x_try, ys = less
                if chi2_try < chi2:
                    kept = [(st.y_nom, st.pred, st.jac) for st in states]
                    for st, y in zip(states, ys, strict=True):
                        st.y_nom = y
                    chi2_jac = evaluate_jac(p_try, x_try)
                    if not math.isfinite(chi2_jac):
                        # the Jacobian's integration runs on its own step sequence and can
                        # overflow, or run out of evaluations, where the trial prediction
                        # did not: no linearisation there, so the trial counts as rejected
                        for st, (y, pred, jac) in zip(states, kept, strict=True):
                            st.y_nom, st.pred, st.jac = y, pred, jac
                        lam *= 10.0
                        continue
                    params, xvals = p_try, x_try
                    chi2_before, chi2 = chi2, chi2_jac
                    history.append(chi2)
                    lam = max(lam / 10.0, LAMBDA_MIN)
                    accepted = True
                    break
                lam *= 10.0
            stop = _stop_rule(accepted, chi2_before - chi2 if accepted else 0.0, chi2,
                              gn_decrease, gradient, scale, options)
            if stop is not None:
                status, message = stop
                if status == "stalled":
                    lam = options.lambda_start
                break
    finally:
        if bar is not None:
            bar.close()
    return build_result(problem, params, states, status, message, history, warnings,
                        iterations, t_start, options, lam, xvals)


__all__ = ["DAMPINGS", "DAMPING_ENV", "LAMBDA_MIN", "STATUSES", "FitOptions", "FitProblem",
           "LOCAL_NAMES", "damping", "default_local_free", "fit"]
