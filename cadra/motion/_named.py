"""Reading a motion fit's estimates by name."""

from __future__ import annotations


class ByName:
    """``value(name)`` and ``sigma(name)`` of a result whose ``values`` and ``sigmas`` follow
    its ``names``."""

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def sigma(self, name: str) -> float:
        return float(self.sigmas[self.names.index(name)])
