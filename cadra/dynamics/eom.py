"""6-DOF rigid-body equations of motion (flat non-rotating earth), numba-compiled.

One code path for the simulator and the fitter. Every function here is written so that it
compiles for float64 *and* complex128 states (complex-step sensitivities): branches are taken on
real parts, and only complex-safe functions are used (``atan`` half-angle forms instead of
``atan2``).

Frames, angles and coefficient senses: ``docs/conventions.md``. Array layouts:
:mod:`cadra.dynamics.layout`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from cadra.aero.program import eval_coefficients
from cadra.dynamics.layout import (
    P_CG_OFFSET,
    P_D,
    P_FRAME,
    P_G,
    P_MASS,
    P_MU,
    P_RHO,
    P_RHO_GRAD,
    P_S,
    P_SOUND,
    P_WIND,
    P_WIND_GRAD,
    PLANE_SIGMA,
)
from cadra.dynamics.modes import constrain


@njit(cache=True)
def rotation_fb(y, R):
    """Write R_FB (body -> facility) of the quaternion in ``y[6:10]`` into ``R`` (3x3).

    The quaternion need not be unit: the matrix is that of ``q / |q|``.
    """
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    s = 2.0 / (qw * qw + qx * qx + qy * qy + qz * qz)
    # R_EB, then flip rows 1 and 2 (F = diag(1, -1, -1) E)
    R[0, 0] = 1.0 - s * (qy * qy + qz * qz)
    R[0, 1] = s * (qx * qy - qw * qz)
    R[0, 2] = s * (qx * qz + qw * qy)
    R[1, 0] = -(s * (qx * qy + qw * qz))
    R[1, 1] = -(1.0 - s * (qx * qx + qz * qz))
    R[1, 2] = -(s * (qy * qz - qw * qx))
    R[2, 0] = -(s * (qx * qz - qw * qy))
    R[2, 1] = -(s * (qy * qz + qw * qx))
    R[2, 2] = -(1.0 - s * (qx * qx + qy * qy))


@njit(cache=True)
def air_data(y, phys, R, v_b, variables):
    """Air-relative body velocity and the aero-model variables at state ``y``.

    Fills ``v_b`` (u, v, w) and ``variables`` in the order of
    :data:`cadra.aero.program.VARIABLES` (alpha, beta, sigma, mach, reynolds, p_hat, q_hat,
    r_hat, phi -- the aerodynamic roll angle atan2(v, w), docs/conventions.md). Returns
    (V, rho).
    """
    x = y[0]
    # air velocity in F: uniform wind plus a linear variation along the range
    ax = y[3] - (phys[P_WIND] + phys[P_WIND_GRAD] * x)
    ay = y[4] - (phys[P_WIND + 1] + phys[P_WIND_GRAD + 1] * x)
    az = y[5] - (phys[P_WIND + 2] + phys[P_WIND_GRAD + 2] * x)
    for j in range(3):
        v_b[j] = R[0, j] * ax + R[1, j] * ay + R[2, j] * az
    u, v, w = v_b[0], v_b[1], v_b[2]
    V = np.sqrt(u * u + v * v + w * w)
    rho = phys[P_RHO] * (1.0 + phys[P_RHO_GRAD] * x)
    s_xz = np.sqrt(u * u + w * w)
    s_perp = np.sqrt(v * v + w * w)
    # half-angle forms: atan2 without atan2 (complex-step safe), valid away from 180 deg
    if (s_xz + u).real > 0.0:
        alpha = 2.0 * np.arctan(w / (s_xz + u))
    else:
        alpha = np.pi + 0.0 * w
    variables[0] = alpha
    variables[1] = np.arcsin(v / V)
    variables[2] = 2.0 * np.arctan(s_perp / (V + u))
    variables[3] = V / phys[P_SOUND]
    variables[4] = rho * V * phys[P_D] / phys[P_MU]
    k = phys[P_D] / (2.0 * V)
    variables[5] = y[10] * k
    variables[6] = y[11] * k
    variables[7] = y[12] * k
    # aerodynamic roll angle atan2(v, w) by half angles (complex-step safe); 0 at sigma = 0
    if s_perp.real <= 1e-300:
        variables[8] = 0.0 * v
    elif w.real >= 0.0:
        variables[8] = 2.0 * np.arctan(v / (s_perp + w))
    elif v.real >= 0.0:
        variables[8] = np.pi - 2.0 * np.arctan(v / (s_perp - w))
    else:
        variables[8] = -np.pi - 2.0 * np.arctan(v / (s_perp - w))
    return V, rho


@njit(cache=True)
def aero_force_moment(v_b, V, rho, phys, coef, plane, F_b, M_b):
    """Aerodynamic force and moment about the cg, body axes, from the coefficients ``coef``.

    ``coef`` is in the order of :data:`cadra.aero.program.COEFFICIENTS`
    (CD, CL, CC, Cl, Cm, Cn, Clp, Cmq, Cnr), evaluated at this state. Writes the static part
    into ``F_b``/``M_b`` and returns the damping derivatives (about x_b, y_b, z_b) that the
    caller multiplies by the non-dimensional rates: (Clp, Cmq, Cnr), or (Clp, Cmq, Cmq) for a
    total-angle (symmetric) model.
    """
    u, v, w = v_b[0], v_b[1], v_b[2]
    qS = 0.5 * rho * V * V * phys[P_S]
    qSd = qS * phys[P_D]
    CD, CL, CC, Cl, Cm, Cn, Clp, Cmq, Cnr = (
        coef[0], coef[1], coef[2], coef[3], coef[4], coef[5], coef[6], coef[7], coef[8]
    )
    evx, evy, evz = u / V, v / V, w / V
    s_xz = np.sqrt(u * u + w * w)
    # body x-z plane lift direction e_L = (sin a, 0, -cos a); e_C = e_L x e_V
    if s_xz.real > 1e-300:
        elx, elz = w / s_xz, -u / s_xz
    else:
        elx, elz = 0.0 * w, 0.0 * w
    ecx = -elz * evy
    ecy = elz * evx - elx * evz
    ecz = elx * evy
    if plane == PLANE_SIGMA:
        s_perp = np.sqrt(v * v + w * w)
        if s_perp.real > 1e-12 * V.real:
            sin_s = s_perp / V
            cos_s = u / V
            # e_N = (x_b - cos(sigma) e_V) / sin(sigma); e_M = (e_V x x_b) / sin(sigma);
            # e_P = (0, v, w) / s_perp, the part of e_V normal to x_b (in the sigma plane)
            enx, eny, enz = sin_s, -cos_s * v / s_perp, -cos_s * w / s_perp
            emy, emz = w / s_perp, -v / s_perp
            epy, epz = v / s_perp, w / s_perp
        else:
            enx, eny, enz = 0.0 * V, 0.0 * V, 0.0 * V
            emy, emz = 0.0 * V, 0.0 * V
            epy, epz = 0.0 * V, 0.0 * V
        # Magnus (docs/conventions.md): C_C along -e_M = (x_b x e_V) / sin(sigma) (McCoy's
        # x x V, out of the sigma plane); C_n about e_P (McCoy's x x (V x x), in the plane)
        F_b[0] = qS * (-CD * evx + CL * enx)
        F_b[1] = qS * (-CD * evy + CL * eny - CC * emy)
        F_b[2] = qS * (-CD * evz + CL * enz - CC * emz)
        M_b[0] = qSd * Cl
        M_b[1] = qSd * (Cm * emy + Cn * epy)
        M_b[2] = qSd * (Cm * emz + Cn * epz)
        # Cmq damps both transverse rates of a symmetric body
        return Clp, Cmq, Cmq
    F_b[0] = qS * (-CD * evx + CL * elx + CC * ecx)
    F_b[1] = qS * (-CD * evy + CC * ecy)
    F_b[2] = qS * (-CD * evz + CL * elz + CC * ecz)
    M_b[0] = qSd * Cl
    M_b[1] = qSd * Cm
    M_b[2] = -qSd * Cn
    return Clp, Cmq, Cnr


@njit(cache=True)
def derivative(y, phys, I, Iinv, ops, args, starts, params, plane, R, v_b, variables, F_b,
               M_b, coef, stack, dy):
    """dy/dt of the 13-state at ``y`` (time-invariant: the range is steady).

    ``I``/``Iinv`` are the body-axis inertia tensor about the cg and its inverse; ``R`` (3, 3),
    ``v_b`` (3,), ``variables`` (8,), ``F_b`` (3,), ``M_b`` (3,), ``coef`` (9,) and ``stack`` are
    scratch arrays of the state's dtype (separate arrays: views made per call cost time).
    """
    rotation_fb(y, R)
    V, rho = air_data(y, phys, R, v_b, variables)
    eval_coefficients(ops, args, starts, variables, params, coef, stack)
    damp_p, damp_q, damp_r = aero_force_moment(v_b, V, rho, phys, coef, plane, F_b, M_b)
    qSd = 0.5 * rho * V * V * phys[P_S] * phys[P_D]
    k = phys[P_D] / (2.0 * V)
    p, q, r = y[10], y[11], y[12]
    # damping derivatives multiply the non-dimensional rates
    M_b[0] += qSd * damp_p * (p * k)
    M_b[1] += qSd * damp_q * (q * k)
    M_b[2] += qSd * damp_r * (r * k)
    # true cg offset from the moment reference point: M_cg = M_ref - offset x F
    ox, oy, oz = phys[P_CG_OFFSET], phys[P_CG_OFFSET + 1], phys[P_CG_OFFSET + 2]
    M_b[0] -= oy * F_b[2] - oz * F_b[1]
    M_b[1] -= oz * F_b[0] - ox * F_b[2]
    M_b[2] -= ox * F_b[1] - oy * F_b[0]
    # translation (facility frame)
    m = phys[P_MASS]
    dy[0] = y[3]
    dy[1] = y[4]
    dy[2] = y[5]
    for i in range(3):
        dy[3 + i] = (R[i, 0] * F_b[0] + R[i, 1] * F_b[1] + R[i, 2] * F_b[2]) / m
    dy[5] -= phys[P_G]
    # rotation: I w' = M - W x (I w), with W the angular velocity of the axes the rates are
    # taken in: the body's own (W = w), or the non-rolling frame's (W = (0, q, r); exact for
    # a body of revolution, whose inertia is the same in both; docs/dynamics.md)
    pf = p if phys[P_FRAME].real < 0.5 else 0.0 * p
    hx = I[0, 0] * p + I[0, 1] * q + I[0, 2] * r
    hy = I[1, 0] * p + I[1, 1] * q + I[1, 2] * r
    hz = I[2, 0] * p + I[2, 1] * q + I[2, 2] * r
    tx = M_b[0] - (q * hz - r * hy)
    ty = M_b[1] - (r * hx - pf * hz)
    tz = M_b[2] - (pf * hy - q * hx)
    dy[10] = Iinv[0, 0] * tx + Iinv[0, 1] * ty + Iinv[0, 2] * tz
    dy[11] = Iinv[1, 0] * tx + Iinv[1, 1] * ty + Iinv[1, 2] * tz
    dy[12] = Iinv[2, 0] * tx + Iinv[2, 1] * ty + Iinv[2, 2] * tz
    # attitude: q' = 1/2 q (x) (0, W)
    qw, qx, qy, qz = y[6], y[7], y[8], y[9]
    dy[6] = -0.5 * (qx * pf + qy * q + qz * r)
    dy[7] = 0.5 * (qw * pf + qy * r - qz * q)
    dy[8] = 0.5 * (qw * q + qz * pf - qx * r)
    dy[9] = 0.5 * (qw * r + qx * q - qy * pf)
    # a wind-tunnel mount replaces the rotational and translational equations
    # (cadra.dynamics.modes); free flight: unchanged
    constrain(y, phys, R, F_b, M_b, dy)
