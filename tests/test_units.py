"""The unit table (cadra.units): values against the units'
definitions, round trips, and the key-suffix rule."""

import math

import numpy as np
import pytest

from cadra import units

RNG = np.random.default_rng(20261124)


def test_definitions():
    # 1 atm = 760 torr = 101325 Pa exactly (the torr's definition)
    assert units.to_si(760.0, "torr") == 101325.0
    assert units.torr_to_pa(760.0) == 101325.0
    # 1 inch = 2.54 cm = 25.4 mm = 0.0254 m (international inch)
    assert units.to_si(2.54, "cm") == pytest.approx(0.0254, rel=1e-16)
    assert units.to_si(25.4, "mm") == pytest.approx(0.0254, rel=1e-16)
    assert units.from_si(0.0254, "mm") == pytest.approx(25.4, rel=1e-16)
    # 1 g cm^2 = 1e-3 kg * 1e-4 m^2
    assert units.to_si(1.0, "g_cm2") == 1e-7
    assert units.g_to_kg(101.02) == pytest.approx(0.10102, rel=1e-16)
    assert units.us_to_s(1.0) == 1e-6
    assert units.to_si(180.0, "deg") == math.pi
    assert units.to_si(360.0, "deg_s") == 2.0 * math.pi


def test_degrees_agree_bit_for_bit_with_the_standard_library():
    """Degree values written by save_model rely on this (docs/aero_models.md)."""
    x = RNG.uniform(-720.0, 720.0, 2000)
    np.testing.assert_array_equal(units.deg_to_rad(x), np.radians(x))
    np.testing.assert_array_equal(units.rad_to_deg(x), np.degrees(x))
    for v in x[:200]:
        assert units.to_si(float(v), "deg") == math.radians(v)
        assert units.from_si(float(v), "deg") == math.degrees(v)


@pytest.mark.parametrize("name", sorted(units.UNITS))
def test_round_trip_every_unit(name):
    x = RNG.uniform(-1e3, 1e3, 500)
    back = units.from_si(units.to_si(x, name), name)
    np.testing.assert_array_max_ulp(back, x, maxulp=2)
    u = units.UNITS[name]
    si = [v for v in units.units_of(u.quantity).values() if v.si_per_unit == 1.0]
    assert len(si) == 1, f"{u.quantity} has no single SI unit"


def test_named_functions_are_the_table():
    x = RNG.uniform(0.0, 100.0, 50)
    for f, name, direction in ((units.cm_to_m, "cm", "to"), (units.m_to_cm, "cm", "from"),
                               (units.pa_to_torr, "torr", "from"),
                               (units.kg_m2_to_g_cm2, "g_cm2", "from"),
                               (units.s_to_us, "us", "from")):
        table = units.to_si if direction == "to" else units.from_si
        np.testing.assert_array_equal(f(x), table(x, name))


def test_split_unit_key():
    assert units.split_unit_key("d_cm") == ("d", "cm")
    assert units.split_unit_key("nose_radius_mm") == ("nose_radius", "mm")
    assert units.split_unit_key("q_deg_s") == ("q", "deg_s")      # the longest suffix
    assert units.split_unit_key("speed_m_s") == ("speed", "m_s")
    assert units.split_unit_key("half_angle_deg", "angle") == ("half_angle", "deg")
    assert units.split_unit_key("half_angle_deg", "length") is None
    assert units.split_unit_key("preset") is None
    assert units.split_unit_key("_m") is None                      # a suffix needs a base
    with pytest.raises(KeyError, match="unknown unit 'furlong'"):
        units.to_si(1.0, "furlong")


def test_aero_parameter_units_are_the_tables():
    from cadra.aero.model import UNITS as AERO_UNITS

    assert AERO_UNITS == {"": 1.0, "deg": math.pi / 180.0}
    assert all(AERO_UNITS[k] == units.UNITS[k].si_per_unit for k in AERO_UNITS)
