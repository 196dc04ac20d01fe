"""Units: the one table through which every non-SI unit meets SI.

Every file key carries its unit in its name (``pressure_torr``, ``mass_g``, ``d_cm``); readers
convert through the one table :data:`UNITS` (``to_si(x, "torr")``, ``from_si(x, "cm")``,
``split_unit_key("d_cm") -> ("d", "cm")``) and the library works in SI only
(docs/conventions.md, "Units"). The named functions (``torr_to_pa``, ``cm_to_m`` ...) are that
table's entries under readable names. All accept floats or numpy arrays and return the same kind.

This module imports nothing of CADRA, so the numerical core (body specs, aero-model parameter
units) and the file formats of :mod:`cadra.io`
convert through the same table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Pascals per torr (1 torr = 101325/760 Pa exactly).
PA_PER_TORR = 101325.0 / 760.0  # 133.32236842...
M_PER_CM = 1e-2
M_PER_MM = 1e-3
M_PER_IN = 0.0254  # the international inch, exactly
KG_PER_G = 1e-3
KG_M2_PER_G_CM2 = 1e-7  # 1 g cm^2 = 1e-3 kg * 1e-4 m^2
S_PER_US = 1e-6


@dataclass(frozen=True)
class Unit:
    """A file unit: its quantity and its SI value.

    ``to_si(x) = x * si_per_unit``; ``from_si(x) = x / si_per_unit``, or ``x * unit_per_si``
    when that is given (degrees: ``x * (180 / pi)``, numpy's and the math module's
    ``degrees``, bit for bit).
    """

    name: str
    quantity: str
    si_per_unit: float
    unit_per_si: float | None = None

    def to_si(self, x):
        return x * self.si_per_unit

    def from_si(self, x):
        return x * self.unit_per_si if self.unit_per_si is not None else x / self.si_per_unit


def _table(*units: Unit) -> dict[str, Unit]:
    return {u.name: u for u in units}


#: Every unit a file key may carry, by its key suffix (``"d_cm"`` -> ``UNITS["cm"]``); ``""``
#: is a dimensionless number (an aero model parameter without a unit).
UNITS = _table(
    Unit("", "dimensionless", 1.0),
    Unit("m", "length", 1.0),
    Unit("cm", "length", M_PER_CM),
    Unit("mm", "length", M_PER_MM),
    Unit("um", "length", 1e-6, 1e6),
    Unit("in", "length", M_PER_IN),
    Unit("kg", "mass", 1.0),
    Unit("g", "mass", KG_PER_G),
    Unit("kg_m2", "inertia", 1.0),
    Unit("g_cm2", "inertia", KG_M2_PER_G_CM2),
    Unit("pa", "pressure", 1.0),
    Unit("torr", "pressure", PA_PER_TORR),
    Unit("k", "temperature", 1.0),
    Unit("s", "time", 1.0),
    Unit("us", "time", S_PER_US),
    Unit("deg", "angle", math.pi / 180.0, 180.0 / math.pi),
    Unit("rad", "angle", 1.0),
    Unit("m_s", "speed", 1.0),
    Unit("rad_s", "angular rate", 1.0),
    Unit("deg_s", "angular rate", math.pi / 180.0, 180.0 / math.pi),
)


def unit(name: str) -> Unit:
    """The :class:`Unit` of key suffix ``name`` (KeyError naming the known units)."""
    try:
        return UNITS[name]
    except KeyError:
        raise KeyError(f"unknown unit {name!r} (known: {sorted(UNITS)})") from None


def to_si(x, name: str):
    """``x`` in unit ``name`` -> SI."""
    return unit(name).to_si(x)


def from_si(x, name: str):
    """SI ``x`` -> unit ``name``."""
    return unit(name).from_si(x)


def units_of(quantity: str) -> dict[str, Unit]:
    """The units of one quantity (``"length"`` -> m, cm, mm), by name."""
    return {k: u for k, u in UNITS.items() if u.quantity == quantity}


def split_unit_key(key: str, quantity: str | None = None) -> tuple[str, str] | None:
    """``"d_cm"`` -> ``("d", "cm")``: a key's base and its unit suffix (the longest known one,
    so ``"rate_deg_s"`` is deg/s), or None if it ends in no known unit (of ``quantity``, if
    given)."""
    known = units_of(quantity) if quantity is not None else UNITS
    for name in sorted(known, key=len, reverse=True):
        if name and key.endswith("_" + name) and len(key) > len(name) + 1:
            return key[: -len(name) - 1], name
    return None


def _converter(name: str, direction: str, doc: str):
    """A named function converting to (``"to_si"``) or from (``"from_si"``) unit ``name``."""
    convert = getattr(UNITS[name], direction)

    def converted(x):
        return convert(x)

    converted.__doc__ = doc
    return converted


torr_to_pa = _converter("torr", "to_si", "Pressure, torr -> Pa.")
pa_to_torr = _converter("torr", "from_si", "Pressure, Pa -> torr.")
cm_to_m = _converter("cm", "to_si", "Length, cm -> m.")
m_to_cm = _converter("cm", "from_si", "Length, m -> cm.")
mm_to_m = _converter("mm", "to_si", "Length, mm -> m.")
m_to_mm = _converter("mm", "from_si", "Length, m -> mm.")
g_to_kg = _converter("g", "to_si", "Mass, g -> kg.")
kg_to_g = _converter("g", "from_si", "Mass, kg -> g.")
g_cm2_to_kg_m2 = _converter("g_cm2", "to_si", "Moment of inertia, g cm^2 -> kg m^2.")
kg_m2_to_g_cm2 = _converter("g_cm2", "from_si", "Moment of inertia, kg m^2 -> g cm^2.")
deg_to_rad = _converter("deg", "to_si", "Angle, degrees -> radians.")
rad_to_deg = _converter("deg", "from_si", "Angle, radians -> degrees.")
us_to_s = _converter("us", "to_si", "Time, microseconds -> seconds.")
s_to_us = _converter("us", "from_si", "Time, seconds -> microseconds.")


def clean_float(x: float, digits: int = 16) -> float:
    """``x`` rounded to ``digits`` significant digits, for writing converted values to files.

    Converting an SI value back to a file unit (kg -> g) leaves binary noise such as
    ``101.02000000000001`` (17 digits); 16 significant digits remove it while changing the
    value by at most 5e-16 relative.
    """
    x = float(x)
    if x == 0.0 or not np.isfinite(x):
        return x
    return float(f"{x:.{digits}g}")


__all__ = [
    "KG_M2_PER_G_CM2", "KG_PER_G", "M_PER_CM", "M_PER_MM", "PA_PER_TORR", "S_PER_US", "UNITS",
    "Unit", "clean_float", "cm_to_m", "deg_to_rad", "from_si", "g_cm2_to_kg_m2", "g_to_kg",
    "kg_m2_to_g_cm2", "kg_to_g", "m_to_cm", "m_to_mm", "mm_to_m", "pa_to_torr", "rad_to_deg",
    "s_to_us", "split_unit_key", "to_si", "torr_to_pa", "unit", "units_of", "us_to_s",
]
