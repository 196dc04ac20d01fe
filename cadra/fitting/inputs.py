"""Stage two's model settings as a user names them: holds, frees and bounds of the model's
parameters in the model file's units.

What ``cadra2`` does with ``--hold``, ``--free`` and ``--bound`` before fitting, as library
functions (docs/fitting.md)::

    model = apply_holds(resolve_model("m2_m070"), hold=["alpha_ref=21.21"], free=["Cnr_A1"],
                        bound=["CD_A1=0.5:1.5"])
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from cadra.aero import AeroModel
from cadra.fitting.priors import holds_as_priors


def parse_assignments(items: Iterable[str] | None) -> dict[str, str | None]:
    """``["A=1", "B"]`` -> ``{"A": "1", "B": None}`` (names and values stripped)."""
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        out[name.strip()] = value.strip() if sep else None
    return out


def apply_holds(model: AeroModel, hold: Iterable[str] | None = None,
                free: Iterable[str] | None = None, bound: Iterable[str] | None = None,
                prior: Iterable[str] | None = None) -> AeroModel:
    """``model`` with parameters held, freed and bounded as a user writes them.

    ``hold``: ``"NAME"`` (held at its value, with the model's own uncertainty),
    ``"NAME=VALUE"`` (held at VALUE, exactly) or ``"NAME=VALUE+-SIGMA"`` (``±`` too: held at
    VALUE with the standard uncertainty SIGMA, propagated into the free parameters' sigmas as
    a consider covariance, :mod:`cadra.fitting.consider`); ``free``: ``"NAME"``;
    ``bound``: ``"NAME=LO:HI"`` (either side may be empty: unbounded); ``prior``:
    ``"NAME"`` (free, with a Gaussian prior at its value with the model's own uncertainty)
    or ``"NAME=VALUE+-SIGMA"`` (free, with the prior VALUE ± SIGMA): the Bayesian
    alternative to a hold with an uncertainty (:mod:`cadra.fitting.priors`). Values are in the
    parameter's unit in the model file (degrees for ``alpha_ref``), converted to SI through
    the unit table (:meth:`cadra.aero.Parameter.to_si`). Unknown names raise ``KeyError``,
    malformed values ``ValueError``.
    """
    def si(name: str, text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{name}: {text!r} is not a number") from None
        return model.parameter(name).to_si(value)

    for name, value in parse_assignments(hold).items():
        model = model.with_vary({name: False})
        if value is not None:
            text, sep, sigma = value.replace("±", "+-").partition("+-")
            model = model.with_values({name: si(name, text)})
            model = model.with_sigmas({name: abs(si(name, sigma)) if sep else 0.0})
    for name in free or []:
        model = model.with_vary({name.strip(): True})
    for name, value in parse_assignments(prior).items():
        if value is None:
            model = holds_as_priors(model, [name])
            continue
        text, sep, sigma = value.replace("±", "+-").partition("+-")
        if not sep or not abs(si(name, sigma)) > 0.0:
            raise ValueError(f"--prior {name}: expected NAME=VALUE+-SIGMA with SIGMA > 0")
        model = model.with_priors({name: (si(name, text), abs(si(name, sigma)))})
    for name, value in parse_assignments(bound).items():
        lo, sep, hi = (value or "").partition(":")
        if not sep:
            raise ValueError(f"--bound {name}: expected NAME=LO:HI")
        model = model.with_bounds({name: (si(name, lo) if lo.strip() else -math.inf,
                                          si(name, hi) if hi.strip() else math.inf)})
    return model


def values_to_si(model: AeroModel, name: str, values: Iterable[float]) -> list[float]:
    """Values of parameter ``name`` written in the model file's unit -> SI."""
    p = model.parameter(name)
    return [p.to_si(v) for v in values]


__all__ = ["apply_holds", "parse_assignments", "values_to_si"]
