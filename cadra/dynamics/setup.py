"""Python-side assembly of a rigid-body problem and the propagate wrapper.

:class:`RigidBody` gathers what the equations of motion need about one shot (mass properties
in body axes, reference length, air, gravity, effects) and turns it into the plain ``phys``
vector the compiled core takes. :func:`propagate_states` calls the compiled RK4 integrator,
choosing float64 or complex128 from its inputs (complex-step sensitivities).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cadra.conventions import G0, body_to_facility_matrix
from cadra.dynamics.effects import Effects
from cadra.dynamics.integrate import propagate
from cadra.dynamics.layout import (
    FRAME_BODY,
    FRAME_NONROLLING,
    N_PHYS,
    N_STATE,
    P_CG_OFFSET,
    P_D,
    P_FRAME,
    P_G,
    P_INERTIA,
    P_MASS,
    P_MODE,
    P_MU,
    P_PIVOT,
    P_RHO,
    P_RHO_GRAD,
    P_S,
    P_SOUND,
    P_WIND,
    P_WIND_GRAD,
    PLANE_ALPHA_BETA,
    PLANE_SIGMA,
)
from cadra.dynamics.modes import TestMode

#: default largest RK4 step, s. For smooth coefficient forms at the fastest pitch rates of seed
#: 004's shots (omega ~ 200 rad/s) the error over a 16-station shot is < 0.01 um and 4e-6 deg;
#: forms with a kink (Table 4's max(A1, A2 + A3 sin^2 sigma) C_mq) lose RK4's order at each
#: crossing: up to ~60 um and 0.01 deg at this step (docs/dynamics.md, "Accuracy").
DT_MAX_DEFAULT = 2.0e-4
#: step used for synthetic truth: error < 0.1 um and 3e-5 deg even across Table 4's kinks
DT_MAX_TRUTH = 2.5e-5

_PLANES = {"alpha_beta": PLANE_ALPHA_BETA, "sigma": PLANE_SIGMA}
#: attitude frames (docs/dynamics.md, "The non-rolling frame")
FRAMES = {"body": FRAME_BODY, "non_rolling": FRAME_NONROLLING}
#: flight variables whose value depends on where the body's roll puts its transverse axes
ROLL_VARIABLES = frozenset({"alpha", "beta", "phi", "q_hat", "r_hat"})
#: relative tolerance of "the same in every transverse direction" (inertia, offsets)
_AXISYMMETRIC_RTOL = 1e-9


def plane_code(angle_plane: str) -> int:
    """Integer code of an aero model's angle plane ("alpha_beta" or "sigma")."""
    try:
        return _PLANES[angle_plane]
    except KeyError:
        raise ValueError(
            f"angle_plane must be one of {sorted(_PLANES)}, got {angle_plane!r}") from None


@dataclass(frozen=True)
class RigidBody:
    """One shot's rigid-body and air data, SI, body axes (docs/conventions.md).

    Attributes
    ----------
    mass_kg : mass.
    inertia_body_kg_m2 : (3, 3) inertia tensor about the nominal cg, body axes.
    d_m : reference length (maximum diameter).
    cg_from_ref_body_m : (3,) nominal cg minus the body reference point, body axes.
    density_kg_m3, speed_of_sound_m_s, viscosity_pa_s : the range air.
    gravity_m_s2 : g (acts along -z of the facility frame).
    effects : optional unmodelled physics (:class:`cadra.dynamics.effects.Effects`).
    mode : how the model is tested (:class:`cadra.dynamics.modes.TestMode`): free flight in a
        range (default) or a tunnel's stream, or on a gimbal, pitch pivot or roll bearing.
    attitude_frame : ``"body"`` (default: the state's quaternion and rates are the body's) or
        ``"non_rolling"`` (a body of revolution integrated in a frame that does not roll with
        it, so its spin sets no step; :func:`non_rolling_obstacle` says when that is exact).
    """

    mass_kg: float
    inertia_body_kg_m2: np.ndarray
    d_m: float
    cg_from_ref_body_m: np.ndarray
    density_kg_m3: float
    speed_of_sound_m_s: float
    viscosity_pa_s: float
    gravity_m_s2: float = G0
    effects: Effects = field(default_factory=Effects)
    mode: TestMode = field(default_factory=TestMode)
    attitude_frame: str = "body"

    def __post_init__(self):
        if self.attitude_frame not in FRAMES:
            raise ValueError(f"attitude_frame must be one of {sorted(FRAMES)}, got "
                             f"{self.attitude_frame!r}")
        I = np.asarray(self.inertia_body_kg_m2, dtype=float)
        if I.shape != (3, 3) or not np.allclose(I, I.T, rtol=1e-12, atol=0):
            raise ValueError("inertia_body_kg_m2 must be a symmetric 3x3 tensor")
        if np.any(np.linalg.eigvalsh(I + np.asarray(self.effects.inertia_delta_body_kg_m2))
                  <= 0):
            raise ValueError("inertia tensor (with effects) is not positive definite")
        if not self.mass_kg > 0 or not self.d_m > 0:
            raise ValueError("mass_kg and d_m must be positive")
        object.__setattr__(self, "inertia_body_kg_m2", I)
        object.__setattr__(self, "cg_from_ref_body_m",
                           np.asarray(self.cg_from_ref_body_m, dtype=float).reshape(3))

    @property
    def area_m2(self) -> float:
        """Reference area S = pi d^2 / 4."""
        return np.pi * self.d_m**2 / 4.0

    def with_effects(self, effects: Effects) -> RigidBody:
        """The same body and air with other effects switched on."""
        return RigidBody(**{**self.__dict__, "effects": effects})

    def phys(self) -> np.ndarray:
        """The physical-constants vector of :mod:`cadra.dynamics.layout`."""
        e = self.effects
        p = np.zeros(N_PHYS)
        p[P_MASS] = self.mass_kg
        p[P_INERTIA:P_INERTIA + 9] = (self.inertia_body_kg_m2
                                      + np.asarray(e.inertia_delta_body_kg_m2)).ravel()
        p[P_D] = self.d_m
        p[P_S] = self.area_m2
        p[P_RHO] = self.density_kg_m3
        p[P_SOUND] = self.speed_of_sound_m_s
        p[P_MU] = self.viscosity_pa_s
        p[P_G] = self.gravity_m_s2
        p[P_WIND:P_WIND + 3] = np.asarray(e.wind_facility_m_s) + self.mode.stream_facility_m_s
        p[P_WIND_GRAD:P_WIND_GRAD + 3] = e.wind_gradient_facility_per_s
        p[P_RHO_GRAD] = e.density_gradient_per_m
        p[P_CG_OFFSET:P_CG_OFFSET + 3] = e.cg_offset_body_m
        p[P_MODE] = self.mode.code
        p[P_PIVOT:P_PIVOT + 3] = self.mode.pivot_from_cg_body_m
        p[P_FRAME] = FRAMES[self.attitude_frame]
        return p

    def with_frame(self, attitude_frame: str) -> RigidBody:
        """The same body and air integrated in another attitude frame."""
        return RigidBody(**{**self.__dict__, "attitude_frame": attitude_frame})

    def ref_from_cg_body_m(self) -> np.ndarray:
        """Body reference point minus the TRUE cg (nominal cg + cg-offset effect), body axes."""
        return -(self.cg_from_ref_body_m + np.asarray(self.effects.cg_offset_body_m))


def non_rolling_obstacle(phys, program, phys_dirs=(), ref_from_cg_body_m=None) -> str:
    """Why the non-rolling frame would not be exact for these physics, or "" when it is.

    The frame drops the body's roll from the attitude, which is exact when nothing depends on
    where the roll puts the body's transverse axes: a free flight (no mount), an inertia
    tensor the same about every transverse axis (no products), no lateral cg offset (nor a
    lateral reference point, ``ref_from_cg_body_m``), a total-angle (sigma) aerodynamic model
    that reads none of :data:`ROLL_VARIABLES`, and no ``phys_dirs`` (sensitivity directions,
    e.g. a gap candidate's lateral cg offset) that would change any of that.
    """
    rows = [np.asarray(phys).real] + [np.abs(np.asarray(d, dtype=float)) for d in phys_dirs]
    ph = rows[0]
    if program.angle_plane != "sigma":
        return "the aerodynamic model is not a total-angle (sigma) model"
    roll_vars = sorted(program.variables_read & ROLL_VARIABLES)
    if roll_vars:
        return f"the aerodynamic model reads {', '.join(roll_vars)}"
    if int(round(ph[P_MODE])) != 0:
        return "the model is held by a mount"
    I = ph[P_INERTIA:P_INERTIA + 9].reshape(3, 3)
    tol = _AXISYMMETRIC_RTOL * abs(I[1, 1])
    if (np.abs(I - np.diag(np.diag(I))).max() > tol or abs(I[1, 1] - I[2, 2]) > tol
            or any(np.any(d[P_INERTIA:P_INERTIA + 9] != 0) for d in rows[1:])):
        return "the inertia tensor is not that of a body of revolution"
    if any(np.any(row[P_CG_OFFSET + 1:P_CG_OFFSET + 3] != 0) for row in rows):
        return "the cg is off the axis"
    if ref_from_cg_body_m is not None and np.any(
            np.abs(np.asarray(ref_from_cg_body_m, dtype=float)[1:]) > 1e-12):
        return "the reference point is off the axis"
    return ""


#: largest roll per step |p| h at which the simulator keeps the body's own frame
SPIN_STEP_LIMIT = 0.05


def simulation_frame(rigid: RigidBody, program, spin_rad_s: float, step_s: float,
                     roll_needed: bool) -> RigidBody:
    """``rigid`` in the frame a simulation integrates in: the non-rolling frame where the
    body's spin would limit the step (|p| h > :data:`SPIN_STEP_LIMIT`), nothing needs its roll
    angle (``roll_needed``: e.g. a finned outline to render) and the frame is exact
    (:func:`non_rolling_obstacle`); else the body's own."""
    if (roll_needed or abs(spin_rad_s) * step_s <= SPIN_STEP_LIMIT
            or non_rolling_obstacle(rigid.phys(), program, (), rigid.ref_from_cg_body_m())):
        return rigid
    return rigid.with_frame("non_rolling")


def rigid_body_from_mass(mass_kg: float, cg_model_m, inertia_model_kg_m2, d_m: float,
                         atmosphere, effects: Effects | None = None,
                         mode: TestMode | None = None) -> RigidBody:
    """A :class:`RigidBody` from mass properties in MODEL axes (as shot files and specs give
    them; docs/conventions.md) and a :class:`cadra.atmosphere.Atmosphere`."""
    from cadra.conventions import model_to_body_inertia, model_to_body_vector

    return RigidBody(
        mass_kg=float(mass_kg),
        inertia_body_kg_m2=model_to_body_inertia(np.asarray(inertia_model_kg_m2, dtype=float)),
        d_m=float(d_m),
        cg_from_ref_body_m=model_to_body_vector(np.asarray(cg_model_m, dtype=float)),
        density_kg_m3=atmosphere.density, speed_of_sound_m_s=atmosphere.speed_of_sound,
        viscosity_pa_s=atmosphere.viscosity, effects=effects or Effects(),
        mode=mode or TestMode(),
    )


def state_from_reference(r_ref_F, v_F, q, rates_body, ref_from_cg_body_m) -> np.ndarray:
    """13-state from the reference-point position (what images show), cg velocity, attitude
    quaternion (B->E) and body rates: ``r_cg = r_ref - R_FB @ ref_from_cg``."""
    q = np.asarray(q, dtype=float)
    R = body_to_facility_matrix(q)
    y = np.empty(N_STATE)
    y[0:3] = np.asarray(r_ref_F, dtype=float) - R @ np.asarray(ref_from_cg_body_m, dtype=float)
    y[3:6] = v_F
    y[6:10] = q / np.linalg.norm(q)
    y[10:13] = rates_body
    return y


def propagate_states(y0, t0: float, times, phys, program, params,
                     dt_max: float = DT_MAX_DEFAULT) -> np.ndarray:
    """States (n, 13) at ``times`` (any order) from ``y0`` at epoch ``t0``.

    ``program`` is a :class:`cadra.aero.program.AeroProgram` and ``params`` its parameter
    values (SI). If any of ``y0``, ``phys``, ``params`` is complex the integration is complex
    (complex-step derivatives); otherwise float64.
    """
    y0 = np.asarray(y0)
    phys = np.asarray(phys)
    params = np.asarray(params)
    times = np.asarray(times, dtype=float)
    if y0.shape != (N_STATE,) or phys.shape != (N_PHYS,):
        raise ValueError(f"state must be ({N_STATE},) and phys ({N_PHYS},); got "
                         f"{y0.shape}, {phys.shape}")
    if not (dt_max > 0):
        raise ValueError("dt_max must be positive")
    if phys.real[P_FRAME] >= 0.5 and (why := non_rolling_obstacle(phys, program)):
        raise ValueError(f"the non-rolling frame is not exact here: {why}")
    dtype = (np.complex128 if any(np.iscomplexobj(a) for a in (y0, phys, params))
             else np.float64)
    order = np.argsort(times, kind="stable")
    t_sorted = np.ascontiguousarray(times[order])
    out = np.empty((t_sorted.size, N_STATE), dtype=dtype)
    propagate(
        np.ascontiguousarray(y0, dtype=dtype), float(t0), t_sorted, float(dt_max),
        np.ascontiguousarray(phys, dtype=dtype), program.ops, program.args, program.starts,
        np.ascontiguousarray(params, dtype=dtype), plane_code(program.angle_plane),
        int(program.stack_size), out,
    )
    result = np.empty_like(out)
    result[order] = out
    return result
