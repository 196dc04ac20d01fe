"""Reference fitter for stage two: off-the-shelf SciPy over the same physics (a baseline).

What a careful analyst would write without CADRA's machinery: the model trajectory from
:func:`scipy.integrate.solve_ivp` (an adaptive Runge-Kutta pair, tight tolerances) over the
*same* equations of motion (by default the compiled :func:`cadra.dynamics.eom.derivative`,
called from Python in the right-hand side; see below) and the *same* observation model
(:func:`cadra.dynamics.observe.observe`), and the fit by :func:`scipy.optimize.least_squares`
with its finite-difference Jacobian. The unknowns are those of :func:`cadra.fitting.solver.fit`:
the model's free aerodynamic parameters (SI/radians, shared by the shots) and each shot's 12
local corrections at its epoch (:data:`cadra.fitting.sensitivity.LOCAL_NAMES`, applied with
:func:`cadra.fitting.sensitivity.apply_local`), residuals weighted by 1/sigma.

The right-hand side comes in two variants (``rhs=``): ``"compiled"`` calls CADRA's numba
:func:`cadra.dynamics.eom.derivative` (the strict baseline: only the integrator and the fitter
differ from CADRA's), ``"python"`` is what a SciPy user without CADRA would write: the same
6-DOF equations in plain Python on float scalars (:func:`derivative_python`, a line-by-line
translation of :mod:`cadra.dynamics.eom`), the aerodynamic coefficients from the model's
expression trees by the pure-Python evaluator :func:`cadra.aero.expr.evaluate_tree`; no
compiled code in the loop.

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

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cadra.aero import AeroModel
from cadra.aero.expr import evaluate_tree
from cadra.aero.program import COEFFICIENTS, VARIABLES
from cadra.channels import residual
from cadra.dynamics import layout as L
from cadra.dynamics.eom import derivative
from cadra.dynamics.integrate import inverse3
from cadra.dynamics.setup import plane_code
from cadra.fitting.sensitivity import LOCAL_NAMES, N_LOCAL, apply_local, observables
from cadra.flight.data import ShotData

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
    rhs : the right-hand side used, ``"compiled"`` or ``"python"``.
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
    rhs: str = "compiled"


# --- the right-hand side in plain Python (a line-by-line translation of cadra.dynamics.eom) ---

def rotation_fb_python(y) -> list[list[float]]:
    """R_FB (body -> facility), rows as lists, of the quaternion ``y[6:10]`` (need not be unit).

    Plain-Python translation of :func:`cadra.dynamics.eom.rotation_fb`.
    """
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    s = 2.0 / (qw * qw + qx * qx + qy * qy + qz * qz)
    # R_EB, then flip rows 1 and 2 (F = diag(1, -1, -1) E)
    return [[1.0 - s * (qy * qy + qz * qz), s * (qx * qy - qw * qz), s * (qx * qz + qw * qy)],
            [-(s * (qx * qy + qw * qz)), -(1.0 - s * (qx * qx + qz * qz)),
             -(s * (qy * qz - qw * qx))],
            [-(s * (qx * qz - qw * qy)), -(s * (qy * qz + qw * qx)),
             -(1.0 - s * (qx * qx + qy * qy))]]


def air_data_python(y, phys, R) -> tuple[tuple[float, float, float], float, float, dict]:
    """Air-relative body velocity (u, v, w) (m/s), airspeed V (m/s), density rho (kg/m^3) and
    the aero-model variables ``{name: value}`` (:data:`cadra.aero.program.VARIABLES`; angles
    rad) at state ``y``; plain-Python translation of :func:`cadra.dynamics.eom.air_data`.
    """
    x = y[0]
    ax = y[3] - (phys[L.P_WIND] + phys[L.P_WIND_GRAD] * x)
    ay = y[4] - (phys[L.P_WIND + 1] + phys[L.P_WIND_GRAD + 1] * x)
    az = y[5] - (phys[L.P_WIND + 2] + phys[L.P_WIND_GRAD + 2] * x)
    u, v, w = (R[0][j] * ax + R[1][j] * ay + R[2][j] * az for j in range(3))
    V = math.sqrt(u * u + v * v + w * w)
    rho = phys[L.P_RHO] * (1.0 + phys[L.P_RHO_GRAD] * x)
    s_xz = math.sqrt(u * u + w * w)
    s_perp = math.sqrt(v * v + w * w)
    alpha = 2.0 * math.atan(w / (s_xz + u)) if s_xz + u > 0.0 else math.pi
    k = phys[L.P_D] / (2.0 * V)
    phi = math.atan2(v, w) if s_perp > 0.0 else 0.0
    values = (alpha, math.asin(v / V), 2.0 * math.atan(s_perp / (V + u)), V / phys[L.P_SOUND],
              rho * V * phys[L.P_D] / phys[L.P_MU], y[10] * k, y[11] * k, y[12] * k, phi)
    return (u, v, w), V, rho, dict(zip(VARIABLES, values, strict=True))


def aero_force_moment_python(v_b, V, rho, phys, coef, sigma_plane: bool
                             ) -> tuple[list[float], list[float], tuple[float, float, float]]:
    """Static aerodynamic force and moment (N, N m; body axes, about the cg) and the damping
    derivatives (about x_b, y_b, z_b) from the 9 coefficients ``coef``
    (:data:`cadra.aero.program.COEFFICIENTS` order); plain-Python translation of
    :func:`cadra.dynamics.eom.aero_force_moment`.
    """
    u, v, w = v_b
    qS = 0.5 * rho * V * V * phys[L.P_S]
    qSd = qS * phys[L.P_D]
    CD, CL, CC, Cl, Cm, Cn, Clp, Cmq, Cnr = coef
    evx, evy, evz = u / V, v / V, w / V
    s_xz = math.sqrt(u * u + w * w)
    if s_xz > 1e-300:
        elx, elz = w / s_xz, -u / s_xz
    else:
        elx, elz = 0.0, 0.0
    ecx = -elz * evy
    ecy = elz * evx - elx * evz
    ecz = elx * evy
    if sigma_plane:
        s_perp = math.sqrt(v * v + w * w)
        if s_perp > 1e-12 * V:
            sin_s, cos_s = s_perp / V, u / V
            enx, eny, enz = sin_s, -cos_s * v / s_perp, -cos_s * w / s_perp
            emy, emz = w / s_perp, -v / s_perp
            epy, epz = v / s_perp, w / s_perp
        else:
            enx = eny = enz = emy = emz = epy = epz = 0.0
        # Magnus: C_C along -e_M, C_n about e_P (docs/conventions.md)
        F = [qS * (-CD * evx + CL * enx), qS * (-CD * evy + CL * eny - CC * emy),
             qS * (-CD * evz + CL * enz - CC * emz)]
        M = [qSd * Cl, qSd * (Cm * emy + Cn * epy), qSd * (Cm * emz + Cn * epz)]
        return F, M, (Clp, Cmq, Cmq)
    F = [qS * (-CD * evx + CL * elx + CC * ecx), qS * (-CD * evy + CC * ecy),
         qS * (-CD * evz + CL * elz + CC * ecz)]
    M = [qSd * Cl, qSd * Cm, -qSd * Cn]
    return F, M, (Clp, Cmq, Cnr)


def python_rhs(phys: np.ndarray, model: AeroModel, params: np.ndarray):
    """The right-hand side ``f(t, y) -> dy/dt`` (13,) in plain Python, for ``solve_ivp``.

    The equations of :func:`cadra.dynamics.eom.derivative` on Python floats (``math``), with
    the 9 coefficients from ``model``'s expression trees by
    :func:`cadra.aero.expr.evaluate_tree` (``params``, (n_params,) SI/rad in ``model.names``
    order, give the values). ``phys`` is the constants vector of :mod:`cadra.dynamics.layout`;
    the inertia inverse is numpy's. No compiled code is called. Free flight only: a
    wind-tunnel mount (:mod:`cadra.dynamics.modes`) is refused, not silently flown free.
    """
    ph = [float(v) for v in phys]
    if int(ph[L.P_MODE]) != L.MODE_FREE:
        raise ValueError("python_rhs: free flight only; a wind-tunnel mount "
                         "(cadra.dynamics.modes) has no plain-Python counterpart")
    I = np.asarray(phys[L.P_INERTIA:L.P_INERTIA + 9], dtype=float).reshape(3, 3)
    Ii = np.linalg.inv(I).tolist()
    I = I.tolist()
    pmap = dict(zip(model.names, (float(v) for v in params), strict=True))
    trees = [model.tree(c) for c in COEFFICIENTS]
    sigma_plane = model.angle_plane == "sigma"
    m, g, d, S = ph[L.P_MASS], ph[L.P_G], ph[L.P_D], ph[L.P_S]
    ox, oy, oz = ph[L.P_CG_OFFSET:L.P_CG_OFFSET + 3]

    def rhs(_t, y):
        y = y.tolist() if isinstance(y, np.ndarray) else list(y)
        R = rotation_fb_python(y)
        v_b, V, rho, variables = air_data_python(y, ph, R)
        coef = [0.0 if t is None else float(evaluate_tree(t, variables, pmap)) for t in trees]
        F, M, (damp_p, damp_q, damp_r) = aero_force_moment_python(v_b, V, rho, ph, coef,
                                                                  sigma_plane)
        qSd = 0.5 * rho * V * V * S * d
        k = d / (2.0 * V)
        p, q, r = y[10], y[11], y[12]
        M[0] += qSd * damp_p * (p * k)
        M[1] += qSd * damp_q * (q * k)
        M[2] += qSd * damp_r * (r * k)
        # true cg offset from the moment reference point: M_cg = M_ref - offset x F
        M[0] -= oy * F[2] - oz * F[1]
        M[1] -= oz * F[0] - ox * F[2]
        M[2] -= ox * F[1] - oy * F[0]
        acc = [(R[i][0] * F[0] + R[i][1] * F[1] + R[i][2] * F[2]) / m for i in range(3)]
        acc[2] -= g
        # rotation: I w' = M - w x (I w)
        hx = I[0][0] * p + I[0][1] * q + I[0][2] * r
        hy = I[1][0] * p + I[1][1] * q + I[1][2] * r
        hz = I[2][0] * p + I[2][1] * q + I[2][2] * r
        tx = M[0] - (q * hz - r * hy)
        ty = M[1] - (r * hx - p * hz)
        tz = M[2] - (p * hy - q * hx)
        wdot = [Ii[i][0] * tx + Ii[i][1] * ty + Ii[i][2] * tz for i in range(3)]
        # attitude: q' = 1/2 q (x) (0, w)
        qw, qx, qy, qz = y[6], y[7], y[8], y[9]
        return np.array([y[3], y[4], y[5], *acc,
                         -0.5 * (qx * p + qy * q + qz * r), 0.5 * (qw * p + qy * r - qz * q),
                         0.5 * (qw * q + qz * p - qx * r), 0.5 * (qw * r + qx * q - qy * p),
                         *wdot])

    return rhs


def derivative_python(y: np.ndarray, phys: np.ndarray, model: AeroModel,
                      params: np.ndarray) -> np.ndarray:
    """dy/dt (13,) at state ``y`` (13,) by :func:`python_rhs` (the plain-Python counterpart of
    :func:`cadra.dynamics.eom.derivative`; units of :mod:`cadra.dynamics.layout`)."""
    return python_rhs(phys, model, params)(0.0, np.asarray(y, dtype=float))


def trajectory_ivp(y0: np.ndarray, t0: float, times: np.ndarray, phys: np.ndarray, program,
                   params: np.ndarray, *, method: str = "DOP853", rtol: float = 1e-10,
                   atol: float = 1e-12, rhs: str = "compiled",
                   model: AeroModel | None = None) -> np.ndarray:
    """States (n, 13) at ``times`` (ascending, s) from ``y0`` at ``t0`` by ``solve_ivp``.

    Integrates forward to the times after ``t0`` and backward to those before it; the states
    at ``times`` come from the method's dense output (``t_eval``). ``rtol``/``atol`` are
    ``solve_ivp``'s tolerances on every state component (SI units of
    :mod:`cadra.dynamics.layout`). ``rhs="compiled"`` evaluates the right-hand side with
    :func:`cadra.dynamics.eom.derivative` and the compiled ``program``; ``rhs="python"`` with
    :func:`python_rhs` over ``model``'s expression trees (``model`` required, ``program``
    unused; ``params`` in ``model.names`` order in both cases). Raises ``RuntimeError`` if the
    integration fails.
    """
    from scipy.integrate import solve_ivp

    phys = np.ascontiguousarray(phys, dtype=float)
    params = np.ascontiguousarray(params, dtype=float)
    if rhs == "python":
        if model is None:
            raise ValueError('trajectory_ivp: rhs="python" needs the model')
        f = python_rhs(phys, model, params)
    elif rhs == "compiled":
        f = _compiled_rhs(phys, program, params)
    else:
        raise ValueError(f'trajectory_ivp: rhs must be "compiled" or "python", got {rhs!r}')
    times = np.asarray(times, dtype=float)
    out = np.empty((times.size, L.N_STATE))
    y0 = np.asarray(y0, dtype=float)
    after = times >= t0
    for sel, t_end in ((after, times[-1]), (~after, times[0])):
        if not sel.any():
            continue
        t_eval = times[sel] if t_end >= t0 else times[sel][::-1]
        if t_end == t0:
            out[sel] = y0
            continue
        sol = solve_ivp(f, (t0, t_end), y0, method=method, t_eval=t_eval, rtol=rtol,
                        atol=atol)
        if sol.status != 0:
            raise RuntimeError(f"solve_ivp failed: {sol.message}")
        out[sel] = sol.y.T if t_end >= t0 else sol.y.T[::-1]
    return out


def _compiled_rhs(phys: np.ndarray, program, params: np.ndarray):
    """``f(t, y)`` calling the compiled :func:`cadra.dynamics.eom.derivative`."""
    I = phys[L.P_INERTIA:L.P_INERTIA + 9].reshape(3, 3).copy()
    Iinv = np.empty((3, 3))
    inverse3(I, Iinv)
    R, v_b, variables = np.empty((3, 3)), np.empty(3), np.empty(len(VARIABLES))
    F_b, M_b, coef = np.empty(3), np.empty(3), np.empty(9)
    stack = np.empty(max(int(program.stack_size), 1))
    dy = np.empty(L.N_STATE)
    ops, args, starts = program.ops, program.args, program.starts
    plane = plane_code(program.angle_plane)

    def rhs(_t, y):
        derivative(np.ascontiguousarray(y), phys, I, Iinv, ops, args, starts, params, plane,
                   R, v_b, variables, F_b, M_b, coef, stack, dy)
        return dy.copy()            # solve_ivp keeps the returned array

    return rhs


def baseline_fit(shots: Sequence[ShotData], model: AeroModel,
                 initial_states: Sequence[np.ndarray], *, method: str = "DOP853",
                 rtol: float = 1e-10, atol: float = 1e-12, jac: str = "2-point",
                 aero_step: float = 1e-4, ftol: float = 1e-10, xtol: float = 1e-10,
                 gtol: float = 1e-10, max_nfev: int | None = None,
                 sparsity: bool = True, rhs: str = "compiled") -> BaselineResult:
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
    rhs : ``"compiled"`` (CADRA's numba :func:`cadra.dynamics.eom.derivative`, default) or
        ``"python"`` (:func:`python_rhs`: the same equations in plain Python with the
        coefficients from :func:`cadra.aero.expr.evaluate_tree`); see :func:`trajectory_ivp`.

    Returns
    -------
    :class:`BaselineResult`.
    """
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    if rhs not in ("compiled", "python"):
        raise ValueError(f'baseline_fit: rhs must be "compiled" or "python", got {rhs!r}')
    t_start = time.perf_counter()
    program = model.compile() if rhs == "compiled" else None
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
                                program, p, method=method, rtol=rtol, atol=atol, rhs=rhs,
                                model=model)
        n_traj[0] += 1
        pred = observables(states, refs[k])
        return (residual(shots[k].meas, pred) / shots[k].sigma)[masks[k]]

    def residuals(x):
        p = params0.copy()
        p[aero_idx] = x[:na]
        out = []
        for k in range(ns):
            u = x[na + N_LOCAL * k: na + N_LOCAL * (k + 1)]
            try:
                out.append(shot_residuals(k, p, u))
            except (RuntimeError, ArithmeticError):     # incl. plain-Python float errors
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
    # The covariance comes from a central-difference Jacobian at the solution with the steps
    # above, computed here: least_squares' own ``res.jac`` is a one-sided (2-point) difference
    # whose step-selection noise moved a sigma by 10 % between SciPy releases, so the
    # reference would depend on a third party's internals. Central differences with these
    # steps are exact to ~1e-8 relative on this problem (they agree with 3-point differences
    # at other steps and with tighter solve_ivp tolerances).
    # A shot's residuals depend on the aero parameters and its own local unknowns only, so a
    # local column is differenced on its shot alone (the rest of the column is zero).
    steps = scale * rstep
    J = np.zeros((res.fun.size, x.size))
    rows = np.cumsum([0, *counts])
    for j in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[j] += steps[j]
        xm[j] -= steps[j]
        if j < na:
            J[:, j] = -(residuals(xp) - residuals(xm)) / (2.0 * steps[j])  # d fitted/sigma
            continue
        k = (j - na) // N_LOCAL
        p = params0.copy()
        p[aero_idx] = x[:na]
        sl = slice(na + N_LOCAL * k, na + N_LOCAL * (k + 1))
        J[rows[k]:rows[k + 1], j] = -(shot_residuals(k, p, xp[sl])
                                      - shot_residuals(k, p, xm[sl])) / (2.0 * steps[j])
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
        elapsed_s=time.perf_counter() - t_start, rhs=rhs)


__all__ = ["BaselineResult", "LOCAL_NAMES", "LOCAL_STEPS", "aero_force_moment_python",
           "air_data_python", "baseline_fit", "derivative_python", "python_rhs",
           "rotation_fb_python", "trajectory_ivp"]
