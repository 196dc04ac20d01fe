"""Seed 002's Run 21 (Jaffe): a 60 deg blunt cone flown free in the JPL supersonic wind tunnel,
simulated with Table 2's perturbations, and the paper's tricyclic fits of it (the cases of
``tools/validate_tricyclic.py``; docs/motion.md, "Seed 002 Table 2").

Each case (:data:`CASES`, Table 2's columns; :data:`SINGLES`, one effect at a time) is
simulated by CADRA's 6-DOF dynamics in the ``tunnel`` test mode (the model, nose upstream,
drifts downstream in a uniform stream; docs/dynamics.md "Test modes"), sampled at the movie's
2000 frames/s, turned into the paper's measured angles (the vertical and horizontal projected
angles of the axis, then seed 002 eqs. 6-7's fixed-plane angles; :func:`simulate`) and fitted
by ``cadra.motion.fit_epicyclic`` in the air's distance x = integral of V dt, as the paper
does, in its four programs: 10-constant, 10-constant with the nonrolling-axis correction (NR,
eq. 8, one iteration), 12-constant (eq. 12's phi'' terms) and 12-constant with NR
(:func:`tricyclic_fits`: the rms angle-of-attack deviations, rms |xi - xi_fit|, deg).

The seed omits the cubic C_m, C_N alpha, C_D, C_mq, the mass (its printed value is garbled)
and the initial conditions: the choices are the constants below, each with its reason
(:class:`Choices` holds those a sensitivity run varies).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_trapezoid

from cadra.aero import model_from_dict
from cadra.body import cone
from cadra.dynamics.effects import Effects
from cadra.dynamics.layout import P_RHO
from cadra.dynamics.modes import TestMode
from cadra.dynamics.observe import air_angles, observe
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.flight.data import rigid_body_from_shot
from cadra.io.shotfile import MassProperties, ShotFile, StationRecord
from cadra.motion import fit_epicyclic, fixed_plane_angles

__all__ = ["CASES", "CG_OFFSET_M", "CHOICES", "Case", "Choices", "N_FRAMES", "PROGRAMS",
           "Record", "SINGLES", "SPIN_RPS", "V_M_S", "aero_model", "rigid_body", "simulate",
           "tricyclic_fits", "tunnel_shot"]

FT, SLUG, LBF = 0.3048, 14.593903, 4.4482216
R_AIR = 287.05

# --- Run 21 (seed 002 Table 1 and text) -------------------------------------------------------
MACH = 3.97
Q_PA = 178.0 * LBF / FT**2                     # 8523 Pa
V_M_S = 2220.0 * FT                            # 676.7 m/s: the stream
D_M = 1.5 * 0.0254
NOSE_RADIUS_M = 0.2 * D_M / 2                  # nose radius / base radius 0.2
HALF_ANGLE_DEG = 60.0
I_Y = 0.49e-6 * SLUG * FT**2                   # 6.64e-7 kg m^2
I_X = 1.45 * I_Y
#: mass: Table 1 prints 0.19e-4 slug (0.28 g), which cannot hold I_x = 9.6e-7 kg m^2 within a
#: 19 mm radius (k_x = 5.9 cm); 0.19e-2 slug (27.7 g) gives k_x = 5.9 mm, a gold core near the
#: axis as the text describes, and with C_D 1.35 the deceleration that makes V fall ~6 % over
#: ~180 frames (the text); 0.19e-3 slug would make it fall 60 %
MASS_KG = 0.19e-2 * SLUG
XCG_FROM_NOSE_M = 0.189 * D_M
RHO = 2.0 * Q_PA / V_M_S**2                    # 0.0372 kg/m^3
#: the stream's static temperature is 72 K (a = V/M = 170 m/s), which the shot file refuses
#: (its range-temperature check, 150-400 K); the forms below have no Mach or Reynolds terms,
#: so only the density matters: the shot file carries T = 290 K and the pressure that gives
#: the stream's density (its Mach number, 1.98, enters nothing)
T_K = 290.0
P_PA = RHO * R_AIR * T_K
FPS = 2000.0                                   # movie frames per second
N_FRAMES = 180                                 # 125-250 in the paper: 0.09 s, V falls ~6 %
#: 0-35 rps in the paper, Run 21's not given: 28 rps makes the p/V part of the linear case's
#: 10-constant residual about the size of the fixed-plane part, as in Table 2 (0.32 vs 0.22 deg
#: in quadrature)
SPIN_RPS = 28.0
LAUNCH_UPSTREAM_M_S = 21.0                     # V = U + 21 at launch, U - 21 at the end
DT_TRUTH = 2.0e-5                              # s, RK4 step of the truth

# --- aerodynamics (ours: the seed prints none of these) ---------------------------------------
#: modified Newtonian for a 60 deg cone at M 3.97 (C_p,max 1.8): C_A = 1.8 sin^2 60 = 1.35,
#: C_N alpha = 1.8 cos^2 60 = 0.45 per rad, so C_L alpha = C_N alpha - C_A = -0.90
CD0, CLA = 1.35, -0.90
#: C_m alpha at zero angle from the paper's own trim: an axial force C_A acting e = 0.0024 in
#: off the cg gives alpha_T = C_A (e/d) / |C_m alpha| = 0.67 deg when C_m alpha = -0.185
CMA0 = -CD0 * (0.0024 / 1.5) / np.radians(0.67)
#: the offset: the paper's 0.0024 in trims the linear moment statically by 0.67 deg (above), but
#: at 28 rps (the trim arm turns with the body) and with the cubic's stiffening at these
#: amplitudes the fitted trim arm K_3 is only 0.48 deg; the offset is scaled to 0.00336 in so
#: that K_3 = 0.67 deg (the 12+NR fit of the cubic + cg case), the table's "0.67 deg trim"
CG_OFFSET_M = 0.0024 * 0.0254 * 0.67 / 0.4792
#: damping: the models were built "to amplify any change in the angle-of-attack envelope"; with
#: C_mq = -0.8 (and the lift and drag terms) the fast arm decays to 48 %, the slow one to 74 %
#: over the flight, which turns a cubic moment into the frequency drift of eq. 11 (the
#: 12-constant program's phi'')
CMQ0 = -0.8
#: the cubic term (Fig. 7's value is not printed): C_m alpha,eff = C_ma0 + C_ma2 delta_e^2 grows
#: by 40 % at delta_e = 15 deg (Fig. 5: "a large increase ... at large delta^2")
CMA2 = -0.5
#: "bicubic" (Fig. 6's two slopes): the cubic slope 2.6x steeper above sigma_b = 8 deg
CMA4, SIGMA_B_DEG = -0.8, 8.0

# --- motion (ours) ----------------------------------------------------------------------------
#: two arms at launch (deg), in phase along +beta: a nonplanar start with 19 deg peaks,
#: the slow (precession) arm the larger, so that the motion cones against the spin. The sense
#: matters: with the fast arm the larger the fixed-plane rotation's drift (phi_hat' falls with
#: the amplitude) partly cancels the p/V drift, and the NR correction then RAISES the
#: 10-constant rms of the linear case (0.25 -> 0.47 deg at 13 + 7.5 deg); Table 2 has it fall
K1_DEG, K2_DEG = 4.0, 15.0
#: density variation: the printed "+-0.02 %" is garbled ([G]: +-0.015 in Mach at M 3.97 is
#: +-1.43 % isentropically); read as +-0.02 (2 %); period: the no-spin pitch period
DENSITY_AMPLITUDE = 0.02


@dataclass(frozen=True)
class Choices:
    """What the seed leaves unstated (the constants above), so a sensitivity run can vary
    them: spin (rps), launch arms (deg), cubic and bicubic terms, damping, density amplitude."""

    spin_rps: float = SPIN_RPS
    k1_deg: float = K1_DEG
    k2_deg: float = K2_DEG
    cma2: float = CMA2
    cma4: float = CMA4
    cmq0: float = CMQ0
    density_amplitude: float = DENSITY_AMPLITUDE


CHOICES = Choices()


@dataclass(frozen=True)
class Case:
    """One column of seed 002 Table 2."""

    key: str
    label: str
    paper: tuple                 # (10, 10+NR, 12, 12+NR) rms deg; None where not given
    cm: str = "linear"           # linear | cubic | bicubic
    drag: bool = True            # False: V (and so p/V) held constant
    cg: bool = False
    inertia_asym: bool = False
    products: bool = False
    density: bool = False


CASES = (
    Case("linear", "linear aerodynamics", (0.4207, 0.3222, None, None)),
    Case("linear_pv", "linear, p/V held constant", (0.2306, 0.0550, None, None), drag=False),
    Case("cubic", "cubic Cm", (0.8045, 0.7446, 0.2170, 0.0517), cm="cubic"),
    Case("bicubic", "bicubic Cm", (None, None, 0.2307, 0.1263), cm="bicubic"),
    Case("cubic_cg", "cubic + cg offset (0.67 deg trim)", (0.8287, 0.6266, 0.2297, 0.1094),
         cm="cubic", cg=True),
    Case("bicubic_cg", "bicubic + cg offset", (None, None, 0.3303, 0.2643), cm="bicubic",
         cg=True),
    Case("cubic_cg_iyz", "cubic + cg + Iy != Iz (2 %)", (None, None, 0.3619, 0.2826),
         cm="cubic", cg=True, inertia_asym=True),
    Case("cubic_cg_iyz_prod", "cubic + cg + Iy != Iz + Ixy, Iyz", (None, None, 0.4578, 0.4081),
         cm="cubic", cg=True, inertia_asym=True, products=True),
    Case("cubic_cg_density", "cubic + cg + tunnel density varied", (None, None, 0.3117, 0.2299),
         cm="cubic", cg=True, density=True),
)


#: one-effect twins for the diagnosis (not in Table 2): each mass or flow effect alone with
#: the cubic moment, so the cg offset's near-alias (a product of inertia also tilts the
#: spinning body's principal axis, a trim at the spin rate) cannot hide behind another effect
SINGLES = (
    Case("cubic_iyz", "cubic + Iy != Iz (2 %) alone", (None,) * 4, cm="cubic",
         inertia_asym=True),
    Case("cubic_prod", "cubic + Ixy, Iyz alone", (None,) * 4, cm="cubic", products=True),
    Case("cubic_density", "cubic + tunnel density varied alone", (None,) * 4, cm="cubic",
         density=True),
)

def aero_model(cm: str, drag: bool = True, ch: Choices = CHOICES):
    """The truth's model in the total angle sigma (a body of revolution): C_D constant, C_L
    linear, C_m linear, cubic or bicubic in sigma (seed 002 eq. 9's M_0 + M_2 delta^2 form),
    C_mq constant."""
    cm_form = {"linear": "Cma0*sigma", "cubic": "(Cma0 + Cma2*sigma**2)*sigma",
               "bicubic": "(Cma0 + Cma2*sigma**2 + Cma4*max(sigma**2 - sb2, 0.0))*sigma"}[cm]
    par = {"CD0": {"value": CD0 if drag else 0.0, "vary": drag}, "CLa": {"value": CLA},
           "Cma0": {"value": CMA0}, "Cmq0": {"value": ch.cmq0}}
    if cm != "linear":
        par["Cma2"] = {"value": ch.cma2}
    if cm == "bicubic":
        par["Cma4"] = {"value": ch.cma4}
        par["sb2"] = {"value": np.radians(SIGMA_B_DEG) ** 2, "vary": False}
    return model_from_dict({
        "format": "cadra.aero/1", "name": f"run21_{cm}", "angle_plane": "sigma",
        "description": "seed 002 Run 21, 60 deg blunt cone (tools/validate_tricyclic.py)",
        "coefficients": {"CD": "CD0", "CL": "CLa*sigma", "Cm": cm_form, "Cmq": "Cmq0"},
        "parameters": par})


def effects(case: Case) -> Effects:
    """The body perturbations of the case: the cg offset across the axis (body z), Iy != Iz
    by 2 % (I_yy = 1.01 I, I_zz = 0.99 I) and the products I_xy = 0.02 I_x, I_yz = 0.02 I_z."""
    dI = np.zeros((3, 3))
    if case.inertia_asym:
        dI[1, 1], dI[2, 2] = 0.01 * I_Y, -0.01 * I_Y
    if case.products:
        dI[0, 1] = dI[1, 0] = 0.02 * I_X
        dI[1, 2] = dI[2, 1] = 0.02 * (I_Y + dI[2, 2])
    return Effects(cg_offset_body_m=(0.0, 0.0, CG_OFFSET_M if case.cg else 0.0),
                   inertia_delta_body_kg_m2=tuple(map(tuple, dI)))


def cg_from_base_m() -> float:
    """Nominal cg minus the cone's reference point (the centre of the base), along the nose
    axis: the cone's length less xcg from the nose (docs/bodies.md)."""
    body = cone(D_M, np.radians(HALF_ANGLE_DEG), nose_radius_m=NOSE_RADIUS_M)
    return body.length_m - XCG_FROM_NOSE_M


def tunnel_shot(n_frames: int = N_FRAMES, shot_id: str = "RUN21-SIM"):
    """Run 21 as a CADRA shot file: the 60 deg blunt cone, its mass properties (model axes:
    x nose, y port, z up), air of the stream's density (T_K, P_PA) and the ``tunnel`` test
    mode; the movie's frames are its stations (docs/shot_file.md)."""
    t = np.arange(n_frames) / FPS
    return ShotFile(
        shot_id=shot_id,
        model={"kind": "cone", "d_cm": 100 * D_M, "half_angle_deg": HALF_ANGLE_DEG,
               "nose_radius_mm": 1000 * NOSE_RADIUS_M},
        mass=MassProperties(MASS_KG, [cg_from_base_m(), 0.0, 0.0], np.diag([I_X, I_Y, I_Y])),
        pressure_pa=P_PA, temperature_k=T_K, facility="hffaf",
        stations=tuple(StationRecord(i + 1, float(tk)) for i, tk in enumerate(t)),
        notes="seed 002 Run 21 (60 deg blunt cone, M 3.97), tools/validate_tricyclic.py",
        test_mode=TestMode(kind="tunnel", stream_m_s=V_M_S))


def rigid_body(case: Case | None = None, n_frames: int = N_FRAMES) -> RigidBody:
    """The dynamics' view of :func:`tunnel_shot` (as ``cadra2`` builds it: gravity on), with
    the case's body perturbations switched on."""
    return rigid_body_from_shot(tunnel_shot(n_frames),
                                effects(case) if case is not None else Effects())


def pitch_rate_no_spin() -> float:
    """The no-spin pitch frequency (rad/s) of the linear moment at the stream's q."""
    return float(np.sqrt(-CMA0 * Q_PA * np.pi * D_M**2 / 4 * D_M / I_Y))


def launch(case: Case, ch: Choices = CHOICES) -> Launch:
    """xi = beta + i alpha = K1 e^{i w1 t} + K2 e^{i w2 t} at launch (linear arms), both arms
    along +beta; the model spinning at SPIN_RPS and moving upstream (the air's V = U + 21 m/s
    falls to about U - 21 by the end with drag; held at U without)."""
    p = 2 * np.pi * ch.spin_rps
    P = p * I_X / I_Y
    w0 = pitch_rate_no_spin()
    r = np.sqrt(P * P / 4 + w0 * w0)
    w1, w2 = P / 2 + r, P / 2 - r
    K1, K2 = np.radians(ch.k1_deg), np.radians(ch.k2_deg)
    return Launch(speed_m_s=LAUNCH_UPSTREAM_M_S if case.drag else 0.0,
                  psi_rad=K1 + K2, q_rad_s=w1 * K1 + w2 * K2, p_rad_s=p)


@dataclass
class Record:
    """A simulated flight: frame times, states, and the paper's measured quantities."""

    t: np.ndarray
    states: np.ndarray
    body: RigidBody
    x: np.ndarray            # air distance, m (integral of V dt)
    alpha_f: np.ndarray      # fixed-plane angles, rad (seed 002 eqs. 6-7)
    beta_f: np.ndarray
    speed: np.ndarray        # air speed, m/s
    spin: np.ndarray         # roll rate p, rad/s


def simulate(case: Case, n_frames: int = N_FRAMES, ch: Choices = CHOICES) -> Record:
    """The case flown in the tunnel (6-DOF, RK4 at DT_TRUTH) and sampled at FPS."""
    body = rigid_body(case, n_frames)
    m = aero_model(case.cm, case.drag, ch)
    prog, vals = m.compile(), m.values()
    t = np.arange(n_frames) / FPS
    y0 = launch(case, ch).state(body)
    phys = body.phys()
    if not case.density:
        states = propagate_states(y0, 0.0, t, phys, prog, vals, DT_TRUTH)
    else:
        # density varied sinusoidally in time with the no-spin pitch period (seed 002,
        # "Nonuniform flow"): piecewise constant over steps of DT_TRUTH at the step's middle
        w0 = pitch_rate_no_spin()
        grid = np.arange(0.0, t[-1] + DT_TRUTH / 2, DT_TRUTH)
        states = np.empty((t.size, y0.size))
        states[0] = y0
        y, k = y0.copy(), 1
        ph, rho0 = phys.copy(), float(phys[P_RHO])
        for a, b in zip(grid[:-1], grid[1:], strict=True):
            ph[P_RHO] = rho0 * (1.0 + ch.density_amplitude * np.sin(w0 * 0.5 * (a + b)))
            y = propagate_states(y, a, [b], ph, prog, vals, DT_TRUTH)[0]
            while k < t.size and abs(t[k] - b) < 1e-12:
                states[k] = y
                k += 1
        assert k == t.size
    obs = observe(states, body.ref_from_cg_body_m())
    ax = obs["axis"]
    theta_v = np.arctan2(ax[:, 2], ax[:, 0])     # side view: vertical angle
    theta_h = np.arctan2(ax[:, 1], ax[:, 0])     # top view: horizontal angle
    a_f, b_f = fixed_plane_angles(theta_v, theta_h)
    V = air_angles(states, body)["airspeed_m_s"]
    x = cumulative_trapezoid(V, t, initial=0.0)
    return Record(t, states, body, x, a_f, b_f, V, states[:, 10].copy())


PROGRAMS = (("10", False, False), ("10+NR", False, True), ("12", True, False),
            ("12+NR", True, True))


def tricyclic_fits(rec: Record, trim: str = "measured") -> dict:
    """The four programs' rms angle-of-attack deviations (deg), fitted in air distance with
    the trim arm at the measured spin over the mean speed (p/V, rad/m); ``trim="arms"``: at
    the rate the paper's nomenclature ties to the arms, p = (I_y/I_x)(phi_1' + phi_2') (at
    mid-record), iterated from the measured one (four fits)."""
    out = {}
    for name, curvature, nr in PROGRAMS:
        p = float(np.mean(rec.spin) / np.mean(rec.speed))
        for _ in range(4 if trim == "arms" else 1):
            f = fit_epicyclic(rec.x, rec.alpha_f, rec.beta_f, trim_rate=p,
                              curvature=curvature, nonrolling=nr, variable="distance")
            xm = 0.5 * (rec.x[0] + rec.x[-1]) - f.s_ref
            p = I_Y / I_X * sum(f.arm(j).omega + f.arm(j).omega_dot * xm for j in (1, 2))
        out[name] = float(np.degrees(f.rms))
    return out
