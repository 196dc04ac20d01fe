"""Unit conversions at file boundaries: the one place where non-SI units meet SI.

Every file key carries its unit in its name (``pressure_torr``, ``mass_g``, ``d_cm``); readers
convert with these functions and the library works in SI only (docs/conventions.md, "Units").
All functions accept floats or numpy arrays and return the same kind.
"""

from __future__ import annotations

import numpy as np

#: Pascals per torr (1 torr = 101325/760 Pa exactly).
PA_PER_TORR = 101325.0 / 760.0  # 133.32236842...
M_PER_CM = 1e-2
M_PER_MM = 1e-3
KG_PER_G = 1e-3
KG_M2_PER_G_CM2 = 1e-7  # 1 g cm^2 = 1e-3 kg * 1e-4 m^2
S_PER_US = 1e-6


def torr_to_pa(p_torr):
    """Pressure, torr -> Pa."""
    return p_torr * PA_PER_TORR


def pa_to_torr(p_pa):
    """Pressure, Pa -> torr."""
    return p_pa / PA_PER_TORR


def cm_to_m(x_cm):
    """Length, cm -> m."""
    return x_cm * M_PER_CM


def m_to_cm(x_m):
    """Length, m -> cm."""
    return x_m / M_PER_CM


def mm_to_m(x_mm):
    """Length, mm -> m."""
    return x_mm * M_PER_MM


def m_to_mm(x_m):
    """Length, m -> mm."""
    return x_m / M_PER_MM


def g_to_kg(m_g):
    """Mass, g -> kg."""
    return m_g * KG_PER_G


def kg_to_g(m_kg):
    """Mass, kg -> g."""
    return m_kg / KG_PER_G


def g_cm2_to_kg_m2(i_g_cm2):
    """Moment of inertia, g cm^2 -> kg m^2."""
    return i_g_cm2 * KG_M2_PER_G_CM2


def kg_m2_to_g_cm2(i_kg_m2):
    """Moment of inertia, kg m^2 -> g cm^2."""
    return i_kg_m2 / KG_M2_PER_G_CM2


def deg_to_rad(a_deg):
    """Angle, degrees -> radians."""
    return np.radians(a_deg)


def rad_to_deg(a_rad):
    """Angle, radians -> degrees."""
    return np.degrees(a_rad)


def us_to_s(t_us):
    """Time, microseconds -> seconds."""
    return t_us * S_PER_US


def s_to_us(t_s):
    """Time, seconds -> microseconds."""
    return t_s / S_PER_US


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
    "KG_M2_PER_G_CM2", "KG_PER_G", "M_PER_CM", "M_PER_MM", "PA_PER_TORR", "S_PER_US",
    "clean_float", "cm_to_m", "deg_to_rad", "g_cm2_to_kg_m2", "g_to_kg", "kg_m2_to_g_cm2",
    "kg_to_g", "m_to_cm", "m_to_mm", "mm_to_m", "pa_to_torr", "rad_to_deg", "s_to_us",
    "torr_to_pa", "us_to_s",
]
