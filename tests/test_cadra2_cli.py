"""``cadra2 fit`` in-process: outputs, refusals and bad input (no images needed: the
trajectory files are made from the simulator's exact truth plus seeded noise)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from cadra.aero import save_model
from cadra.cli.cadra2 import main
from cadra.io.trajectory import COLUMNS, write_trajectory
from cadra.synthetic.simulate import load_shot_spec, simulate_shot, write_shot
from cadra.validation.truth_files import write_trajectory_file

SPECS = Path("sample_shots/specs")


@pytest.fixture(scope="module")
def shots(tmp_path_factory):
    base = tmp_path_factory.mktemp("cli")
    out = {}
    rng = np.random.default_rng(42)
    for name in ("m2_2429", "m2_2427"):
        sim = simulate_shot(load_shot_spec(SPECS / f"{name}.toml"))
        d = write_shot(sim, base / name, images=False, progress=False)
        traj = write_trajectory_file(sim, d / "shot.toml", base / f"{name}_trajectory.csv",
                                     rng)
        out[name] = (sim, d / "shot.toml", traj)
    out["base"] = base
    return out


def test_fit_writes_everything_and_refuses_to_overwrite(shots, capsys):
    sim, _, traj = shots["m2_2429"]
    out = shots["base"] / "fit1"
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(out),
                 "--no-plots"]) == 0     # not -q: the parameter table is printed
    for f in ("results.json", "coefficients.csv", "covariance.csv", "correlation.csv",
              "correlation_coloured.csv", "residuals.csv", "report.md", "model_fitted.toml",
              "config.toml"):
        assert (out / f).is_file(), f
    res = json.loads((out / "results.json").read_text())
    assert res["status"] == "converged"
    text = capsys.readouterr().out
    assert "Cm_A1" in text and "converged" in text
    # fitted values within 3 sigma of Table 4 M2 M0.70 (the truth of the simulated shot)
    table = pd.read_csv(out / "coefficients.csv")
    cm = table.loc[table["coefficient"] == "Cm"].iloc[0]
    assert abs(cm["A1"] - sim.model.parameter("Cm_A1").value) < 3 * cm["A1_sigma"]
    before = (out / "results.json").stat().st_mtime_ns
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(out), "-q"]) == 1
    assert "refusing to overwrite" in capsys.readouterr().err
    assert (out / "results.json").stat().st_mtime_ns == before


def test_multifit_two_shots_with_holds(shots):
    trajs = [str(shots[n][2]) for n in ("m2_2429", "m2_2427")]
    out = shots["base"] / "multi"
    assert main(["fit", *trajs, "--model", "m2_m070", "-o", str(out), "-q", "--no-plots",
                 "--hold", "Cnr_A1=0.81", "--hold", "CD_A5"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert len(res["shots"]) == 2
    free = {name for name, p in res["parameters"].items() if not p["held"]}
    assert "Cnr_A1" not in free and "CD_A5" not in free and "Cm_A1" in free


def test_files_that_do_not_belong_together(shots, capsys):
    _, shot_b, _ = shots["m2_2427"]
    _, _, traj_a = shots["m2_2429"]
    out = shots["base"] / "mismatch"
    assert main(["fit", str(traj_a), "--shot", str(shot_b), "--model", "m2_m070", "-o",
                 str(out), "-q"]) == 1
    err = capsys.readouterr().err
    assert "do not belong together" in err
    assert not out.exists()


def test_too_few_stations(shots, capsys):
    sim, shot_file, _ = shots["m2_2429"]
    traj = write_trajectory_file(sim, shot_file, shots["base"] / "short.csv",
                                 np.random.default_rng(1), rows=[0, 1, 2])
    out = shots["base"] / "short_fit"
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(out), "-q",
                 "--no-plots"]) == 1
    assert "too few stations" in capsys.readouterr().err
    res = json.loads((out / "results.json").read_text())
    assert res["status"] == "failed" and not res["converged"]
    assert "NOT" in (out / "report.md").read_text()


def test_nan_measurements_and_failed_stations(shots):
    sim, shot_file, traj = shots["m2_2429"]
    text = traj.read_text().splitlines()
    header = [i for i, line in enumerate(text) if line.startswith("station,")][0]
    lines = text[:]
    # station 4: failed (values empty); station 6: theta missing
    cols = lines[header].split(",")
    row = lines[header + 4].split(",")
    row[cols.index("status")] = "failed"
    for c in ("x_m", "y_m", "z_m", "theta_deg", "psi_deg"):
        row[cols.index(c)] = ""
    row[cols.index("reason")] = "image unreadable"
    lines[header + 4] = ",".join(row)
    row = lines[header + 6].split(",")
    row[cols.index("theta_deg")] = "nan"
    lines[header + 6] = ",".join(row)
    bad = shots["base"] / "holes.csv"
    bad.write_text("\n".join(lines) + "\n")
    out = shots["base"] / "holes_fit"
    assert main(["fit", str(bad), "--model", "m2_m070", "-o", str(out), "-q",
                 "--no-plots"]) == 0
    res = json.loads((out / "results.json").read_text())
    assert res["n_observations"] == 16 * 5 - 5 - 1


def test_diverging_start_marked_not_converged(shots, capsys):
    sim, _, traj = shots["m2_2429"]
    bad = shots["base"] / "absurd.toml"
    save_model(sim.model.with_values({"Cm_A1": 5e3, "Cmq_A1": 5e3}), bad)
    out = shots["base"] / "diverged"
    rc = main(["fit", str(traj), "--model", str(bad), "--no-auto-start", "-o", str(out),
               "-q", "--no-plots", "--max-iterations", "1"])
    assert rc == 1
    assert "NOT CONVERGED" in capsys.readouterr().err
    res = json.loads((out / "results.json").read_text())
    assert not res["converged"]


def test_unknown_model_and_bad_hold(shots, capsys):
    _, _, traj = shots["m2_2429"]
    out = shots["base"] / "nomodel"
    assert main(["fit", str(traj), "--model", "no_such_model", "-o", str(out), "-q"]) == 1
    assert "no_such_model" in capsys.readouterr().err
    assert main(["fit", str(traj), "--model", "m2_m070", "--hold", "Cx_A9", "-o", str(out),
                 "-q"]) == 1
    assert "Cx_A9" in capsys.readouterr().err
    assert not out.exists()


def test_hold_value_in_file_units():
    """A held value is in the model file's unit (alpha_ref in degrees) and stored in radians;
    bounds of a degree parameter too; an empty side of a bound is no bound; --free frees a
    parameter the file holds (what --hold/--bound/--free give :func:`apply_holds`)."""
    from cadra.aero import resolve_model
    from cadra.fitting.inputs import apply_holds

    m = apply_holds(resolve_model("m2_m070"), hold=["alpha_ref=20.0"],
                    bound=["CD_A1=0.5:1.5", "Cm_A1=:-0.1"], free=["Cmq_A3"])
    assert m.parameter("alpha_ref").value == math.radians(20.0)
    assert not m.parameter("alpha_ref").vary
    assert (m.parameter("CD_A1").min, m.parameter("CD_A1").max) == (0.5, 1.5)
    assert (m.parameter("Cm_A1").min, m.parameter("Cm_A1").max) == (-math.inf, -0.1)
    assert not resolve_model("m2_m070").parameter("Cmq_A3").vary and m.parameter("Cmq_A3").vary


def test_apply_holds_library_function():
    """The CLI's holds are the library's: degree bounds and held values in SI, unknown names
    and malformed values refused by name."""
    from cadra.aero import resolve_model
    from cadra.fitting.inputs import apply_holds, parse_assignments, values_to_si

    base = resolve_model("m2_m070")
    m = apply_holds(base, hold=["CD_A1"], bound=["alpha_ref=15:25"])
    assert base.parameter("CD_A1").vary and not m.parameter("CD_A1").vary
    assert m.parameter("CD_A1").value == base.parameter("CD_A1").value
    assert m.parameter("alpha_ref").min == math.radians(15.0)
    assert m.parameter("alpha_ref").max == math.radians(25.0)
    assert values_to_si(base, "alpha_ref", [90.0, 0.0]) == [math.radians(90.0), 0.0]
    assert values_to_si(base, "Cnr_A1", [0.81]) == [0.81]
    assert parse_assignments([" A = 1", "B"]) == {"A": "1", "B": None}
    with pytest.raises(KeyError, match="Cx_A9"):
        apply_holds(base, hold=["Cx_A9=1"])
    with pytest.raises(ValueError, match="alpha_ref: 'ten' is not a number"):
        apply_holds(base, hold=["alpha_ref=ten"])
    with pytest.raises(ValueError, match="expected NAME=LO:HI"):
        apply_holds(base, bound=["CD_A1=0.5"])


def test_single_fits_and_quasi_linear(shots, capsys):
    """Seed 004 steps 1-2 from the CLI: one linear fit per shot (lifting body -> the
    alpha-beta template), quasi-linear table and plots."""
    trajs = [str(shots[n][2]) for n in ("m2_2429", "m2_2427")]
    out = shots["base"] / "single"
    assert main(["single", *trajs, "-o", str(out)]) == 0
    table = pd.read_csv(out / "single_fits.csv")
    assert list(table["shot_id"]) == ["M2-2429", "M2-2427"]
    assert table["converged"].all()
    # the linear pitch slope is near Table 4's local slope A1 cos(alpha) (~ -0.14)
    assert (table["Cm_a"].between(-0.2, -0.1)).all()
    assert "alpha_rms_deg" in table
    assert (out / "quasi_linear.json").is_file()
    assert any(p.name.startswith("quasi_linear_Cm_a") for p in (out / "plots").iterdir())


def test_hold_one_study_cli(shots):
    """Fig. 15 from the CLI: Cnr_A1 held at three values; chi^2 is lowest at the truth."""
    _, _, traj = shots["m2_2429"]
    out = shots["base"] / "holdone"
    assert main(["holdone", str(traj), "--model", "m2_m070", "--param", "Cnr_A1",
                 "--values", "0.2,0.81,1.6", "-o", str(out)]) == 0
    table = pd.read_csv(out / "hold_one.csv")
    assert list(table["value"]) == [0.2, 0.81, 1.6]
    assert table["chi2"].idxmin() == 1
    assert (out / "hold_one.png").is_file()


# --------------------------------------------------------------------------- calibrate


def _biased_trajectory(sim, shot_file, path, bias, rng, sp=2.5e-7):
    """A trajectory file measured through stations with position/timing biases."""
    t = sim.truth
    v = t[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()
    off = bias[:, :3] + v * bias[:, 3:4]
    n = len(t)
    table = pd.DataFrame({
        "station": t["station"].to_numpy(), "t_s": t["t_s"].to_numpy(), "status": "ok",
        "x_m": t["x_m"] + off[:, 0] + rng.normal(0, sp, n),
        "y_m": t["y_m"] + off[:, 1] + rng.normal(0, sp, n),
        "z_m": t["z_m"] + off[:, 2] + rng.normal(0, sp, n),
        "theta_deg": np.nan if sim.body.kind == "sphere" else t["theta_deg"],
        "psi_deg": np.nan if sim.body.kind == "sphere" else t["psi_deg"],
        "sigma_x_m": sp, "sigma_y_m": sp, "sigma_z_m": sp,
        "sigma_theta_deg": np.nan if sim.body.kind == "sphere" else 0.0012,
        "sigma_psi_deg": np.nan if sim.body.kind == "sphere" else 0.0012,
        "x_top_minus_side_m": 0.0, "x_consistency": 0.0, "reason": "", "warnings": ""})
    write_trajectory(path, table.loc[:, list(COLUMNS)],
                     {"shot_id": sim.spec.shot_id, "shot_file": str(shot_file.resolve())})
    return path


@pytest.fixture(scope="module")
def sphere_trajectories(shots):
    base = shots["base"]
    bias = np.zeros((16, 4))
    bias[4, 1], bias[10, 2], bias[7, 3] = 6e-4, -4e-4, 1e-6
    rng = np.random.default_rng(9)
    trajs = []
    for k in (1, 2, 3):
        sim = simulate_shot(load_shot_spec(SPECS / f"sphere_{k}.toml"))
        d = write_shot(sim, base / f"sphere_{k}", images=False, progress=False)
        trajs.append(str(_biased_trajectory(sim, d / "shot.toml",
                                            base / f"sphere_{k}.csv", bias, rng)))
    return trajs, bias


def test_calibrate_history_and_fit_with_table(shots, sphere_trajectories, capsys, monkeypatch):
    trajs, bias = sphere_trajectories
    root = shots["base"] / "facility_root"
    out = shots["base"] / "cal1"
    assert main(["calibrate", *trajs, "-o", str(out), "--stations-root", str(root)]) == 0
    text = capsys.readouterr().out
    assert "station  5: " in text and "*" in text
    table = pd.read_csv(out / "bias_table.csv", comment="#")
    row = table.set_index("station")
    assert abs(row.loc[5, "bias_y_m"] - 6e-4) < 3 * row.loc[5, "sigma_y_m"]
    assert abs(row.loc[11, "bias_z_m"] + 4e-4) < 3 * row.loc[11, "sigma_z_m"]
    assert abs(row.loc[8, "bias_time_s"] - 1e-6) < 3 * row.loc[8, "sigma_time_s"]
    hist = root / "stations" / "hffaf" / "bias_history.jsonl"
    assert len(hist.read_text().splitlines()) == 1
    for f in ("comparison.csv", "biases.png", "report.md"):
        assert (out / f).is_file()
    # a second calibration appends (never rewrites) and is compared with the first
    out2 = shots["base"] / "cal2"
    assert main(["calibrate", *trajs, "-o", str(out2), "--stations-root", str(root)]) == 0
    lines = hist.read_text().splitlines()
    assert len(lines) == 2
    assert "Comparison with the station history (1 earlier" in (out2 / "report.md").read_text()
    # a capsule shot through the same stations, fitted with the current table
    sim, shot_file, _ = shots["m2_2429"]
    traj = _biased_trajectory(sim, shot_file, shots["base"] / "capsule_biased.csv", bias,
                              np.random.default_rng(4))
    fit_out = shots["base"] / "fit_with_table"
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(fit_out), "-q",
                 "--no-plots", "--bias-table", "current", "--stations-root", str(root)]) == 0
    report = (fit_out / "report.md").read_text()
    assert "station bias table applied" in report and "bias_history.jsonl" in report
    # without --stations-root the fit reads the history where calibrate writes it by default
    # (CADRA_STATIONS_ROOT here), not ./stations of the working folder
    monkeypatch.setenv("CADRA_STATIONS_ROOT", str(root))
    monkeypatch.chdir(shots["base"])
    fit_env = shots["base"] / "fit_with_table_env"
    assert main(["fit", str(traj), "--model", "m2_m070", "-o", str(fit_env), "-q",
                 "--no-plots", "--bias-table", "current"]) == 0
    assert str(hist) in (fit_env / "report.md").read_text()


def test_calibrate_quiet_prints_one_status_line(shots, sphere_trajectories, capsys):
    """-q: one line (the history's 'recorded in', or the estimate's head without a history);
    the station rows use the one value ± sigma format otherwise (docs/cli.md)."""
    trajs, _ = sphere_trajectories
    root = shots["base"] / "quiet_root"
    assert main(["calibrate", *trajs, "-o", str(shots["base"] / "calq"), "--stations-root",
                 str(root), "-q"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1 and out.startswith("recorded in ")
    assert main(["calibrate", *trajs, "-o", str(shots["base"] / "calq2"), "--stations-root",
                 str(root), "--no-history", "-q"]) == 0
    out = capsys.readouterr().out
    assert out.count("\n") == 1 and out.startswith("hffaf: station biases from 3")
    assert main(["calibrate", *trajs, "-o", str(shots["base"] / "calq3"), "--stations-root",
                 str(root), "--no-history"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if "station  5:" in line]
    assert rows and " ± " in rows[0] and "±0" not in rows[0]


def test_calibrate_refusals(shots, sphere_trajectories, capsys):
    trajs, _ = sphere_trajectories
    root = shots["base"] / "refusal_root"
    _, _, capsule_traj = shots["m2_2429"]
    out = shots["base"] / "cal_bad"
    assert main(["calibrate", str(capsule_traj), "-o", str(out), "--stations-root",
                 str(root)]) == 1
    assert "sphere" in capsys.readouterr().err
    assert not out.exists()
    # a history from another facility
    other = root / "stations" / "hffaf"
    other.mkdir(parents=True)
    (other / "bias_history.jsonl").write_text(
        '{"format": "cadra-station-bias-1", "facility": "other_range"}\n')
    assert main(["calibrate", *trajs, "-o", str(out), "--stations-root", str(root)]) == 1
    err = capsys.readouterr().err
    assert "bias_history.jsonl" in err or "facility" in err
    assert not out.exists()
    # a corrupted history
    (other / "bias_history.jsonl").write_text("not json at all\n{}\n")
    assert main(["calibrate", *trajs, "-o", str(out), "--stations-root", str(root)]) == 1
    assert "line" in capsys.readouterr().err
    assert not out.exists()


def test_trajectory_and_shot_from_a_folder_or_a_file(shots, tmp_path):
    """Stage one's folder stands for its trajectory.csv; the shot file is the one the
    trajectory names unless given; what is missing is said."""
    import shutil

    from cadra.flight import FitDataError
    from cadra.flight.load import load_shots, trajectory_and_shot

    sim, shot_file, traj = shots["m2_2429"]
    folder = tmp_path / "cadra1"
    folder.mkdir()
    shutil.copyfile(traj, folder / "trajectory.csv")
    assert trajectory_and_shot(folder) == (folder / "trajectory.csv", shot_file.resolve())
    assert trajectory_and_shot(traj, "other.toml") == (traj, Path("other.toml"))
    with pytest.raises(FitDataError, match=r"empty: no trajectory file \(give stage one's "
                                           r"trajectory\.csv"):
        (tmp_path / "empty").mkdir()
        trajectory_and_shot(tmp_path / "empty")
    data, paths = load_shots([folder], min_sigma_angle_deg=90.0)
    assert paths == [folder / "trajectory.csv"] and data[0].shot_id == "M2-2429"
    # the angle floor arrives in radians: every measured angle's sigma is at least pi/2; the
    # roll, not measured, has no sigma at all
    assert np.all(data[0].sigma[:, 3:5] >= math.radians(90.0))
    assert np.all(np.isnan(data[0].sigma[:, 5]))
    with pytest.raises(ValueError, match="one --shot per trajectory"):
        load_shots([folder, traj], [shot_file])
