"""Reference fitter for stage two: off-the-shelf SciPy over the same physics (a baseline).

What a careful analyst would write without CADRA's machinery: the model trajectory from
:func:`scipy.integrate.solve_ivp` (an adaptive Runge-Kutta pair, tight tolerances) over the
*same* equations of motion (the compiled :func:`cadra.dynamics.eom.derivative`, called
from Python in the right-hand side) and the *same* observation model
(:func:`cadra.dynamics.observe.observe`), and the fit by :func:`scipy.optimize.least_squares`
with its finite-difference Jacobian. The unknowns are those of :func:`cadra.fitting.solver.fit`:
the model's free aerodynamic parameters (SI/radians, shared by the shots) and each shot's 12
local corrections at its epoch (:data:`cadra.fitting.sensitivity.LOCAL_NAMES`, applied with
:func:`cadra.fitting.sensitivity.apply_local`), residuals weighted by 1/sigma.

It exists to check CADRA's fitter (two implementations, one answer:
``tests/test_fit_baseline.py``) and to measure its speed-up (``tools/bench_cadra2.py``). It is
deliberately plain: no complex step, no block-arrow solve; for several shots it only tells
``least_squares`` the Jacobian's sparsity (each shot's residuals depend on its own local
unknowns and the shared aero ones), so the finite differences of different shots' local
columns are taken together, and it chooses the finite-difference steps (:data:`LOCAL_STEPS`,
``aero_step``): with ``least_squares``' default step on raw SI unknowns the differences drown
in ``solve_ivp``'s step-selection noise and the fit stops early, at a higher chi^2.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cadra.aero import AeroModel
from cadra.dynamics.eom import derivative
from cadra.dynamics.integrate import inverse3
from cadra.dynamics.layout import N_STATE, P_INERTIA
from cadra.dynamics.setup import plane_code
from cadra.fitting.data import ShotData
from cadra.fitting.sensitivity import LOCAL_NAMES, N_LOCAL, apply_local, observables

#: finite-difference steps of the 12 local unknowns (m, m/s, rad, rad/s): each moves the
#: trajectory by ~1e-5 m or rad over a shot, far above ``solve_ivp``'s step-selection noise
#: (~2e-10 m at rtol 1e-10) and far below the film noise (0.1 mm, 1.7e-3 rad); 10x smaller
#: steps (and aero_step 1e-5) already give visibly noisier Jacobians (measured on M2-2429)
LOCAL_STEPS = np.array([1e-5] * 3 + [1e-3] * 3 + [1e-5] * 3 + [1e-3] * 3)


@dataclass(frozen=True)
class BaselineResult:
    """Outcome of :func:`baseline_fit`.

    Attributes
    ----------
    success : ``least_squares``' own verdict (a convergence criterion was met).
    status, message : ``least_squares``' status code and message.
    aero_names : free aerodynamic parameters, in the model's order.
    aero_values, aero_sigma : their fitted values and 1-sigma from ``(J^T J)^-1`` (SI/rad).
    states : per shot, the fitted (13,) state at its epoch.
    local_sigma : per shot, 1-sigma of the 12 local unknowns (:data:`LOCAL_NAMES` units).
    chi2 : weighted sum of squared residuals at the solution.
    n_observations : number of measured channels.
    nfev, njev : residual-vector and Jacobian evaluations (finite-difference evaluations are
        not in ``nfev``; ``n_trajectories`` counts every trajectory integrated).
    n_trajectories : ``solve_ivp`` trajectories integrated in all.
    elapsed_s : wall time of the fit, s.
    """

    success: bool
    status: int
    message: str
    aero_names: tuple[str, ...]
    aero_values: np.ndarray
    aero_sigma: np.ndarray
    states: tuple[np.ndarray, ...]
    local_sigma: tuple[np.ndarray, ...]
    chi2: float
    n_observations: int
    nfev: int
    njev: int
    n_trajectories: int
    elapsed_s: float


def trajectory_ivp(y0: np.ndarray, t0: float, times: np.ndarray, phys: np.ndarray, program,
                   params: np.ndarray, *, method: str = "DOP853", rtol: float = 1e-10,
                   atol: float = 1e-12) -> np.ndarray:
    """States (n, 13) at ``times`` (ascending, s) from ``y0`` at ``t0`` by ``solve_ivp``.

    Integrates forward to the times after ``t0`` and backward to those before it; the states
    at ``times`` come from the method's dense output (``t_eval``). ``rtol``/``atol`` are
    ``solve_ivp``'s tolerances on every state component (SI units of
    :mod:`cadra.dynamics.layout`). Raises ``RuntimeError`` if the integration fails.
    """
    from scipy.integrate import solve_ivp

    phys = np.ascontiguousarray(phys, dtype=float)
    params = np.ascontiguousarray(params, dtype=float)
    I = phys[P_INERTIA:P_INERTIA + 9].reshape(3, 3).copy()
    Iinv = np.empty((3, 3))
    inverse3(I, Iinv)
    R, v_b, variables = np.empty((3, 3)), np.empty(3), np.empty(8)
    F_b, M_b, coef = np.empty(3), np.empty(3), np.empty(9)
    stack = np.empty(max(int(program.stack_size), 1))
    dy = np.empty(N_STATE)
    ops, args, starts = program.ops, program.args, program.starts
    plane = plane_code(program.angle_plane)

    def rhs(_t, y):
        derivative(np.ascontiguousarray(y), phys, I, Iinv, ops, args, starts, params, plane,
                   R, v_b, variables, F_b, M_b, coef, stack, dy)
        return dy.copy()            # solve_ivp keeps the returned array

    times = np.asarray(times, dtype=float)
    out = np.empty((times.size, N_STATE))
    y0 = np.asarray(y0, dtype=float)
    after = times >= t0
    for sel, t_end in ((after, times[-1]), (~after, times[0])):
        if not sel.any():
            continue
        t_eval = times[sel] if t_end >= t0 else times[sel][::-1]
        if t_end == t0:
            out[sel] = y0
            continue
        sol = solve_ivp(rhs, (t0, t_end), y0, method=method, t_eval=t_eval, rtol=rtol,
                        atol=atol)
        if sol.status != 0:
            raise RuntimeError(f"solve_ivp failed: {sol.message}")
        out[sel] = sol.y.T if t_end >= t0 else sol.y.T[::-1]
    return out


def baseline_fit(shots: Sequence[ShotData], model: AeroModel,
                 initial_states: Sequence[np.ndarray], *, method: str = "DOP853",
                 rtol: float = 1e-10, atol: float = 1e-12, jac: str = "2-point",
                 aero_step: float = 1e-4, ftol: float = 1e-10, xtol: float = 1e-10,
                 gtol: float = 1e-10, max_nfev: int | None = None,
                 sparsity: bool = True) -> BaselineResult:
    """Fit like :func:`cadra.fitting.solver.fit` with ``scipy.optimize.least_squares``.

    Parameters
    ----------
    shots, model, initial_states : as for :func:`cadra.fitting.solver.fit` (all 12 local
        unknowns of every shot are free; shots must have angle measurements).
    method, rtol, atol : ``solve_ivp`` method and tolerances (:func:`trajectory_ivp`).
    jac : ``least_squares``' finite-difference scheme (``'2-point'`` or ``'3-point'``).
    aero_step : finite-difference step of each aero parameter, relative to
        ``max(|value|, 0.1)``; the local unknowns step by :data:`LOCAL_STEPS`. The unknowns
        are scaled so that ``least_squares``' own step is these steps: its default on raw SI
        unknowns (~1.5e-8 absolute near zero) drowns in ``solve_ivp``'s step-selection
        noise (~1e-10 m) and the fit stops early, at a higher chi^2.
    ftol, xtol, gtol, max_nfev : ``least_squares``' stopping rules (method ``'trf'``;
        the aero parameters' bounds are passed to it).
    sparsity : for several shots, pass the Jacobian's block-arrow sparsity pattern to
        ``least_squares`` (it then groups columns of different shots' local unknowns into one
        finite-difference evaluation).

    Returns
    -------
    :class:`BaselineResult`.
    """
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    t_start = time.perf_counter()
    program = model.compile()
    params0 = model.values()
    aero_idx = model.free_indices()
    na = aero_idx.size
    ns = len(shots)
    if len(initial_states) != ns:
        raise ValueError("baseline_fit: one initial state per shot is needed")
    if not all(sd.has_angles for sd in shots):
        raise ValueError("baseline_fit: every shot needs angle measurements (12 local "
                         "unknowns)")
    y_nom = [np.asarray(y, dtype=float).copy() for y in initial_states]
    t0s = [float(sd.t_s[sd.epoch_index]) for sd in shots]
    phys = [sd.rigid.phys() for sd in shots]
    refs = [sd.rigid.ref_from_cg_body_m() for sd in shots]
    masks = [sd.mask for sd in shots]
    counts = [int(m.sum()) for m in masks]
    n_traj = [0]

    def shot_residuals(k, p, u):
        states = trajectory_ivp(apply_local(y_nom[k], u), t0s[k], shots[k].t_s, phys[k],
                                program, p, method=method, rtol=rtol, atol=atol)
        n_traj[0] += 1
        pred = observables(states, refs[k])
        return ((shots[k].meas - pred) / shots[k].sigma)[masks[k]]

    def residuals(x):
        p = params0.copy()
        p[aero_idx] = x[:na]
        out = []
        for k in range(ns):
            u = x[na + N_LOCAL * k: na + N_LOCAL * (k + 1)]
            try:
                out.append(shot_residuals(k, p, u))
            except (RuntimeError, FloatingPointError, ZeroDivisionError):
                out.append(np.full(counts[k], 1e10))
        return np.concatenate(out)

    # unknowns scaled so that least_squares' own finite-difference step (sqrt(eps) or
    # eps^(1/3) of max(1, |x|)) is a step of ``aero_step``*max(|value|, 0.1) in each aero
    # parameter and of LOCAL_STEPS in the local unknowns
    rstep = np.finfo(float).eps ** (0.5 if jac == "2-point" else 1.0 / 3.0)
    raw0 = np.concatenate([params0[aero_idx], np.zeros(N_LOCAL * ns)])
    scale = np.concatenate([aero_step * np.maximum(np.abs(params0[aero_idx]), 0.1),
                            np.tile(LOCAL_STEPS, ns)]) / rstep
    lo = np.concatenate([[model.parameters[i].min for i in aero_idx],
                         np.full(N_LOCAL * ns, -np.inf)]) / scale
    hi = np.concatenate([[model.parameters[i].max for i in aero_idx],
                         np.full(N_LOCAL * ns, np.inf)]) / scale
    kwargs = {}
    if sparsity and ns > 1:
        pattern = lil_matrix((sum(counts), raw0.size), dtype=int)
        row = 0
        for k in range(ns):
            pattern[row:row + counts[k], :na] = 1
            pattern[row:row + counts[k], na + N_LOCAL * k: na + N_LOCAL * (k + 1)] = 1
            row += counts[k]
        kwargs["jac_sparsity"] = pattern
    res = least_squares(lambda z: residuals(z * scale), raw0 / scale, jac=jac,
                        bounds=(lo, hi), method="trf", x_scale="jac", ftol=ftol, xtol=xtol,
                        gtol=gtol, max_nfev=max_nfev, **kwargs)
    x = res.x * scale
    J = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
    J = J / scale                                   # d residual / d raw unknown
    cov = np.linalg.pinv(J.T @ J, rcond=1e-15, hermitian=True)
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    states, local_sigma = [], []
    for k in range(ns):
        sl = slice(na + N_LOCAL * k, na + N_LOCAL * (k + 1))
        states.append(apply_local(y_nom[k], x[sl]))
        local_sigma.append(sig[sl].copy())
    names = model.names
    return BaselineResult(
        success=bool(res.success), status=int(res.status), message=str(res.message),
        aero_names=tuple(names[i] for i in aero_idx), aero_values=x[:na].copy(),
        aero_sigma=sig[:na].copy(), states=tuple(states), local_sigma=tuple(local_sigma),
        chi2=float(res.fun @ res.fun), n_observations=sum(counts), nfev=int(res.nfev),
        njev=int(res.njev or 0), n_trajectories=n_traj[0],
        elapsed_s=time.perf_counter() - t_start)


__all__ = ["BaselineResult", "LOCAL_NAMES", "LOCAL_STEPS", "baseline_fit", "trajectory_ivp"]
