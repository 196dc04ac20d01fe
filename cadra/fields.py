"""Plain-data fields: typed getters that name the key path, unit-suffixed keys through the unit
table, and reading a TOML file with errors that name the file.

Every file format of CADRA (shot files, facility reference files, shot specifications, body
specs, aero-model files) validates its keys with one :class:`Fields`, bound to the format's
own error class::

    fields = Fields(ShotFileError)
    rng = fields.table(data, "range")                       # "range: missing" / "expected a table"
    fields.check_unknown(rng, {"pressure_torr", "temperature_k"}, "range.")
    p = fields.number(fields.require(rng, "pressure_torr", "range."), "range.pressure_torr")

Messages are ``"<key path>: <what is wrong>"``; :func:`read_toml` and :func:`prefixed_by`
put the file's path in front (``"shot.toml: range.pressure_torr: ..."``).

This module imports nothing of CADRA but :mod:`cadra.units`, so the numerical core's own data
languages (body specs, aero models) use it as the file formats of :mod:`cadra.io` do;
:mod:`cadra.io.toml_file` offers it with the atomic TOML writer.
"""

from __future__ import annotations

import contextlib
import math
import os
import tomllib
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cadra import units


def read_toml(path: str | os.PathLike, error: type[Exception] = ValueError,
              read_error: type[Exception] | None = None) -> dict:
    """Parse the TOML file ``path``.

    Raises ``read_error`` (default ``error``) ``"<path>: cannot read (<why>)"`` when the file
    cannot be read, and ``error`` ``"<path>: not a text file (...)"`` when it is not UTF-8
    and ``"<path>: not valid TOML (<why>)"`` when it does not parse.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise (read_error or error)(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file (not UTF-8: byte 0x{exc.object[exc.start]:02x} "
                    f"at position {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc})") from None
    except RecursionError:
        raise error(f"{path}: not valid TOML (arrays or tables nested too deeply)") from None


@contextlib.contextmanager
def prefixed_by(path: str | os.PathLike, *errors: type[Exception]) -> Iterator[None]:
    """Re-raise any of ``errors`` raised inside as the same class with ``"<path>: "`` in front
    of the message (a key path becomes a file and key path)."""
    try:
        yield
    except errors as exc:
        raise type(exc)(f"{path}: {exc}") from None


def frozen_array(value, shape: tuple[int, ...] | int | None = None) -> np.ndarray:
    """A read-only float64 copy of ``value`` (reshaped to ``shape``): what frozen dataclasses
    hold, so their arrays cannot change under them."""
    a = np.array(value, dtype=float)
    if shape is not None:
        a = a.reshape(shape)
    a.setflags(write=False)
    return a


def _is_number(value) -> bool:
    return (isinstance(value, int | float | np.integer | np.floating)
            and not isinstance(value, bool | np.bool_))


@dataclass(frozen=True)
class Fields:
    """Typed getters for parsed TOML, raising ``error`` (a ``ValueError`` subclass, usually)
    with the offending key path. ``where`` arguments are the key path of the table being read,
    ending in ``"."`` (``"mass."``, ``"stations[2]."``), or ``""`` at top level.
    """

    error: type[Exception] = ValueError

    def fail(self, key: str, message: str) -> Exception:
        """The error ``"<key>: <message>"`` (to raise)."""
        return self.error(f"{key}: {message}")

    def require(self, data: Mapping, key: str, where: str = ""):
        """``data[key]``; ``"<where><key>: missing"`` if absent."""
        if key not in data:
            raise self.fail(f"{where}{key}", "missing")
        return data[key]

    def table(self, data: Mapping, key: str, where: str = "", *,
              required: bool = True) -> Mapping:
        """The sub-table ``data[key]`` (missing: an error if ``required``, else ``{}``)."""
        if key not in data and not required:
            return {}
        return self.as_table(self.require(data, key, where), f"{where}{key}")

    def as_table(self, value, key: str) -> Mapping:
        """``value`` if it is a table, else ``"<key>: expected a table, got <type>"``."""
        if not isinstance(value, Mapping):
            raise self.fail(key, f"expected a table, got {type(value).__name__}")
        return value

    def check_unknown(self, data: Mapping, known, where: str = "") -> None:
        """Refuse keys not in ``known`` (typos): ``"<where><key>: unknown key (known: ...)"``."""
        unknown = sorted(set(data) - set(known), key=str)
        if unknown:
            raise self.fail(f"{where}{unknown[0]}", f"unknown key (known: {sorted(known)})")

    def number(self, value, key: str) -> float:
        """A finite number (not a boolean), as float."""
        if not _is_number(value):
            raise self.fail(key, f"expected a number, got {value!r}")
        if isinstance(value, int) and abs(value) > 2**1023:
            raise self.fail(key, f"integer of {len(str(abs(value)))} digits is too large")
        x = float(value)
        if not math.isfinite(x):
            raise self.fail(key, f"must be finite, got {value!r}")
        return x

    def positive(self, value, key: str, upper: float | None = None) -> float:
        """A finite number > 0 (and <= ``upper``: larger is a unit mistake)."""
        x = self.number(value, key)
        if not x > 0:
            raise self.fail(key, f"must be positive, got {value!r}")
        if upper is not None and x > upper:
            raise self.fail(key, f"{value!r} is implausibly large (> {upper:g}; check the unit)")
        return x

    def in_range(self, value, key: str, lo: float, hi: float, what: str) -> float:
        """A finite number in ``(lo, hi]``; outside, ``"... -- not <what> (check the unit)"``."""
        x = self.number(value, key)
        if not (lo < x <= hi):
            raise self.fail(key, f"{value!r} is outside ({lo:g}, {hi:g}] -- not {what} "
                                 f"(check the unit)")
        return x

    def integer(self, value, key: str, lo: int | None = None, hi: int | None = None) -> int:
        """An integer (not a boolean) in ``[lo, hi]``."""
        if not isinstance(value, int | np.integer) or isinstance(value, bool):
            raise self.fail(key, f"expected an integer, got {value!r}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            if hi is None:
                raise self.fail(key, f"must be >= {lo}, got {value!r}")
            if lo is None:
                raise self.fail(key, f"must be <= {hi}, got {value!r}")
            raise self.fail(key, f"{value!r} outside [{lo}, {hi}]")
        return int(value)

    def string(self, value, key: str, *, empty: bool = True, what: str = "a string") -> str:
        """A string (non-blank unless ``empty``)."""
        if not isinstance(value, str) or (not empty and not value.strip()):
            raise self.fail(key, f"expected {what}, got {value!r}")
        return value

    def vector(self, value, n: int, key: str, form: str = "") -> np.ndarray:
        """``n`` finite numbers as a float array; ``form`` shows the expected layout in the
        message (``" [x, y, z]"``)."""
        if not isinstance(value, list | tuple | np.ndarray) or len(value) != n:
            raise self.fail(key, f"expected {n} numbers{form}, got {value!r}")
        return np.array([self.number(v, f"{key}[{i}]") for i, v in enumerate(value)])

    def unit_value(self, data: Mapping, base: str, quantity: str, where: str = "",
                   default_unit: str | None = None) -> tuple[float | None, str]:
        """The SI value of quantity ``base`` given under one unit-suffixed key (``d_cm``,
        ``d_mm`` or ``d_m`` for a length), converted through :data:`cadra.units.UNITS`.

        Returns ``(value, key)``; when it is absent, ``(None, base + "_" + default_unit)``
        (default: the quantity's first unit in the table), the key to name as missing. Two
        keys for one quantity are refused (``"d_mm: 'd' is given twice (d_cm, d_mm)"``).
        """
        names = list(units.units_of(quantity))
        keys = [f"{base}_{u}" for u in names if f"{base}_{u}" in data]
        if len(keys) > 1:
            raise self.fail(f"{where}{keys[1]}", f"{base!r} is given twice ({', '.join(keys)})")
        if not keys:
            return None, f"{base}_{default_unit or names[0]}"
        key = keys[0]
        x = self.number(data[key], f"{where}{key}")
        return units.to_si(x, key[len(base) + 1:]), key


__all__ = ["Fields", "frozen_array", "prefixed_by", "read_toml"]
