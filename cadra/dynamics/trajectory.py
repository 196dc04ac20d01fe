"""Trajectories of a shot: launch conditions, light-sheet spark times, truth tables.

Pure functions over plain data (a scheduler can ship them). The 6-DOF core is
:func:`cadra.dynamics.setup.propagate_states`; this module adds the range geometry: the spark of
station k fires when the model's reference point crosses the station's light sheet
(x = x_k, plus a small trigger delay), so every image shows the model near the station.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from cadra.conventions import (
    alpha_cev_deg,
    axis_from_inclinations,
    quat_from_axis_roll,
)
from cadra.dynamics.observe import air_angles, observe
from cadra.dynamics.setup import DT_MAX_DEFAULT, RigidBody, propagate_states, state_from_reference


@dataclass(frozen=True)
class Launch:
    """Initial conditions at the epoch t = 0 (SI, facility frame F; angles rad).

    The position is that of the body's reference point (what the images show). The velocity is
    given by speed and flight-path angles (gamma: + climbing; chi: + toward port); the attitude
    by the nose-axis inclinations theta (+ up), psi (+ port) and the roll about the nose axis
    (0 = body z_b down, pi = "upside down"); rates are body rates (p, q, r).
    """

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    speed_m_s: float = 300.0
    gamma_rad: float = 0.0
    chi_rad: float = 0.0
    theta_rad: float = 0.0
    psi_rad: float = 0.0
    roll_rad: float = 0.0
    p_rad_s: float = 0.0
    q_rad_s: float = 0.0
    r_rad_s: float = 0.0

    def velocity_F(self) -> np.ndarray:
        cg, sg = np.cos(self.gamma_rad), np.sin(self.gamma_rad)
        return self.speed_m_s * np.array([cg * np.cos(self.chi_rad), cg * np.sin(self.chi_rad),
                                          sg])

    def quaternion(self) -> np.ndarray:
        return quat_from_axis_roll(axis_from_inclinations(self.theta_rad, self.psi_rad),
                                   self.roll_rad)

    def state(self, body: RigidBody) -> np.ndarray:
        """The 13-state (cg-based) of this launch for ``body``."""
        return state_from_reference(
            [self.x_m, self.y_m, self.z_m], self.velocity_F(), self.quaternion(),
            [self.p_rad_s, self.q_rad_s, self.r_rad_s], body.ref_from_cg_body_m())


def crossing_times(y0, body: RigidBody, program, params, x_planes, *,
                   dt_max: float = DT_MAX_DEFAULT, tol_m: float = 1e-9) -> np.ndarray:
    """Times (s) at which the reference point crosses the planes x = ``x_planes`` (m).

    Secant/Newton iteration on the propagated trajectory (each evaluation is a full
    propagation, so the times are exact to ``tol_m`` / V, far below a nanosecond).
    """
    x_planes = np.asarray(x_planes, dtype=float)
    phys = body.phys()
    ref = body.ref_from_cg_body_m()
    v0 = float(np.linalg.norm(y0[3:6]))
    t = (x_planes - observe(y0[None, :], ref)["x_m"][0]) / v0
    for _ in range(30):
        states = propagate_states(y0, 0.0, t, phys, program, params, dt_max)
        obs = observe(states, ref)
        err = obs["x_m"] - x_planes
        if np.all(np.abs(err) < tol_m):
            return t
        t = t - err / states[:, 3]
    raise RuntimeError("light-sheet crossing times did not converge (does the model reach "
                       "every station?)")


def truth_table(times, states, body: RigidBody, stations=None) -> pd.DataFrame:
    """Exact per-station truth: reference point, inclinations, cg, velocity, aero angles.

    Units are in the column names (m, s, deg, m/s).
    """
    ref = body.ref_from_cg_body_m()
    obs = observe(states, ref)
    air = air_angles(states, body)
    rows = []
    for k, (t, y) in enumerate(zip(times, states, strict=True)):
        alpha, beta, sigma = air["alpha_rad"][k], air["beta_rad"][k], air["sigma_rad"][k]
        V = float(air["airspeed_m_s"][k])
        rows.append({
            "station": int(stations[k]) if stations is not None else k + 1,
            "t_s": float(t),
            "x_m": obs["x_m"][k], "y_m": obs["y_m"][k], "z_m": obs["z_m"][k],
            "theta_deg": np.degrees(obs["theta_rad"][k]),
            "psi_deg": np.degrees(obs["psi_rad"][k]),
            # the non-rolling frame does not carry the body's roll angle
            "phi_deg": (np.nan if body.attitude_frame == "non_rolling"
                        else np.degrees(obs["phi_rad"][k])),
            "q0": y[6], "q1": y[7], "q2": y[8], "q3": y[9],
            "x_cg_m": y[0], "y_cg_m": y[1], "z_cg_m": y[2],
            "vx_m_s": y[3], "vy_m_s": y[4], "vz_m_s": y[5],
            "p_rad_s": y[10], "q_rad_s": y[11], "r_rad_s": y[12],
            "airspeed_m_s": V,
            "mach": float(air["mach"][k]),
            "alpha_deg": np.degrees(alpha), "beta_deg": np.degrees(beta),
            "sigma_deg": np.degrees(sigma), "alpha_cev_deg": alpha_cev_deg(alpha),
        })
    return pd.DataFrame(rows)
