"""A fit's parameters as a mapping, in lmfit's manner: ``result.params["Cm_A1"].value``.

:meth:`cadra.fitting.result.FitResult.params` builds a :class:`FitParameters` from what the
fit stored: every aerodynamic parameter of the model (held ones with ``vary=False`` and no
``stderr``), the fit's extra unknowns (effects, station biases) and each shot's initial state
at its epoch (``"<shot id>:<name>"``, :data:`cadra.fitting.sensitivity.LOCAL_NAMES`). Values
are SI (radians for angles); ``stderr`` is the 1-sigma of the covariance ``(J^T W J)^-1``
(``inf`` where the data do not determine it); ``correl`` the correlations with the other
free parameters.

A shot's attitude is fitted as a small rotation about its body axes from the fitted attitude
(``rot_x_rad`` .. ``rot_z_rad``): its value is 0 by construction and its stderr is the
attitude's uncertainty about each body axis.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

from cadra.numfmt import pm


@dataclass(frozen=True)
class FitParameter:
    """One parameter of a fit (module doc)."""

    name: str
    value: float
    stderr: float | None        # None: held (not estimated)
    vary: bool
    min: float = -math.inf
    max: float = math.inf
    init_value: float | None = None
    kind: str = "aero"          # "aero", "extra" or "state"
    correl: Mapping[str, float] = field(default_factory=dict)

    @property
    def sigma(self) -> float | None:
        """``stderr`` under CADRA's name."""
        return self.stderr

    @property
    def at_bound(self) -> bool:
        return self.vary and (self.value <= self.min or self.value >= self.max)

    def __repr__(self) -> str:
        held = "" if self.vary else ", held"
        bound = ", at a bound" if self.at_bound else ""
        return f"<FitParameter {self.name} = {pm(self.value, self.stderr)}{held}{bound}>"


class FitParameters(Mapping[str, FitParameter]):
    """The parameters of a fit by name, in the fit's order (read-only)."""

    def __init__(self, params: list[FitParameter]):
        self._params = {p.name: p for p in params}

    def __getitem__(self, name: str) -> FitParameter:
        try:
            return self._params[name]
        except KeyError:
            raise KeyError(f"no parameter {name!r} in this fit (it has "
                           f"{', '.join(list(self._params)[:8])}"
                           f"{', ...' if len(self._params) > 8 else ''})") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._params)

    def __len__(self) -> int:
        return len(self._params)

    def valuesdict(self) -> dict[str, float]:
        """``{name: value}`` of every parameter (lmfit's ``valuesdict``)."""
        return {n: p.value for n, p in self._params.items()}

    def free(self) -> list[str]:
        """The names of the fitted (free) parameters."""
        return [n for n, p in self._params.items() if p.vary]

    def __repr__(self) -> str:
        n_free = sum(p.vary for p in self._params.values())
        return f"<FitParameters: {len(self)} ({n_free} free)>"


__all__ = ["FitParameter", "FitParameters"]
