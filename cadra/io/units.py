"""Unit conversions at file boundaries: :mod:`cadra.units`, the one unit table, under the name
the file formats of :mod:`cadra.io` have always used (``from cadra.io import units``)."""

from cadra.units import (
    KG_M2_PER_G_CM2,
    KG_PER_G,
    M_PER_CM,
    M_PER_MM,
    PA_PER_TORR,
    S_PER_US,
    UNITS,
    Unit,
    clean_float,
    cm_to_m,
    deg_to_rad,
    from_si,
    g_cm2_to_kg_m2,
    g_to_kg,
    kg_m2_to_g_cm2,
    kg_to_g,
    m_to_cm,
    m_to_mm,
    mm_to_m,
    pa_to_torr,
    rad_to_deg,
    s_to_us,
    split_unit_key,
    to_si,
    torr_to_pa,
    unit,
    units_of,
    us_to_s,
)

__all__ = [
    "KG_M2_PER_G_CM2", "KG_PER_G", "M_PER_CM", "M_PER_MM", "PA_PER_TORR", "S_PER_US", "UNITS",
    "Unit", "clean_float", "cm_to_m", "deg_to_rad", "from_si", "g_cm2_to_kg_m2", "g_to_kg",
    "kg_m2_to_g_cm2", "kg_to_g", "m_to_cm", "m_to_mm", "mm_to_m", "pa_to_torr", "rad_to_deg",
    "s_to_us", "split_unit_key", "to_si", "torr_to_pa", "unit", "units_of", "us_to_s",
]
