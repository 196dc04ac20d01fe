"""Optional simulator effects: physics the nominal model leaves out, switched on from data.

Each effect is a plain number or vector with its unit in the field name; all default to "off".
They enter the dynamics through the ``phys`` vector (:mod:`cadra.dynamics.layout`) and the
observation model (a cg offset moves the observed reference point too), so the simulator that
makes data and the fitter that explains it run the same code with the same switches.

========================================  ==================================================
effect (TOML key in an ``[effects]`` table) meaning
========================================  ==================================================
``cg_offset_body_m = [x, y, z]``          true cg minus the nominal cg (the aero moment
                                          reference), body axes (x nose, y stbd, z down)
``inertia_delta_body_kg_m2 = [[...]]``    added to the nominal inertia tensor about the cg,
                                          body axes: products of inertia, asymmetry
``density_gradient_per_m``                (1/rho) d rho / dx along the range
``wind_facility_m_s = [wx, wy, wz]``      uniform air velocity in F (cross-flow: wy, wz)
``wind_gradient_facility_per_s = [...]``  d(wind)/dx, so wind(x) = wind + x * gradient
========================================  ==================================================
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


def _vec3(value, key: str) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"effects.{key}: expected 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class Effects:
    """Unmodelled-physics switches; the default instance is the nominal model."""

    cg_offset_body_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia_delta_body_kg_m2: tuple[tuple[float, float, float], ...] = field(
        default=((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    )
    density_gradient_per_m: float = 0.0
    wind_facility_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    wind_gradient_facility_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "cg_offset_body_m", _vec3(self.cg_offset_body_m,
                                                            "cg_offset_body_m"))
        object.__setattr__(self, "wind_facility_m_s", _vec3(self.wind_facility_m_s,
                                                             "wind_facility_m_s"))
        object.__setattr__(self, "wind_gradient_facility_per_s", _vec3(
            self.wind_gradient_facility_per_s, "wind_gradient_facility_per_s"))
        dI = np.asarray(self.inertia_delta_body_kg_m2, dtype=float)
        if dI.shape != (3, 3) or not np.all(np.isfinite(dI)):
            raise ValueError("effects.inertia_delta_body_kg_m2: expected a 3x3 matrix")
        if not np.allclose(dI, dI.T, rtol=0, atol=1e-15):
            raise ValueError("effects.inertia_delta_body_kg_m2: must be symmetric")
        object.__setattr__(self, "inertia_delta_body_kg_m2",
                           tuple(tuple(float(v) for v in row) for row in dI))
        g = float(self.density_gradient_per_m)
        if not np.isfinite(g) or abs(g) > 0.1:
            raise ValueError(
                f"effects.density_gradient_per_m: {g!r} is not a plausible relative gradient "
                "(|value| <= 0.1 per metre)")
        object.__setattr__(self, "density_gradient_per_m", g)

    @classmethod
    def from_dict(cls, data: dict | None) -> Effects:
        """From a TOML ``[effects]`` table; unknown keys are refused by name."""
        data = dict(data or {})
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"effects: unknown key(s) {unknown}; known: {sorted(known)}")
        return cls(**data)

    def to_dict(self) -> dict:
        """Plain-data form (only the effects that are on)."""
        default = Effects()
        out = {}
        for key, value in asdict(self).items():
            if value != getattr(default, key):
                out[key] = [list(r) for r in value] if key == "inertia_delta_body_kg_m2" else (
                    list(value) if isinstance(value, tuple) else value)
        return out

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the effects that are switched on."""
        return tuple(self.to_dict())
