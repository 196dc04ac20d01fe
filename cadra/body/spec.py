"""Body specs: the plain-data form of a body in shot files (file units, keys carry units).

Examples::

    {"kind": "capsule", "preset": "M2"}
    {"kind": "capsule", "preset": "M2", "d_cm": 3.556, "h_cm": 2.342}    # Table 2, per shot
    {"kind": "capsule", "d_cm": 3.557, "h_cm": 2.338, "R1_cm": 4.267, "R2_cm": 0.178,
     "l1_cm": 1.008}
    {"kind": "sphere", "d_cm": 2.0}
    {"kind": "cone", "d_cm": 2.0, "half_angle_deg": 10.0, "nose_radius_mm": 0.1}
    {"kind": "bullet", "preset": "M80"}                 # BRL MR 1833's 7.62 mm M-80 ball
    {"kind": "bullet", "d_cm": 0.782, "length_cm": 2.814, "ogive_length_cm": 1.407,
     "boattail_length_cm": 0.439, "boattail_angle_deg": 9.0, "meplat_mm": 0.3}
    {"kind": "finner", "preset": "basic_finner"}        # seed 001's Basic Finner (d = 3 cm)
    {"kind": "finner", "preset": "basic_finner", "d_cm": 2.0}   # the same in calibres, d = 2 cm
    {"kind": "finner", "d_cm": 3.0, "length_cm": 30.0, "half_angle_deg": 10.0,
     "fin_chord_cm": 3.0, "fin_span_cm": 3.0, "fin_thickness_mm": 2.4}

Lengths take one of the suffixes ``_m``, ``_cm``, ``_mm``; angles ``_deg`` or ``_rad``. An
optional ``name`` names the body. Unknown or missing keys raise ValueError naming the key.
"""

from __future__ import annotations

from collections.abc import Mapping

from cadra.body.bullet import KIND as _BULLET
from cadra.body.bullet import PRESETS as _BULLET_PRESETS
from cadra.body.bullet import bullet, bullet_preset
from cadra.body.capsule import PRESETS, capsule
from cadra.body.finner import KIND as _FINNER
from cadra.body.finner import PRESETS as _FINNER_PRESETS
from cadra.body.finner import FinnedBody, finner, finner_preset
from cadra.body.model import KINDS as _MODEL_KINDS
from cadra.body.model import Body
from cadra.body.shapes import cone, sphere
from cadra.fields import Fields
from cadra.units import units_of

_F = Fields(ValueError)
#: quantity of a spec key's unit suffix: lengths (m, cm, mm) and angles (deg, rad), converted
#: through the unit table (:data:`cadra.units.UNITS`)
_LENGTH, _ANGLE = "length", "angle"

#: kind -> (length quantities, angle quantities, other keys)
_SCHEMA = {
    "sphere": (("d",), (), ()),
    "capsule": (("d", "h", "R1", "R2", "l1"), (), ("preset",)),
    "cone": (("d", "nose_radius"), ("half_angle",), ()),
    _BULLET: (("d", "length", "ogive_length", "boattail_length", "ogive_radius", "meplat"),
              ("boattail_angle",), ("preset",)),
    _FINNER: (("d", "length", "fin_chord", "fin_span", "fin_thickness"), ("half_angle",),
              ("preset",)),
}
#: Kinds ``body_from_spec`` builds: :data:`cadra.body.model.KINDS`, the bullet and the finner.
KINDS = (*_MODEL_KINDS, *(k for k in _SCHEMA if k not in _MODEL_KINDS))
#: lengths that may be 0 (0: no blunting, no boattail, a pointed nose)
_MAY_BE_ZERO = ("nose_radius", "boattail_length", "meplat")


def _quantity(spec: Mapping, base: str, quantity: str) -> tuple[float | None, str]:
    """SI value of quantity ``base`` given with any one unit suffix (None if absent), and the
    key it was given under (``base + "_cm"`` if absent)."""
    return _F.unit_value(spec, base, quantity, default_unit="cm")


def _missing(kind: str, base: str, why: str = "") -> ValueError:
    alts = "/".join(f"{base}_{u}" for u in units_of(_LENGTH))
    return ValueError(f"{base}_cm: missing from the {kind} spec (give one of {alts}){why}")


def body_from_spec(spec: Mapping) -> Body | FinnedBody:
    """Build a :class:`~cadra.body.model.Body` from a plain-data spec (module docstring); a
    ``"finner"`` spec gives a :class:`~cadra.body.finner.FinnedBody`.

    Raises
    ------
    ValueError
        naming the offending key: unknown kind or key, a missing dimension, a quantity given
        in two units, a non-number, or dimensions that cannot make the body.
    """
    if not isinstance(spec, Mapping):
        raise ValueError(f"body spec: expected a mapping, got {type(spec).__name__}")
    if "kind" not in spec:
        raise ValueError(f"kind: missing from the body spec (one of {', '.join(KINDS)})")
    kind = spec["kind"]
    if kind not in KINDS:
        raise ValueError(f"kind: {kind!r} is not one of {list(KINDS)}")
    lengths, angles, others = _SCHEMA[kind]
    known = {"kind", "name", *others}
    known |= {f"{q}_{u}" for q in lengths for u in units_of(_LENGTH)}
    known |= {f"{q}_{u}" for q in angles for u in units_of(_ANGLE)}
    for key in spec:
        if key not in known:
            raise ValueError(f"{key}: unknown key for a {kind} spec (known: {sorted(known)})")
    name = spec.get("name")
    if name is not None and not isinstance(name, str):
        raise ValueError(f"name: expected a string, got {name!r}")
    val, where = {}, {}
    for q in lengths + angles:
        val[q], where[q] = _quantity(spec, q, _LENGTH if q in lengths else _ANGLE)
    for q in lengths:
        if val[q] is not None and not (val[q] > 0 or (q in _MAY_BE_ZERO and val[q] == 0)):
            what = "a non-negative" if q in _MAY_BE_ZERO else "a positive"
            raise ValueError(f"{where[q]}: must be {what} length, got {spec[where[q]]!r}")
    try:
        return _build(kind, spec, val, name)
    except ValueError as exc:  # constructors name SI arguments ("h_m: ..."): use the spec key
        msg = str(exc)
        head, sep, tail = msg.partition(": ")
        q = head[:-2] if head.endswith("_m") else head[:-4] if head.endswith("_rad") else None
        if sep and q in where:
            raise ValueError(f"{where[q]}: {tail}") from None
        raise


def _build(kind: str, spec: Mapping, val: dict, name: str | None) -> Body | FinnedBody:
    lengths = _SCHEMA[kind][0]

    if kind == "sphere":
        if val["d"] is None:
            raise _missing(kind, "d")
        return sphere(val["d"], name=name or "sphere")
    if kind == "cone":
        if val["d"] is None:
            raise _missing(kind, "d")
        if val["half_angle"] is None:
            raise ValueError("half_angle_deg: missing from the cone spec "
                             "(give half_angle_deg or half_angle_rad)")
        return cone(val["d"], val["half_angle"], nose_radius_m=val["nose_radius"] or 0.0,
                    name=name or "cone")
    if kind == _BULLET:
        return _bullet_from_spec(spec, val, name)
    if kind == _FINNER:
        return _finner_from_spec(spec, val, name)
    preset = spec.get("preset")
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"preset: {preset!r} is not one of {list(PRESETS)}")
    if preset is None:
        for q in lengths:
            if val[q] is None:
                raise _missing(kind, q, " when no preset is given")
    return capsule(preset, d_m=val["d"], h_m=val["h"], R1_m=val["R1"], R2_m=val["R2"],
                   l1_m=val["l1"], name=name)


def _preset(spec: Mapping, presets) -> str | None:
    """The spec's ``preset``, one of ``presets``, or None."""
    preset = spec.get("preset")
    if preset is not None and preset not in presets:
        raise ValueError(f"preset: {preset!r} is not one of {list(presets)}")
    return preset


def _bullet_from_spec(spec: Mapping, val: dict, name: str | None) -> Body:
    kw = {"d_m": val["d"], "length_m": val["length"], "ogive_length_m": val["ogive_length"],
          "boattail_length_m": val["boattail_length"],
          "boattail_angle_rad": val["boattail_angle"], "ogive_radius_m": val["ogive_radius"],
          "meplat_m": val["meplat"]}
    preset = _preset(spec, _BULLET_PRESETS)
    if preset is not None:
        return bullet_preset(preset, name=name, **kw)
    for q in ("d", "length", "ogive_length"):
        if val[q] is None:
            raise _missing(_BULLET, q, " when no preset is given")
    if val["boattail_length"] and val["boattail_angle"] is None:
        raise ValueError("boattail_angle_deg: missing from the bullet spec with a boattail "
                         "(give boattail_angle_deg or boattail_angle_rad)")
    return bullet(**{k: v for k, v in kw.items() if v is not None}, name=name or _BULLET)


def _finner_from_spec(spec: Mapping, val: dict, name: str | None) -> FinnedBody:
    """A preset scales its calibre dimensions by the given d; other keys override (SI)."""
    kw = {"length_m": val["length"], "half_angle_rad": val["half_angle"],
          "fin_chord_m": val["fin_chord"], "fin_span_m": val["fin_span"],
          "fin_thickness_m": val["fin_thickness"]}
    preset = _preset(spec, _FINNER_PRESETS)
    if preset is not None:
        return finner_preset(preset, name=name, d_m=val["d"], **kw)
    for q in ("d", "length", "fin_chord", "fin_span"):
        if val[q] is None:
            raise _missing(_FINNER, q, " when no preset is given")
    if val["half_angle"] is None:
        raise ValueError("half_angle_deg: missing from the finner spec "
                         "(give half_angle_deg or half_angle_rad)")
    return finner(val["d"], **kw, name=name or _FINNER)


__all__ = ["KINDS", "body_from_spec"]
