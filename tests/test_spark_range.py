"""A spin-stabilised bullet on the BRL-like spark range (docs/spark_range.md), against
independent truth.

- Aliasing, analytically: two arms sampled 4 m apart, the fast one turning 1.7 times between
  stations; the free epicyclic fit finds its alias, and the spin puts it back in its band
  (the frequencies written here, 1e-6).
- The shot file's [gun]: twist and muzzle velocity give p = 2 pi V / twist; errors name keys.
- The sample round M80-S1 (``sample_shots/m80_spark_1``: the bundled ``m80`` as truth) with
  film-level noise, through ``cadra2 fit`` from the shot file's twist alone: converged in the
  truth's basin, the coefficients within 3 sigma of the model file's values; through
  ``cadra2 motion --twist 12``: C_m_alpha within 3 sigma, every output naming its rate
  normalisation, d/V values half the d/2V ones.
- A fit far above its noise (sigmas stated 10 times too small) is reported as converged to a
  poor minimum, names its worst channel, and exits 1.
- An unmeasured roll channel carries no sigma, and film-level data fit in one phase.
- The fit integrates a bullet in the non-rolling frame, a finned body whose roll it measures
  in the body's own, and falls back to the body frame for a lateral cg-offset extra.
"""

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import resolve_model
from cadra.cli.cadra2 import main as cadra2_main
from cadra.facility.reference import spark_range_text
from cadra.flight.data import floor_sigmas, launch_spin, with_launch_spin
from cadra.flight.load import load_shots
from cadra.io.facility_file import load_facility
from cadra.io.shotfile import ShotFileError, load_shot, shot_from_dict, shot_to_dict
from cadra.motion import dealias_arms, fit_epicyclic
from cadra.units import M_PER_IN
from cadra.validation.truth_files import write_trajectory_file

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_shots" / "m80_spark_1"
TWIST_M = 12 * M_PER_IN


def test_the_facility_is_its_generators_output():
    assert tomllib.loads(spark_range_text()) == tomllib.loads(
        (ROOT / "facilities" / "spark_range.toml").read_text())
    f = load_facility("spark_range")
    x = np.array([s.x_m for s in f.stations])
    assert len(x) == 25 and np.allclose(np.diff(x), 4.0)


def test_the_spin_puts_an_aliased_arm_back_in_its_band():
    """xi = K_f e^{(l_f + i w_f) s} + K_s e^{(l_s + i w_s) s}, w_f = 2.70, w_s = 0.383 rad/m,
    stations 4 m apart (Nyquist 0.785 rad/m): the sampled fast arm is w_f - 2 (2 pi / 4)."""
    s = np.arange(25) * 4.0 + np.random.default_rng(3).normal(0, 0.002, 25)
    wf, ws, lf, ls = 2.70, 0.383, -4e-4, -2e-4
    xi = 0.01 * np.exp((lf + 1j * wf) * s + 0.3j) + 0.02 * np.exp((ls + 1j * ws) * s - 1.1j)
    sig = np.full(s.size, 1e-6)
    free = fit_epicyclic(s, xi.imag, xi.real, sig, sig, variable="distance")
    w_free = sorted(free.values[[free.layout.index("omega1"), free.layout.index("omega2")]])
    assert abs(w_free[0] - (wf - 2 * math.pi / 2.0)) < 1e-3     # the alias, not the arm
    out = dealias_arms(free, s, xi.imag, xi.real, sig, sig, expected_sum=1.02 * (wf + ws),
                       expected_product=wf * ws)
    w = sorted(out.fit.values[[out.fit.layout.index("omega1"), out.fit.layout.index("omega2")]])
    np.testing.assert_allclose(w, [ws, wf], atol=1e-6)
    assert out.aliased and sorted(out.shifts) == [0, 2]
    assert "aliased arms" in out.note()
    with pytest.raises(ValueError, match="sums to the spin"):
        dealias_arms(free, s, xi.imag, xi.real, sig, sig, expected_sum=0.3 * (wf + ws))


def test_the_gun_table_gives_the_spin_and_its_errors_name_keys():
    data = tomllib.loads((SAMPLE / "shot.toml").read_text())
    shot = load_shot(SAMPLE / "shot.toml")
    assert shot.gun.spin_rad_s() == pytest.approx(2 * math.pi * 838.0 / TWIST_M, rel=1e-12)
    again = shot_from_dict(shot_to_dict(shot)).gun
    assert again.twist_m_per_turn == pytest.approx(TWIST_M, rel=1e-15)
    assert again.muzzle_velocity_m_s == 838.0 and again.muzzle_spin_rad_s is None
    for gun, key in (({"twist_in_per_turn": 12, "twist_m_per_turn": 0.3}, "twist_in_per_turn"),
                     ({"twist_in_per_turn": 0.1}, "twist_in_per_turn"),
                     ({"muzzle_spin_rad_s": 1e4, "twist_in_per_turn": 12}, "muzzle_spin"),
                     ({"muzzle_velocity_m_s": 800.0}, "gun"),
                     ({"twist_in_per_turn": 12, "spin": 3}, "spin")):
        with pytest.raises(ShotFileError, match=key):
            shot_from_dict({**data, "gun": gun})


@pytest.fixture(scope="module")
def spark(tmp_path_factory):
    base = tmp_path_factory.mktemp("spark")
    return base, write_trajectory_file(SAMPLE / "truth.csv", SAMPLE / "shot.toml",
                                       base / "trajectory.csv", np.random.default_rng(1833),
                                       shot_id="M80-S1")


def test_cadra2_fit_from_the_twist_alone(spark, capsys):
    base, traj = spark
    shots, _ = load_shots([traj])
    assert launch_spin(shots[0]) == pytest.approx(2 * math.pi * 838.0 / TWIST_M)
    out = base / "fit"
    code = cadra2_main(["fit", str(traj), "--model", "m80", "--free", "CDD2", "-o", str(out),
                        "--no-plots", "-q"])
    assert code == 0, capsys.readouterr().err
    results = json.loads((out / "results.json").read_text())
    assert results["verdict"] == "converged"
    truth = {p.name: p.value for p in resolve_model("m80").parameters}
    for name in ("CD0", "CNA", "CDD2", "CMA", "CMQ", "CMPA"):
        par = results["parameters"][name]
        assert abs(par["value"] - truth[name]) < 3 * par["sigma"], (name, par)


def test_cadra2_motion_with_the_twist_names_its_rates(spark, capsys):
    base, traj = spark
    outs = {}
    for rates in ("d/2V", "d/V"):
        out = base / f"motion_{rates.replace('/', '')}"
        code = cadra2_main(["motion", str(traj), "--twist", "12", "--curvature", "--rates",
                            rates, "-o", str(out), "-q"])
        assert code == 0, capsys.readouterr().err
        outs[rates] = pd.read_csv(out / "coefficients.csv").iloc[0]
        report = (out / "report.md").read_text()
        assert f"q {rates.replace('/', ' / ')}" in report and "aliased" in report
    lin = outs["d/2V"]
    assert lin["rate_normalisation"] == "d/2V" and outs["d/V"]["rate_normalisation"] == "d/V"
    assert outs["d/V"]["Cmq_sum_per_rad"] == pytest.approx(0.5 * lin["Cmq_sum_per_rad"])
    assert outs["d/V"]["Cm_alpha_per_rad"] == pytest.approx(lin["Cm_alpha_per_rad"])
    assert abs(lin["Cm_alpha_per_rad"] - 1.82) < 3 * lin["Cm_alpha_sigma_per_rad"]
    # a bullet fitted without its spin is warned about
    assert "spin is not known" in _fit_without_gun(base, traj, capsys)
    # without the twist (a shot file without [gun]) the fast arm stays where the stations
    # put it, and C_m_alpha is far off
    gunless = _gunless(base)
    out = base / "motion_no_twist"
    cadra2_main(["motion", str(traj), "--shot", str(gunless), "-o", str(out), "-q"])
    capsys.readouterr()
    c = pd.read_csv(out / "coefficients.csv").iloc[0]
    assert abs(c["Cm_alpha_per_rad"] - 1.82) > 10 * c["Cm_alpha_sigma_per_rad"]


def _gunless(base: Path) -> Path:
    text = (SAMPLE / "shot.toml").read_text()
    path = base / "gunless.toml"
    if not path.exists():
        path.write_text(text[:text.index("[gun]")] + text[text.index("[[stations]]"):])
    return path


def _fit_without_gun(base, traj, capsys) -> str:
    cadra2_main(["fit", str(traj), "--shot", str(_gunless(base)), "--model", "m80",
                 "--max-iterations", "2", "-o", str(base / "fit_no_gun"), "--no-plots", "-q"])
    return capsys.readouterr().err


def test_a_fit_far_above_its_noise_is_a_poor_minimum(spark, capsys):
    base, _ = spark

    def tiny(t):
        for col in ("sigma_x_m", "sigma_y_m", "sigma_z_m"):
            t[col] = 1e-5                   # the noise is 1e-4 m: sigmas 10 times too small
    traj = write_trajectory_file(SAMPLE / "truth.csv", SAMPLE / "shot.toml",
                                 base / "tiny.csv", np.random.default_rng(7),
                                 shot_id="M80-S1", edit=tiny)
    out = base / "poor"
    code = cadra2_main(["fit", str(traj), "--model", "m80", "-o", str(out), "--no-plots",
                        "-q"])
    err = capsys.readouterr().err
    assert code == 1
    assert "POOR MINIMUM" in err and "carries" in err and "station" in err
    results = json.loads((out / "results.json").read_text())
    assert results["verdict"] == "poor_minimum" and results["chi2_p_value"] < 1e-6


def test_an_unmeasured_roll_has_no_sigma_and_film_data_fit_in_one_phase(spark):
    from cadra.fitting import fit_shots

    _, traj = spark
    shot = load_shots([traj], min_sigma_angle_deg=0.0)[0][0]
    assert not shot.has_roll and np.all(np.isnan(floor_sigmas(shot, {"angle_rad": 1e-3})
                                                 .sigma[:, 5]))
    res, _ = fit_shots([shot], resolve_model("m80"))
    assert res.converged and "phases" not in res.options


def test_the_fit_chooses_its_attitude_frame():
    from cadra.dynamics.layout import P_CG_OFFSET
    from cadra.fitting.extras import Extra, phys_direction
    from cadra.fitting.problem import FitProblem
    from cadra.flight.data import shot_data_from_truth
    from cadra.synthetic.simulate import load_shot_spec, simulate_shot

    truth = pd.read_csv(SAMPLE / "truth.csv")
    sim = simulate_shot(load_shot_spec(ROOT / "sample_shots" / "specs" / "m80_spark_1.toml"))
    assert sim.rigid.attitude_frame == "non_rolling" and truth["phi_deg"].isna().all()
    sd = shot_data_from_truth(truth, sim.rigid.with_frame("body"), "M80-S1", "bullet",
                              sigma_position_m=1e-4, sigma_angle_rad=1e-3)
    y0 = sim.states[sd.epoch_index]
    model = resolve_model("m80")
    assert FitProblem((sd,), model, (y0,)).frames == ("non_rolling",)
    lateral = Extra("cg_y", phys_direction(P_CG_OFFSET + 1))
    assert FitProblem((sd,), model, (y0,), extras=(lateral,)).frames == ("body",)
    spec = ROOT / "sample_shots" / "specs" / "finner_1.toml"
    fin = simulate_shot(load_shot_spec(spec))
    fd = shot_data_from_truth(fin.truth, fin.rigid, "FIN", "finner", sigma_position_m=1e-4,
                              sigma_angle_rad=1e-3)
    assert FitProblem((fd,), fin.model, (fin.states[fd.epoch_index],)).frames == ("body",)
    # the spin comes from the twist and the measured speed when no muzzle velocity is given
    no_v = with_launch_spin(sd, twist_m_per_turn=TWIST_M)
    assert math.isnan(no_v.launch_spin_rad_s)
    assert launch_spin(no_v, 800.0) == pytest.approx(2 * math.pi * 800.0 / TWIST_M)
