"""Magnus force and moment of total-angle (sigma) models (docs/conventions.md) against
independent truth.

- Linear theory (McCoy, *Modern Exterior Ballistics*, ch. 10): the complex yaw of a spinning
  symmetric projectile obeys, in arc length s (calibers),

      xi'' + (H - iP) xi' - (M + iPT) xi = 0,   kappa = rho S d / 2m,
      H = kappa [C_La - C_D - C_mq / (2 k_t^2)],  P = (I_x / I_y) p d / V,
      M = kappa C_Ma / k_t^2,  T = kappa [C_La + C_Mpa / k_a^2],

  k_a^2 = I_x / m d^2, k_t^2 = I_y / m d^2 (C_mq multiplies q d / 2V, McCoy's C_Mq + C_Ma_dot
  multiplies q d / V: C_mq = 2 (C_Mq + C_Ma_dot)). The two roots of
  lambda^2 + (H - iP) lambda - (M + iPT) = 0 are the fast and slow arms: damping rate = real
  part, frequency = imaginary part (per caliber). The linearised swerve is
  b' = kappa (C_La - i C_Npa p d / V) xi for the direction b of the velocity (Magnus force
  along McCoy's x × V).
- The directions of C_C and C_n at given body states (aero_force_moment called directly).
- Model files: C_C and C_n load in sigma models, C_nr is still refused.
"""

import numpy as np
import pytest

from cadra.aero import load_model, model_from_dict
from cadra.dynamics.eom import aero_force_moment
from cadra.dynamics.layout import PLANE_SIGMA
from cadra.dynamics.observe import complex_yaw
from cadra.dynamics.setup import RigidBody, propagate_states
from cadra.dynamics.trajectory import Launch
from cadra.validation.arms import fit_two_arms

# a 7.62 mm bullet of the M-80's size (BRL MR 1833; illustrative mass properties): 9.5 g,
# d = 7.82 mm, I_x = 6.5e-8 kg m^2, I_y = 5.3e-7 kg m^2; sea-level air, gravity off
MASS, D, IX, IY = 9.5e-3, 7.82e-3, 6.5e-8, 5.3e-7
RHO, SOUND = 1.225, 340.29
BODY = RigidBody(mass_kg=MASS, inertia_body_kg_m2=np.diag([IX, IY, IY]), d_m=D,
                 cg_from_ref_body_m=np.zeros(3), density_kg_m3=RHO,
                 speed_of_sound_m_s=SOUND, viscosity_pa_s=1.79e-5, gravity_m_s2=0.0)
KA2, KT2 = IX / (MASS * D * D), IY / (MASS * D * D)
# McCoy-like coefficients at Mach 2.4 (his normalisation; C_Ma > 0: statically unstable)
CD, CLA, CMA, CMQ_MCCOY, CNPA, CMPA = 0.30, 2.5, 2.9, -5.0, 0.3, 0.1
MACH, SPIN = 2.4, 2.2e4  # p = 2.2e4 rad/s: gyroscopic stability S_g = P^2 / 4M = 2.17
# spin damping that keeps p / V constant (p and V both decay as exp(-kappa C_D s)), so P is
# constant in arc length as the constant-coefficient linear theory assumes (McCoy's C_lp =
# -k_a^2 C_D = -0.034, a bullet's value). With C_lp = 0 instead, P drifts by 9 % over the flight
# and the fitted damping rates miss the constant-P theory by 7 % and 1 %.
CLP = -2.0 * KA2 * CD
KAPPA = RHO * BODY.area_m2 * D / (2.0 * MASS)


def bullet_model(CMpa=CMPA, CNpa=CNPA):
    return model_from_dict({
        "name": "bullet-magnus", "angle_plane": "sigma",
        "coefficients": {"CD": "CD0", "CL": "CLa*sin(sigma)", "Cm": "Cma*sin(sigma)",
                         "Cmq": "Cmq0", "Clp": "Clp0", "CC": "CNpa*2*p_hat*sin(sigma)",
                         "Cn": "CMpa*2*p_hat*sin(sigma)"},
        "parameters": {k: {"value": v} for k, v in dict(
            CD0=CD, CLa=CLA, Cma=CMA, Cmq0=2.0 * CMQ_MCCOY, Clp0=CLP, CNpa=CNpa,
            CMpa=CMpa).items()},
    })


def theory_roots(V, p, CMpa=CMPA):
    """The two roots (fast, slow) of McCoy's yaw equation, per caliber."""
    P = IX / IY * p * D / V
    M = KAPPA * CMA / KT2
    H = KAPPA * (CLA - CD - 2.0 * CMQ_MCCOY / (2.0 * KT2))
    T = KAPPA * (CLA + CMpa / KA2)
    a, b = H - 1j * P, -(M + 1j * P * T)
    root = np.sqrt(a * a - 4.0 * b)
    lam = np.array([(-a + root) / 2.0, (-a - root) / 2.0])
    return lam[np.argsort(-lam.imag)]


@pytest.fixture(scope="module")
def flight():
    """6-DOF flight of 12000 calibers (94 m), 1.5 deg initial yaw, sampled every 10 calibers
    of arc length (drag only along e_V: V = V0 exp(-kappa C_D s) exactly)."""
    V0 = MACH * SOUND
    ds = 10.0
    s = np.arange(0.0, 12000.0 + ds, ds)
    k = KAPPA * CD
    t = np.expm1(k * s) * D / (k * V0)
    model = bullet_model()
    launch = Launch(speed_m_s=V0, theta_rad=np.radians(1.5), p_rad_s=SPIN)
    # RK4 with the body spinning at p needs p h << 1: at h = 5 us (p h = 0.11) the fitted
    # damping rates are within 0.06 % of the h -> 0 values, at 10 us 0.4 %, at 20 us 10 %
    states = propagate_states(launch.state(BODY), 0.0, t, BODY.phys(), model.compile(),
                              model.values(), 5e-6)
    v = states[:, 3:6]
    V = np.linalg.norm(v, axis=1)
    # the velocity's direction; the complex yaw: nose axis minus it, (port, up) components of F
    b = (v[:, 1] + 1j * v[:, 2]) / V
    return dict(s=s, ds=ds, V0=V0, V=V, states=states, xi=complex_yaw(states), b=b)


def test_speed_and_spin_per_caliber_as_assumed(flight):
    s, V = flight["s"], flight["V"]
    np.testing.assert_allclose(V, flight["V0"] * np.exp(-KAPPA * CD * s), rtol=1e-9)
    p_hat = flight["states"][:, 10] * D / (2.0 * V)
    np.testing.assert_allclose(p_hat, p_hat[0], rtol=1e-9)


def test_yaw_arms_match_mccoy_linear_theory(flight):
    """Measured (h = 5 us): fast arm damping -1.0779e-4 vs -1.0773e-4 per caliber (0.06 %),
    slow -7.825e-5 vs -7.826e-5 (0.02 %); frequencies 0.022401 vs 0.022398 and 0.0034383 vs
    0.0034371 rad per caliber (0.01 %, 0.03 %). Linear theory drops the Magnus force in the yaw
    equation (setting C_Npa = 0 moves the fitted roots by < 0.05 %), O(kappa^2) terms (1e-5)
    and the O(sigma^2) nonlinearity at 1.5 deg (7e-4). The Magnus moment decides it: reversed
    in eom.py, the fit gives -1.668e-4 and -1.93e-5 (the theory with -C_Mpa: factors 1.55 and
    0.25); about e_M instead of e_P, the damping rates miss by up to 38 %."""
    lam, K = fit_two_arms(flight["xi"], flight["ds"])
    truth = theory_roots(flight["V0"], SPIN)
    assert np.all(np.abs(K) > 1e-3)  # both arms excited
    np.testing.assert_allclose(lam.real, truth.real, rtol=0.01)
    np.testing.assert_allclose(lam.imag, truth.imag, rtol=2e-3)
    # the model of two damped arms explains the history
    fitted = np.exp(np.outer(flight["s"], lam)) @ K
    assert np.max(np.abs(fitted - flight["xi"])) < 2e-3 * np.max(np.abs(flight["xi"]))
    # the reversed Magnus moment is far outside the tolerance
    wrong = theory_roots(flight["V0"], SPIN, CMpa=-CMPA)
    assert np.all(np.abs(wrong.real / truth.real - 1) > 0.3)


def test_swerve_matches_linearised_magnus_force(flight):
    """b(s) - b(0) = kappa (C_La - i C_Npa p d / V) int xi ds: regressing the 6-DOF velocity
    direction on the integral of the fitted arms recovers C_La and C_Npa (measured 2.49996 and
    0.2989, i.e. 0.36 %; the Magnus part is 2.5 % of the lift part, so a reversed force gives
    C_Npa = -0.3)."""
    lam, K = fit_two_arms(flight["xi"], flight["ds"])
    g = (np.expm1(np.outer(flight["s"], lam)) / lam) @ K
    b = flight["b"]
    c = np.vdot(g, b - b[0]) / np.vdot(g, g) / KAPPA
    nu = SPIN * D / flight["V0"]
    assert c.real == pytest.approx(CLA, rel=1e-3)
    assert -c.imag / nu == pytest.approx(CNPA, rel=0.02)


# --- directions at given body states ---------------------------------------------------------

def forces(v_b, coef, dtype=float):
    v_b = np.asarray(v_b, dtype=dtype)
    V = np.sqrt(np.sum(v_b * v_b))
    F = np.zeros(3, dtype=dtype)
    M = np.zeros(3, dtype=dtype)
    aero_force_moment(v_b, V, np.asarray(RHO, dtype=dtype)[()], BODY.phys().astype(dtype),
                      np.asarray(coef, dtype=dtype), PLANE_SIGMA, F, M)
    return F, M, 0.5 * RHO * V * V * BODY.area_m2


def coefs(**kw):
    names = ("CD", "CL", "CC", "Cl", "Cm", "Cn", "Clp", "Cmq", "Cnr")
    return np.array([kw.get(n, 0.0) for n in names])


def rot_x(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


@pytest.mark.parametrize("sigma_deg", [0.5, 10.0, 60.0, 135.0])
@pytest.mark.parametrize("phi_deg", [0.0, 37.0, 90.0, 200.0, 300.0])
def test_magnus_directions(sigma_deg, phi_deg):
    """C_C along (x_b x e_V) / sin(sigma), normal to the plane of x_b and the wind; C_n about
    e_P = (0, v, w) / sqrt(v^2 + w^2), in that plane (McCoy's x × V and x × (V × x))."""
    sig, phi = np.radians(sigma_deg), np.radians(phi_deg)
    V = 800.0
    v_b = V * np.array([np.cos(sig), np.sin(sig) * np.cos(phi), np.sin(sig) * np.sin(phi)])
    e_v, x_b = v_b / V, np.array([1.0, 0.0, 0.0])
    F, M, qS = forces(v_b, coefs(CC=1.0))
    np.testing.assert_allclose(F, qS * np.cross(x_b, e_v) / np.sin(sig), atol=1e-12 * qS)
    assert abs(F @ e_v) < 1e-12 * qS and abs(F @ x_b) < 1e-12 * qS
    np.testing.assert_allclose(M, 0.0, atol=1e-12 * qS)
    F, M, qS = forces(v_b, coefs(Cn=1.0))
    e_p = np.array([0.0, v_b[1], v_b[2]]) / np.hypot(v_b[1], v_b[2])
    np.testing.assert_allclose(M, qS * D * e_p, atol=1e-12 * qS * D)
    assert abs(M @ np.cross(e_v, x_b)) < 1e-12 * qS * D  # in the plane of x_b and e_V
    assert M @ e_v > 0.0  # e_P is e_V's part normal to x_b
    np.testing.assert_allclose(F, 0.0, atol=1e-12 * qS)


@pytest.mark.parametrize("phi_deg", [25.0, 90.0, 180.0, 250.0])
def test_force_and_moment_turn_with_the_wind_about_the_axis(phi_deg):
    """Rotational invariance about x_b: rotating (v, w) by phi rotates F and M by phi."""
    coef = coefs(CD=0.3, CL=0.4, CC=-0.05, Cl=0.01, Cm=0.2, Cn=0.03)
    v_b = np.array([780.0, 60.0, -110.0])
    Rx = rot_x(np.radians(phi_deg))
    F0, M0, _ = forces(v_b, coef)
    F1, M1, _ = forces(Rx @ v_b, coef)
    np.testing.assert_allclose(F1, Rx @ F0, rtol=1e-12, atol=1e-12 * np.abs(F0).max())
    np.testing.assert_allclose(M1, Rx @ M0, rtol=1e-12, atol=1e-12 * np.abs(M0).max())


def test_right_hand_spin_nose_up_senses():
    """Nose up relative to the wind (w > 0, body z down): a positive C_C pushes to port
    (-y_b; the classical Magnus sense of a positive C_Npa with right-hand spin), a positive
    C_n turns the nose to starboard (about +z_b), a positive C_m pitches it further up."""
    v_b = 800.0 * np.array([np.cos(0.02), 0.0, np.sin(0.02)])
    F, _, qS = forces(v_b, coefs(CC=1.0))
    np.testing.assert_allclose(F, [0.0, -qS, 0.0], atol=1e-12 * qS)
    _, M, qS = forces(v_b, coefs(Cn=1.0, Cm=0.5))
    np.testing.assert_allclose(M, qS * D * np.array([0.0, 0.5, 1.0]), atol=1e-12 * qS * D)


def test_zero_total_angle_has_no_magnus():
    F, M, qS = forces([800.0, 0.0, 0.0], coefs(CD=0.3, CC=1.0, Cn=1.0, Cl=0.1))
    np.testing.assert_allclose(F, [-0.3 * qS, 0.0, 0.0])
    np.testing.assert_allclose(M, [0.1 * qS * D, 0.0, 0.0])


def test_complex_step_through_magnus_terms():
    """Complex-step safe: Im F(w + ih) / h equals the central difference."""
    coef = coefs(CD=0.3, CL=0.4, CC=-0.05, Cm=0.2, Cn=0.03)
    v_b = np.array([780.0, 60.0, -110.0])
    h = 1e-20
    Fc, Mc, _ = forces(v_b + np.array([0.0, 0.0, 1j * h]), coef, dtype=complex)
    dv = np.array([0.0, 0.0, 1e-4])
    Fp, Mp, _ = forces(v_b + dv, coef)
    Fm, Mm, _ = forces(v_b - dv, coef)
    np.testing.assert_allclose(Fc.imag / h, (Fp - Fm) / 2e-4, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(Mc.imag / h, (Mp - Mm) / 2e-4, rtol=1e-6, atol=1e-11)


# --- model files ------------------------------------------------------------------------------

def test_sigma_model_file_with_magnus_loads(tmp_path):
    path = tmp_path / "bullet.toml"
    path.write_text('angle_plane = "sigma"\n[coefficients]\nCD = "CD0"\n'
                    'CC = "CNpa*2*p_hat*sin(sigma)"\nCn = "CMpa*2*p_hat*sin(sigma)"\n'
                    '[parameters]\nCD0 = { value = 0.3 }\nCNpa = { value = 0.3 }\n'
                    'CMpa = { value = 0.1 }\n', encoding="utf-8")
    model = load_model(path)
    out = model.evaluate(0.1, 0.0, 0.1, 2.4, p_hat=0.1)
    assert out["CC"] == pytest.approx(0.3 * 0.2 * np.sin(0.1))
    assert out["Cn"] == pytest.approx(0.1 * 0.2 * np.sin(0.1))


def test_sigma_model_still_refuses_cnr():
    msg = (r"coefficients\.Cnr: not used by total-angle \(sigma\) models "
           r"\(docs/conventions\.md: C_mq damps both transverse rates\)")
    with pytest.raises(ValueError, match=msg):
        model_from_dict({"name": "s", "angle_plane": "sigma",
                         "coefficients": {"CC": "A", "Cnr": "B"},
                         "parameters": {"A": {"value": 1.0}, "B": {"value": 1.0}}})


# --- the non-rolling frame (docs/dynamics.md) -------------------------------------------------

def test_non_rolling_frame_flies_the_same_bullet_at_steps_its_spin_forbids(flight):
    """The same 94 m flight in the non-rolling frame at h = 50 us (p h = 1.1, where the body
    frame's RK4 diverges) and at 5 us agree to 1.2e-5 of the yaw amplitude (measured; the fast
    arm turns 0.11 rad a step), and with the body frame at 5 us (p h = 0.11) to 1e-5 rad; the
    arms fitted to it match McCoy's linear theory as the body frame's do. The adaptive
    integrator needs a quarter of the body frame's evaluations (measured 37 500 against
    297 852), which exceed the old fixed budget of 150 000."""
    from cadra.dynamics.integrate import propagate_adaptive

    V0, ds = MACH * SOUND, flight["ds"]
    s = flight["s"]
    t = np.expm1(KAPPA * CD * s) * D / (KAPPA * CD * V0)
    model = bullet_model()
    prog = model.compile()
    launch = Launch(speed_m_s=V0, theta_rad=np.radians(1.5), p_rad_s=SPIN)
    nr = BODY.with_frame("non_rolling")
    coarse, fine = (propagate_states(launch.state(nr), 0.0, t, nr.phys(), prog,
                                     model.values(), h) for h in (5e-5, 5e-6))
    amp = np.abs(flight["xi"]).max()
    assert np.abs(complex_yaw(coarse) - complex_yaw(fine)).max() < 3e-5 * amp
    assert np.abs(complex_yaw(fine) - flight["xi"]).max() < 1e-5
    np.testing.assert_allclose(coarse[:, 10], flight["states"][:, 10], rtol=1e-12)
    lam, _ = fit_two_arms(complex_yaw(coarse), ds)
    truth = theory_roots(V0, SPIN)
    np.testing.assert_allclose(lam.real, truth.real, rtol=0.01)
    np.testing.assert_allclose(lam.imag, truth.imag, rtol=2e-3)
    counts = {}
    for body in (BODY, nr):
        out = np.empty((t.size, 13))
        counts[body.attitude_frame] = propagate_adaptive(
            launch.state(body), 0.0, t, 2e-3, 1e-8, 1e-8, body.phys(), prog.ops, prog.args,
            prog.starts, model.values(), PLANE_SIGMA, prog.stack_size, out)
        assert np.abs(complex_yaw(out) - flight["xi"]).max() < 1e-5
    assert 0 < 4 * counts["non_rolling"] < counts["body"]


def test_non_rolling_frame_is_refused_where_it_is_not_exact():
    from cadra.dynamics.effects import Effects
    from cadra.dynamics.setup import non_rolling_obstacle

    prog = bullet_model().compile()
    assert non_rolling_obstacle(BODY.phys(), prog) == ""
    lateral = BODY.with_effects(Effects(cg_offset_body_m=(0.0, 1e-4, 0.0)))
    assert "cg is off the axis" in non_rolling_obstacle(lateral.phys(), prog)
    flat = RigidBody(**{**BODY.__dict__, "inertia_body_kg_m2": np.diag([IX, IY, 1.1 * IY])})
    assert "body of revolution" in non_rolling_obstacle(flat.phys(), prog)
    reads_phi = model_from_dict({"name": "x", "angle_plane": "sigma",
                                 "coefficients": {"CD": "c0 + c1*sin(4*phi)"},
                                 "parameters": {"c0": {"value": 0.3}, "c1": {"value": 0.01}}})
    assert "reads phi" in non_rolling_obstacle(BODY.phys(), reads_phi.compile())
    d = np.zeros(BODY.phys().size)
    d[24] = 1.0                                       # a lateral cg-offset sensitivity
    assert "cg is off the axis" in non_rolling_obstacle(BODY.phys(), prog, [d])
    with pytest.raises(ValueError, match="not exact here"):
        nr = lateral.with_frame("non_rolling")
        propagate_states(Launch(speed_m_s=800.0).state(nr), 0.0, [0.0, 1e-3], nr.phys(),
                         prog, bullet_model().values())
