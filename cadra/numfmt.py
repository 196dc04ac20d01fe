"""The one look of a value with its sigma, wherever CADRA shows one: the console (``cadra1``,
``cadra2``), the fit, calibration, gap and study reports (docs/cli.md).

:func:`pm` gives sigma to 2 significant digits and the value to the same decimal place
(``-1.5575 ± 0.0065``), and a plain word where a number is not determined instead of
``nan ± nan``. Pure formatting, no I/O: every layer may import it.
"""

from __future__ import annotations

import math


def pm(value: float | None, sigma: float | None = None, unit: str = "") -> str:
    """``value ± sigma [unit]``.

    sigma to 2 significant digits and the value to the same decimal place (for sigmas from
    1e-8 to 99; beyond, 4 and 2 significant digits); ``value [unit]`` (6 significant digits)
    when ``sigma`` is None, ``value ± 0`` when it is 0 or below; ``not determined`` for a
    non-finite or None value and ``value [unit] (σ not determined)`` for a non-finite sigma.
    """
    u = f" {unit}" if unit else ""
    if value is None or not math.isfinite(value):
        return "not determined"
    if sigma is None:
        return f"{value:.6g}{u}"
    if not math.isfinite(sigma):
        return f"{value:.6g}{u} (σ not determined)"
    if sigma <= 0:
        return f"{value:.6g} ± 0{u}"
    place = math.floor(math.log10(sigma)) - 1
    if -8 <= place <= 0:
        dec = -place
        return f"{value:.{dec}f} ± {sigma:.{dec}f}{u}"
    return f"{value:.4g} ± {sigma:.2g}{u}"


__all__ = ["pm"]
