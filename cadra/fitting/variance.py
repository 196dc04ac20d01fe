"""Variance components: one sigma scale per channel, estimated by the fit itself.

Stage one's sigmas can be wrong by a common factor per channel. This happens when a noise
source shows in the errors but not in the residuals stage one sees. tools/bench_e2e.py
measures such factors on renders: the errors run 1.13 to 1.35 times the reported sigmas,
depending on the channel and the body (docs/stage1.md, "Honesty in whole shots"). A
multi-station fit sees it. Over a set of shots each channel has ~100 residuals, and a
correct weighting gives each channel a chi^2 equal to its share of the degrees of freedom,
the sum of (1 - leverage) over its residuals (:meth:`FitResult.dof_by_channel`).

:func:`fit_variance_components` is the classic iterated estimate (Helmert's, in Förstner's
form). It works in rounds:

1. compute each channel's factor ``f_c = chi^2_c / dof_c``;
2. multiply the channel's sigmas by ``sqrt(f_c)``;
3. refit from the converged point.

The rounds stop when every factor is within 2 % of 1, or after ``max_rounds``. The
coefficient sigmas then carry the noise the data show, channel by channel, not one overall
Birge factor. Each factor has a relative 1-sigma of ``sqrt(2 / dof_c)``, about 0.14 for 100
degrees of freedom.

This is a model of the stage-one errors, not a cure for them, so the result says how far each
channel was rescaled. ``result.options["variance_components"]`` holds the factors with their
sigmas and the chi^2/nu before rescaling. The report prints them. A factor far from 1 is a
finding about stage one.

Pure functions over plain data (shots, model, states).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from cadra import channels as channel_registry
from cadra.fitting.result import FitResult
from cadra.flight.data import ShotData

__all__ = ["channel_variance_factors", "fit_variance_components", "rescale_channels"]

#: rounds stop when every channel's factor is within this of 1
TOLERANCE = 0.02


def channel_variance_factors(result: FitResult) -> dict:
    """Per channel: ``(factor, dof)``, where ``factor = chi^2_c / dof_c`` and ``dof_c`` is
    the sum of (1 - leverage) over the channel's residuals. A channel without residuals, or
    with fewer than one degree of freedom, is left out."""
    r = result.residuals
    dof = result.dof_by_channel()
    out = {}
    for ch in channel_registry.NAMES:
        sel = r["channel"] == ch
        d = dof.get(ch, math.nan)
        if not sel.any() or not (d >= 1.0):
            continue
        chi2 = float(np.sum(r.loc[sel, "normalized"].to_numpy(float) ** 2))
        out[ch] = (chi2 / d, d)
    return out


def rescale_channels(shots, factors: dict) -> list[ShotData]:
    """The shots with each channel's sigmas multiplied by ``sqrt(factor)``."""
    scale = np.ones(channel_registry.N_CHANNELS)
    for ch, f in factors.items():
        scale[channel_registry.NAMES.index(ch)] = math.sqrt(f)
    return [replace(s, sigma=s.sigma * scale) for s in shots]


def fit_variance_components(shots, result: FitResult, options, *, local_free=None,
                            max_rounds: int = 5) -> tuple[FitResult, list[ShotData]]:
    """Refit ``result`` (a converged fit of ``shots``) with per-channel sigma scales estimated
    from its own residuals, in rounds (module doc).

    Returns the final fit and the rescaled shots it used.
    ``result.options["variance_components"]`` records:

    - ``factors``: the cumulative variance factor per channel;
    - ``sigma_scale``: its square root;
    - ``factor_sigma``: the factor's 1-sigma, ``f * sqrt(2 / dof_c)``;
    - ``rounds``: the refits taken;
    - ``reduced_chi2_before``: the fit's chi^2/nu with stage one's own sigmas.
    """
    from cadra.fitting.solver import fit

    cumulative = dict.fromkeys(channel_registry.NAMES, 1.0)
    dof_last = {}
    before = result.reduced_chi2
    current, scaled = result, list(shots)
    rounds = 0                       # refits taken (a refit that fails to converge is not)
    for _ in range(max_rounds):
        factors = channel_variance_factors(current)
        dof_last = {ch: d for ch, (_, d) in factors.items()}
        if all(abs(f - 1.0) <= TOLERANCE for f, _ in factors.values()):
            break
        trial = {ch: cumulative[ch] * f for ch, (f, _) in factors.items()}
        trial_shots = rescale_channels(shots, trial)
        refit = fit(trial_shots, current.model, [sf.state for sf in current.shots],
                    options=options, local_free=local_free, extras=current.extras_at_values())
        if not refit.converged:   # keep the last converged round
            break
        cumulative.update(trial)
        current, scaled = refit, trial_shots
        rounds += 1
    info = {"factors": {ch: cumulative[ch] for ch in dof_last},
            "sigma_scale": {ch: math.sqrt(cumulative[ch]) for ch in dof_last},
            "factor_sigma": {ch: cumulative[ch] * math.sqrt(2.0 / dof_last[ch])
                             for ch in dof_last},
            "dof": dof_last, "rounds": rounds, "reduced_chi2_before": before}
    return replace(current, options={**current.options, "variance_components": info}), scaled
