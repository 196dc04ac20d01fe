"""Simulated roll-bearing records of seed 001's roll lock-in (Eq. 27): a cruciform finner held
at a fixed angle of attack in a wind tunnel, free only in roll, flown by CADRA's 6-DOF
dynamics in the ``roll_bearing`` test mode with the lock-in as aero-model forms.

The seed gives no body or tunnel; two are used:

- :data:`TABLE_IV_FINNER` at :data:`TABLE_IV_SPEED_M_S`: a light 30 mm finner (I_x 2.5e-5
  kg m^2) in sea-level air at 30 m/s, for seed 001 Table IV's case (``tools/
  validate_roll_seed001.py``, docs/pureroll.md);
- :data:`SLOW_FINNER` at :data:`SLOW_SPEED_M_S`: a heavier finner in a low-density tunnel,
  roll inertia large against rho S d^3, so the roll damping per cycle is small (lambda /
  omega ~ 0.005) and the averaging of Eq. 31 applies.

Both are held at :data:`ALPHA` (10 deg). :func:`lockin_model` writes Eq. 27 as forms,
:func:`bearing` builds the mount, :func:`release_state` releases it at an aerodynamic roll
angle and :func:`roll_history` flies it.
"""

from __future__ import annotations

import numpy as np

from cadra.aero import model_from_dict
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import air_angles
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch

__all__ = ["ALPHA", "DT_TRUTH", "SLOW_FINNER", "SLOW_SPEED_M_S", "TABLE_IV_FINNER",
           "TABLE_IV_SPEED_M_S", "bearing", "lockin_model", "release_state", "roll_history"]

#: seed 001 Table IV's case: a light 30 mm finner in sea-level air
TABLE_IV_FINNER = dict(mass_kg=0.1, inertia_body_kg_m2=np.diag([2.5e-5, 5e-4, 5e-4]), d_m=0.03,
                       cg_from_ref_body_m=[-0.1, 0.0, 0.0], density_kg_m3=1.225,
                       speed_of_sound_m_s=340.0, viscosity_pa_s=1.8e-5, gravity_m_s2=0.0)
#: m/s, a subsonic (Notre Dame-like) tunnel
TABLE_IV_SPEED_M_S = 30.0
#: a finner in a low-density tunnel: slow roll damping (lambda / omega ~ 0.005)
SLOW_FINNER = dict(mass_kg=0.5, inertia_body_kg_m2=np.diag([2.0e-4, 2.5e-3, 2.5e-3]), d_m=0.03,
                   cg_from_ref_body_m=[-0.1, 0.0, 0.0], density_kg_m3=0.3,
                   speed_of_sound_m_s=340.0, viscosity_pa_s=1.8e-5, gravity_m_s2=0.0)
SLOW_SPEED_M_S = 60.0
#: the bearing's fixed angle of attack
ALPHA = np.radians(10.0)
#: s, the simulator's RK4 step
DT_TRUTH = 2e-4


def lockin_model(Cla: float = 0.5, Clp0: float = -2.0, Clp2: float = 15.0):
    """Seed 001 Eq. 27 as forms: the induced roll moment ``Cla sin(4 phi)`` (rolling by
    +gamma raises phi by gamma, so p = phi' and Eq. 27's L(alpha) sin 4 gamma is q S d Cla
    sin 4 phi; lock-in at phi = pi/4) and the roll damping quadratic about pi/4. Defaults:
    Table IV's inputs."""
    return model_from_dict({
        "format": "cadra.aero/1", "name": "lockin", "angle_plane": "sigma",
        "coefficients": {"CD": "0.5", "CL": "2*sin(sigma)", "Cm": "-0.5*sin(sigma)",
                         "Cl": "Cla*sin(4*phi)", "Clp": "Clp0 + Clp2*(phi - pi/4)**2"},
        "parameters": {"Cla": {"value": Cla}, "Clp0": {"value": Clp0},
                       "Clp2": {"value": Clp2}},
    })


def bearing(finner: dict | None = None, speed_m_s: float = TABLE_IV_SPEED_M_S) -> RigidBody:
    """The finner (default :data:`TABLE_IV_FINNER`) on its roll bearing in a stream of
    ``speed_m_s``."""
    return RigidBody(**(TABLE_IV_FINNER if finner is None else finner),
                     mode=TestMode(kind="roll_bearing", stream_m_s=speed_m_s))


def release_state(body: RigidBody, phi0_rad: float, p0_rad_s: float = 0.0,
                  alpha_rad: float = ALPHA) -> np.ndarray:
    """The bearing's state at ``alpha_rad`` with the aerodynamic roll angle at ``phi0_rad``
    and roll rate ``p0_rad_s``: the launch's roll angle moves phi one for one (its sense is
    the launch's convention, read off here)."""
    def state(roll):
        return Launch(speed_m_s=0.0, theta_rad=alpha_rad, roll_rad=roll,
                      p_rad_s=p0_rad_s).state(body)

    def phi_at(roll):
        return air_angles(state(roll)[None, :], body)["phi_rad"][0]

    sense = np.sign(phi_at(0.1) - phi_at(0.0))
    return state((phi0_rad - phi_at(0.0)) * sense)


def roll_history(model, phi0_deg: float, t, body: RigidBody, *,
                 dt_max: float = DT_TRUTH) -> tuple[np.ndarray, np.ndarray]:
    """(phi, states): the aerodynamic roll angle phi = gamma (rad, unwrapped) and the states
    at ``t`` of ``body`` released at rest in roll at ``phi0_deg``."""
    y0 = release_state(body, np.radians(phi0_deg))
    states = propagate_states(y0, 0.0, t, body.phys(), model.compile(), model.values(),
                              dt_max=dt_max)
    return np.unwrap(air_angles(states, body)["phi_rad"]), states
