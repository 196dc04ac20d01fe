"""The library of candidate unmodelled effects (DESIGN.md section 9; seed 002 Table 2).

Each candidate is an augmentation of the fitted model with parameters of its own, in one of
three kinds:

- ``dynamics``: directions in the ``phys`` vector of :mod:`cadra.dynamics.layout` (the
  simulator's effects: lateral cg offset, inertia asymmetry and products of inertia, density
  gradient along the range, cross-flow), differentiated by complex step through the same 6-DOF
  code; a cg offset also moves the observed reference point (added analytically);
- ``aero``: extra terms of the aerodynamic model's forms with new parameters at zero (a
  missing higher-order C_m term, an alpha-dependent C_mq, a Magnus moment, Mach dependence of
  C_m within the shot), differentiated by complex step through the same aero-model evaluator;
- ``measurement``: per-station terms added to what stage one measures (a station's position
  bias in x, y or z -- one candidate per channel, so a one-channel survey error is not charged
  for three parameters --, its timing bias, its optical scale error), linear in their
  parameters.

All parameters are SI; each candidate names its parameters with units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cadra.aero import AeroModel, Parameter
from cadra.dynamics.layout import (
    N_PHYS,
    P_CG_OFFSET,
    P_INERTIA,
    P_RHO_GRAD,
    P_WIND,
)


@dataclass(frozen=True)
class Candidate:
    """One candidate effect (see module doc).

    ``phys_dirs`` (k, N_PHYS) for a dynamics effect; ``terms`` {coefficient: expression} in the
    new parameters ``params`` for an aero effect; ``station``/``measure`` ("position_x",
    "position_y", "position_z", "timing", "scale") for a measurement effect.
    """

    name: str
    kind: str
    params: tuple[str, ...]
    description: str
    phys_dirs: np.ndarray | None = None
    terms: dict = field(default_factory=dict)
    station: int | None = None
    measure: str = ""

    @property
    def n_params(self) -> int:
        return len(self.params)


def _dir(*pairs) -> np.ndarray:
    d = np.zeros(N_PHYS)
    for idx, val in pairs:
        d[idx] += val
    return d


def dynamics_candidates() -> list[Candidate]:
    I = P_INERTIA
    return [
        Candidate("lateral cg offset", "dynamics", ("cg_offset_y_m", "cg_offset_z_m"),
                  "true cg off the nominal one across the axis (body y, z)",
                  np.array([_dir((P_CG_OFFSET + 1, 1.0)), _dir((P_CG_OFFSET + 2, 1.0))])),
        # a body of revolution's transverse asymmetry as the pair (Iyy - Izz, Iyz) in the
        # fit's body frame: the pair turns by 2 phi with the roll, so it spans every
        # orientation of the transverse principal axes with the roll held, and the data are
        # near linear in it (no saddle where a roll angle would see no gradient); the
        # principal difference is sqrt((Iyy - Izz)^2 + 4 Iyz^2) (docs/gap.md)
        Candidate("inertia asymmetry", "dynamics", ("Iyy_minus_Izz_kg_m2", "Iyz_kg_m2"),
                  "transverse moments of inertia differ (principal difference "
                  "sqrt((Iyy - Izz)^2 + 4 Iyz^2))",
                  np.array([_dir((I + 4, 0.5), (I + 8, -0.5)),
                            _dir((I + 5, 1.0), (I + 7, 1.0))])),
        # the products coupling roll with pitch and yaw (the body axis is not a principal
        # axis); the pair turns with the roll, so it too spans every orientation
        Candidate("products of inertia", "dynamics", ("Ixy_kg_m2", "Ixz_kg_m2"),
                  "the body axis is not a principal axis of inertia (mass asymmetry)",
                  np.array([_dir((I + 1, 1.0), (I + 3, 1.0)),
                            _dir((I + 2, 1.0), (I + 6, 1.0))])),
        Candidate("density gradient", "dynamics", ("drho_dx_over_rho_per_m",),
                  "air density varies along the range", np.array([_dir((P_RHO_GRAD, 1.0))])),
        Candidate("cross-flow", "dynamics", ("wind_y_m_s", "wind_z_m_s"),
                  "air moving across the range", np.array([_dir((P_WIND + 1, 1.0)),
                                                           _dir((P_WIND + 2, 1.0))])),
    ]


def aero_candidates(model: AeroModel, mach_nominal: float) -> list[Candidate]:
    """Missing aero terms, written in the model's own angle (s = sin(alpha) - sin(alpha_ref)
    when the model has ``alpha_ref``, sin(alpha) otherwise; sin(sigma) for total-angle
    models)."""
    names = set(model.names)
    M0 = f"{mach_nominal:.6g}"
    if model.angle_plane == "sigma":
        s = "sin(sigma)"
        out = [
            Candidate("higher-order Cm", "aero", ("gap_Cm5",), "C_m term in sin^5(sigma)",
                      terms={"Cm": f"gap_Cm5*{s}**5"}),
            Candidate("alpha-dependent Cmq", "aero", ("gap_Cmq2",),
                      "C_mq term in sin^2(sigma)", terms={"Cmq": f"gap_Cmq2*{s}**2"}),
            Candidate("Mach dependence of Cm", "aero", ("gap_CmM",),
                      "C_m slope changing with Mach within the shot",
                      terms={"Cm": f"gap_CmM*(mach - {M0})*{s}"}),
        ]
    else:
        s = "(sin(alpha) - sin(alpha_ref))" if "alpha_ref" in names else "sin(alpha)"
        out = [
            Candidate("higher-order Cm", "aero", ("gap_Cm3",), f"C_m term in {s}^3",
                      terms={"Cm": f"gap_Cm3*{s}**3"}),
            Candidate("alpha-dependent Cmq", "aero", ("gap_Cmq2",), f"C_mq term in {s}^2",
                      terms={"Cmq": f"gap_Cmq2*{s}**2"}),
            Candidate("Magnus moment", "aero", ("gap_Cnpa",),
                      "yawing moment from spin and angle of attack",
                      terms={"Cn": "gap_Cnpa*p_hat*sin(alpha)"}),
            Candidate("Mach dependence of Cm", "aero", ("gap_CmM",),
                      "C_m changing with Mach within the shot",
                      terms={"Cm": f"gap_CmM*(mach - {M0})"}),
        ]
    return out


def measurement_candidates(stations) -> list[Candidate]:
    out = []
    for st in stations:
        st = int(st)
        for c in "xyz":
            out.append(Candidate(f"station {st} {c} bias", "measurement", (f"st{st}_{c}_m",),
                                 f"the station's measured {c} is offset (wire survey)",
                                 station=st, measure=f"position_{c}"))
        out.append(Candidate(f"station {st} timing bias", "measurement", (f"st{st}_dt_s",),
                             "the spark fires off its recorded time", station=st,
                             measure="timing"))
        out.append(Candidate(f"station {st} optical scale", "measurement",
                             (f"st{st}_scale",), "the station's image scale is off",
                             station=st, measure="scale"))
    return out


def augmented_model(model: AeroModel, cand: Candidate) -> AeroModel:
    """``model`` with the candidate's terms added (new parameters at 0, free)."""
    forms = dict(model.coefficients)
    for coef, expr in cand.terms.items():
        forms[coef] = f"({forms[coef]}) + ({expr})" if coef in forms else expr
    params = tuple(model.parameters) + tuple(Parameter(n, 0.0) for n in cand.params)
    return AeroModel(name=f"{model.name}+{cand.name}", angle_plane=model.angle_plane,
                     coefficients=forms, parameters=params, description=model.description,
                     reference=model.reference, moment_reference=model.moment_reference)


def library(model: AeroModel, stations, mach_nominal: float) -> list[Candidate]:
    """Every candidate for a fit with ``model`` over ``stations``."""
    return dynamics_candidates() + aero_candidates(model, mach_nominal) + \
        measurement_candidates(stations)
