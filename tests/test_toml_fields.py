"""The shared TOML helpers (cadra.fields, cadra.io.toml_file): every error names the file and
the key path; unit-suffixed keys convert through the unit table; writes are atomic."""

import math
import os
import tomllib

import numpy as np
import pytest

from cadra.fields import Fields, frozen_array, prefixed_by, read_toml
from cadra.io.shotfile import ShotFileError, load_shot
from cadra.io.spec_file import SpecError, load_shot_spec
from cadra.io.toml_file import write_toml


class FormatError(ValueError):
    pass


F = Fields(FormatError)


def test_read_toml_errors_name_the_file(tmp_path):
    missing = tmp_path / "missing.toml"
    with pytest.raises(FormatError, match=rf"^{missing}: cannot read \(No such file"):
        read_toml(missing, FormatError)
    with pytest.raises(FileNotFoundError, match=rf"^{missing}: cannot read"):
        read_toml(missing, FormatError, read_error=FileNotFoundError)
    broken = tmp_path / "broken.toml"
    broken.write_text("a = 1\nb = \n")
    with pytest.raises(FormatError, match=rf"^{broken}: not valid TOML \(.*line 2"):
        read_toml(broken, FormatError)
    good = tmp_path / "good.toml"
    good.write_text('a = 1\n[t]\nx_cm = 2.5\n')
    assert read_toml(good) == {"a": 1, "t": {"x_cm": 2.5}}


@pytest.mark.parametrize("call, message", [
    (lambda: F.require({"a": 1}, "mass_g", "mass."), "mass.mass_g: missing"),
    (lambda: F.table({"range": 3}, "range"), "range: expected a table, got int"),
    (lambda: F.table({}, "range"), "range: missing"),
    (lambda: F.number("1.0", "range.temperature_k"),
     "range.temperature_k: expected a number, got '1.0'"),
    (lambda: F.number(True, "x"), "x: expected a number, got True"),
    (lambda: F.number(math.inf, "x_m"), "x_m: must be finite, got inf"),
    (lambda: F.positive(0.0, "mass.mass_g"), "mass.mass_g: must be positive, got 0.0"),
    (lambda: F.positive(2.0, "scale_m_per_px", 1e-2),
     "scale_m_per_px: 2.0 is implausibly large (> 0.01; check the unit)"),
    (lambda: F.in_range(76000.0, "range.pressure_torr", 0.01, 7600.0, "a range pressure"),
     "range.pressure_torr: 76000.0 is outside (0.01, 7600] -- not a range pressure "
     "(check the unit)"),
    (lambda: F.integer(2.0, "stations[1].id", 1, 10), "stations[1].id: expected an integer"),
    (lambda: F.integer(0, "stations[1].id", 1, 10), "stations[1].id: 0 outside [1, 10]"),
    (lambda: F.vector([1.0, 2.0], 3, "wires[1].p0_m"),
     "wires[1].p0_m: expected 3 numbers, got [1.0, 2.0]"),
    (lambda: F.vector([1.0, "b", 3.0], 3, "cg_cm"), "cg_cm[1]: expected a number, got 'b'"),
    (lambda: F.check_unknown({"mass_g": 1, "mas_kg": 2, "zz": 3}, {"mass_g"}, "mass."),
     "mass.mas_kg: unknown key (known: ['mass_g'])"),
    (lambda: F.string("", "shot_id", empty=False, what="a shot id"),
     "shot_id: expected a shot id, got ''"),
])
def test_getters_name_the_key(call, message):
    with pytest.raises(FormatError) as exc:
        call()
    assert str(exc.value).startswith(message)


def test_getters_return_typed_values():
    assert F.number(3, "n") == 3.0 and isinstance(F.number(3, "n"), float)
    assert F.integer(np.int64(7), "n", 1, 10) == 7
    assert F.table({}, "view_defaults", required=False) == {}
    np.testing.assert_array_equal(F.vector((1, 2.5, -3), 3, "v"), [1.0, 2.5, -3.0])
    assert F.in_range(340.1, "p", 0.01, 7600.0, "a pressure") == 340.1


def test_unit_suffixed_keys_through_the_table():
    # 35.56 mm = 3.556 cm = 0.03556 m (the M2 diameter of seed 004 Table 2)
    value, key = F.unit_value({"d_mm": 35.56}, "d", "length", "model.")
    assert key == "d_mm" and value == pytest.approx(0.03556, rel=1e-15)
    value, key = F.unit_value({"half_angle_deg": 10.0}, "half_angle", "angle")
    assert key == "half_angle_deg" and value == math.radians(10.0)
    assert F.unit_value({}, "h", "length", default_unit="cm") == (None, "h_cm")
    with pytest.raises(FormatError, match=r"^model\.d_mm: 'd' is given twice \(d_cm, d_mm\)"):
        F.unit_value({"d_cm": 3.556, "d_mm": 35.56}, "d", "length", "model.")
    with pytest.raises(FormatError, match=r"^model\.d_cm: expected a number"):
        F.unit_value({"d_cm": "3.5"}, "d", "length", "model.")


def test_prefixed_by_puts_the_file_before_the_key_path(tmp_path):
    with pytest.raises(FormatError, match=r"^shot\.toml: mass\.mass_g: missing$"):
        with prefixed_by("shot.toml", FormatError):
            F.require({}, "mass_g", "mass.")
    with pytest.raises(KeyError):  # other errors pass unchanged
        with prefixed_by("shot.toml", FormatError):
            raise KeyError("x")


def test_formats_name_file_and_key(tmp_path):
    """The file formats read through the helpers: the message is '<file>: <key path>: ...'."""
    shot = tmp_path / "shot.toml"
    shot.write_text('schema_version = 1\nshot_id = "S"\nfacility = "hffaf"\n'
                    'model = { kind = "sphere", d_cm = 2.0 }\n'
                    "[mass]\nmass_g = 30.0\ncg_from_reference_cm = [0.0, 0.0, 0.0]\n"
                    "inertia_g_cm2 = [[12.0, 0.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 12.0]]\n"
                    "[range]\npressure_torr = 76000.0\ntemperature_k = 294.0\n"
                    "[[stations]]\nstation = 1\ntime_s = 0.0\n")
    with pytest.raises(ShotFileError, match=rf"^{shot}: range\.pressure_torr: 76000\.0 is "
                                            r"outside \(0\.01, 7600\]"):
        load_shot(shot)
    spec = tmp_path / "spec.toml"
    spec.write_text('aero_model = "sphere"\nmodel = { kind = "sphere", d_cm = 2.0 }\n'
                    "[mass]\nmass_g = 30.0\nx_cg_from_ref_cm = 0.0\n"
                    "inertia_g_cm2 = [12.0, 12.0, 12.0]\ny_cg_mm = 1.0\n")
    with pytest.raises(SpecError, match=rf"^{spec}: mass\.y_cg_mm: unknown key"):
        load_shot_spec(spec)


def test_write_toml_is_atomic_and_refuses_to_overwrite(tmp_path):
    path = tmp_path / "out" / "m.toml"
    data = {"name": "m", "t": {"x_cm": 2.5, "v": [1, 2]}}
    write_toml(path, data, header="a header\nsecond line")
    text = path.read_text()
    assert text.startswith("# a header\n# second line\n")
    assert tomllib.loads(text) == data
    with pytest.raises(FileExistsError, match="overwrite=True"):
        write_toml(path, {"name": "other"})
    assert tomllib.loads(path.read_text()) == data
    write_toml(path, {"name": "other"}, overwrite=True)
    assert tomllib.loads(path.read_text()) == {"name": "other"}
    assert os.listdir(path.parent) == ["m.toml"]  # no temporary file left behind


def test_frozen_array():
    a = frozen_array([[1, 2, 3]], 3)
    assert a.dtype == np.float64 and a.shape == (3,)
    with pytest.raises(ValueError):
        a[0] = 5.0
