"""What to fire next: candidate shots ranked by the information they add (docs/design.md).

The planner starts from a group's fit (its :class:`~cadra.fitting.problem.FitProblem` at the
fitted point, parameters the user wants to learn about freed with ``free``). The group's
information about its shared unknowns (:func:`cadra.fitting.information.problem_information`,
the solver's own Jacobian) is the "now". A candidate (:mod:`cadra.studies.candidates`) is flown
with the same problem's physics at the current estimate; its Jacobian gives the information it
would add, its own initial state profiled out. The predicted covariance after firing it is the
inverse of the sum. Nothing is refitted: the prediction is the linearised one, exact for a
problem linear in its unknowns over the sigmas' scale (``tools/bench_design.py`` checks it by
firing the best candidate in simulation, from images, and refitting).

Criteria (each a variance ratio: 1 is no gain, smaller is better), with ``s_i`` each
unknown's sigma now (its value's magnitude where the group does not determine it yet):

- ``"sigmas"``: the mean of ``(sigma_i / s_i)^2`` over the ``targets`` the user names;
- ``"A"``: the same over every shared unknown (A-optimal, scale-free);
- ``"D"``: ``det(scaled covariance)^(1/n)``, the geometric mean (D-optimal).

The search (:meth:`Planner.plan`): a Latin-hypercube sample of the candidate space and its
corners (an information criterion's optimum often lies at the most extreme conditions
allowed), then a bounded Powell search (scipy) from the best few over the continuous
dimensions at their station count. :func:`sequence` chooses several shots one after
another, each scored with the ones before it added.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

from cadra.fitting.information import (
    RCOND,
    covariance_sigmas,
    problem_information,
    shot_information,
)
from cadra.fitting.problem import FitProblem
from cadra.studies.candidates import (
    DIMENSIONS,
    Candidate,
    CandidateSpace,
    Template,
    candidate_shot,
    template_of,
)

__all__ = ["CRITERIA", "MOVES", "PlanResult", "Planner", "planner", "sequence"]

#: the ranking criteria (module doc)
CRITERIA = ("sigmas", "A", "D")
#: a candidate "moves" an unknown whose predicted sigma is at least this fraction below now's
MOVES = 0.10


@dataclass(frozen=True, eq=False)
class Planner:
    """The group now and what a candidate would add (module doc); build with :func:`planner`."""

    problem: FitProblem
    template: Template
    names: tuple[str, ...]           # the shared unknowns
    values: np.ndarray
    info: np.ndarray                 # the information now
    sigma_now: np.ndarray
    scale: np.ndarray
    criterion: str
    targets: tuple[str, ...]

    def _score(self, sig: np.ndarray, info: np.ndarray) -> float:
        z = sig / self.scale
        if self.criterion == "sigmas":
            idx = [self.names.index(t) for t in self.targets]
            return float(np.mean(z[idx] ** 2))
        if self.criterion == "A":
            return float(np.mean(z ** 2))
        S = info * np.outer(self.scale, self.scale)
        w = np.linalg.eigvalsh(0.5 * (S + S.T))
        w = np.maximum(w, RCOND * max(float(w[-1]), 1e-300))
        return float(math.exp(-np.mean(np.log(w))))

    def candidate_information(self, c: Candidate) -> np.ndarray:
        """The information candidate ``c`` adds (shared unknowns; its own state profiled)."""
        cp = candidate_shot(self.template, c, self.problem)
        sd = cp.shots[0]
        return shot_information(cp.jacobian()[0], sd.sigma, sd.mask, cp.local_free[0].size)

    def evaluate(self, c: Candidate) -> dict:
        """Candidate ``c``'s row: its dimensions, ``objective`` (inf if it cannot be flown),
        ``status`` and the predicted sigma of every shared unknown (``sigma_<name>``)."""
        row = {**c.as_dict(), "objective": math.inf, "status": "ok"}
        try:
            info = self.info + self.candidate_information(c)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
            return {**row, "status": str(exc)}
        _, sig = covariance_sigmas(info)
        row["objective"] = self._score(sig, info)
        row.update({f"sigma_{n}": float(s) for n, s in zip(self.names, sig, strict=True)})
        return row

    def flown_range_deg(self, c: Candidate) -> tuple[float, float]:
        """The smallest and largest total angle of attack, deg, candidate ``c`` flies at its
        stations (what its motion sweeps)."""
        h = candidate_shot(self.template, c, self.problem).histories()[0]
        s = np.degrees(h["air"]["sigma_rad"])
        return float(s.min()), float(s.max())

    @property
    def objective_now(self) -> float:
        _, sig = covariance_sigmas(self.info)
        return self._score(sig, self.info)

    def with_shot(self, c: Candidate) -> Planner:
        """The planner once candidate ``c`` has been fired (its information added; the scale
        stays, so objectives remain comparable)."""
        info = self.info + self.candidate_information(c)
        return replace(self, info=info, sigma_now=covariance_sigmas(info)[1])

    def plan(self, space: CandidateSpace, n_candidates: int = 1000, *, refine: int = 3,
             refine_evaluations: int = 120, n_best: int = 5, seed: int = 0,
             progress: bool = False) -> PlanResult:
        """Rank ``n_candidates`` candidates from ``space`` (a Latin-hypercube sample) and the
        range's corners (when they are at most a quarter as many), then search from the best
        ``refine`` of them with bounded Powell (at most ``refine_evaluations``
        evaluations each); the best ``n_best`` distinct candidates of all that were scored."""
        from tqdm import tqdm

        t0 = time.perf_counter()
        drawn = space.sample(n_candidates, seed)
        corners = space.corners() if 2 ** len(space.varied) <= n_candidates // 4 else []
        rows = [{**self.evaluate(c), "source": "sample" if k < len(drawn) else "corner"}
                for k, c in enumerate(tqdm(drawn + corners, desc="plan: candidates",
                                           unit="shot", disable=not progress))]
        t_sample = time.perf_counter() - t0
        table = pd.DataFrame(rows).sort_values("objective", kind="stable")
        refined = []
        cont = [n for n in space.varied if n != "stations"]
        if cont and refine > 0:
            for _, r in table.head(refine).iterrows():
                refined += self._refine(space, cont, _candidate_of(r), refine_evaluations)
        t_refine = time.perf_counter() - t0 - t_sample
        table = pd.DataFrame(rows + refined).sort_values("objective", kind="stable")
        best = table.loc[~_rounded(table).duplicated()].head(n_best).copy()
        swept = [self.flown_range_deg(_candidate_of(r)) for _, r in best.iterrows()]
        best["flown_min_deg"] = [a for a, _ in swept]
        best["flown_max_deg"] = [b for _, b in swept]
        return PlanResult(planner=self, table=table.reset_index(drop=True),
                          best=best.reset_index(drop=True), space=space,
                          seconds_sample=t_sample, seconds_refine=t_refine,
                          n_sample=len(rows), n_refine=len(refined))

    def _refine(self, space, names, start: Candidate, budget: int) -> list[dict]:
        from scipy.optimize import minimize

        rows: list[dict] = []
        u_start = space.unit(start)

        def cost(u):
            if len(rows) >= budget:
                return 1e30
            c = space.at({**u_start, **dict(zip(names, u, strict=True))})
            row = {**self.evaluate(c), "source": "refine", "stations": start.stations}
            rows.append(row)
            return row["objective"] if math.isfinite(row["objective"]) else 1e30

        minimize(cost, [u_start[n] for n in names], method="Powell",
                 bounds=[(0.0, 1.0)] * len(names),
                 options={"maxfev": budget, "xtol": 1e-3, "ftol": 1e-4})
        return rows


#: candidates closer than this in every dimension count as one in the list of the best
DISTINCT = {"angle_deg": 0.5, "rate_deg_s": 5.0, "mach": 0.01, "roll_deg": 5.0,
            "cg_shift_mm": 0.5, "stations": 1}


def _rounded(table: pd.DataFrame) -> pd.DataFrame:
    return pd.DataFrame({n: np.round(table[n].to_numpy(float) / d) for n, d in DISTINCT.items()},
                        index=table.index)


def _candidate_of(row) -> Candidate:
    return Candidate(**{n: (int(row[n]) if n == "stations" else float(row[n]))
                        for n in DIMENSIONS})


def planner(fit, *, targets=(), criterion: str | None = None, free=(),
            template: str | None = None) -> Planner:
    """The planner of a group's fit (a :class:`~cadra.fitting.result.FitResult` or its
    :class:`FitProblem`): ``targets`` the unknowns whose sigmas to reduce (criterion
    ``"sigmas"``, the default when given; otherwise ``"A"``), ``free`` held parameters to
    treat as unknown (at their held value, without their uncertainty: "could the data fix
    it?"), ``template`` the shot candidates are built from (default: the one with the most
    stations)."""
    problem = getattr(fit, "problem", fit)
    if not isinstance(problem, FitProblem):
        raise ValueError("plan: needs a fit with its fit problem (a FitResult or FitProblem)")
    if free:
        unknown = [n for n in free if n not in problem.model.names]
        if unknown:
            raise ValueError(f"plan: no parameter {unknown[0]!r} in model "
                             f"{problem.model.name}")
        problem = replace(problem, model=problem.model.with_vary({n: True for n in free}))
    criterion = criterion or ("sigmas" if targets else "A")
    if criterion not in CRITERIA:
        raise ValueError(f"plan: criterion must be one of {CRITERIA}, got {criterion!r}")
    names = tuple(problem.param_names[:problem.n_shared])
    missing = [t for t in targets if t not in names]
    if missing:
        raise ValueError(f"plan: {missing[0]!r} is not a free unknown of the fit (free: "
                         f"{', '.join(names)}; a held one can be freed with free=)")
    if criterion == "sigmas" and not targets:
        raise ValueError("plan: the 'sigmas' criterion needs the unknowns to target")
    values = problem.theta0[:problem.n_shared]
    info = problem_information(problem)
    _, sig = covariance_sigmas(info)
    scale = np.where(np.isfinite(sig) & (sig > 0), sig, np.maximum(np.abs(values), 1e-12))
    return Planner(problem=problem, template=template_of(problem, template), names=names,
                   values=values, info=info, sigma_now=sig, scale=scale, criterion=criterion,
                   targets=tuple(targets))


@dataclass(frozen=True, eq=False)
class PlanResult:
    """A plan (:meth:`Planner.plan`): every scored candidate (``table``) and the best."""

    planner: Planner
    table: pd.DataFrame
    best: pd.DataFrame
    space: CandidateSpace
    seconds_sample: float
    seconds_refine: float
    n_sample: int
    n_refine: int

    @property
    def best_candidate(self) -> Candidate:
        return _candidate_of(self.best.iloc[0])

    @property
    def sampled(self) -> pd.DataFrame:
        return self.table[self.table["source"] == "sample"]

    def moves(self, row) -> list[tuple[str, float]]:
        """What candidate ``row`` is good for: (unknown, fractional drop of its sigma) where
        it drops by at least :data:`MOVES`, largest first."""
        p = self.planner
        out = []
        for n, s in zip(p.names, p.sigma_now, strict=True):
            new = row.get(f"sigma_{n}", math.nan)
            drop = 1.0 if not math.isfinite(s) and math.isfinite(new) else (
                1.0 - new / s if math.isfinite(s) and s > 0 else 0.0)
            if drop >= MOVES:
                out.append((n, float(drop)))
        return sorted(out, key=lambda t: -t[1])

    def sigmas(self) -> pd.DataFrame:
        """Per shared unknown: its value, sigma now, and the predicted sigma after each of
        the best candidates (``best_1`` ...)."""
        p = self.planner
        out = pd.DataFrame({"parameter": p.names, "value": p.values, "sigma_now": p.sigma_now})
        for i, r in self.best.iterrows():
            out[f"best_{i + 1}"] = [r[f"sigma_{n}"] for n in p.names]
        return out

    def report(self) -> str:
        """The plan as text (what ``cadra2 plan`` prints)."""
        p = self.planner
        what = (f"the sigmas of {', '.join(p.targets)}" if p.criterion == "sigmas"
                else f"the whole covariance ({p.criterion}-optimal)")
        lines = [f"plan: {self.n_sample} candidates sampled ({self.seconds_sample:.1f} s) and "
                 f"{self.n_refine} scored by the search ({self.seconds_refine:.1f} s) from "
                 f"template {p.template.shot.shot_id}, to reduce {what}; objective now "
                 f"{p.objective_now:.4g} (a variance ratio: 1 = no gain)"]
        for i, r in self.best.iterrows():
            desc = ", ".join(f"{n} {r[n]:.4g}" for n in DIMENSIONS)
            moved = ", ".join(f"{n} -{100 * d:.0f} %" for n, d in self.moves(r)) or "nothing"
            lines.append(f"  {i + 1}. objective {r['objective']:.4g}: {desc}; its motion "
                         f"sweeps {r['flown_min_deg']:.1f}-{r['flown_max_deg']:.1f} deg")
            lines.append(f"     moves: {moved}")
        shown = p.targets or p.names
        lines.append(f"{'parameter':14s} {'now':>11s} " + " ".join(
            f"{'best ' + str(i + 1):>11s}" for i in range(len(self.best))))
        tab = self.sigmas()
        for _, r in tab[tab["parameter"].isin(shown)].iterrows():
            lines.append(f"{r['parameter']:14s} {r['sigma_now']:>11.4g} " + " ".join(
                f"{r[f'best_{i + 1}']:>11.4g}" for i in range(len(self.best))))
        return "\n".join(lines)


def sequence(p: Planner, space: CandidateSpace, n_shots: int, **plan_options
             ) -> list[PlanResult]:
    """``n_shots`` shots chosen one after another: each the best of a plan scored with the
    ones before it fired (:meth:`Planner.with_shot`)."""
    out = []
    for _ in range(n_shots):
        res = p.plan(space, **plan_options)
        out.append(res)
        p = p.with_shot(res.best_candidate)
    return out
