"""Test modes: free flight in a range or a wind tunnel, and the constrained wind-tunnel mounts.

The papers CADRA reduces ran their models in five ways (seeds 000-002):

=================  ==========================================================================
kind               what moves
=================  ==========================================================================
``range``          free flight through still air (the default; the model flies down the range)
``tunnel``         free flight in a uniform stream of ``stream_m_s`` along -x of F (the model,
                   nose upstream, drifts downstream; launched at rest or with any velocity)
``gimbal``         3-DOF angular motion about a fixed point (a gimbal or ball joint): attitude
                   and body rates free, the pivot held
``pitch_pivot``    1-DOF rotation about the body y axis through the pivot (a pitch pivot)
``roll_bearing``   1-DOF rotation about the body x axis through the pivot, the axis held at a
                   fixed attitude to the stream (a roll bearing at a fixed angle of attack)
=================  ==========================================================================

The constrained mounts are not a separate model: :func:`constrain` takes the free-flight
derivative that :func:`cadra.dynamics.eom.derivative` has just computed (the aerodynamic force
and moment of the one aero-model code path, about the true cg) and replaces the rotational and
translational equations by those of a body turning about the pivot:

- moment about the pivot: M_P = M_cg + d x (F_aero + m g), d = cg - pivot (body axes; the
  mount's reaction passes through the pivot and has no moment about it);
- inertia about the pivot: I_P = I_cg + m (|d|^2 E - d d^T) (parallel axes);
- gimbal: I_P w' = M_P - w x I_P w; pitch pivot: q' = (M_P - w x I_P w)_y / I_P,yy, p' = r' = 0;
  roll bearing: p' = (M_P - w x I_P w)_x / I_P,xx, q' = r' = 0 (the bearing's reactions take the
  other components);
- the cg moves with the body about the fixed pivot: v_cg = R_FB (w x d),
  a_cg = R_FB (w' x d + w x (w x d)), so the air sees the cg's own velocity (a pivot ahead of
  the cg adds the plunging the body really has).

Every integration first makes its starting state consistent with the mount (:func:`mount`:
the allowed rates, the cg velocity), and then keeps the pivot fixed to rounding (a test checks
it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from cadra.dynamics.layout import (
    MODE_FREE,
    MODE_GIMBAL,
    MODE_PITCH,
    MODE_ROLL,
    P_CG_OFFSET,
    P_G,
    P_INERTIA,
    P_MASS,
    P_MODE,
    P_PIVOT,
)

#: mode kinds (file values) and their codes in ``phys``
KINDS = {"range": MODE_FREE, "tunnel": MODE_FREE, "gimbal": MODE_GIMBAL,
         "pitch_pivot": MODE_PITCH, "roll_bearing": MODE_ROLL}
#: kinds whose pivot is held fixed
MOUNTED = ("gimbal", "pitch_pivot", "roll_bearing")


@dataclass(frozen=True)
class TestMode:
    """How the model is tested (module doc). SI; the pivot in body axes from the nominal cg.

    Attributes
    ----------
    kind : one of :data:`KINDS`.
    stream_m_s : the tunnel's stream speed (along -x of F); 0 in a range.
    pivot_from_cg_body_m : (3,) pivot point minus the nominal cg, body axes (x nose, y stbd,
        z down); the gimbal centre, the pitch pivot's point on its axis, a point of the roll
        bearing's axis. Only for mounted kinds.
    """

    __test__ = False          # not a pytest class

    kind: str = "range"
    stream_m_s: float = 0.0
    pivot_from_cg_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"test_mode.kind: {self.kind!r} is not a test mode; one of "
                             f"{sorted(KINDS)}")
        u = float(self.stream_m_s)
        if not np.isfinite(u) or u < 0:
            raise ValueError(f"test_mode.stream_m_s: {self.stream_m_s!r} must be a finite "
                             "speed >= 0 (the stream flows along -x)")
        if self.kind == "range" and u != 0:
            raise ValueError("test_mode.stream_m_s: a range has still air (kind = 'tunnel' for "
                             "a stream)")
        if self.kind in MOUNTED and u <= 0:
            raise ValueError(f"test_mode.stream_m_s: a {self.kind} needs a stream speed > 0")
        piv = np.asarray(self.pivot_from_cg_body_m, dtype=float)
        if piv.shape != (3,) or not np.all(np.isfinite(piv)):
            raise ValueError("test_mode.pivot_from_cg_body_m: expected 3 finite numbers, got "
                             f"{self.pivot_from_cg_body_m!r}")
        if self.kind not in MOUNTED and np.any(piv):
            raise ValueError(f"test_mode.pivot_from_cg_body_m: a {self.kind} has no pivot")
        object.__setattr__(self, "stream_m_s", u)
        object.__setattr__(self, "pivot_from_cg_body_m", tuple(float(v) for v in piv))

    @property
    def code(self) -> int:
        return KINDS[self.kind]

    @property
    def mounted(self) -> bool:
        return self.kind in MOUNTED

    @property
    def stream_facility_m_s(self) -> np.ndarray:
        """The stream as an air velocity in F."""
        return np.array([-self.stream_m_s, 0.0, 0.0])


@njit(cache=True)
def mount(y, phys, R):
    """Make the state ``y`` (13,) consistent with the mount coded in ``phys``, in place: the
    rates the mount allows (p = r = 0 on a pitch pivot, q = r = 0 on a roll bearing) and the
    cg velocity the body's rotation about the pivot gives it, v = R_FB (w x d). The position
    is kept (it says where the pivot is). Free flight: nothing to do. Every integration
    starts here, so a fit's corrections to the attitude and rates, a cg-offset extra or a
    complex-step perturbation move the cg velocity with them."""
    code = int(phys[P_MODE].real)
    if code == MODE_FREE:
        return
    if code == MODE_PITCH:
        y[10] = 0.0 * y[10]
        y[12] = 0.0 * y[12]
    elif code == MODE_ROLL:
        y[11] = 0.0 * y[11]
        y[12] = 0.0 * y[12]
    dx = phys[P_CG_OFFSET] - phys[P_PIVOT]
    dyy = phys[P_CG_OFFSET + 1] - phys[P_PIVOT + 1]
    dz = phys[P_CG_OFFSET + 2] - phys[P_PIVOT + 2]
    p, q, r = y[10], y[11], y[12]
    vx = q * dz - r * dyy
    vy = r * dx - p * dz
    vz = p * dyy - q * dx
    for i in range(3):
        y[3 + i] = R[i, 0] * vx + R[i, 1] * vy + R[i, 2] * vz


@njit(cache=True)
def constrain(y, phys, R, F_b, M_b, dy):
    """Replace the free-flight ``dy`` by that of the mount coded in ``phys`` (module doc).

    ``F_b``/``M_b`` are the aerodynamic force and the moment about the true cg (damping and
    cg offset included) that :func:`cadra.dynamics.eom.derivative` left in its scratch arrays;
    ``R`` is R_FB. Free flight: nothing to do.
    """
    code = int(phys[P_MODE].real)
    if code == MODE_FREE:
        return
    m = phys[P_MASS]
    g = phys[P_G]
    # d = true cg - pivot (body axes)
    dx = phys[P_CG_OFFSET] - phys[P_PIVOT]
    dyy = phys[P_CG_OFFSET + 1] - phys[P_PIVOT + 1]
    dz = phys[P_CG_OFFSET + 2] - phys[P_PIVOT + 2]
    # total external force at the cg but the mount's reaction: aero + gravity (-g z_F)
    fx = F_b[0] - m * g * R[2, 0]
    fy = F_b[1] - m * g * R[2, 1]
    fz = F_b[2] - m * g * R[2, 2]
    mx = M_b[0] + dyy * fz - dz * fy
    my = M_b[1] + dz * fx - dx * fz
    mz = M_b[2] + dx * fy - dyy * fx
    # inertia about the pivot (parallel axes)
    dd = dx * dx + dyy * dyy + dz * dz
    I00 = phys[P_INERTIA] + m * (dd - dx * dx)
    I01 = phys[P_INERTIA + 1] - m * dx * dyy
    I02 = phys[P_INERTIA + 2] - m * dx * dz
    I11 = phys[P_INERTIA + 4] + m * (dd - dyy * dyy)
    I12 = phys[P_INERTIA + 5] - m * dyy * dz
    I22 = phys[P_INERTIA + 8] + m * (dd - dz * dz)
    p, q, r = y[10], y[11], y[12]
    hx = I00 * p + I01 * q + I02 * r
    hy = I01 * p + I11 * q + I12 * r
    hz = I02 * p + I12 * q + I22 * r
    tx = mx - (q * hz - r * hy)
    ty = my - (r * hx - p * hz)
    tz = mz - (p * hy - q * hx)
    if code == MODE_GIMBAL:
        # I_P w' = tau by the adjugate (complex-step safe)
        c00 = I11 * I22 - I12 * I12
        c01 = I12 * I02 - I01 * I22
        c02 = I01 * I12 - I11 * I02
        det = I00 * c00 + I01 * c01 + I02 * c02
        c11 = I00 * I22 - I02 * I02
        c12 = I02 * I01 - I00 * I12
        c22 = I00 * I11 - I01 * I01
        dy[10] = (c00 * tx + c01 * ty + c02 * tz) / det
        dy[11] = (c01 * tx + c11 * ty + c12 * tz) / det
        dy[12] = (c02 * tx + c12 * ty + c22 * tz) / det
    elif code == MODE_PITCH:
        dy[10] = 0.0 * tx
        dy[11] = ty / I11
        dy[12] = 0.0 * tz
    else:
        dy[10] = tx / I00
        dy[11] = 0.0 * ty
        dy[12] = 0.0 * tz
    # the cg turns about the fixed pivot: v = w x d, a = w' x d + w x (w x d) (body axes)
    vx = q * dz - r * dyy
    vy = r * dx - p * dz
    vz = p * dyy - q * dx
    wdx, wdy, wdz = dy[10], dy[11], dy[12]
    ax = wdy * dz - wdz * dyy + (q * vz - r * vy)
    ay = wdz * dx - wdx * dz + (r * vx - p * vz)
    az = wdx * dyy - wdy * dx + (p * vy - q * vx)
    for i in range(3):
        dy[i] = R[i, 0] * vx + R[i, 1] * vy + R[i, 2] * vz
        dy[3 + i] = R[i, 0] * ax + R[i, 1] * ay + R[i, 2] * az


__all__ = ["KINDS", "MOUNTED", "TestMode", "constrain", "mount"]
