"""Stage-two output layer: files, report and plots of a real (small) fit.

One M2-2429 fit (seed 004 shot, Table 4 M2 M0.70 truth) with three free aerodynamic
parameters, started 2 % off their truth from the exact epoch state, measured with film-era
noise; the written files are checked against the FitResult itself and against independent
conversions (deg = rad * 180 / pi; the model's own parameter values).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from cadra.fitting.solver import fit
from cadra.flight.data import CHANNELS, FILM_SIGMAS, shot_data_from_truth
from cadra.report.fit import write_fit_outputs
from cadra.synthetic.simulate import load_shot_spec, simulate_shot

FREE = ("CD_A1", "Cm_A1", "Cmq_A1")
FILES = ("results.json", "coefficients.csv", "covariance.csv", "correlation.csv",
         "correlation_coloured.csv", "residuals.csv", "report.md", "plots/coefficients.png",
         "plots/angles.png", "plots/residuals.png", "plots/trajectory3d.png")


@pytest.fixture(scope="module")
def fitted():
    shot = simulate_shot(load_shot_spec("sample_shots/specs/m2_2429.toml"))
    truth = pd.read_csv("sample_shots/m2_2429/truth.csv")
    sd = shot_data_from_truth(truth, shot.rigid, shot.spec.shot_id, shot.body.kind,
                              sigma_position_m=FILM_SIGMAS["position_m"],
                              sigma_angle_rad=FILM_SIGMAS["angle_rad"],
                              rng=np.random.default_rng(2429))
    model = shot.model.with_vary({n: n in FREE for n in shot.model.names})
    start = model.with_values({n: model.parameter(n).value * 1.02 for n in FREE})
    result = fit([sd], start, [shot.states[sd.epoch_index]])
    assert result.converged, result.message
    return {"result": result, "shots": [sd], "start": start, "truth_model": shot.model,
            "bodies": {sd.shot_id: shot.body}}


@pytest.fixture(scope="module")
def written(fitted, tmp_path_factory):
    out = tmp_path_factory.mktemp("fit") / "m2_2429_fit"
    path = write_fit_outputs(fitted["result"], fitted["shots"], out,
                             start_model=fitted["start"], bodies=fitted["bodies"],
                             reference_model=fitted["truth_model"])
    assert path == out
    return out


def test_every_file_written(written):
    for name in FILES:
        assert (written / name).is_file(), name
        assert (written / name).stat().st_size > 0, name
    leftovers = [p.name for p in written.parent.iterdir() if p.name != written.name]
    assert leftovers == []


def test_results_json_equals_result(fitted, written):
    res = fitted["result"]
    data = json.loads((written / "results.json").read_text(encoding="utf-8"))
    assert data["status"] == res.status and data["converged"] is True
    assert data["chi2"] == res.chi2 and data["dof"] == res.dof
    assert data["reduced_chi2"] == res.reduced_chi2
    assert (data["n_observations"], data["n_free"], data["iterations"]) == \
        (res.n_observations, res.n_free, res.iterations)
    for n, v, s, sc, ss in zip(res.aero_names, res.aero_values, res.aero_sigma,
                               res.aero_sigma_coloured, res.aero_sigma_scaled, strict=True):
        p = data["parameters"][n]
        assert (p["value"], p["sigma"], p["sigma_coloured"], p["sigma_scaled"]) == (v, s, sc, ss)
        assert p["held"] is False
        assert p["initial"] == fitted["start"].parameter(n).value
    held = [n for n in res.model.names if n not in res.aero_names]
    for n in held:
        assert data["parameters"][n]["held"] is True
        assert data["parameters"][n]["sigma"] is None
        assert data["parameters"][n]["value"] == res.model.parameter(n).value
    (shot,) = data["shots"]
    sf = res.shots[0]
    assert shot["shot_id"] == sf.shot_id and shot["t0_s"] == sf.t0_s
    np.testing.assert_array_equal(shot["cg_state"], sf.state)
    np.testing.assert_array_equal(shot["velocity_sigma_m_s"], sf.local_sigma[3:6])
    np.testing.assert_array_equal(shot["rates_sigma_rad_s"], sf.local_sigma[9:12])
    for ch in CHANNELS:
        unit, f = ("m", 1.0) if ch in "xyz" else ("deg", 180.0 / math.pi)
        if not np.isfinite(sf.rms[ch]):          # not measured (a capsule's roll): null
            assert shot["residual_rms"][f"{ch}_{unit}"] is None
            continue
        assert shot["residual_rms"][f"{ch}_{unit}"] == pytest.approx(sf.rms[ch] * f,
                                                                       rel=1e-15)
        assert data["residual_noise_floor"][f"{ch}_{unit}"] == pytest.approx(
            res.noise_floor()[ch] * f, rel=1e-15)
    assert data["dof_by_channel"]["phi"] is None           # the roll: not measured
    assert sum(v for v in data["dof_by_channel"].values() if v is not None) == pytest.approx(
        res.dof, abs=1e-6)
    # the epoch reference point is the fitted trajectory's prediction at the epoch station
    k = fitted["shots"][0].epoch_index
    r = res.residuals[res.residuals["station"] == fitted["shots"][0].stations[k]]
    for j, ch in enumerate("xyz"):
        fit_ch = float(r.loc[r["channel"] == ch, "fitted"].iloc[0])
        assert shot["reference_point_m"][j] == pytest.approx(fit_ch, abs=1e-9)
    # and its sigma is a real propagated sigma: positive, below the measurement sigma
    assert all(0 < s < FILM_SIGMAS["position_m"] for s in shot["reference_point_sigma_m"])


def test_coefficient_table_values_are_the_models(fitted, written):
    res = fitted["result"]
    table = pd.read_csv(written / "coefficients.csv")
    model = res.model
    checked = 0
    for row in table.itertuples(index=False):
        d = row._asdict()
        for k in range(1, 10):
            name = f"{d['coefficient']}_A{k}"
            if f"A{k}" in d and name in model.names:
                assert d[f"A{k}"] == model.parameter(name).value, name
                assert bool(d[f"A{k}_held"]) == (name not in res.aero_names)
                if name in res.aero_names:
                    assert d[f"A{k}_sigma"] == res.sigma(name)
                checked += 1
    assert checked == sum(1 for n in model.names if "_A" in n)
    report = (written / "report.md").read_text(encoding="utf-8")
    assert "| coefficient | form | A1 ± σ |" in report
    assert "**Status: converged**" in report


def test_matrices_labelled(fitted, written):
    res = fitted["result"]
    for name, M in (("covariance.csv", res.covariance), ("correlation.csv", res.correlation()),
                    ("correlation_coloured.csv", res.correlation(coloured=True))):
        df = pd.read_csv(written / name, index_col="parameter")
        assert tuple(df.index) == res.param_names == tuple(df.columns)
        np.testing.assert_array_equal(df.to_numpy(), M)


def test_residuals_csv_angles_in_degrees(fitted, written):
    res = fitted["result"]
    df = pd.read_csv(written / "residuals.csv")
    assert list(df.columns) == ["shot_id", "station", "t_s", "channel", "unit", "measured",
                                "fitted", "residual", "sigma", "normalized", "leverage"]
    r = res.residuals
    assert len(df) == len(r)
    ang = df["channel"].isin(["theta", "psi"]).to_numpy()
    assert set(df.loc[ang, "unit"]) == {"deg"} and set(df.loc[~ang, "unit"]) == {"m"}
    for col in ("residual", "measured", "fitted", "sigma"):
        np.testing.assert_allclose(df.loc[ang, col], r.loc[ang, col] * 180.0 / np.pi,
                                   rtol=1e-15, atol=0)
        np.testing.assert_array_equal(df.loc[~ang, col], r.loc[~ang, col])
    # film sigma 0.1 deg in the file
    np.testing.assert_allclose(df.loc[ang, "sigma"], 0.1, rtol=1e-14)
    np.testing.assert_array_equal(df["leverage"], r["leverage"])


def test_refuses_to_overwrite(fitted, written):
    before = (written / "results.json").read_bytes()
    with pytest.raises(FileExistsError):
        write_fit_outputs(fitted["result"], fitted["shots"], written, plots=False)
    assert (written / "results.json").read_bytes() == before


def test_overwrite_replaces(fitted, tmp_path):
    out = tmp_path / "fit"
    write_fit_outputs(fitted["result"], fitted["shots"], out, plots=False, title="first")
    write_fit_outputs(fitted["result"], fitted["shots"], out, plots=False, title="second",
                      overwrite=True)
    assert json.loads((out / "results.json").read_text())["title"] == "second"
    assert not (out / "plots").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit"]


def test_no_partial_output_when_a_plot_fails(fitted, tmp_path, monkeypatch):
    from cadra.report import fit_plots as plots

    def broken(*args, **kwargs):
        raise ValueError("plot failed on purpose")

    monkeypatch.setattr(plots, "plot_coefficients", broken)
    out = tmp_path / "fit"
    with pytest.raises(ValueError, match="on purpose"):
        write_fit_outputs(fitted["result"], fitted["shots"], out)
    assert list(tmp_path.iterdir()) == []
    # an existing output being replaced stays as it was
    write_fit_outputs(fitted["result"], fitted["shots"], out, plots=False, title="kept")
    with pytest.raises(ValueError, match="on purpose"):
        write_fit_outputs(fitted["result"], fitted["shots"], out, overwrite=True)
    assert json.loads((out / "results.json").read_text())["title"] == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit"]


def _tiny_figure(*args, **kwargs):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1))
    fig.add_subplot().plot([0, 1])
    return fig


def test_3d_falls_back_to_matplotlib_without_offscreen_rendering(fitted, tmp_path,
                                                                 monkeypatch):
    from cadra.report import fit_plots as plots

    monkeypatch.setattr(plots, "offscreen_rendering", lambda: (False, "no OpenGL here"))
    with pytest.raises(plots.RenderingUnavailable, match="no OpenGL here"):
        plots.render_trajectory_3d(fitted["result"], fitted["shots"], tmp_path / "x.png")
    assert isinstance(plots.RenderingUnavailable("x"), RuntimeError)
    for name in ("plot_coefficients", "plot_angle_histories", "plot_residuals"):
        monkeypatch.setattr(plots, name, _tiny_figure)
    out = tmp_path / "fit"
    write_fit_outputs(fitted["result"], fitted["shots"], out, bodies=fitted["bodies"])
    assert (out / "plots" / "trajectory3d.png").stat().st_size > 0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "the 3-D view was drawn with matplotlib: no OpenGL here" in report


def test_body_from_kind_when_no_body_given(fitted):
    from cadra.report.fit_plots import resolve_body

    sd = fitted["shots"][0]
    body, generic = resolve_body(sd)
    assert generic and body.kind == "capsule" and body.diameter_m == sd.rigid.d_m
    body, generic = resolve_body(sd, fitted["bodies"])
    assert not generic and body is fitted["bodies"][sd.shot_id]


def test_report_tables_have_as_many_cells_as_headings(written):
    """Every markdown table of the report: each row has its header's number of cells (the
    residual table once lacked the roll column its rows carry)."""
    lines = (written / "report.md").read_text(encoding="utf-8").splitlines()
    header = None
    for line in lines:
        if not line.startswith("|"):
            header = None
            continue
        n = line.count("|")
        if header is None:
            header = n
        assert n == header, line
    assert "| φ (deg) |" in "\n".join(lines)


def test_a_finned_body_is_drawn_as_its_body_of_revolution():
    """The 3-D view's surface of a finned body (no ``arcs`` of its own) is its cone-cylinder:
    the radius d/2 along the cylinder, the length the body's."""
    from cadra.body import body_from_spec
    from cadra.report.fit_plots import body_surface

    fb = body_from_spec({"kind": "finner", "preset": "basic_finner", "d_m": 0.007})
    P = body_surface(fb)
    r = np.hypot(P[..., 1], P[..., 2])
    assert r.max() == pytest.approx(0.0035, rel=1e-9)
    assert np.ptp(P[..., 0]) == pytest.approx(fb.length_m, rel=1e-9)
