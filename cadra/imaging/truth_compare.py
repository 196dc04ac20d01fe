"""Stage one against a known truth (``cadra1 --truth``): measured minus truth per station and
channel, in the file's units and in the measurement's own sigmas, with the shot-wide means.

A pure function of two tables, so a benchmark, a test or a campaign report can call it on
plain data. The truth is matched to the measurement by its ``station`` column; its channel
columns are the trajectory file's (``x_m, y_m, z_m`` of the reference point, ``theta_deg,
psi_deg``; docs/conventions.md).

Why the shot-wide means matter: stage two fits many stations of a shot at once, so an error
that all stations of a shot share does not average down; ``mean_z`` with its 1-sigma
``1 / sqrt(n)`` (for independent errors of honest sigmas) shows whether there is one.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from cadra import channels as channel_registry
from cadra.stats import chi2_p_value

__all__ = ["TruthComparison", "compare_with_truth"]


class TruthComparison:
    """``per_station``: one row per measured station, ``{c}_error_{unit}`` and
    ``{c}_error_sigma`` per channel (NaN where not measured). ``summary``: one row per channel:
    ``n``, ``mean_error`` and ``rms_error`` (file unit, named in ``unit``), ``mean_z`` (shot-wide
    mean of error / sigma) with ``mean_z_sigma`` = 1/sqrt(n), ``rms_z``, ``max_abs_z`` and
    ``chi2_p`` (the probability of a chi^2 of the z at least this large with n degrees of
    freedom, if the errors were independent with the reported sigmas)."""

    def __init__(self, per_station: pd.DataFrame, summary: pd.DataFrame, unmatched: list[int]):
        self.per_station = per_station
        self.summary = summary
        self.unmatched = unmatched


def compare_with_truth(table: pd.DataFrame, truth: pd.DataFrame, *,
                       roll_period_rad: float = 2.0 * math.pi) -> TruthComparison:
    """Compare a stage-one trajectory table (``station``, ``status``, the value and sigma
    columns of :mod:`cadra.channels`) with a truth table that has a ``station`` column.

    ``roll_period_rad``: the roll error is taken modulo this period (whole turns by default;
    a cruciform finned body's fins look alike, so stage one knows its roll to a quarter turn
    only: ``pi / 2``).

    Failed stations are left out; stations without a truth row are listed in ``unmatched``.
    Raises ``ValueError`` if the truth has no ``station`` column (it cannot be matched).
    """
    if "station" not in truth:
        raise ValueError("the truth table has no 'station' column: it cannot be matched to "
                         "the measured stations")
    measured = table[table["status"] != "failed"] if "status" in table else table
    by_station = truth.drop_duplicates("station").set_index("station")
    stations = measured["station"].to_numpy(int)
    known = np.isin(stations, by_station.index.to_numpy(int))
    unmatched = [int(s) for s in stations[~known]]
    measured = measured[known]
    t = by_station.loc[measured["station"].to_numpy(int)]
    rows = {"station": measured["station"].to_numpy(int)}
    summary = []
    for c in channel_registry.OBSERVED:
        if c.value_column not in measured or c.value_column not in t:
            continue
        m = measured[c.value_column].to_numpy(float)
        s = measured[c.sigma_column].to_numpy(float)
        err = m - t[c.value_column].to_numpy(float)
        if c.periodic:          # whole periods are no error (a roll measured continuously)
            period = float(channel_registry.from_si(roll_period_rad, c.file_unit))
            err = err - period * np.floor((err + 0.5 * period) / period)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(np.isfinite(s) & (s > 0), err / s, np.nan)
        rows[f"{c.name}_error_{c.file_unit}"] = err
        rows[f"{c.name}_error_sigma"] = z
        ok = np.isfinite(z)
        n = int(ok.sum())
        if n == 0:
            continue
        zz, ee = z[ok], err[ok]
        summary.append({
            "channel": c.name, "unit": c.file_unit, "n": n,
            "mean_error": float(ee.mean()), "rms_error": float(np.sqrt(np.mean(ee ** 2))),
            "mean_z": float(zz.mean()), "mean_z_sigma": 1.0 / math.sqrt(n),
            "rms_z": float(np.sqrt(np.mean(zz ** 2))), "max_abs_z": float(np.abs(zz).max()),
            "chi2_p": chi2_p_value(float(np.sum(zz ** 2)), n)})
    return TruthComparison(pd.DataFrame(rows), pd.DataFrame(summary), unmatched)
