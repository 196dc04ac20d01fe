"""The library of candidate unmodelled effects (docs/gap.md; seed 002 Table 2).

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
  for three parameters --, its timing bias, its optical scale error; on point-source stations
  each view's spark off its surveyed distance, through the response the facility's geometry
  gives, :mod:`cadra.gap.optics`), linear in their parameters;
- ``held``: a parameter the model holds (``vary = false``), freed from its held value: a
  held value the data reject is an unmodelled effect too, and the sigmas of the free
  parameters it moves are not valid while it is held (seed 004 holds parameters as everyday
  practice). Reference points of the forms (:data:`REFERENCE_PARAMETERS`) are not tested.

The range air's effects (density gradient, cross-flow) come in two forms in a fit of several
shots: per shot (``scope = "shot"``, one parameter per shot: the air of each firing) and
shared by the set (``scope = "set"``: the same range air for every shot, one parameter); the
ranking charges the per-shot form for its parameters (docs/gap.md).

All parameters are SI; each candidate names its parameters with units.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from cadra.aero import AeroModel, Parameter
from cadra.dynamics.layout import (
    P_CG_OFFSET,
    P_INERTIA,
    P_RHO_GRAD,
    P_WIND,
)
from cadra.fitting.extras import phys_direction


@dataclass(frozen=True)
class Candidate:
    """One candidate effect (see module doc).

    ``phys_dirs`` (k, N_PHYS) for a dynamics effect; ``terms`` {coefficient: expression} in the
    new parameters ``params`` for an aero effect; ``station``/``measure`` ("position_x",
    "position_y", "position_z", "timing", "scale", or "response" with its ``response`` per
    shot, :class:`cadra.fitting.extras.Extra`, or ``responses``, one a parameter) for a
    measurement effect; for a held
    parameter, ``params`` is its name. ``scope``: a dynamics effect's parameters per shot
    ("shot") or one set for every shot of the fit ("set").
    """

    name: str
    kind: str
    params: tuple[str, ...]
    description: str
    phys_dirs: np.ndarray | None = None
    terms: dict = field(default_factory=dict)
    station: int | None = None
    measure: str = ""
    scope: str = "shot"
    response: tuple = ()
    #: a measurement effect of several parameters: one response per parameter (``response``
    #: is then empty)
    responses: tuple = ()

    @property
    def n_params(self) -> int:
        return len(self.params)


#: held parameters that are reference points of the forms (the Mach and angle about which a
#: form is expanded), not coefficients: freeing one reparametrizes the forms, so they are not
#: tested as held values
REFERENCE_PARAMETERS = ("M_ref", "alpha_ref")
#: the per-shot and the shared form of one range-air effect (name of the per-shot candidate
#: -> name of the shared one)
SHARED_FORMS = {"density gradient": "shared density gradient",
                "cross-flow": "shared cross-flow"}


def dynamics_candidates(n_shots: int = 1) -> list[Candidate]:
    """Body and air effects; with ``n_shots`` > 1 also the range air's shared forms."""
    out = _dynamics()
    if n_shots > 1:
        for c in list(out):
            if c.name in SHARED_FORMS:
                out.append(Candidate(SHARED_FORMS[c.name], "dynamics", c.params,
                                     c.description + ", the same for every shot of the set",
                                     c.phys_dirs, scope="set"))
    return out


def held_candidates(model: AeroModel) -> list[Candidate]:
    """Every parameter ``model`` holds at a value other than 0, but the forms' reference
    points, freed. A parameter held at 0 is a term of the form left out (seed 004's blank
    cells, "the term modified by that parameter was not used"): whether a term is missing is
    the question of the library's aero terms, and offering every blank cell too would only
    dilute the test of the physical candidates (five on M2 M0.70: a cross-flow at p = 4e-4
    then missed the Bonferroni level). A held value other than 0 is a judgment (the M1
    M1.10 Cmq peak, 3.65, that the paper does not print) that can be wrong."""
    return [Candidate(f"held {p.name}", "held", (p.name,),
                      f"{p.name} is held at {p.value:.6g}: freed")
            for p in model.parameters
            if not p.vary and p.value != 0.0 and p.name not in REFERENCE_PARAMETERS]


def form_counterpart(name: str) -> str | None:
    """The other form (per shot / shared) of a range-air effect, or None."""
    for per_shot, shared in SHARED_FORMS.items():
        if name == per_shot:
            return shared
        if name == shared:
            return per_shot
    return None


def _dynamics() -> list[Candidate]:
    I = P_INERTIA
    return [
        Candidate("lateral cg offset", "dynamics", ("cg_offset_y_m", "cg_offset_z_m"),
                  "true cg off the nominal one across the axis (body y, z)",
                  np.array([phys_direction(P_CG_OFFSET + 1), phys_direction(P_CG_OFFSET + 2)])),
        # a body of revolution's transverse asymmetry as the pair (Iyy - Izz, Iyz) in the
        # fit's body frame: the pair turns by 2 phi with the roll, so it spans every
        # orientation of the transverse principal axes with the roll held, and the data are
        # near linear in it (no saddle where a roll angle would see no gradient); the
        # principal difference is sqrt((Iyy - Izz)^2 + 4 Iyz^2) (docs/gap.md)
        Candidate("inertia asymmetry", "dynamics", ("Iyy_minus_Izz_kg_m2", "Iyz_kg_m2"),
                  "transverse moments of inertia differ (principal difference "
                  "sqrt((Iyy - Izz)^2 + 4 Iyz^2))",
                  np.array([phys_direction((I + 4, 0.5), (I + 8, -0.5)),
                            phys_direction(I + 5, I + 7)])),
        # the products coupling roll with pitch and yaw (the body axis is not a principal
        # axis); the pair turns with the roll, so it too spans every orientation
        Candidate("products of inertia", "dynamics", ("Ixy_kg_m2", "Ixz_kg_m2"),
                  "the body axis is not a principal axis of inertia (mass asymmetry)",
                  np.array([phys_direction(I + 1, I + 3), phys_direction(I + 2, I + 6)])),
        Candidate("density gradient", "dynamics", ("drho_dx_over_rho_per_m",),
                  "air density varies along the range", np.array([phys_direction(P_RHO_GRAD)])),
        Candidate("cross-flow", "dynamics", ("wind_y_m_s", "wind_z_m_s"),
                  "air moving across the range",
                  np.array([phys_direction(P_WIND + 1), phys_direction(P_WIND + 2)])),
    ]


def aero_candidates(model: AeroModel, mach_nominal: float) -> list[Candidate]:
    """Missing aero terms, written in the model's own angle (s = sin(alpha) - sin(alpha_ref)
    when the model has ``alpha_ref``, sin(alpha) otherwise; sin(sigma) for total-angle
    models)."""
    names = set(model.names)
    # about the model's own reference Mach where it has one (then the term is the model's
    # held Mach term when that is a blank cell: ``same_term``)
    M0 = f"{model.parameter('M_ref').value if 'M_ref' in names else mach_nominal:.6g}"
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


def measurement_candidates(stations, sparks: dict | None = None,
                           perspective: dict | None = None) -> list[Candidate]:
    """The per-station measurement candidates; ``sparks``: ``(station, view)`` -> the
    response of each shot's measurement there to that view's spark distance
    (:func:`cadra.gap.optics.spark_responses`), one candidate each; ``perspective``: view
    name -> the response of each shot's measurements at every station to point-source optics
    where the facility declares parallel ones (:func:`cadra.gap.optics.perspective_responses`),
    one candidate each."""
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
    fitted = {int(s) for s in stations}
    for (st, view), resp in sorted((sparks or {}).items()):
        if int(st) in fitted:
            out.append(Candidate(f"station {st} {view} spark distance", "measurement",
                                 (f"st{st}_{view}_spark_m",),
                                 f"the {view} view's spark is off its surveyed distance from "
                                 f"the film (m, + farther): a scale error growing with the "
                                 f"model's offset", station=int(st), measure="response",
                                 response=resp))
    for view, columns in sorted((perspective or {}).items()):
        columns = tuple(tuple(e for e in col if int(e[1]) in fitted) for col in columns)
        if all(columns):
            out.append(Candidate(f"{view} view point-source optics", "measurement",
                                 (f"{view}_inv_spark_distance_per_m", f"{view}_scale_at_foot",
                                  f"{view}_x_depth_per_m"),
                                 f"the {view} view's images are shadows cast by a spark "
                                 f"(1/value m from the line of flight), not parallel light "
                                 f"as the facility file declares: an error growing with the "
                                 f"model's offset times its depth, at every station (with "
                                 f"the view's scale about the spark's foot, as the file's "
                                 f"map may be right at another depth than its wires', and "
                                 f"the view's share of x)",
                                 measure="response", responses=columns))
    return out


def augmented_model(model: AeroModel, cand: Candidate) -> AeroModel:
    """``model`` with the candidate's terms added (new parameters at 0, free); a held
    candidate's parameter freed at its held value."""
    if cand.kind == "held":
        return model.with_vary({n: True for n in cand.params})
    forms = dict(model.coefficients)
    for coef, expr in cand.terms.items():
        forms[coef] = f"({forms[coef]}) + ({expr})" if coef in forms else expr
    params = tuple(model.parameters) + tuple(Parameter(n, 0.0) for n in cand.params)
    return AeroModel(name=f"{model.name}+{cand.name}", angle_plane=model.angle_plane,
                     coefficients=forms, parameters=params, description=model.description,
                     reference=model.reference, moment_reference=model.moment_reference)


def _term_change(model: AeroModel, changed: AeroModel, mach_nominal: float) -> np.ndarray:
    """Every coefficient's change from ``model`` to ``changed`` on a grid of angles and
    Mach numbers about the nominal one (flattened)."""
    a = np.radians(np.linspace(-40.0, 40.0, 9))[:, None, None]
    b = np.radians(np.array([-7.0, 0.0, 11.0]))[None, :, None]
    m = mach_nominal + np.array([-0.05, 0.0, 0.04])[None, None, :]
    c0, c1 = model.evaluate(a, b, None, m, p_hat=0.01, q_hat=0.002), changed.evaluate(
        a, b, None, m, p_hat=0.01, q_hat=0.002)
    return np.concatenate([np.ravel(c1[k] - c0[k]) for k in c0])


def same_term(model: AeroModel, held: Candidate, aero: Candidate, mach_nominal: float) -> bool:
    """Freeing the held parameter adds exactly the aero candidate's term (a blank cell of the
    model's table that is the candidate: M1 M1.10's Cm_A2 (M - M_ref) sin(sigma) is the Mach
    dependence of C_m): the same change of every coefficient per unit, on a grid."""
    name = held.params[0]
    d_held = _term_change(model, model.with_values(
        {name: model.parameter(name).value + 1.0}), mach_nominal)
    aug = augmented_model(model, aero)
    d_aero = _term_change(aug, aug.with_values({aero.params[0]: 1.0}), mach_nominal)
    scale = max(float(np.max(np.abs(d_held))), float(np.max(np.abs(d_aero))), 1e-300)
    return bool(np.max(np.abs(d_held - d_aero)) <= 1e-9 * scale)


def library(model: AeroModel, stations, mach_nominal: float,
            n_shots: int = 1, sparks: dict | None = None,
            perspective: dict | None = None) -> list[Candidate]:
    """Every candidate for a fit of ``n_shots`` shots with ``model`` over ``stations``
    (``sparks``, ``perspective``: the facility's optics candidates' responses,
    :func:`measurement_candidates`). A held
    parameter that is the same term as an aero candidate is offered once, as that candidate
    (its description names the held parameter)."""
    aero = aero_candidates(model, mach_nominal)
    held = []
    for h in held_candidates(model):
        twin = next((a for a in aero if len(a.params) == 1
                     and same_term(model, h, a, mach_nominal)), None)
        if twin is None:
            held.append(h)
        else:
            i = aero.index(twin)
            aero[i] = replace(twin, description=twin.description
                              + f" (the model holds this term: {h.params[0]})")
    return (dynamics_candidates(n_shots) + aero + held
            + measurement_candidates(stations, sparks, perspective))
