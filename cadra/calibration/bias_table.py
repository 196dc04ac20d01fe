"""Correcting shots by a station bias table named as a user names it: ``"current"`` (the latest
entry of the facility's station history) or a bias-table CSV (docs/calibration.md).

What ``cadra2 fit --bias-table`` and ``cadra2 calibrate`` do before their work, as library
functions::

    facility = shots_facility(shots)                       # the one facility they come from
    shots, note = correct_by_bias_table(shots, "current")          # the history calibrate wrote
"""

from __future__ import annotations

import os
from collections.abc import Sequence

from cadra.calibration.history import current_table, load_bias_table, load_history
from cadra.calibration.sphere import apply_bias_table
from cadra.flight.data import ShotData

#: the ``table`` of :func:`correct_by_bias_table` that means "the history's latest entry"
CURRENT = "current"


def shot_facility(shot: ShotData) -> str:
    """The facility (name or path, as its shot's record gives it) a shot was measured in:
    the shot data's own, else its shot file's."""
    if shot.facility:
        return shot.facility
    if "shot_file" not in shot.source:
        raise ValueError(f"{shot.shot_id}: the facility it was measured in is not known "
                         "(give ShotData.facility)")
    from cadra.io.shotfile import load_shot

    return load_shot(shot.source["shot_file"]).facility


def shots_facility(shots: Sequence[ShotData], error: type[Exception] = ValueError) -> str:
    """The one facility all ``shots`` come from; ``error`` if they come from several."""
    facilities = {shot_facility(s) for s in shots}
    if len(facilities) != 1:
        raise error(f"the shots come from several facilities {sorted(facilities)}")
    return facilities.pop()


def correct_by_bias_table(shots: Sequence[ShotData], table: str | os.PathLike,
                          stations_root: str | os.PathLike | None = None
                          ) -> tuple[list[ShotData], str]:
    """The shots corrected by a station bias table, and a note for the report.

    ``table`` is :data:`CURRENT` (the latest complete entry of
    ``<stations_root>/stations/<facility>/``; ``stations_root`` resolved as ``cadra2
    calibrate`` resolves it, :func:`cadra.calibration.history.stations_root`, so the fit
    reads the history the
    calibration wrote, whatever the working folder)
    or a bias-table CSV, which must be of the shots' facility
    (:func:`cadra.calibration.sphere.apply_bias_table` applies it). Raises ``ValueError``
    saying what does not fit. The history's warnings (a torn last line of an interrupted
    append, skipped) are in the note, which the fit's report and console carry.
    """
    facility = shots_facility(shots)
    from cadra.calibration.history import stations_root as resolve_stations_root

    root = resolve_stations_root(stations_root)
    warnings: list[str] = []
    if str(table) == CURRENT:
        history, warnings = load_history(root, facility)
        bias = current_table(history)
        if bias is None:
            raise ValueError(f"--bias-table current: no station history for facility "
                             f"{facility!r} under {root / 'stations'}")
        source = (f"{root / 'stations' / facility / 'bias_history.jsonl'}, "
                  + (f"latest complete entry ({len(history)}; the history warns: "
                     f"{'; '.join(warnings)})" if warnings else "latest entry"))
    else:
        bias = load_bias_table(table)
        source = str(table)
    if bias.facility != facility:
        raise ValueError(f"bias table of facility {bias.facility!r} given for shots of "
                         f"facility {facility!r}")
    note = (f"station bias table applied: {source} (created {bias.created_utc}, from shots "
            f"{', '.join(bias.shots)})")
    return [apply_bias_table(s, bias) for s in shots], note


__all__ = ["CURRENT", "correct_by_bias_table", "shot_facility", "shots_facility"]
