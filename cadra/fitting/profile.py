"""Profile likelihood of one parameter of a fit: the honest interval where chi^2 is not quadratic.

A fit's sigma (the covariance at its minimum) describes chi^2 only as far as chi^2 is quadratic
in the unknowns. When the data fix a parameter only through a curved or flat valley -- an
inertia asymmetry traded against a freed roll angle of a body that swings in one plane
(docs/gap.md) -- that sigma can be orders of magnitude too small. The profile holds the
parameter at a sequence of values and refits every other unknown at each (warm-started from
the neighbouring point, outward from the fit on each side, steps growing geometrically from
twice the fit's sigma); the interval is where the profiled chi^2 stays within ``level`` of its
minimum (4: the two-sigma, ~95 % interval of one parameter), the level scaled by the reduced
chi^2 when that exceeds 1, as the sigmas are. Where chi^2 is quadratic it is the fit's
+-2 sigma; where it is not, it is what the data say.

The parameter is a free aero parameter of the fit's model (held through ``vary``) or one of
its extras (held through :attr:`cadra.fitting.extras.Extra.held`). A point of the profile below
the fit's own chi^2 (the fit sat in a shallower minimum) becomes the profile's minimum.

Pure function over plain data (shots, a result): ships to a scheduler like a fit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from cadra.fitting.result import FitResult
from cadra.fitting.sensitivity import LOCAL_NAMES, N_LOCAL, apply_local
from cadra.fitting.solver import FitOptions, fit
from cadra.flight.data import ShotData

#: convergence control of the profile's held fits (warm-started a step away: they settle fast)
PROFILE_OPTIONS = FitOptions(max_iterations=30)
#: extra starting roll angles (rad, about the body axis) of the held fits of a fit that frees
#: a shot's roll: an asymmetry held at a new size moves the roll the fit wants, and a fit that
#: sits where the roll's effect is stationary (cos 2 phi = +-1 for an inertia asymmetry) sees
#: no gradient to leave it; one start each side breaks that symmetry
ROLL_STARTS_RAD = (math.radians(15.0), -math.radians(15.0))
#: refinement fits per side once the profile has crossed the level (safeguarded secant)
REFINE_FITS = 3


@dataclass(frozen=True, eq=False)
class Profile:
    """A parameter's profile likelihood (SI, the parameter's own unit)."""

    name: str
    values: np.ndarray          # the values held, sorted
    chi2: np.ndarray            # the profiled chi^2 at each
    best_value: float           # the lowest point (the fit's value unless a lower one was found)
    best_chi2: float
    lower: float                # the interval: chi^2 - best_chi2 <= threshold; -inf / inf
    upper: float                # where the profile never rose that far within the steps taken
    threshold: float            # level times max(1, reduced chi^2)
    n_fits: int
    n_unsettled: int = 0        # held fits that stalled or ran out of iterations: where they
    #                             did, the profile is an upper bound on the true one and the
    #                             interval may be too narrow

    @property
    def closed(self) -> bool:
        return math.isfinite(self.lower) and math.isfinite(self.upper)


def _held_fit(prev: FitResult, shots_by_id: dict, name: str, value: float,
              options: FitOptions) -> FitResult | None:
    """``prev``'s fit redone with ``name`` held at ``value``, from ``prev``'s solution."""
    model = prev.model
    extras = prev.extras_at_values()
    names = [e.name for e in extras]
    if name in names:
        k = names.index(name)
        extras[k] = replace(extras[k], value=float(value), held=True)
    else:
        model = model.with_values({name: float(value)}).with_vary({name: False})
    local = [sf.local_free_indices for sf in prev.shots]
    rot_x = LOCAL_NAMES.index("rot_x_rad")
    starts = [0.0] + (list(ROLL_STARTS_RAD) if any(rot_x in lf for lf in local) else [])
    best = None
    for roll in starts:
        if best is not None and best.status == "converged":
            break           # the warm start settled: no need for the other rolls
        states = []
        for sf, lf in zip(prev.shots, local, strict=True):
            u = np.zeros(N_LOCAL)
            if rot_x in lf:
                u[rot_x] = roll
            states.append(apply_local(sf.state, u))
        try:
            res = fit([shots_by_id[sf.shot_id] for sf in prev.shots], model, states,
                      options=options, local_free=local, extras=extras)
        except (ValueError, FloatingPointError):
            continue
        if res.status != "failed" and math.isfinite(res.chi2) and (
                best is None or res.chi2 < best.chi2):
            best = res
    return best


def _crossing(v_in, d_in, v_out, d_out, threshold):
    """Where the profile crosses ``threshold`` between an inside and an outside point
    (interpolated in sqrt(dchi^2), linear in the value for a quadratic profile)."""
    u_in, u_out = math.sqrt(max(d_in, 0.0)), math.sqrt(max(d_out, 0.0))
    if u_out <= u_in:
        return v_out
    f = (math.sqrt(threshold) - u_in) / (u_out - u_in)
    return v_in + min(max(f, 0.0), 1.0) * (v_out - v_in)


def profile_parameter(result: FitResult, shots: Sequence[ShotData], name: str, *,
                      level: float = 4.0, grow: float = 3.0, max_steps: int = 8,
                      options: FitOptions = PROFILE_OPTIONS) -> Profile:
    """Profile likelihood of ``name`` (a free aero parameter or extra of ``result``) over the
    data ``shots`` (module doc). At most ``max_steps`` held fits per side plus
    :data:`REFINE_FITS` refinements of the crossing; the first step is twice the fit's sigma
    (or a tenth of the value where the sigma is not usable), each next one ``grow`` times the
    last. A fit that frees a shot's roll angle gets a held fit that does not converge from the
    warm start redone from the starting rolls :data:`ROLL_STARTS_RAD` (the lowest chi^2
    kept). ``n_unsettled`` counts the held fits that still did not converge: the profile is
    then only an upper bound on chi^2 there, and the interval may be too narrow."""
    if level <= 0 or grow <= 1 or max_steps < 1:
        raise ValueError("profile_parameter: level > 0, grow > 1 and max_steps >= 1 needed")
    if name not in result.extra_names and name not in result.aero_names:
        raise ValueError(f"profile_parameter: {name!r} is not a free parameter of the fit "
                         f"(free: {', '.join(result.aero_names + result.extra_names)})")
    by_id = {s.shot_id: s for s in shots}
    missing = [sf.shot_id for sf in result.shots if sf.shot_id not in by_id]
    if missing:
        raise ValueError(f"profile_parameter: no data for shot(s) {', '.join(missing)}")
    v0, s0 = result.value(name), result.sigma(name)
    if not (math.isfinite(s0) and s0 > 0):
        s0 = 0.1 * abs(v0) if v0 != 0 else 1e-12
    threshold = level * max(1.0, result.reduced_chi2 if result.dof > 0 else 1.0)
    pts = [(v0, result.chi2)]
    n_fits = n_unsettled = 0

    def held(prev, v):
        """The held fit at ``v`` from ``prev``, recorded: (fit, dchi^2 from the fit) or
        (None, inf) when it failed."""
        nonlocal n_fits, n_unsettled
        r = _held_fit(prev, by_id, name, v, options)
        n_fits += 1
        if r is None:
            return None, math.inf
        n_unsettled += r.status != "converged"
        pts.append((v, r.chi2))
        return r, r.chi2 - result.chi2

    for side in (-1.0, 1.0):
        prev, inside = result, (v0, 0.0)
        step = 2.0 * s0
        for _ in range(max_steps):
            v = v0 + side * step
            r, d = held(prev, v)
            if r is None:
                break
            if d >= threshold:
                # refine the crossing inside the bracket (secant in sqrt(dchi^2), kept off
                # the bracket's ends), each fit warm-started from the bracket's inner end
                outside = (v, d)
                for _ in range(REFINE_FITS):
                    vc = _crossing(inside[0], inside[1], outside[0], outside[1], threshold)
                    lo_v, hi_v = sorted((inside[0], outside[0]))
                    w = hi_v - lo_v
                    vc = min(max(vc, lo_v + 0.1 * w), hi_v - 0.1 * w)
                    rc, dc = held(prev, vc)
                    if rc is None:
                        break
                    if dc >= threshold:
                        outside = (vc, dc)
                    else:
                        prev, inside = rc, (vc, dc)
                    if abs(dc - threshold) < 0.1 * threshold:
                        break
                break
            prev, inside = r, (v, d)
            step *= grow
    vals = np.array([p[0] for p in pts])
    chi2 = np.array([p[1] for p in pts])
    order = np.argsort(vals, kind="stable")
    vals, chi2 = vals[order], chi2[order]
    i_best = int(np.argmin(chi2))
    dchi = chi2 - chi2[i_best]
    bounds = []
    for direction in (-1, 1):
        i = i_best
        while 0 <= i + direction < vals.size and dchi[i + direction] <= threshold:
            i += direction
        j = i + direction
        if 0 <= j < vals.size:
            bounds.append(_crossing(vals[i], dchi[i], vals[j], dchi[j], threshold))
        else:
            bounds.append(direction * math.inf)
    return Profile(name=name, values=vals, chi2=chi2, best_value=float(vals[i_best]),
                   best_chi2=float(chi2[i_best]), lower=float(bounds[0]),
                   upper=float(bounds[1]), threshold=float(threshold), n_fits=n_fits,
                   n_unsettled=n_unsettled)


__all__ = ["PROFILE_OPTIONS", "Profile", "profile_parameter"]
