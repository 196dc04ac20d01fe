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

from cadra.dynamics.eom import derivative
from cadra.dynamics.layout import N_STATE, P_INERTIA


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
    dtype_one = y0[0] * 0.0 + 1.0
    I = np.empty((3, 3), dtype=y0.dtype)
    for i in range(3):
        for j in range(3):
            I[i, j] = phys[P_INERTIA + 3 * i + j] * dtype_one
    Iinv = np.empty((3, 3), dtype=y0.dtype)
    inverse3(I, Iinv)
    scratch = (np.empty((3, 3), dtype=y0.dtype), np.empty(3, dtype=y0.dtype),
               np.empty(8, dtype=y0.dtype), np.empty(3, dtype=y0.dtype),
               np.empty(3, dtype=y0.dtype))
    coef = np.empty(9, dtype=y0.dtype)
    stack = np.empty(max(stack_size, 1), dtype=y0.dtype)
    k1 = np.empty(N_STATE, dtype=y0.dtype)
    k2 = np.empty(N_STATE, dtype=y0.dtype)
    k3 = np.empty(N_STATE, dtype=y0.dtype)
    k4 = np.empty(N_STATE, dtype=y0.dtype)
    tmp = np.empty(N_STATE, dtype=y0.dtype)
    y = np.empty(N_STATE, dtype=y0.dtype)
    n_out = t_out.shape[0]
    # first output index at or after the epoch
    split = 0
    while split < n_out and t_out[split] < t0:
        split += 1
    # forward
    for i in range(N_STATE):
        y[i] = y0[i]
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
    for i in range(N_STATE):
        y[i] = y0[i]
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
