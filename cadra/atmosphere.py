"""Range air from measured pressure and temperature: ideal gas, Sutherland viscosity.

Pure functions in SI (Pa, K, kg/m^3, m/s, Pa s). Dry air is an ideal gas with
``R = 287.05 J/(kg K)`` and ``gamma = 1.4`` (DESIGN section 6), so

* density ``rho = P / (R T)``,
* speed of sound ``a = sqrt(gamma R T)``,
* viscosity from Sutherland's law (White, *Viscous Fluid Flow*, 3rd ed., Table 1-2):
  ``mu = mu_ref (T/T_ref)^(3/2) (T_ref + S) / (T + S)`` with ``mu_ref = 1.716e-5 Pa s``,
  ``T_ref = 273.15 K``, ``S = 110.4 K`` (valid to ~2 % from 170 K to 1900 K).

Reynolds number and seed 004
----------------------------
Seed 004 (Table 3 notes): "A nominal viscosity for air, at 295 K, was used to compute Re_D" --
the table's Re uses one viscosity for every shot, whatever the shot's temperature. Reproduce it
with ``Atmosphere.reynolds(V, d, viscosity=SEED004_NOMINAL_VISCOSITY_PA_S)`` or with
``Atmosphere.from_pt(P, T, viscosity_pa_s=...)``; ``from_pt(P, T, nominal_viscosity_t_k=295.0)``
evaluates Sutherland's law at 295 K instead of at the shot's T.

Which viscosity reproduces Table 3 (tests/test_atmosphere.py): with rho from P, T (R = 287.05)
and each shot's own d (Table 2), a single constant ``mu`` in [1.80945e-5, 1.80976e-5] Pa s
reproduces all 24 printed Re to half a unit of their last digit. The handbook value
``1.81e-5 Pa s`` (air near room temperature) is 0.013 % above that interval and reproduces every
row to half a unit + 0.02 %; it is :data:`SEED004_NOMINAL_VISCOSITY_PA_S`. Sutherland's law at
295 K gives 1.8222e-5 Pa s, 0.7 % higher, so it under-predicts every Table 3 Re by ~0.7 %
(a constant bias, not scatter). CADRA's default (:attr:`Atmosphere.viscosity`) stays Sutherland
at the shot's temperature, the physically right value for any Re-dependent model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Specific gas constant of dry air, J/(kg K).
R_AIR = 287.05
#: Ratio of specific heats of air.
GAMMA_AIR = 1.4
#: Sutherland's law constants for air (White): reference viscosity (Pa s), reference
#: temperature (K), Sutherland temperature (K).
SUTHERLAND_MU_REF_PA_S = 1.716e-5
SUTHERLAND_T_REF_K = 273.15
SUTHERLAND_S_K = 110.4
#: The "nominal viscosity for air, at 295 K" seed 004 used for Table 3's Re_D (see module doc).
SEED004_NOMINAL_VISCOSITY_PA_S = 1.81e-5
#: The temperature seed 004 quotes for its nominal viscosity, K.
SEED004_NOMINAL_VISCOSITY_T_K = 295.0


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


def density(pressure_pa: float, temperature_k: float) -> float:
    """Ideal-gas density of air, kg/m^3: ``P / (R T)``."""
    return _check_positive("pressure_pa", pressure_pa) / (
        R_AIR * _check_positive("temperature_k", temperature_k))


def speed_of_sound(temperature_k: float) -> float:
    """Speed of sound in air, m/s: ``sqrt(gamma R T)``."""
    return math.sqrt(GAMMA_AIR * R_AIR * _check_positive("temperature_k", temperature_k))


def sutherland_viscosity(temperature_k: float) -> float:
    """Dynamic viscosity of air by Sutherland's law (constants in the module doc), Pa s."""
    t = _check_positive("temperature_k", temperature_k)
    return (SUTHERLAND_MU_REF_PA_S * (t / SUTHERLAND_T_REF_K) ** 1.5
            * (SUTHERLAND_T_REF_K + SUTHERLAND_S_K) / (t + SUTHERLAND_S_K))


#: Alias: the viscosity law CADRA uses.
viscosity = sutherland_viscosity


@dataclass(frozen=True)
class Atmosphere:
    """Uniform range air.

    Attributes
    ----------
    pressure_pa : static pressure, Pa.
    temperature_k : static temperature, K.
    density : kg/m^3.
    speed_of_sound : m/s.
    viscosity : dynamic viscosity used for Reynolds numbers, Pa s (Sutherland at
        ``temperature_k`` unless :meth:`from_pt` was told otherwise).
    """

    pressure_pa: float
    temperature_k: float
    density: float
    speed_of_sound: float
    viscosity: float

    @classmethod
    def from_pt(cls, pressure_pa: float, temperature_k: float, *,
                nominal_viscosity_t_k: float | None = None,
                viscosity_pa_s: float | None = None) -> Atmosphere:
        """Air state from pressure (Pa) and temperature (K).

        Parameters
        ----------
        pressure_pa, temperature_k : the range's measured P and T (SI).
        nominal_viscosity_t_k : evaluate the viscosity at this temperature instead of the
            shot's (seed 004 used 295 K for every shot); ignored if ``viscosity_pa_s`` is given.
        viscosity_pa_s : use this viscosity outright (e.g. ``SEED004_NOMINAL_VISCOSITY_PA_S``).
        """
        p = _check_positive("pressure_pa", pressure_pa)
        t = _check_positive("temperature_k", temperature_k)
        if viscosity_pa_s is not None:
            mu = _check_positive("viscosity_pa_s", viscosity_pa_s)
        elif nominal_viscosity_t_k is not None:
            mu = sutherland_viscosity(nominal_viscosity_t_k)
        else:
            mu = sutherland_viscosity(t)
        return cls(pressure_pa=p, temperature_k=t, density=density(p, t),
                   speed_of_sound=speed_of_sound(t), viscosity=mu)

    def mach(self, velocity_m_s: float) -> float:
        """Mach number of an air-relative speed (m/s)."""
        return velocity_m_s / self.speed_of_sound

    def reynolds(self, velocity_m_s: float, length_m: float,
                 viscosity: float | None = None) -> float:
        """Reynolds number ``rho V L / mu`` for speed V (m/s) and length L (m, e.g. diameter).

        ``viscosity`` (Pa s) overrides :attr:`viscosity` -- e.g. seed 004's nominal value.
        """
        mu = self.viscosity if viscosity is None else _check_positive("viscosity", viscosity)
        return self.density * velocity_m_s * length_m / mu

    def dynamic_pressure(self, velocity_m_s: float) -> float:
        """``q = rho V^2 / 2``, Pa."""
        return 0.5 * self.density * velocity_m_s * velocity_m_s


__all__ = [
    "GAMMA_AIR", "R_AIR", "SEED004_NOMINAL_VISCOSITY_PA_S", "SEED004_NOMINAL_VISCOSITY_T_K",
    "SUTHERLAND_MU_REF_PA_S", "SUTHERLAND_S_K", "SUTHERLAND_T_REF_K", "Atmosphere", "density",
    "speed_of_sound", "sutherland_viscosity", "viscosity",
]
