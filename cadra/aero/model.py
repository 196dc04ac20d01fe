"""Aerodynamic models as data: parameters, coefficient forms, TOML files.

An :class:`AeroModel` holds the coefficient forms (expression text, see :mod:`cadra.aero.expr`
and docs/aero_models.md) and the :class:`Parameter` s they use. Parameters follow lmfit's
semantics (``Parameter(name, value, vary, min, max)``); values inside the library are SI
(angles in radians) whatever unit the file uses. Frames and coefficient senses:
docs/conventions.md.

Validation policy: every parameter a form uses must be declared, and every declared parameter
must be used by some form (an unused parameter is an **error**: it would be a silent fit
unknown with no effect, i.e. a singular Jacobian column).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from cadra import units as _units
from cadra.aero.evaluate import nonfinite_constant, nonfinite_origin
from cadra.aero.expr import (
    NAME_RE,
    RESERVED,
    ExpressionError,
    compile_program,
    parameter_names,
    parse_expression,
    to_text,
)
from cadra.aero.program import (
    COEFFICIENTS,
    N_COEFFICIENTS,
    N_VARIABLES,
    AeroProgram,
    eval_coefficients_batch,
)
from cadra.atomic import atomic_write_text
from cadra.fields import Fields, read_toml

#: the two kinds of model (docs/conventions.md, "Aerodynamic coefficients")
ANGLE_PLANES = ("alpha_beta", "sigma")
#: points the moment coefficients may be about
MOMENT_REFERENCES = ("cg",)
#: file units of parameter values -> factor to SI (entries of :data:`cadra.units.UNITS`,
#: through which values are converted)
UNITS = {name: _units.UNITS[name].si_per_unit for name in ("", "deg")}
#: coefficients a total-angle (sigma) model may not define (conventions: C_mq damps both
#: transverse rates, so C_nr would be ignored; C_C and C_n are the Magnus force and moment)
SIGMA_UNUSED = ("Cnr",)
#: the ``format`` key written by :func:`save_model`
FILE_FORMAT = "cadra.aero/1"
#: directory of the bundled model files
MODELS_DIR = Path(__file__).resolve().parent / "models"

#: the points at which a loaded model's coefficients must be finite somewhere (rad, Mach;
#: with the reference's ``mach_nominal``, Reynolds number 1e6, rates 0 and 0.01)
CHECK_ALPHA = (-0.2, 0.1, 0.4)
CHECK_BETA = (-0.1, 0.0, 0.1)
CHECK_MACH = (0.3, 0.7, 0.95, 1.2, 2.0, 4.0, 8.0, 20.0)


class ModelFileError(ValueError):
    """An aero model file (or dictionary) that cannot be right: the message starts with the
    file and names the key, the coefficient or the term."""


_F = Fields(ModelFileError)
_MODEL_KEYS = ("format", "name", "description", "angle_plane", "moment_reference", "reference",
               "coefficients", "parameters")
_PARAM_KEYS = ("value", "vary", "min", "max", "unit", "note", "sigma", "prior")


def _is_number(x) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(
        x, bool | np.bool_)


@dataclass(frozen=True)
class Parameter:
    """One model parameter (lmfit semantics), value and bounds in SI / radians.

    Attributes
    ----------
    name : identifier (letters, digits, ``_``; starts with a letter; not a variable/function).
    value : float, SI (radians for angles).
    vary : bool, free in fits (True) or held (False).
    min, max : bounds, SI; ``-inf``/``inf`` when unbounded. ``min <= value <= max``.
    unit : unit of the value *in the file*: ``""`` (as is) or ``"deg"`` (file degrees).
    note : free text (provenance, OCR decisions); kept through save/load.
    sigma : the value's own standard uncertainty, SI (0: exact). A held parameter's sigma
        is propagated into the free ones' as a consider covariance
        (:mod:`cadra.fitting.consider`, docs/fitting.md, "Held values with an uncertainty").
    prior : the mean of a Gaussian prior, SI (None: no prior), whose standard deviation is
        ``sigma``: the fit adds ``((value - prior) / sigma)^2`` to its chi^2 (the Bayesian
        alternative to a hold with an uncertainty, :mod:`cadra.fitting.priors`).
    """

    name: str
    value: float
    vary: bool = True
    min: float = -math.inf
    max: float = math.inf
    unit: str = ""
    note: str = ""
    sigma: float = 0.0
    prior: float | None = None

    def __post_init__(self):
        key = f"parameters.{self.name}"
        if not isinstance(self.name, str) or not NAME_RE.match(self.name):
            raise ValueError(f"parameters.{self.name!r}: invalid name (letters, digits and '_', "
                             "starting with a letter)")
        if self.name in RESERVED:
            raise ValueError(f"{key}: reserved name (a variable, function or constant)")
        for attr in ("value", "min", "max", "sigma"):
            v = getattr(self, attr)
            if not _is_number(v):
                raise ValueError(f"{key}: {attr} must be a number, got {v!r}")
            v = float(v)
            if math.isnan(v):
                raise ValueError(f"{key}: {attr} is NaN")
            object.__setattr__(self, attr, v)
        if not math.isfinite(self.value):
            raise ValueError(f"{key}: value must be finite, got {self.value}")
        if not (math.isfinite(self.sigma) and self.sigma >= 0.0):
            raise ValueError(f"{key}: sigma must be a finite number >= 0, got {self.sigma}")
        if self.prior is not None:
            if not (_is_number(self.prior) and math.isfinite(float(self.prior))):
                raise ValueError(f"{key}: prior must be a finite number, got {self.prior!r}")
            object.__setattr__(self, "prior", float(self.prior))
            if not self.sigma > 0.0:
                raise ValueError(f"{key}: a prior needs its sigma (> 0)")
        if not isinstance(self.vary, bool | np.bool_):
            raise ValueError(f"{key}: vary must be true or false, got {self.vary!r}")
        object.__setattr__(self, "vary", bool(self.vary))
        if self.min > self.max:
            raise ValueError(f"{key}: min ({self.min:g}) > max ({self.max:g})")
        if not (self.min <= self.value <= self.max):
            raise ValueError(f"{key}: value {self.value:g} outside its bounds "
                             f"[{self.min:g}, {self.max:g}] (SI units)")
        if self.unit not in UNITS:
            raise ValueError(f"{key}: unit must be one of {sorted(UNITS)}, got {self.unit!r}")
        if not isinstance(self.note, str):
            raise ValueError(f"{key}: note must be a string")

    def replace(self, **changes) -> Parameter:
        """A copy with some attributes changed (validated)."""
        return Parameter(**{**self.__dict__, **changes})

    @property
    def file_value(self) -> float:
        """The value in the file's unit (:attr:`unit`)."""
        return _to_file(self.value, self.unit)

    @property
    def file_sigma(self) -> float:
        """The value's own uncertainty in the file's unit (:attr:`unit`)."""
        return _to_file(self.sigma, self.unit)

    def to_si(self, file_value: float) -> float:
        """A value in this parameter's file unit (:attr:`unit`, e.g. degrees) -> SI."""
        return _from_file(float(file_value), self.unit)


def _to_file(x: float, unit: str) -> float:
    """SI -> file unit, choosing the float whose conversion back is exactly ``x``."""
    if unit == "" or not math.isfinite(x):
        return x
    d = _units.from_si(x, unit)
    if _from_file(d, unit) == x:
        return d
    up = down = d
    for _ in range(16):
        up, down = math.nextafter(up, math.inf), math.nextafter(down, -math.inf)
        for c in (up, down):
            if _from_file(c, unit) == x:
                return c
    return d


def _from_file(x: float, unit: str) -> float:
    if unit == "" or not math.isfinite(x):
        return float(x)
    return _units.to_si(x, unit)


@dataclass(frozen=True)
class AeroModel:
    """An aerodynamic model: coefficient forms over variables and parameters.

    Attributes
    ----------
    name : short identifier (e.g. ``"m2_m070"``).
    angle_plane : ``"alpha_beta"`` (lifting bodies: forms in alpha, beta) or ``"sigma"``
        (symmetric bodies: forms in the total angle of attack; see docs/conventions.md).
    coefficients : coefficient name (of :data:`cadra.aero.program.COEFFICIENTS`) -> expression
        text. Coefficients not listed are 0.
    parameters : the declared parameters, in the order of :meth:`values`.
    description : free text.
    reference : reference-case metadata (e.g. ``{"case": "M2 M0.70", "mach_nominal": 0.7}``);
        scalar values only.
    moment_reference : point the moment coefficients are about: ``"cg"``.
    """

    name: str
    angle_plane: str
    coefficients: dict
    parameters: tuple
    description: str = ""
    reference: dict = field(default_factory=dict)
    moment_reference: str = "cg"

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ValueError("name: must be a non-empty string")
        if self.angle_plane not in ANGLE_PLANES:
            raise ValueError(f"angle_plane: must be one of {ANGLE_PLANES}, "
                             f"got {self.angle_plane!r}")
        if self.moment_reference not in MOMENT_REFERENCES:
            raise ValueError(f"moment_reference: must be one of {MOMENT_REFERENCES}, "
                             f"got {self.moment_reference!r}")
        if not isinstance(self.description, str):
            raise ValueError("description: must be a string")
        if not isinstance(self.reference, Mapping):
            raise ValueError("reference: must be a table")
        ref = {}
        for k, v in self.reference.items():
            if not isinstance(k, str) or not isinstance(v, str | int | float | bool):
                raise ValueError(f"reference.{k}: values must be strings, numbers or booleans")
            ref[k] = v
        object.__setattr__(self, "reference", ref)
        params = tuple(self.parameters)
        seen = set()
        for p in params:
            if not isinstance(p, Parameter):
                raise ValueError(f"parameters: expected Parameter objects, got {p!r}")
            if p.name in seen:
                raise ValueError(f"parameters.{p.name}: declared twice")
            seen.add(p.name)
        object.__setattr__(self, "parameters", params)
        if not isinstance(self.coefficients, Mapping):
            raise ValueError("coefficients: must be a table of name -> expression")
        forms = {}
        for k in self.coefficients:
            if k not in COEFFICIENTS:
                raise ValueError(f"coefficients.{k}: unknown coefficient (expected one of "
                                 f"{', '.join(COEFFICIENTS)})")
        for k in COEFFICIENTS:
            if k in self.coefficients:
                text = self.coefficients[k]
                if not isinstance(text, str):
                    raise ValueError(f"coefficients.{k}: must be an expression string")
                forms[k] = text
        if self.angle_plane == "sigma":
            for k in SIGMA_UNUSED:
                if k in forms:
                    raise ValueError(
                        f"coefficients.{k}: not used by total-angle (sigma) models "
                        "(docs/conventions.md: C_mq damps both transverse rates); use "
                        "angle_plane = \"alpha_beta\"")
        object.__setattr__(self, "coefficients", forms)
        trees = {k: parse_expression(t, seen, context=f"coefficients.{k}")
                 for k, t in forms.items()}
        used = set()
        for t in trees.values():
            used |= parameter_names(t)
        unused = [p.name for p in params if p.name not in used]
        if unused:
            raise ValueError(f"parameters.{unused[0]}: declared but not used by any "
                             f"coefficient form" + (f" (also unused: {', '.join(unused[1:])})"
                                                    if len(unused) > 1 else ""))
        object.__setattr__(self, "_trees", trees)
        object.__setattr__(self, "_index", {p.name: i for i, p in enumerate(params)})
        object.__setattr__(self, "_cache", {})

    # --- parameters ----------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in the order of :meth:`values`."""
        return tuple(p.name for p in self.parameters)

    def index(self, name: str) -> int:
        """Position of parameter ``name`` in :meth:`values`."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(f"model {self.name!r} has no parameter {name!r}") from None

    def parameter(self, name: str) -> Parameter:
        """The parameter called ``name``."""
        return self.parameters[self.index(name)]

    def values(self) -> np.ndarray:
        """Parameter values (SI), float64, in declaration order (the ``params`` vector)."""
        return np.array([p.value for p in self.parameters], dtype=np.float64)

    def free_names(self) -> tuple[str, ...]:
        """Names of the parameters with ``vary=True``, in declaration order."""
        return tuple(p.name for p in self.parameters if p.vary)

    def free_indices(self) -> np.ndarray:
        """Positions of the free parameters in :meth:`values`."""
        return np.array([i for i, p in enumerate(self.parameters) if p.vary], dtype=np.int64)

    def parameters_in(self, coefficient: str) -> tuple[str, ...]:
        """Names of the parameters the form of ``coefficient`` uses (declaration order)."""
        if coefficient not in COEFFICIENTS:
            raise KeyError(f"unknown coefficient {coefficient!r}")
        tree = self._trees.get(coefficient)
        used = parameter_names(tree) if tree is not None else set()
        return tuple(n for n in self.names if n in used)

    def tree(self, coefficient: str) -> tuple | None:
        """Parsed expression tree of ``coefficient`` (``None`` when it is 0)."""
        return self._trees.get(coefficient)

    def _derive(self, parameters: tuple) -> AeroModel:
        # same forms and names: share the parsed trees and the compiled program
        new = object.__new__(AeroModel)
        for k, v in self.__dict__.items():
            object.__setattr__(new, k, v)
        object.__setattr__(new, "parameters", parameters)
        return new

    def _changed(self, changes: Mapping) -> AeroModel:
        params = list(self.parameters)
        for name, change in changes.items():
            i = self.index(name)
            try:
                params[i] = params[i].replace(**change)
            except TypeError as exc:  # pragma: no cover - internal misuse
                raise ValueError(f"parameters.{name}: {exc}") from None
        return self._derive(tuple(params))

    def with_values(self, values: Mapping[str, float]) -> AeroModel:
        """A copy with new parameter values (SI / radians); bounds are enforced."""
        return self._changed({n: {"value": v} for n, v in values.items()})

    def with_vary(self, vary: Mapping[str, bool]) -> AeroModel:
        """A copy with parameters freed (True) or held (False)."""
        return self._changed({n: {"vary": v} for n, v in vary.items()})

    def with_sigmas(self, sigmas: Mapping[str, float]) -> AeroModel:
        """A copy with the parameters' own uncertainties (SI; 0: exact) changed."""
        return self._changed({n: {"sigma": v} for n, v in sigmas.items()})

    def with_priors(self, priors: Mapping[str, tuple[float, float] | None]) -> AeroModel:
        """A copy with Gaussian priors ``name -> (mean, sigma)`` (SI) on parameters, each
        made free; ``None`` removes a parameter's prior (its sigma stays)."""
        return self._changed({n: ({"prior": None} if ms is None else
                                  {"prior": ms[0], "sigma": ms[1], "vary": True})
                              for n, ms in priors.items()})

    def with_bounds(self, bounds: Mapping[str, tuple[float, float]]) -> AeroModel:
        """A copy with new ``(min, max)`` bounds (SI)."""
        return self._changed({n: {"min": b[0], "max": b[1]} for n, b in bounds.items()})

    def with_free_values(self, x: Iterable[float]) -> AeroModel:
        """A copy with the free parameters (in :meth:`free_names` order) set to ``x``."""
        x = list(x)
        names = self.free_names()
        if len(x) != len(names):
            raise ValueError(f"expected {len(names)} free values, got {len(x)}")
        return self.with_values(dict(zip(names, (float(v) for v in x), strict=True)))

    # --- finite checks -------------------------------------------------------------------

    def check_points(self) -> dict[str, np.ndarray]:
        """The points of :meth:`check_finite`: variable name -> (n,) array (a product of
        :data:`CHECK_ALPHA`, :data:`CHECK_BETA`, :data:`CHECK_MACH` and the reference's
        ``mach_nominal``, and rates 0 and 0.01)."""
        mach = list(CHECK_MACH)
        m0 = self.reference.get("mach_nominal")
        if _is_number(m0) and 0 < m0 < 100:  # (NaN, inf and huge integers fail the test)
            mach.append(float(m0))
        a, b, m, r = np.meshgrid(CHECK_ALPHA, CHECK_BETA, mach, (0.0, 0.01), indexing="ij")
        a, b, m, r = a.ravel(), b.ravel(), m.ravel(), r.ravel()
        return {"alpha": a, "beta": b, "sigma": np.arccos(np.cos(a) * np.cos(b)), "mach": m,
                "reynolds": np.full_like(a, 1e6), "p_hat": r, "q_hat": r, "r_hat": r,
                "phi": np.arctan2(np.sin(b), np.sin(a) * np.cos(b))}

    def check_finite(self) -> None:
        """Refuse a form with a constant term that is not finite (``1/0``, ``exp(1000)``) or
        that is not finite at any of :meth:`check_points` with the current values
        (``log(-mach)``): :class:`ModelFileError` naming the coefficient and the term."""
        pts = self.check_points()
        pmap = {p.name: p.value for p in self.parameters}
        for k, tree in self._trees.items():
            const = nonfinite_constant(tree)
            if const is not None:
                raise ModelFileError(f"coefficients.{k}: the term {to_text(const[0])} is "
                                     f"{const[1]} (not a finite number)")
            bad = nonfinite_origin(tree, pts, pmap, everywhere=True)
            if bad is not None:
                v = np.ravel(bad[1])[0]
                raise ModelFileError(
                    f"coefficients.{k}: not finite at any of the check points (alpha "
                    f"{min(CHECK_ALPHA)}..{max(CHECK_ALPHA)} rad, Mach {min(CHECK_MACH)}.."
                    f"{max(CHECK_MACH)}, the parameters' values): the term "
                    f"{to_text(bad[0])} is {v}")

    def nonfinite_note(self, params=None, points: dict | None = None) -> str:
        """``""`` when every coefficient is finite at ``points`` (variable name -> (n,) array;
        default :meth:`check_points`) with ``params`` (default :meth:`values`), else ``";
        coefficient CD is not finite at alpha=.., mach=..: the term exp(1000.0 * mach) is
        inf"`` (for a fit's or a simulation's failure message)."""
        p = self.values() if params is None else np.asarray(params, dtype=float)
        pts = self.check_points() if points is None else {
            k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in points.items()}
        pmap = dict(zip(self.names, p.tolist(), strict=True))
        for k, tree in self._trees.items():
            bad = nonfinite_origin(tree, pts, pmap, everywhere=False)
            if bad is not None:
                i = int(np.argmax(~np.isfinite(np.broadcast_to(bad[1], pts["alpha"].shape))))
                at = ", ".join(f"{n}={pts[n][i]:.3g}" for n in ("alpha", "beta", "mach"))
                v = np.broadcast_to(bad[1], pts["alpha"].shape)[i]
                return (f"; coefficient {k} is not finite at {at}: the term "
                        f"{to_text(bad[0])} is {v}")
        return ""

    # --- evaluation ----------------------------------------------------------------------

    def compile(self) -> AeroProgram:
        """The compiled program (cached; shared by copies that differ only in values)."""
        prog = self._cache.get("program")
        if prog is None:
            prog = compile_program(self._trees, self.names, self.angle_plane,
                                   self.moment_reference)
            self._cache["program"] = prog
        return prog

    def evaluate(self, alpha, beta, sigma, mach, reynolds=0.0, p_hat=0.0, q_hat=0.0,
                 r_hat=0.0, phi=0.0, *, params=None) -> dict:
        """The 9 coefficients at (arrays of) points, with the compiled numba program.

        Inputs broadcast against each other; angles in radians. ``sigma=None`` computes
        ``arccos(cos(alpha) cos(beta))``; ``phi`` is the aerodynamic roll angle
        (docs/conventions.md; 0 by default). ``params`` overrides :meth:`values`. Any complex
        input gives complex results (complex step). Returns ``{name: array}`` in the order of
        :data:`cadra.aero.program.COEFFICIENTS` (numpy scalars for scalar inputs).
        """
        if sigma is None:
            sigma = np.arccos(np.cos(alpha) * np.cos(beta))
        arrays = [np.asarray(a) for a in (alpha, beta, sigma, mach, reynolds, p_hat, q_hat,
                                          r_hat, phi)]
        p = self.values() if params is None else np.asarray(params)
        if p.shape != (len(self.parameters),):
            raise ValueError(f"params must have shape ({len(self.parameters)},), "
                             f"got {p.shape}")
        complex_ = any(np.iscomplexobj(a) for a in (*arrays, p))
        dtype = np.complex128 if complex_ else np.float64
        b = np.broadcast_arrays(*arrays)
        shape = b[0].shape
        n = int(np.prod(shape))
        var = np.empty((n, N_VARIABLES), dtype=dtype)
        for j, a in enumerate(b):
            var[:, j] = a.reshape(-1)
        out = np.empty((n, N_COEFFICIENTS), dtype=dtype)
        prog = self.compile()
        eval_coefficients_batch(prog.ops, prog.args, prog.starts, var,
                                np.ascontiguousarray(p, dtype=dtype), out, prog.new_stack(dtype))
        if shape == ():
            return {k: out[0, j] for j, k in enumerate(COEFFICIENTS)}
        return {k: out[:, j].reshape(shape) for j, k in enumerate(COEFFICIENTS)}

    # --- file form -----------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The TOML-ready dictionary :func:`save_model` writes (file units)."""
        params = {}
        for p in self.parameters:
            d = {"value": _to_file(p.value, p.unit), "vary": p.vary}
            if p.min != -math.inf:
                d["min"] = _to_file(p.min, p.unit)
            if p.max != math.inf:
                d["max"] = _to_file(p.max, p.unit)
            if p.unit:
                d["unit"] = p.unit
            if p.note:
                d["note"] = p.note
            if p.sigma > 0.0:
                d["sigma"] = p.file_sigma
            if p.prior is not None:
                d["prior"] = _to_file(p.prior, p.unit)
            params[p.name] = d
        out = {"format": FILE_FORMAT, "name": self.name}
        if self.description:
            out["description"] = self.description
        out["angle_plane"] = self.angle_plane
        out["moment_reference"] = self.moment_reference
        if self.reference:
            out["reference"] = dict(self.reference)
        out["coefficients"] = dict(self.coefficients)
        out["parameters"] = params
        return out


def model_from_dict(data: Mapping, source: str = "model") -> AeroModel:
    """An :class:`AeroModel` from the file dictionary (see docs/aero_models.md).

    Errors are ``ValueError`` s that start with ``source`` and name the offending key.
    """
    try:
        model = _model_from_dict(data, source)
        model.check_finite()
        return model
    except ExpressionError as exc:
        raise exc.prefixed(source) from None
    except ValueError as exc:
        raise ModelFileError(f"{source}: {exc}") from None


def _model_from_dict(data: Mapping, source: str) -> AeroModel:
    _F.check_unknown(data, _MODEL_KEYS)
    fmt = data.get("format", FILE_FORMAT)
    if fmt != FILE_FORMAT:
        raise ValueError(f"format: {fmt!r} is not {FILE_FORMAT!r}")
    for k in ("angle_plane", "coefficients", "parameters"):
        _F.require(data, k)
    coefficients = data["coefficients"]
    if not isinstance(coefficients, Mapping):
        raise ValueError("coefficients: must be a table of name = \"expression\"")
    ptable = data["parameters"]
    if not isinstance(ptable, Mapping):
        raise ValueError("parameters: must be a table of name = { value = ..., vary = ... }")
    params = []
    for name, entry in ptable.items():
        key = f"parameters.{name}"
        if not isinstance(entry, Mapping):
            raise ValueError(f"{key}: must be a table such as {{ value = 1.0, vary = true }}")
        _F.check_unknown(entry, _PARAM_KEYS, f"{key}.")
        _F.require(entry, "value", f"{key}.")
        unit = entry.get("unit", "")
        if unit not in UNITS:
            raise ValueError(f"{key}.unit: must be one of {sorted(UNITS)}, got {unit!r}")
        conv = {}
        for k, default in (("value", None), ("min", -math.inf), ("max", math.inf),
                           ("sigma", 0.0)):
            v = entry.get(k, default)
            if not _is_number(v):
                raise ValueError(f"{key}.{k}: must be a number, got {v!r}")
            if isinstance(v, int) and abs(v) > 2**1023:
                raise ValueError(f"{key}.{k}: integer of {len(str(abs(v)))} digits is too "
                                 "large for a float64")
            conv[k] = _from_file(float(v), unit)
        vary = entry.get("vary", True)
        if not isinstance(vary, bool):
            raise ValueError(f"{key}.vary: must be true or false, got {vary!r}")
        note = entry.get("note", "")
        if not isinstance(note, str):
            raise ValueError(f"{key}.note: must be a string")
        prior = entry.get("prior")
        if prior is not None:
            if not _is_number(prior):
                raise ValueError(f"{key}.prior: must be a number, got {prior!r}")
            prior = _from_file(float(prior), unit)
        params.append(Parameter(name=str(name), value=conv["value"], vary=vary,
                                min=conv["min"], max=conv["max"], unit=unit, note=note,
                                sigma=conv["sigma"], prior=prior))
    name = data.get("name", Path(source).stem)
    if not isinstance(data.get("reference", {}), Mapping):
        raise ValueError("reference: must be a table of name = value")
    return AeroModel(
        name=name, angle_plane=data["angle_plane"], coefficients=dict(coefficients),
        parameters=tuple(params), description=data.get("description", ""),
        reference=dict(data.get("reference", {})),
        moment_reference=data.get("moment_reference", "cg"),
    )


def load_model(path: str | os.PathLike) -> AeroModel:
    """Read an aerodynamic model file (TOML; docs/aero_models.md); errors name the file and
    the key."""
    path = Path(path)
    data = read_toml(path, ModelFileError, read_error=FileNotFoundError)
    data.setdefault("name", path.stem)
    return model_from_dict(data, source=str(path))


def save_model(model: AeroModel, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``model`` as TOML, atomically (:func:`cadra.atomic.atomic_write_text`).

    Refuses to replace an existing file unless ``overwrite=True`` (``FileExistsError``).
    Returns the path written.
    """
    text = ("# CADRA aerodynamic model (docs/aero_models.md), written by "
            "cadra.aero.save_model\n" + tomli_w.dumps(model.to_dict()))
    return atomic_write_text(path, text, overwrite=overwrite)


class ModelNotFoundError(KeyError, ValueError):
    """No bundled aero model, or no model file, by the name given (the message says which and
    lists the bundled names). A ``KeyError`` (a name looked up) and a ``ValueError`` (an input
    refused)."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


def bundled_model_names() -> tuple[str, ...]:
    """Names of the model files shipped in ``cadra/aero/models``."""
    return tuple(sorted(p.stem for p in MODELS_DIR.glob("*.toml")))


def bundled_model_table() -> list[dict]:
    """One row per bundled model: ``name``, ``case`` (the paper's case it reproduces, or
    "—"), ``plane`` (its angle plane), ``free`` (its free parameters' names) and
    ``description``."""
    rows = []
    for name in bundled_model_names():
        m = resolve_model(name)
        rows.append({"name": name, "case": str(m.reference.get("case", "—")),
                     "plane": m.angle_plane, "free": m.free_names(),
                     "description": m.description})
    return rows


def is_model_path(name_or_path: str | os.PathLike) -> bool:
    """Whether ``name_or_path`` names a model file rather than a bundled model: a ``Path``, or
    text with a directory part or a suffix (``"models/m.toml"``, ``"m.toml"``, ``"./m"``)."""
    if isinstance(name_or_path, os.PathLike):
        return True
    p = Path(name_or_path)
    return bool(p.suffix) or len(p.parts) != 1 or str(name_or_path) != p.name


def resolve_model_path(name_or_path: str | os.PathLike, base_dir: str | os.PathLike | None = None
                       ) -> Path:
    """The file of an aero model given as a bundled name or a path (:func:`is_model_path`).

    A bundled name (``"m2_m070"``) is looked up in :data:`MODELS_DIR` only. A path is that
    file -- relative paths are tried against ``base_dir`` first (e.g. the directory of the
    spec that names the model), then the working directory -- and never falls back to a
    bundled model of the same stem. Raises :class:`ModelNotFoundError` saying what was tried.
    """
    bundled = bundled_model_names()
    if not is_model_path(name_or_path):
        path = MODELS_DIR / f"{name_or_path}.toml"
        if path.is_file():
            return path
        raise ModelNotFoundError(f"no bundled aero model {str(name_or_path)!r} (bundled: "
                                 f"{', '.join(bundled)}; a model file is given by its path)")
    p = Path(name_or_path)
    tried = [Path(base_dir) / p] if base_dir is not None and not p.is_absolute() else []
    tried.append(p)
    for c in tried:
        if c.is_file():
            return c
    hint = (f"; the bundled model {p.stem!r} is named without a directory or suffix"
            if p.stem in bundled else "")
    raise ModelNotFoundError(f"aero model file {str(name_or_path)!r} not found (looked at "
                             f"{', '.join(str(c) for c in tried)}){hint}")


def resolve_model(name_or_path: str | os.PathLike, base_dir: str | os.PathLike | None = None
                  ) -> AeroModel:
    """An aero model from a bundled name (``"m2_m070"``) or a model file path: the one
    resolver of model names (:func:`resolve_model_path`)."""
    return load_model(resolve_model_path(name_or_path, base_dir))


def load_bundled_model(name: str) -> AeroModel:
    """A bundled model by name (e.g. ``"m2_m070"``); :class:`ModelNotFoundError` (a
    ``KeyError``) naming the bundled models if there is none."""
    if is_model_path(name):
        raise ModelNotFoundError(f"{name!r} is a path, not a bundled model name (bundled: "
                                 f"{', '.join(bundled_model_names())})")
    return resolve_model(name)
