"""Aerodynamic models (cadra.aero.model): the bundled seed-004 Table 4 models against the same
forms written out by hand in numpy (an independent transcription of seed 004 Table 4, with the
OCR decisions of docs/aero_models.md), complex-step derivatives against analytic ones, and the
TOML file format (round trip, refusals, validation messages)."""

import math
import os
import pickle

import numpy as np
import pytest

from cadra.aero import (
    COEFFICIENTS,
    AeroModel,
    ExpressionError,
    Parameter,
    bundled_model_names,
    load_bundled_model,
    load_model,
    model_from_dict,
    save_model,
)

RNG = np.random.default_rng(4004)
D = np.radians

# --- seed 004 Table 4, by hand ---------------------------------------------------------------
# Each function returns the 9 coefficients (COEFFICIENTS order) at arrays a (alpha), b (beta),
# s (sigma), M (Mach). Numbers copied from seed 004 Table 4 (OCR text lines ~355-381); M_ref
# is the case's nominal Mach; blank cells are 0.


def m1_m110(a, b, s, M):
    dM, S = M - 1.10, np.sin(s)
    CD = (1.361 + 0.516 * dM - 2.784 * dM**2 + (-0.723 - 0.467 * dM) * S**2 - 0.191 * S**4)
    CL = (-1.470 - 0.082 * dM + 2.170 * dM**2 + 0.461 * S**2 + 0.07 * S**4) * S
    Cm = (-0.1170 + 0.0 * dM - 0.0176 * S**2 + 0.0402 * S**4) * S
    Cmq = np.maximum(-0.967, 3.65 - 174.24 * S**2)
    z = 0 * S
    return CD, CL, z, z, Cm, z, z, Cmq, z


def m1_m125(a, b, s, M):
    dM, S = M - 1.25, np.sin(s)
    CD = (1.406 + 0.226 * dM - 1.252 * dM**2 + (-0.392 + 0.105 * dM) * S**2 - 0.968 * S**4)
    CL = (-1.328 - 0.740 * dM + 1.111 * S**2) * S
    Cm = (-0.1151 + 0.0010 * dM + 0.0262 * S**2 + 0.0096 * S**4) * S
    Cmq = np.maximum(-0.604, 2.400 - 174.24 * S**2)
    z = 0 * S
    return CD, CL, z, z, Cm, z, z, Cmq, z


def m2_m070(a, b, s, M):
    dM, x, cb = M - 0.70, np.sin(a) - np.sin(D(21.21)), np.cos(b)
    CD = 0.953 + 0.276 * dM + (-0.531 + 1.357 * dM) * x * cb - 0.774 * x**2 * cb**2
    CL = -0.896 * np.sin(a) * cb
    below = 0.0095 + 0.0150 * dM - 0.1532 * x
    Cm = np.where(a < D(21.21), below, below + 0.0614 * x**2)
    Cmq = np.maximum(-1.553, 3.700 - 6895 * x**2)
    z = 0 * x
    return (CD, CL, -0.486 * np.sin(b), z, Cm, -0.1316 * np.sin(b), z, Cmq, 0.810 + z)


def m2_m093(a, b, s, M):
    dM, x, cb = M - 0.93, np.sin(a) - np.sin(D(25.87)), np.cos(b)
    CD = 0.981 + 1.006 * dM + 36.930 * dM**2 - 0.950 * x * cb - 1.448 * x**2 * cb**2
    CL = -1.020 * np.sin(a) * cb
    below = -0.0007 + 0.1346 * dM + (-0.1283 + 0.2040 * dM) * x
    above = below + 0.7275 * (0.0079 - 0.9495 * x + 2.2388 * x**2) * x
    Cm = np.where(a < D(25.87), below, above)
    Cmq = -1.390 + 7.140 * x**2
    z = 0 * x
    return (CD, CL, -0.291 * np.sin(b), z, Cm, -0.1507 * np.sin(b), z, Cmq, 0.590 + z)


def m3_m120(a, b, s, M):
    dM, x, cb = M - 1.20, np.sin(a) - np.sin(D(33.99)), np.cos(b)
    CD = 1.233 + 0.127 * dM - 0.777 * x * cb
    CL = -1.073 * np.sin(a) * cb
    below = 0.0124 - 0.1373 * x + 0.9563 * (0.0252 - 0.044 * dM) * dM
    above = below + 0.8463 * ((-0.1093 + 0.2665 * dM) + (0.61 + 0.90 * dM) * x) * x
    Cm = np.where(a < D(33.99), below, above)
    Cmq = -2.390 + 0 * x
    z = 0 * x
    return (CD, CL, z, z, Cm, z, z, Cmq, z)


TABLE4 = {"m1_m110": (m1_m110, 1.10, 0.0), "m1_m125": (m1_m125, 1.25, 0.0),
          "m2_m070": (m2_m070, 0.70, 21.21), "m2_m093": (m2_m093, 0.93, 25.87),
          "m3_m120": (m3_m120, 1.20, 33.99)}


def sample_points(mach_nom, alpha_ref_deg, n=40):
    """(alpha, beta, sigma, M): both sides of alpha_ref, small and large angles, Mach +-0.06."""
    a = D(alpha_ref_deg + np.concatenate([RNG.uniform(-25, 25, n - 4), [-3, -0.5, 0.5, 3]]))
    b = D(RNG.uniform(-8, 8, n))
    s = np.arccos(np.cos(a) * np.cos(b))
    if alpha_ref_deg == 0.0:  # total-angle models: sigma over 0-60 deg, incl. the Cmq peak
        s = D(np.concatenate([RNG.uniform(0, 60, n - 4), [0.0, 2.0, 8.0, 12.0]]))
    M = mach_nom + RNG.uniform(-0.06, 0.06, n)
    return a, b, s, M


@pytest.mark.parametrize("name", sorted(TABLE4))
def test_table4_models_match_hand_transcription(name):
    fn, mach_nom, aref = TABLE4[name]
    model = load_bundled_model(name)
    a, b, s, M = sample_points(mach_nom, aref)
    got = model.evaluate(a, b, s, M)
    want = fn(a, b, s, M)
    for k, c in enumerate(COEFFICIENTS):
        np.testing.assert_allclose(got[c], np.broadcast_to(want[k], a.shape), rtol=1e-12,
                                   atol=1e-14, err_msg=f"{name} {c}")
    # float64 and complex128 agree (zero imaginary step)
    gotc = model.evaluate(a.astype(complex), b, s, M)
    for c in COEFFICIENTS:
        np.testing.assert_allclose(gotc[c].real, got[c], rtol=1e-14, atol=1e-16)
        assert np.all(gotc[c].imag == 0)


@pytest.mark.parametrize("name", ["m2_m070", "m2_m093", "m3_m120"])
def test_one_sided_cm_is_continuous_at_alpha_ref(name):
    model = load_bundled_model(name)
    aref = model.parameter("alpha_ref").value
    eps = 1e-9
    lo = model.evaluate(aref - eps, 0.0, None, 0.9)["Cm"]
    hi = model.evaluate(aref + eps, 0.0, None, 0.9)["Cm"]
    assert hi == pytest.approx(lo, abs=1e-9)


def test_complex_step_dcm_dalpha_equals_analytic_m2_m070():
    model = load_bundled_model("m2_m070")
    aref, h = D(21.21), 1e-30
    a = D(np.array([5.0, 15.0, 21.0, 21.5, 30.0, 45.0]))
    b = D(np.array([0.0, 2.0, -3.0, 1.0, 5.0, -1.0]))
    M = np.array([0.62, 0.7, 0.75, 0.68, 0.71, 0.66])
    g = model.evaluate(a + 1j * h, b, np.arccos(np.cos(a) * np.cos(b)), M)["Cm"].imag / h
    x = np.sin(a) - np.sin(aref)
    want = np.cos(a) * (-0.1532 + np.where(a > aref, 2 * 0.0614 * x, 0.0))
    np.testing.assert_allclose(g, want, rtol=1e-13)
    # and with respect to a parameter: dCm/dCm_A1 = sin a - sin a_ref
    p = model.values().astype(complex)
    p[model.index("Cm_A1")] += 1j * h
    g = model.evaluate(a, b, None, M, params=p)["Cm"].imag / h
    np.testing.assert_allclose(g, x, rtol=1e-14)
    # dCmq/dalpha: 0 on the plateau, 2 A3 x cos a on the peak
    g = model.evaluate(a + 1j * h, b, None, M)["Cmq"].imag / h
    peak = 3.700 - 6895 * x**2 > -1.553
    np.testing.assert_allclose(g, np.where(peak, 2 * -6895 * x * np.cos(a), 0.0), rtol=1e-12)


def test_complex_step_dcm_dsigma_equals_analytic_m1_m110():
    model = load_bundled_model("m1_m110")
    s = D(np.array([0.5, 5.0, 20.0, 40.0, 70.0]))
    M = np.array([1.06, 1.10, 1.13, 1.08, 1.11])
    h = 1e-30
    g = model.evaluate(0.0, 0.0, s + 1j * h, M)["Cm"].imag / h
    S = np.sin(s)
    want = np.cos(s) * (-0.1170 + 3 * -0.0176 * S**2 + 5 * 0.0402 * S**4)
    np.testing.assert_allclose(g, want, rtol=1e-13)


def test_vectorised_evaluate_shapes_and_scalar():
    model = load_bundled_model("m2_m070")
    a = D(np.linspace(0, 40, 12)).reshape(3, 4)
    r = model.evaluate(a, 0.0, None, 0.7)
    assert set(r) == set(COEFFICIENTS) and r["Cm"].shape == (3, 4)
    r0 = model.evaluate(a[1, 2], 0.0, None, 0.7)
    assert np.ndim(r0["CD"]) == 0
    assert r0["CD"] == r["CD"][1, 2]
    with pytest.raises(ValueError, match="params must have shape"):
        model.evaluate(0.1, 0.0, None, 0.7, params=[1.0, 2.0])


# --- parameters and model validation ---------------------------------------------------------


def small_model(**kw):
    args = dict(
        name="t", angle_plane="alpha_beta",
        coefficients={"Cm": "Cm_a*(sin(alpha) - sin(alpha_ref))", "CD": "CD_0"},
        parameters=(Parameter("alpha_ref", D(20.0), vary=False, unit="deg", min=0.0,
                              max=D(90.0)),
                    Parameter("Cm_a", -0.15), Parameter("CD_0", 1.0, min=0.0)))
    args.update(kw)
    return AeroModel(**args)


def test_parameter_validation_names_the_key():
    with pytest.raises(ValueError, match=r"parameters\.Cm_a: min \(2\) > max \(1\)"):
        Parameter("Cm_a", 1.5, min=2.0, max=1.0)
    with pytest.raises(ValueError, match=r"parameters\.Cm_a: value 3 outside its bounds"):
        Parameter("Cm_a", 3.0, min=0.0, max=1.0)
    with pytest.raises(ValueError, match=r"parameters\.sin: reserved"):
        Parameter("sin", 1.0)
    with pytest.raises(ValueError, match=r"parameters\.'2x'"):
        Parameter("2x", 1.0)
    with pytest.raises(ValueError, match=r"parameters\.A: unit"):
        Parameter("A", 1.0, unit="rad")
    with pytest.raises(ValueError, match=r"parameters\.A: value must be finite"):
        Parameter("A", math.inf)
    with pytest.raises(ValueError, match=r"parameters\.A: vary must be"):
        Parameter("A", 1.0, vary="yes")


def test_model_validation_names_the_key():
    with pytest.raises(ExpressionError, match=r"coefficients\.Cm: undeclared name 'Cm_b'"):
        small_model(coefficients={"Cm": "Cm_a*alpha + Cm_b", "CD": "CD_0 + 0*alpha_ref"})
    with pytest.raises(ValueError, match=r"parameters\.CD_0: declared but not used"):
        small_model(coefficients={"Cm": "Cm_a*(sin(alpha) - sin(alpha_ref))"})
    with pytest.raises(ValueError, match=r"coefficients\.Cx: unknown coefficient"):
        small_model(coefficients={"Cx": "CD_0", "Cm": "Cm_a*alpha_ref"})
    with pytest.raises(ValueError, match=r"parameters\.Cm_a: declared twice"):
        small_model(parameters=(Parameter("Cm_a", 1.0), Parameter("Cm_a", 2.0)),
                    coefficients={"Cm": "Cm_a"})
    with pytest.raises(ValueError, match=r"angle_plane"):
        small_model(angle_plane="pitch")
    with pytest.raises(ValueError, match=r"coefficients\.Cnr: not used by total-angle"):
        AeroModel(name="s", angle_plane="sigma", coefficients={"Cnr": "A"},
                  parameters=(Parameter("A", 1.0),))


def test_with_values_vary_bounds_and_shared_program():
    m = small_model()
    assert m.names == ("alpha_ref", "Cm_a", "CD_0")
    assert m.free_names() == ("Cm_a", "CD_0")
    np.testing.assert_array_equal(m.free_indices(), [1, 2])
    m2 = m.with_values({"Cm_a": -0.2}).with_vary({"alpha_ref": True})
    assert m2.parameter("Cm_a").value == -0.2 and m2.free_names() == m.names
    assert m.parameter("Cm_a").value == -0.15  # frozen: the original is unchanged
    assert m2.compile() is m.compile()  # same structure, same compiled program
    np.testing.assert_array_equal(m.with_free_values([-0.3, 2.0]).values(),
                                  [D(20.0), -0.3, 2.0])
    with pytest.raises(ValueError, match=r"parameters\.CD_0: value -1 outside"):
        m.with_values({"CD_0": -1.0})
    with pytest.raises(ValueError, match=r"parameters\.CD_0: min"):
        m.with_bounds({"CD_0": (2.0, 1.0)})
    with pytest.raises(KeyError, match="no parameter 'Cx'"):
        m.with_values({"Cx": 1.0})
    assert m.parameters_in("Cm") == ("alpha_ref", "Cm_a")
    assert m.parameters_in("Cl") == ()
    r = m.evaluate(D(25.0), 0.0, None, 0.7)
    assert r["Cm"] == pytest.approx(-0.15 * (np.sin(D(25.0)) - np.sin(D(20.0))), rel=1e-15)
    assert r["CD"] == 1.0 and r["Cl"] == 0.0
    again = pickle.loads(pickle.dumps(m2))
    assert again == m2 and again.compile().ops.tolist() == m2.compile().ops.tolist()


# --- files -------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", bundled_model_names())
def test_bundled_models_round_trip(name, tmp_path):
    model = load_bundled_model(name)
    path = save_model(model, tmp_path / f"{name}.toml")
    again = load_model(path)
    assert again == model
    np.testing.assert_array_equal(again.values(), model.values())  # bit-identical (deg too)
    assert again.compile().ops.tolist() == model.compile().ops.tolist()
    assert [p.name for p in tmp_path.iterdir()] == [f"{name}.toml"]  # no temp files left


def test_bundled_models_are_the_expected_set():
    names = set(bundled_model_names())
    assert {"m1_m110", "m1_m125", "m2_m070", "m2_m093", "m3_m120", "sphere", "cone_linear",
            "linear_template_sigma", "linear_template_alpha_beta"} <= names
    for n in ("m1_m110", "m1_m125", "sphere", "cone_linear", "linear_template_sigma"):
        assert load_bundled_model(n).angle_plane == "sigma"
    for n in ("m2_m070", "m2_m093", "m3_m120", "linear_template_alpha_beta"):
        m = load_bundled_model(n)
        assert m.angle_plane == "alpha_beta" and m.compile().moment_reference == "cg"
    # deg in the file, radians inside; shared constants held
    m = load_bundled_model("m2_m070")
    ar = m.parameter("alpha_ref")
    assert ar.unit == "deg" and ar.value == pytest.approx(D(21.21), rel=1e-15)
    assert not ar.vary and not m.parameter("M_ref").vary
    assert not m.parameter("Cmq_A3").vary and m.parameter("Cmq_A3").value == -6895


def test_save_refuses_to_overwrite_unless_asked(tmp_path):
    m = small_model()
    path = tmp_path / "m.toml"
    save_model(m, path)
    with pytest.raises(FileExistsError, match="overwrite=True"):
        save_model(m.with_values({"Cm_a": -0.5}), path)
    assert load_model(path) == m
    save_model(m.with_values({"Cm_a": -0.5}), path, overwrite=True)
    assert load_model(path).parameter("Cm_a").value == -0.5
    assert sorted(os.listdir(tmp_path)) == ["m.toml"]


def test_degree_values_round_trip(tmp_path):
    # values that came from degrees (files, users) come back bit-identical; an arbitrary
    # radian value may have no float64 degree value that converts back to it exactly: it comes
    # back within 1 ulp
    from_deg = [math.radians(d) for d in np.round(RNG.uniform(0, 90, 200), 4)]
    arbitrary = list(RNG.uniform(0, 1.5, 200))
    for vals, exact in ((from_deg, True), (arbitrary, False)):
        params = tuple(Parameter(f"a{i}", float(v), unit="deg") for i, v in enumerate(vals))
        m = AeroModel(name="deg", angle_plane="sigma",
                      coefficients={"CD": " + ".join(p.name for p in params)},
                      parameters=params)
        again = load_model(save_model(m, tmp_path / "deg.toml", overwrite=True))
        if exact:
            np.testing.assert_array_equal(again.values(), vals)
        else:
            np.testing.assert_array_max_ulp(again.values(), np.array(vals), maxulp=1)


FILE = """
name = "bad"
angle_plane = "alpha_beta"
[coefficients]
Cm = "Cm_a*(sin(alpha) - sin(alpha_ref))"
[parameters]
alpha_ref = { value = 20.0, unit = "deg", vary = false }
Cm_a = { value = -0.15 }
"""


@pytest.mark.parametrize("edit, pattern", [
    (("Cm_a = { value = -0.15 }", "Cm_a = { value = -0.15, min = 1.0, max = 0.0 }"),
     r"bad\.toml: parameters\.Cm_a: min \(1\) > max \(0\)"),
    (("Cm_a = { value = -0.15 }", "Cm_a = { value = -0.15, min = 0.0 }"),
     r"bad\.toml: parameters\.Cm_a: value -0\.15 outside its bounds"),
    (("Cm_a = { value = -0.15 }", "Cm_a = { value = -0.15, fixed = true }"),
     r"bad\.toml: parameters\.Cm_a\.fixed: unknown key"),
    (("Cm_a = { value = -0.15 }", "Cm_a = { vary = true }"),
     r"bad\.toml: parameters\.Cm_a\.value: missing"),
    (("Cm_a = { value = -0.15 }", "Cm_a = { value = \"x\" }"),
     r"bad\.toml: parameters\.Cm_a\.value: must be a number"),
    (("Cm_a = { value = -0.15 }", "Cm_a = -0.15"),
     r"bad\.toml: parameters\.Cm_a: must be a table"),
    (("vary = false }", "vary = 0 }"), r"parameters\.alpha_ref\.vary: must be true or false"),
    (("unit = \"deg\"", "unit = \"grad\""), r"parameters\.alpha_ref\.unit: must be one of"),
    (("angle_plane", "planes = 1\nangle_plane"), r"bad\.toml: planes: unknown key"),
    (("Cm = \"Cm_a*", "Cm = \"Cm_b*"),
     r"bad\.toml: coefficients\.Cm: undeclared name 'Cm_b'"),
    (("Cm = \"Cm_a*", "Cm = \"os.system(1)*"),
     r"bad\.toml: coefficients\.Cm: attribute access"),
    (("alpha_ref = {", "Cn_b = { value = 1.0 }\nalpha_ref = {"),
     r"bad\.toml: parameters\.Cn_b: declared but not used"),
    (("name = \"bad\"", "name = \"bad\"\nformat = \"other/2\""), r"format:"),
])
def test_file_validation_names_the_key(tmp_path, edit, pattern):
    old, new = edit
    assert old in FILE
    path = tmp_path / "bad.toml"
    path.write_text(FILE.replace(old, new, 1))
    with pytest.raises(ValueError, match=pattern):
        load_model(path)


def test_file_units_and_model_from_dict(tmp_path):
    path = tmp_path / "ok.toml"
    path.write_text(FILE)
    m = load_model(path)
    assert m.parameter("alpha_ref").value == pytest.approx(D(20.0), rel=1e-15)
    assert m.parameter("alpha_ref").file_value == pytest.approx(20.0, rel=1e-15)
    d = m.to_dict()
    assert d["parameters"]["alpha_ref"] == {"value": 20.0, "vary": False, "unit": "deg"}
    assert model_from_dict(d, "x") == m
    with pytest.raises(ValueError, match="not valid TOML"):
        (tmp_path / "broken.toml").write_text("name = ")
        load_model(tmp_path / "broken.toml")


# --- one resolver of model names ---------------------------------------------------------------


def test_bundled_name_resolves_to_the_bundled_file():
    from cadra.aero import MODELS_DIR, resolve_model, resolve_model_path

    assert resolve_model_path("m2_m070") == MODELS_DIR / "m2_m070.toml"
    model = resolve_model("m2_m070")
    assert model == load_model(MODELS_DIR / "m2_m070.toml") == load_bundled_model("m2_m070")
    assert model.parameter("alpha_ref").value == math.radians(21.21)  # Table 4, printed


def test_a_path_is_a_path_never_the_bundled_model_of_its_stem(tmp_path, monkeypatch):
    """A name with a directory part or a suffix is a file path; if the file is not there the
    bundled model of the same stem must not be loaded silently."""
    from cadra.aero import ModelNotFoundError, is_model_path, resolve_model

    monkeypatch.chdir(tmp_path)
    for name in ("no_such_dir/m2_m070.toml", "no_such_dir/m2_m070", "m2_m070.toml",
                 "./m2_m070", tmp_path / "m2_m070"):
        assert is_model_path(name)
        with pytest.raises(ModelNotFoundError) as exc:
            resolve_model(name)
        msg = str(exc.value)
        assert msg.startswith(f"aero model file '{name}' not found (looked at ")
        assert "the bundled model 'm2_m070' is named without a directory or suffix" in msg
        assert isinstance(exc.value, KeyError) and isinstance(exc.value, ValueError)
    assert not is_model_path("m2_m070")
    with pytest.raises(ModelNotFoundError,
                       match=r"^no bundled aero model 'm2_m07' \(bundled: "
                             r"basic_finner, cone_linear, linear_template_alpha_beta"):
        resolve_model("m2_m07")
    with pytest.raises(KeyError, match="is a path, not a bundled model name"):
        load_bundled_model("models/m2_m070")


def test_a_local_file_with_a_bundled_stem_is_that_file(tmp_path, monkeypatch):
    from cadra.aero import resolve_model

    local = load_bundled_model("m2_m070").with_values({"Cnr_A1": 0.5})
    (tmp_path / "models").mkdir()
    save_model(local, tmp_path / "models" / "m2_m070.toml")
    monkeypatch.chdir(tmp_path)
    assert resolve_model("models/m2_m070.toml").parameter("Cnr_A1").value == 0.5
    assert resolve_model("m2_m070").parameter("Cnr_A1").value == 0.810   # the bundled one
    # relative paths are tried against base_dir first (a spec's folder), then the cwd
    other = tmp_path / "spec_dir"
    (other / "models").mkdir(parents=True)
    save_model(local.with_values({"Cnr_A1": 0.25}), other / "models" / "m2_m070.toml")
    assert resolve_model("models/m2_m070.toml", base_dir=other).parameter("Cnr_A1").value \
        == 0.25
    assert resolve_model("models/m2_m070.toml", base_dir=tmp_path / "nowhere"
                         ).parameter("Cnr_A1").value == 0.5


def test_parameter_to_si_uses_the_file_unit():
    p = Parameter("alpha_ref", math.radians(20.0), unit="deg")
    assert p.to_si(21.21) == math.radians(21.21)
    assert Parameter("Cm_A1", -0.15).to_si(-0.1532) == -0.1532
