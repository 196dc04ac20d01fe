"""Gap diagnosis: candidates ranked by score tests against a fit that leaves the effect out.

Truth: shots simulated WITH an effect (the simulator's effects, or injected measurement
errors), measured with stage-one-like noise, fitted WITHOUT it; the diagnosis is not told what
was injected.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from cadra.dynamics.effects import Effects
from cadra.fitting import fit_shots
from cadra.flight import shot_data_from_truth
from cadra.gap.score import diagnose_gap
from cadra.synthetic.simulate import load_shot_spec, simulate_shot
from cadra.validation.gap_cases import BODY_PAIRS
from cadra.validation.gap_scoring import (
    body_truth_in_fit_frame,
    effect_size_ok,
    exceed_pvalue,
    linear_shrink,
    magnitude_within_2sigma,
    size_within_2sigma,
)

SP = 2.8e-7                      # m, stage one's capsule precision
SA = np.radians(0.0012)          # rad


@pytest.fixture(scope="module")
def spec():
    return load_shot_spec("sample_shots/specs/m2_2429.toml")


def _fit(spec, effects=None, seed=3, edit=None):
    sim = simulate_shot(replace(spec, effects=effects or Effects()))
    sd = shot_data_from_truth(sim.truth, sim.rigid.with_effects(Effects()), "M2-2429",
                              "capsule", sigma_position_m=SP, sigma_angle_rad=SA,
                              rng=np.random.default_rng(seed))
    if edit is not None:
        sd = replace(sd, meas=edit(sd.meas.copy()))
    res, _ = fit_shots([sd], sim.model)
    assert res.converged
    return res, sd


def test_null_shot_has_no_significant_effect(spec):
    res, sd = _fit(spec)
    dg = diagnose_gap(res, [sd])
    assert not dg.added and not dg.unexplained
    assert dg.verdict.startswith("no significant unmodelled effect")


def test_lateral_cg_offset_found_sized_and_removed(spec):
    res, sd = _fit(spec, Effects(cg_offset_body_m=(0.0, 0.0, 2e-4)))
    dg = diagnose_gap(res, [sd])
    assert dg.ranking.iloc[0]["candidate"] == "lateral cg offset"
    first = dg.added[0]
    assert first["effect"] == "lateral cg offset"
    z, sz = first["size"][1], first["sigma"][1]
    assert abs(z - 2e-4) <= 2 * sz
    # rms per position channel back to within 10 % of a fit without the effect
    clean, sd0 = _fit(spec)
    for ch in "xyz":
        assert dg.rms_after[ch] <= 1.10 * clean.rms()[ch] + 1e-9, ch
    assert dg.rms_before["z"] > 3 * dg.rms_after["z"]


def test_station_position_bias_found(spec):
    def edit(m):
        m[6, 1] += 3e-6
        m[6, 2] -= 2e-6
        return m

    res, sd = _fit(spec, edit=edit)
    dg = diagnose_gap(res, [sd])
    effects = {a["effect"]: a for a in dg.added}
    assert dg.added[0]["effect"] in ("station 7 y bias", "station 7 z bias")
    # once one channel's bias is in, the station's scale error (s y, s z) explains the other
    # channel exactly as its bias does: the diagnosis may add either, naming the other as an
    # alias -- both say "station 7, that channel"
    named = set(effects) | {al for a in dg.added for al in a["aliases"]}
    assert named >= {"station 7 y bias", "station 7 z bias"}
    for name, truth in (("station 7 y bias", 3e-6), ("station 7 z bias", -2e-6)):
        if name in effects:
            v, s = effects[name]["size"][0], effects[name]["sigma"][0]
            assert abs(v - truth) <= 2 * s, name


def test_out_of_library_effect_reported_unexplained_where_it_lies(spec):
    """Angle biases at two stations (stage one's angle channel: not a library effect) must not
    be pinned on a library effect; the verdict names where the residual lies."""
    def edit(m):
        m[4, 3] += np.radians(0.02)
        m[11, 4] -= np.radians(0.02)
        return m

    res, sd = _fit(spec, edit=edit)
    dg = diagnose_gap(res, [sd])
    assert dg.unexplained
    assert "station 5 theta" in dg.verdict or "station 12 psi" in dg.verdict


def test_diagnose_cli(tmp_path, spec):
    """cadra2 diagnose from a trajectory file: a cg offset found, report written."""
    import pandas as pd

    from cadra.cli.cadra2 import main
    from cadra.io.trajectory import COLUMNS, write_trajectory
    from cadra.synthetic.simulate import write_shot

    sim = simulate_shot(replace(spec, effects=Effects(cg_offset_body_m=(0, 0, 2e-4))))
    d = write_shot(sim, tmp_path / "shot", images=False, progress=False)
    # the shot file tells the analyst nothing of the effect: its cg is the nominal one
    rng = np.random.default_rng(5)
    t = sim.truth
    n = len(t)
    table = pd.DataFrame({
        "station": t["station"], "t_s": t["t_s"], "status": "ok",
        "x_m": t["x_m"] + rng.normal(0, SP, n), "y_m": t["y_m"] + rng.normal(0, SP, n),
        "z_m": t["z_m"] + rng.normal(0, SP, n),
        "theta_deg": t["theta_deg"] + rng.normal(0, 0.0012, n),
        "psi_deg": t["psi_deg"] + rng.normal(0, 0.0012, n),
        "sigma_x_m": SP, "sigma_y_m": SP, "sigma_z_m": SP, "sigma_theta_deg": 0.0012,
        "sigma_psi_deg": 0.0012, "x_top_minus_side_m": 0.0, "x_consistency": 0.0,
        "reason": "", "warnings": ""})
    traj = write_trajectory(tmp_path / "traj.csv", table.loc[:, list(COLUMNS)],
                            {"shot_id": sim.spec.shot_id,
                             "shot_file": str((d / "shot.toml").resolve())})
    out = tmp_path / "diag"
    assert main(["diagnose", str(traj), "--model", "m2_m070", "-o", str(out)]) == 0
    report = (out / "report.md").read_text()
    assert "lateral cg offset" in report.split("## How much")[0]
    assert (out / "ranking.csv").is_file() and (out / "where.csv").is_file()
    for name in ("where_sequence.csv", "where_frequency.csv", "where_stage_one.csv",
                 "where.png"):
        assert (out / name).is_file(), name
    assert "## Where the fit as given misses" in report
    assert "| noise floor after |" in report


# ---- "where" tests (cadra.gap.where) against hand-made residuals of known structure ----

def _table(values_by_shot, channel="z"):
    import pandas as pd

    rows = []
    for shot, vals in values_by_shot.items():
        for k, v in enumerate(vals):
            rows.append({"shot_id": shot, "station": k + 1, "channel": channel,
                         "normalized": float(v), "t_s": 0.001 * k})
    return pd.DataFrame(rows)


def test_runs_test_counts_runs_and_flags_a_systematic_pattern():
    from cadra.gap.where import sequence_tests
    from cadra.stats import runs_of_sign

    rt = runs_of_sign(np.array([1, 2, -1, -3, -2, 4, 5, -1]))
    runs, z = rt.runs, rt.z
    assert runs == 4 and rt.longest == 3 and rt.n == 8
    # hand formula: n1 = n2 = 4: mean 5, variance 2*16*(32-8)/(64*7) = 12/7
    assert z == pytest.approx((4 - 5) / np.sqrt(12 / 7))
    # a slow drift (one sign change in 16) is flagged; white noise mostly is not
    drift = np.linspace(-3, 3, 16)
    seq = sequence_tests(_table({"A": drift}))
    assert seq.loc[0, "runs"] == 2 and seq.loc[0, "runs_p"] < 0.01
    assert seq.loc[0, "lag1_autocorrelation"] > 0.7
    rng = np.random.default_rng(0)
    flagged = [sequence_tests(_table({"A": rng.standard_normal(16)})).loc[0, "runs_p"] < 0.01
               for _ in range(400)]
    assert np.mean(flagged) < 0.03


def test_frequency_content_finds_a_residual_at_the_pitch_frequency():
    from cadra.gap.where import frequency_content

    t = 0.001 * np.arange(16)
    rng = np.random.default_rng(1)
    r = 2.0 * np.sin(2 * np.pi * 60.0 * t + 0.4) + rng.standard_normal(16)
    table = _table({"A": r})
    fr = frequency_content(table, {"A": {"pitch": 60.0, "yaw": 23.0}})
    pitch = fr[fr["motion"] == "pitch"].iloc[0]
    assert pitch["p_value"] < 1e-3
    assert pitch["amplitude_sigma"] == pytest.approx(2.0, abs=0.8)


def test_cross_shot_tells_a_repeated_misfit_from_one_that_varies():
    from cadra.gap.where import cross_shot

    rng = np.random.default_rng(2)
    shots = {f"S{k}": rng.standard_normal(16) for k in range(5)}
    for v in shots.values():
        v[6] += 3.0                      # station 7: the same misfit in every shot
    shots["S0"][10] += 8.0               # station 11: one shot only
    cs = cross_shot(_table(shots)).set_index("station")
    assert cs.loc[7, "p_repeat"] < 1e-6 and cs.loc[7, "p_scatter"] > 0.01
    assert cs.loc[11, "p_scatter"] < 1e-6


def test_motion_frequency_matches_the_fitted_pitch_period(spec):
    """The dominant frequency of the fitted theta history matches linear theory's
    omega^2 = -Cm_alpha q S d / I of the same shot to a few percent."""
    from cadra.gap.where import motion_frequencies

    res, sd = _fit(spec)
    f = motion_frequencies(res, [sd])[sd.shot_id]
    sim = simulate_shot(spec)
    t = sim.truth
    theta = np.radians(t["theta_deg"].to_numpy())
    # count the truth's zero crossings of the detrended theta over the record
    th = theta - np.polyval(np.polyfit(t["t_s"], theta, 2), t["t_s"])
    dense_t = np.linspace(t["t_s"].min(), t["t_s"].max(), 2000)
    dense = np.interp(dense_t, t["t_s"], th)
    crossings = np.count_nonzero(np.diff(np.sign(dense)) != 0)
    f_truth = crossings / 2 / (dense_t[-1] - dense_t[0])
    assert f["pitch"] == pytest.approx(f_truth, rel=0.25)
    assert np.isnan(f["roll"])          # M2 does not roll


def test_motion_frequencies_of_a_multifit_name_every_shot_with_its_own_motion():
    """A two-shot multi-fit (M2-2429 and M2-2425): each shot's pitch frequency is its own
    truth's to a few percent (the where-tests of a multi-fit once asked the fit problem for
    one shot's dense history with times for that shot alone, and failed)."""
    from cadra.gap.where import motion_frequencies

    shots, truths = [], {}
    for name, seed in (("m2_2429", 3), ("m2_2425", 4)):
        sp = load_shot_spec(f"sample_shots/specs/{name}.toml")
        sim = simulate_shot(sp)
        sid = sp.shot_id
        shots.append(shot_data_from_truth(sim.truth, sim.rigid, sid, "capsule",
                                          sigma_position_m=SP, sigma_angle_rad=SA,
                                          rng=np.random.default_rng(seed)))
        truths[sid] = sim
    res, _ = fit_shots(shots, truths[shots[0].shot_id].model)
    assert res.converged
    f = motion_frequencies(res, shots)
    assert set(f) == {sd.shot_id for sd in shots}
    for sd in shots:
        t = truths[sd.shot_id].truth
        theta = np.radians(t["theta_deg"].to_numpy())
        th = theta - np.polyval(np.polyfit(t["t_s"], theta, 2), t["t_s"])
        dense_t = np.linspace(t["t_s"].min(), t["t_s"].max(), 2000)
        crossings = np.count_nonzero(np.diff(np.sign(np.interp(dense_t, t["t_s"], th))) != 0)
        f_truth = crossings / 2 / (dense_t[-1] - dense_t[0])
        assert f[sd.shot_id]["pitch"] == pytest.approx(f_truth, rel=0.25)


def test_validation_turns_body_truth_into_the_fits_frame():
    """The fit of a body of revolution has its own roll (no roll mark): the simulator's body
    effect must be expressed in the fit's body frame before it is compared. A fit frame
    rolled by delta about the axis (A_fit = A_truth Rx(delta)) has its y axis at
    (0, cos delta, sin delta) and its z axis at (0, -sin delta, cos delta) in the truth's body
    frame: the offset and the moments about those axes are the independent truth."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    delta = np.radians(-150.9)
    a_truth = Rotation.from_euler("ZY", [8.7, 26.1], degrees=True)
    a_fit = a_truth * Rotation.from_euler("x", delta)

    def q(r):                                   # scalar first, as the states store it
        x, y, z, w = r.as_quat()
        return np.array([w, x, y, z])

    states = np.zeros((2, 13))
    states[:, 6:10] = q(a_truth)
    sim = SimpleNamespace(times_s=np.array([0.0, 0.06]), states=states)
    ey = np.array([0.0, np.cos(delta), np.sin(delta)])
    ez = np.array([0.0, -np.sin(delta), np.cos(delta)])
    cg = body_truth_in_fit_frame("cg", {"cg_offset_y_m": 0.0, "cg_offset_z_m": 1.64e-4},
                                 sim, 0.03, q(a_fit))
    c = np.array([0.0, 0.0, 1.64e-4])
    assert cg["cg_offset_y_m"] == pytest.approx(ey @ c, abs=1e-15)
    assert cg["cg_offset_z_m"] == pytest.approx(ez @ c, abs=1e-15)
    a, b = 2.098e-9, 1.772e-9
    dI = np.array([[0, 0, 0], [0, a / 2, b], [0, b, -a / 2]])
    ia = body_truth_in_fit_frame("inertia_asym", {"Iyy_minus_Izz_kg_m2": a,
                                                  "Iyz_kg_m2": b}, sim, 0.03, q(a_fit))
    assert ia["Iyy_minus_Izz_kg_m2"] == pytest.approx(ey @ dI @ ey - ez @ dI @ ez, rel=1e-9)
    assert ia["Iyz_kg_m2"] == pytest.approx(ey @ dI @ ez, rel=1e-9)
    # the principal difference does not depend on the frame
    assert np.hypot(ia["Iyy_minus_Izz_kg_m2"], 2 * ia["Iyz_kg_m2"]) == pytest.approx(
        np.hypot(a, 2 * b), rel=1e-12)
    ex = np.array([1.0, 0.0, 0.0])
    P = np.zeros((3, 3))
    P[0, 2] = P[2, 0] = 5e-7
    pr = body_truth_in_fit_frame("products", {"Ixy_kg_m2@S": 0.0, "Ixz_kg_m2@S": 5e-7},
                                 sim, 0.03, q(a_fit))
    assert pr["Ixy_kg_m2@S"] == pytest.approx(ex @ P @ ey, rel=1e-9)
    assert pr["Ixz_kg_m2@S"] == pytest.approx(ex @ P @ ez, rel=1e-9)


def test_a_perfect_diagnosis_passes_the_effect_vector_score_at_two_sigmas_rate():
    """Sizes drawn from N(truth, C), a perfect diagnosis: as one vector with its covariance
    an effect of k parameters passes 95.45 % of the time for any k and any correlation;
    "every parameter within 2 sigma" passes 0.9545^k independent, and correlated between
    those and 0.9545. A one-parameter effect is scored alone."""
    rng = np.random.default_rng(3)
    n = 4000
    se = math.sqrt(0.9545 * 0.0455 / n)
    for k, rho in ((2, 0.0), (2, 0.9), (6, 0.3)):
        names = tuple(f"p{i}" for i in range(k))
        sig = np.geomspace(1e-3, 1.0, k)
        cov = (rho + (1 - rho) * np.eye(k)) * np.outer(sig, sig)
        truth = dict(zip(names, rng.standard_normal(k), strict=True))
        draws = rng.multivariate_normal([truth[p] for p in names], cov, n)
        vec = per = 0
        for d in draws:
            added = {"params": names, "size": list(d), "sigma": list(sig),
                     "covariance": cov.tolist()}
            vec += effect_size_ok(added, truth)
            per += size_within_2sigma(added, truth)
        assert abs(vec / n - 0.9545) < 4 * se
        if rho == 0.0:
            assert abs(per / n - 0.9545 ** k) < 4 * se
        assert per / n < 0.9545 - 4 * se
    one = {"params": ("q",), "size": [2.1], "sigma": [1.0], "covariance": [[1.0]]}
    assert not effect_size_ok(one, {"q": 0.0})
    assert effect_size_ok(one, {"q": 0.2})


def test_validation_compares_body_pairs_as_vectors_with_their_covariance():
    """A body swinging in one plane sees one combination of (Iyy - Izz, Iyz): correlation
    0.99999 (an M1-2393 trial). Off the truth along that valley is within two sigma (the
    data cannot tell), across it is not, whatever the component sigmas say; without a
    covariance the sigmas alone are used. A zero truth is a vector like any other."""
    g = BODY_PAIRS["inertia_asym"]
    s1, s2, rho = 1.0e-8, 2.56e-8, 0.99999
    cov = [[s1 * s1, rho * s1 * s2], [rho * s1 * s2, s2 * s2]]
    truth = {"Iyy_minus_Izz_kg_m2": 4.1e-9, "Iyz_kg_m2": 4e-11}
    along = {"params": g[0], "sigma": [s1, s2], "covariance": cov,
             "size": [4.1e-9 + 2.4 * s1, 4e-11 + 2.4 * s2]}    # 2.4 sigma each, in step
    assert size_within_2sigma(along, truth, g)
    assert not size_within_2sigma(dict(along, covariance=None), truth, g)
    across = dict(along, size=[4.1e-9 + 0.01 * s1, 4e-11 - 0.01 * s2])
    assert not size_within_2sigma(across, truth, g)
    assert size_within_2sigma(dict(across, covariance=None), truth, g)
    # the size: the magnitude, by its profile over the orientation. With an isotropic sigma
    # (in (Iyy - Izz, 2 Iyz)) that is | |v| - t | <= 2 sigma; along the valley above, the
    # truth's magnitude is reached at 2.4 sigma in step, too far for one parameter
    iso = {"params": g[0], "size": [3e-9, 2e-9], "sigma": [1e-9, 0.5e-9],
           "covariance": [[1e-18, 0.0], [0.0, 0.25e-18]]}          # |(a, 2b)| = 5e-9
    assert magnitude_within_2sigma(iso, {g[0][0]: 3.1e-9, g[0][1]: 0.0}, g)
    assert not magnitude_within_2sigma(iso, {g[0][0]: 0.0, g[0][1]: 2.9e-9 / 2}, g)
    assert magnitude_within_2sigma(iso, {g[0][0]: 0.0, g[0][1]: 6.9e-9 / 2}, g)
    assert not magnitude_within_2sigma(along, truth, g)
    # a zero truth (the other shots of a set): the 2-parameter 2-sigma quantile is
    # chi^2 = 6.18, so (2, 1.5) sigma (6.25) fails and (2, 1.4) sigma (5.96) passes
    zero = {"Ixy_kg_m2": 0.0, "Ixz_kg_m2": 0.0}
    pr = {"params": ("Ixy_kg_m2", "Ixz_kg_m2"), "size": [2e-9, 1.5e-9], "sigma": [1e-9, 1e-9],
          "covariance": [[1e-18, 0.0], [0.0, 1e-18]]}
    assert not size_within_2sigma(pr, zero, BODY_PAIRS["products"])
    pr["size"] = [2e-9, 1.4e-9]
    assert size_within_2sigma(pr, zero, BODY_PAIRS["products"])
    # an effect that keeps its sign: the signed interval
    d = {"params": ("drho",), "size": [2e-3], "sigma": [1e-6],
         "interval_2sigma": [(1.9e-3, 2.1e-3, True)]}
    assert size_within_2sigma(d, {"drho": 2.05e-3})
    assert not size_within_2sigma(d, {"drho": -2.05e-3})


def test_verdict_gives_the_profile_interval_and_says_when_it_is_unsure():
    from cadra.gap.score import size_text

    a = {"params": ("x",), "size": [1.0], "sigma": [0.001], "refit_status": "stalled",
         "interval_2sigma": [(0.5, float("inf"), True)]}
    text = size_text(a)
    assert "profile interval [0.5, open]" in text and "what the data allow" in text
    a["interval_2sigma"] = [(0.9, 1.1, False)]
    assert "may still be too narrow" in size_text(a)
    a["interval_2sigma"] = None
    assert "± 0.001" in size_text(a) and "far too small" in size_text(a)


def test_inertia_asymmetry_at_any_roll_found_as_its_principal_difference():
    """A symmetric M1 body whose transverse principal moments differ by 0.1 % of Iyy, their
    axes at 30 deg of roll: (Iyy - Izz, Iyz) = (d cos 60, d/2 sin 60). The fit holds the roll
    (a body of revolution); the candidate's pair spans every orientation, so the refit
    converges and its principal difference sqrt((Iyy - Izz)^2 + 4 Iyz^2) is within 2 sigma of
    d (the simulator's truth). One shot swinging mostly in one plane sees the inertia about
    the swing axis, which trades with the stiffness: the pair's sigmas are as large as d
    (the refit's honest answer; the old one-parameter form with a free roll claimed 1e-10)."""
    spec = load_shot_spec("sample_shots/specs/m1_2380.toml")
    I_yy = float(np.asarray(spec.inertia_model_kg_m2)[1][1])
    d = 1e-3 * I_yy
    a, b = d * np.cos(np.radians(60.0)), d / 2 * np.sin(np.radians(60.0))
    sim = simulate_shot(replace(spec, effects=Effects(
        inertia_delta_body_kg_m2=((0, 0, 0), (0, a / 2, b), (0, b, -a / 2)))))
    sd = shot_data_from_truth(sim.truth, sim.rigid.with_effects(Effects()), spec.shot_id,
                              "capsule", sigma_position_m=SP, sigma_angle_rad=SA,
                              rng=np.random.default_rng(5))
    res, _ = fit_shots([sd], sim.model)
    dg = diagnose_gap(res, [sd], sim.model)
    first = dg.added[0]
    assert first["effect"] == "inertia asymmetry"
    assert first["refit_status"] == "converged"
    (va, vb), (sa, sb) = first["size"], first["sigma"]
    m = float(np.hypot(va, 2 * vb))
    sm = float(np.hypot(va / m * sa, 2 * vb / m * 2 * sb))
    assert abs(m - d) <= 2 * sm, (m, d, sm)
    # the roll is held where both the simulator and the fit start it (0): the pair itself,
    # not only its magnitude, is within the two-sigma region of the truth (chi^2, 2 dof)
    assert ((va - a) / sa) ** 2 + ((vb - b) / sb) ** 2 <= 6.18


def test_validation_predicts_the_shrink_ratio_from_the_fits_linearizations():
    """``linear_shrink`` on a linear least-squares problem, against dense solves: the ratio
    of per-channel rms of the residuals left by two design matrices on the same noise (the
    "after" fit's rows in another order), and how often it exceeds 1.10 on other noise."""
    from types import SimpleNamespace

    import pandas as pd

    rng = np.random.default_rng(3)
    stations, chans = np.arange(1, 17), ["x", "y", "z"]
    keys = [("s", int(st), ch) for st in stations for ch in chans]
    n = len(keys)
    sigma = np.array([2.0 if ch == "z" else 1.0 for _, _, ch in keys])
    Jc = rng.standard_normal((n, 12))
    Ja = np.column_stack([Jc + 0.2 * rng.standard_normal((n, 12)), rng.standard_normal(n)])
    noise = {k: float(v) for k, v in zip(keys, rng.standard_normal(n), strict=True)}

    def fake(J, order):
        frame = pd.DataFrame({"shot_id": [keys[i][0] for i in order],
                              "station": [keys[i][1] for i in order],
                              "channel": [keys[i][2] for i in order],
                              "sigma": sigma[order]})
        return SimpleNamespace(jacobian=J[order], covariance=np.linalg.inv(J.T @ J),
                               residuals=frame)

    clean = fake(Jc, np.arange(n))
    after = fake(Ja, rng.permutation(n))

    def ratio(E):
        rc = E - Jc @ np.linalg.lstsq(Jc, E, rcond=None)[0]
        ra = E - Ja @ np.linalg.lstsq(Ja, E, rcond=None)[0]
        ch = np.array([k[2] for k in keys])
        return np.max([np.sqrt(np.sum((sigma[ch == c, None] * ra[ch == c]) ** 2, axis=0)
                               / np.sum((sigma[ch == c, None] * rc[ch == c]) ** 2, axis=0))
                       for c in chans], axis=0)

    lin = linear_shrink(clean, after, noise, np.random.default_rng(4), draws=4000)
    predicted, prob = lin["ratio"], lin["prob"]
    e = np.array([noise[k] for k in keys])[:, None]
    assert predicted == pytest.approx(float(ratio(e)[0]), rel=1e-10)
    # chi^2 after - clean: for the noise drawn, and its mean over draws (one more column:
    # -1, the difference of the two projections' traces)
    rc = e - Jc @ np.linalg.lstsq(Jc, e, rcond=None)[0]
    ra = e - Ja @ np.linalg.lstsq(Ja, e, rcond=None)[0]
    assert lin["dchi2"] == pytest.approx(float(np.sum(ra**2) - np.sum(rc**2)), rel=1e-10)
    assert lin["dchi2_mean"] == pytest.approx(-1.0, abs=4 * math.sqrt(lin["dchi2_var"] / 4000))
    mc = float(np.mean(ratio(np.random.default_rng(9).standard_normal((n, 20000))) > 1.10))
    assert 0.02 < mc < 0.98                 # the problem is one where the rate means something
    assert prob == pytest.approx(mc, abs=4 * math.sqrt(mc * (1 - mc) / 4000))
    # the same fit twice: ratio 1, never above the limit
    same = linear_shrink(clean, clean, noise, np.random.default_rng(4), draws=500)
    assert same["ratio"] == pytest.approx(1.0, abs=1e-12) and same["prob"] == 0.0
    assert same["dchi2_mean"] == pytest.approx(0.0, abs=1e-9)


def test_validation_tail_probability_of_trials_above_the_limit():
    """``exceed_pvalue``: with equal probabilities the binomial tail (scipy); with unequal
    ones the sum over all 2^n outcomes."""
    import itertools

    from scipy import stats

    rows = [{"shrink_ratio": 1.2 if i < 7 else 1.0, "shrink_exceed_prob": 0.3}
            for i in range(20)]
    assert exceed_pvalue(rows) == pytest.approx(stats.binom.sf(6, 20, 0.3), rel=1e-12)
    q = [0.1, 0.5, 0.02, 0.7, 0.33, 0.9]
    rows = [{"shrink_ratio": r, "shrink_exceed_prob": p}
            for r, p in zip([1.3, 1.0, 1.2, 1.05, 1.11, 1.0], q, strict=True)]
    brute = sum(math.prod(p if o else 1 - p for o, p in zip(out, q, strict=True))
                for out in itertools.product([0, 1], repeat=len(q)) if sum(out) >= 3)
    assert exceed_pvalue(rows) == pytest.approx(brute, rel=1e-12)


def test_a_column_of_rounding_is_no_direction():
    """The score test of a candidate whose computed column is rounding (the data do not
    depend on it): without the fit's scale it is a random unit vector, whose chi^2 drop is
    drawn from chi^2_1 (so p < 0.05 one time in twenty); with it, no score at all. A column
    that matters, or one of a pair that does, is scored as before."""
    from cadra.gap.score import _orth, score

    rng = np.random.default_rng(4)
    n = 300
    J = rng.normal(size=(n, 6)) * np.array([1e6, 1e4, 1e3, 3e2, 1e5, 1e2])
    Q, r = _orth(J), rng.normal(size=n)
    scale = float(np.linalg.norm(J, axis=0).max())
    drops = [score(Q, r, rng.normal(size=(n, 1)) * 1e-27, n, 6)["dchi2"] for _ in range(400)]
    assert 0.6 < np.mean(drops) < 1.4                          # chi^2_1: mean 1
    assert score(Q, r, rng.normal(size=(n, 1)) * 1e-27, n, 6, scale) is None
    C = rng.normal(size=(n, 1)) * 1e-3 + r[:, None] * 1e-2       # small, but it matters
    assert score(Q, r, C, n, 6, scale)["dchi2"] == pytest.approx(score(Q, r, C, n, 6)["dchi2"])
    pair = np.hstack([C, rng.normal(size=(n, 1)) * 1e-27])
    sc = score(Q, r, pair, n, 6, scale)
    assert sc["k"] == 1 and sc["dchi2"] == pytest.approx(score(Q, r, C, n, 6)["dchi2"])
    assert math.isfinite(sc["sigma"][0]) and sc["sigma"][1] == np.inf


def test_a_spheres_moment_terms_are_not_scored():
    """A sphere's record holds positions, which the library's aero terms (all moments) do
    not move: their candidates get no score (they were scored as rounding's random direction
    and refitted, from scratch, one time in twenty), while the body, air and station
    candidates are scored."""
    from cadra.validation.gap_cases import shot_spec
    from cadra.validation.gap_measure import measure

    sp = shot_spec("sphere_1")
    sim = simulate_shot(sp)
    sd = measure(sim, sim.rigid.with_effects(Effects()), sp, 5, None)
    res, _ = fit_shots([sd], sim.model)
    dg = diagnose_gap(res, [sd])
    kinds = set(dg.ranking["kind"])
    assert "aero" not in kinds and {"dynamics", "measurement"} <= kinds
    assert {"density gradient", "cross-flow"} <= set(dg.ranking["candidate"])
