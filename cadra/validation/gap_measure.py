"""Stage-one-like measurements of a simulated shot, for the gap validation.

A simulated shot's truth turned into the measurements stage one would give (its precision:
0.28 um in position for a capsule, 0.22 um for a sphere, 0.0012 deg in angle), optionally
translated by a lateral launch offset, with a measurement edit applied: a function of the
measurement array (a station's position bias, angle biases), or a tuple naming a station's
timing bias or optical scale error, which :func:`measure` applies from the truth's velocity or
position at that station.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

__all__ = ["SA_DEG", "SP", "SP_SPHERE", "measure"]

#: stage one's precision: position (m) of a capsule or a cone, of a sphere; angle (deg)
SP, SP_SPHERE, SA_DEG = 2.8e-7, 2.2e-7, 0.0012


def measure(sim, nominal, spec, seed, edit, offset=(0.0, 0.0)):
    """Stage-one-like measurements of a simulated shot, with a measurement edit applied;
    ``offset``: (y, z) m by which the whole path is translated (a lateral launch offset);
    ``seed`` None: without noise. ``edit``: None, a function of the measurement array, or
    ``("timing", station row, dt)`` (the spark fired dt after its recorded time) or
    ``("scale", station row, s)`` (the station's scale off by s about its optical centre)."""
    from cadra.flight import shot_data_from_truth

    sphere = sim.body.kind == "sphere"
    truth = sim.truth.copy()
    truth["y_m"] += offset[0]
    truth["z_m"] += offset[1]
    sd = shot_data_from_truth(truth, nominal, spec.shot_id, sim.body.kind,
                              sigma_position_m=SP_SPHERE if sphere else SP,
                              sigma_angle_rad=math.radians(SA_DEG),
                              rng=None if seed is None else np.random.default_rng(seed))
    if edit is None:
        return sd
    meas = sd.meas.copy()
    if isinstance(edit, tuple):
        kind, st, v = edit
        if kind == "timing":      # the spark fired v after its recorded time
            meas[st, :3] += truth[["vx_m_s", "vy_m_s", "vz_m_s"]].to_numpy()[st] * v
        else:                     # scale about the station's optical centre (x_station, 0, 0)
            c = np.array([truth["x_m"].iloc[st], 0.0, 0.0])
            meas[st, :3] += v * (truth[["x_m", "y_m", "z_m"]].to_numpy()[st] - c)
    else:
        meas = edit(meas)
    return replace(sd, meas=meas)
