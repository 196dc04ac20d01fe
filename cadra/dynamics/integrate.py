"""Fixed-step RK4 propagation of the 6-DOF state to a list of output times (numba).

The step is the largest h <= ``dt_max`` that divides each interval between consecutive output
times evenly, so every output time is hit exactly. Output times may lie before the epoch ``t0``
(the state is then integrated backward), which lets a fit put its epoch mid-range.

Works for float64 and complex128 states and parameters (complex-step sensitivities); times are
always real.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cadra.aero.program import N_VARIABLES
from cadra.dynamics.eom import derivative, rotation_fb
from cadra.dynamics.layout import N_STATE, P_INERTIA
from cadra.dynamics.modes import mount


@njit(cache=True)
def inverse3(A, out):
    """Inverse of a 3x3 matrix by the adjugate (complex-step safe)."""
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    c01 = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    c02 = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    det = A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02
    out[0, 0] = c00 / det
    out[1, 0] = c01 / det
    out[2, 0] = c02 / det
    out[0, 1] = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / det
    out[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / det
    out[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / det
    out[0, 2] = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / det
    out[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / det
    out[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / det


@njit(cache=True)
def _rk4_span(y, h, n, phys, I, Iinv, ops, args, starts, params, plane, scratch, coef, stack,
              k1, k2, k3, k4, tmp):
    """Advance ``y`` in place by ``n`` RK4 steps of size ``h`` (h may be negative)."""
    R, v_b, variables, F_b, M_b = scratch
    for _ in range(n):
        derivative(y, phys, I, Iinv, ops, args, starts, params, plane, R, v_b, variables, F_b,
                   M_b, coef, stack, k1)
        for i in range(N_STATE):
            tmp[i] = y[i] + 0.5 * h * k1[i]
        derivative(tmp, phys, I, Iinv, ops, args, starts, params, plane, R, v_b, variables,
                   F_b, M_b, coef, stack, k2)
        for i in range(N_STATE):
            tmp[i] = y[i] + 0.5 * h * k2[i]
        derivative(tmp, phys, I, Iinv, ops, args, starts, params, plane, R, v_b, variables,
                   F_b, M_b, coef, stack, k3)
        for i in range(N_STATE):
            tmp[i] = y[i] + h * k3[i]
        derivative(tmp, phys, I, Iinv, ops, args, starts, params, plane, R, v_b, variables,
                   F_b, M_b, coef, stack, k4)
        for i in range(N_STATE):
            y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@njit(cache=True)
def _start(y0, phys, R, y):
    """Copy ``y0`` into ``y``, made consistent with the test mode's mount (a wind-tunnel
    mount's allowed rates and cg velocity; free flight: unchanged)."""
    for i in range(N_STATE):
        y[i] = y0[i]
    rotation_fb(y, R)
    mount(y, phys, R)


@njit(cache=True)
def _workspace(y0, phys, stack_size):
    """Inertia tensor and its inverse from ``phys``, and the scratch arrays of the RK4 steps,
    in the state's dtype (float64 or complex128)."""
    dtype_one = y0[0] * 0.0 + 1.0
    I = np.empty((3, 3), dtype=y0.dtype)
    for i in range(3):
        for j in range(3):
            I[i, j] = phys[P_INERTIA + 3 * i + j] * dtype_one
    Iinv = np.empty((3, 3), dtype=y0.dtype)
    inverse3(I, Iinv)
    scratch = (np.empty((3, 3), dtype=y0.dtype), np.empty(3, dtype=y0.dtype),
               np.empty(N_VARIABLES, dtype=y0.dtype), np.empty(3, dtype=y0.dtype),
               np.empty(3, dtype=y0.dtype))
    coef = np.empty(9, dtype=y0.dtype)
    stack = np.empty(max(stack_size, 1), dtype=y0.dtype)
    k1 = np.empty(N_STATE, dtype=y0.dtype)
    k2 = np.empty(N_STATE, dtype=y0.dtype)
    k3 = np.empty(N_STATE, dtype=y0.dtype)
    k4 = np.empty(N_STATE, dtype=y0.dtype)
    tmp = np.empty(N_STATE, dtype=y0.dtype)
    return I, Iinv, scratch, coef, stack, k1, k2, k3, k4, tmp


@njit(cache=True)
def propagate(y0, t0, t_out, dt_max, phys, ops, args, starts, params, plane, stack_size, out):
    """Integrate from state ``y0`` at time ``t0`` to each time of ``t_out`` (ascending).

    Parameters
    ----------
    y0 : (13,) state at ``t0`` (float64 or complex128; see :mod:`cadra.dynamics.layout`).
    t0 : float, epoch, s.
    t_out : (n,) float64 ascending output times, s (may straddle ``t0``).
    dt_max : float, largest RK4 step, s.
    phys : (N_PHYS,) physical constants, same dtype as ``y0``.
    ops, args, starts, params, plane, stack_size : the compiled aerodynamic model
        (:class:`cadra.aero.program.AeroProgram`) and its parameter values (``params`` has the
        state's dtype).
    out : (n, 13) written with the state at each output time.
    """
    I, Iinv, scratch, coef, stack, k1, k2, k3, k4, tmp = _workspace(y0, phys, stack_size)
    y = np.empty(N_STATE, dtype=y0.dtype)
    n_out = t_out.shape[0]
    # first output index at or after the epoch
    split = 0
    while split < n_out and t_out[split] < t0:
        split += 1
    # forward
    _start(y0, phys, scratch[0], y)
    t = t0
    for j in range(split, n_out):
        span = t_out[j] - t
        if span > 0.0:
            n = int(np.ceil(span / dt_max - 1e-9))
            _rk4_span(y, span / n, n, phys, I, Iinv, ops, args, starts, params, plane, scratch,
                      coef, stack, k1, k2, k3, k4, tmp)
        t = t_out[j]
        for i in range(N_STATE):
            out[j, i] = y[i]
    # backward
    _start(y0, phys, scratch[0], y)
    t = t0
    for j in range(split - 1, -1, -1):
        span = t_out[j] - t
        if span < 0.0:
            n = int(np.ceil(-span / dt_max - 1e-9))
            _rk4_span(y, span / n, n, phys, I, Iinv, ops, args, starts, params, plane, scratch,
                      coef, stack, k1, k2, k3, k4, tmp)
        t = t_out[j]
        for i in range(N_STATE):
            out[j, i] = y[i]


#: work limit of one adaptive run: at least ~50 times what a 16-station shot needs at
#: tolerance 1e-8, and :data:`EVALS_PER_SECOND` per second of the record it spans, so the
#: budget grows with the record and only a runaway integration meets it
MAX_ADAPTIVE_EVALS = 150_000
EVALS_PER_SECOND = 3_000_000
#: the smallest step (s) of an adaptive run: a step this small that still misses the
#: tolerance stops the run (a trajectory blowing up in finite time, from a trial's absurd
#: parameters, shrinks its steps towards its singularity; the fastest spin a projectile
#: survives, ~3e4 rad/s, needs steps ~1000x longer)
H_MIN_S = 1e-9


@njit(cache=True)
def adaptive_budget(t0, t_out):
    """The derivative evaluations one adaptive run from ``t0`` to ``t_out`` may take."""
    span = 0.0
    if t_out.shape[0] > 0:
        span = max(t_out[-1], t0) - min(t_out[0], t0)
    return max(MAX_ADAPTIVE_EVALS, int(EVALS_PER_SECOND * span))


@njit(cache=True)
def _doubling_error(y1, y2, tol_pos, tol_ang, tau):
    """Step-doubling error of one step, in units of the tolerance (real parts only)."""
    e = 0.0
    for i in range(3):
        d = abs((y2[i] - y1[i]).real) / tol_pos
        if d > e:
            e = d
        d = abs((y2[3 + i] - y1[3 + i]).real) * tau / tol_pos
        if d > e:
            e = d
        d = abs((y2[10 + i] - y1[10 + i]).real) * tau / tol_ang
        if d > e:
            e = d
    for i in range(6, 10):
        d = 2.0 * abs((y2[i] - y1[i]).real) / tol_ang
        if d > e:
            e = d
    return e


@njit(cache=True)
def propagate_adaptive(y0, t0, t_out, h_max, tol_pos, tol_ang, phys, ops, args, starts,
                       params, plane, stack_size, out):
    """Like :func:`propagate`, with the RK4 step chosen by step doubling (Richardson).

    Each step of size h is also taken as two steps of h/2; their difference (real parts only,
    so a complex-step run makes exactly the float run's step choices) estimates the local
    error, and the step is accepted when the position error is below ``tol_pos`` (m) and the
    attitude error below ``tol_ang`` (rad); velocity and rate errors count as the position and
    angle errors they make over 10 ms. The accepted value is the extrapolated
    ``y2 + (y2 - y1) / 15``. Smooth stretches run at up to ``h_max``; the step shrinks only
    where the dynamics are rough, e.g. at the kinks of Table 4's ``max(...)`` pitch-damping
    forms, where fixed-step RK4 loses its order (docs/dynamics.md).

    A run that needs more than :func:`adaptive_budget` derivative evaluations (a tumbling or
    diverging trajectory, e.g. from absurd starting values), meets a non-finite state, or
    misses the tolerance with a step of :data:`H_MIN_S` (a blow-up in finite time) stops;
    its remaining outputs are NaN, so a caller sees a failed prediction, never a hang.

    Returns the number of derivative evaluations (negative when the run was stopped).
    """
    tau = 0.01
    I, Iinv, scratch, coef, stack, k1, k2, k3, k4, tmp = _workspace(y0, phys, stack_size)
    y = np.empty(N_STATE, dtype=y0.dtype)
    y1 = np.empty(N_STATE, dtype=y0.dtype)
    y2 = np.empty(N_STATE, dtype=y0.dtype)
    n_out = t_out.shape[0]
    n_eval = 0
    budget = adaptive_budget(t0, t_out)
    split = 0
    while split < n_out and t_out[split] < t0:
        split += 1
    for direction in (1, -1):
        _start(y0, phys, scratch[0], y)
        t = t0
        h = h_max * direction
        if direction == 1:
            j_first, j_stop, j_step = split, n_out, 1
        else:
            j_first, j_stop, j_step = split - 1, -1, -1
        for j in range(j_first, j_stop, j_step):
            target = t_out[j]
            while (target - t) * direction > 1e-15:
                last = False
                if (t + h - target) * direction >= -1e-12:
                    h_try = target - t
                    last = True
                else:
                    h_try = h
                # one full step
                for i in range(N_STATE):
                    y1[i] = y[i]
                _rk4_span(y1, h_try, 1, phys, I, Iinv, ops, args, starts, params, plane,
                          scratch, coef, stack, k1, k2, k3, k4, tmp)
                # two half steps
                for i in range(N_STATE):
                    y2[i] = y[i]
                _rk4_span(y2, 0.5 * h_try, 2, phys, I, Iinv, ops, args, starts, params,
                          plane, scratch, coef, stack, k1, k2, k3, k4, tmp)
                n_eval += 12
                err = _doubling_error(y1, y2, tol_pos, tol_ang, tau)
                if (n_eval > budget or not np.isfinite(err)
                        or (err > 1.0 and abs(h_try) <= H_MIN_S)):
                    for jj in range(n_out):
                        for i in range(N_STATE):
                            out[jj, i] = np.nan
                    return -n_eval
                if err <= 1.0:
                    for i in range(N_STATE):
                        y[i] = y2[i] + (y2[i] - y1[i]) / 15.0
                    t = target if last else t + h_try
                    fac = 4.0 if err < 1e-6 else min(4.0, 0.9 * err ** -0.2)
                    if not last or abs(h_try) >= abs(h):
                        h = h_try * fac
                else:
                    h = h_try * max(0.1, 0.9 * err ** -0.2)
                if abs(h) > h_max:
                    h = h_max * direction
                if abs(h) < H_MIN_S:
                    h = H_MIN_S * direction
            for i in range(N_STATE):
                out[j, i] = y[i]
    return n_eval


@njit(cache=True, nogil=True)
def propagate_batch(Y0, t0, t_out, h_max, tol_pos, tol_ang, PHYS, ops, args, starts, PARAMS,
                    plane, stack_size, OUT):
    """:func:`propagate_adaptive` for each row of ``Y0``/``PHYS``/``PARAMS`` (m runs) into
    ``OUT`` (m, n, 13). Releases the GIL, so threads can share the rows out."""
    n_eval = 0
    for k in range(Y0.shape[0]):
        n_eval += abs(propagate_adaptive(Y0[k], t0, t_out, h_max, tol_pos, tol_ang, PHYS[k], ops,
                                     args, starts, PARAMS[k], plane, stack_size, OUT[k]))
    return n_eval
