"""Falsification: search a family's parameter space for the layout where a controller comes
closest to an obstacle, a collision first, with CMA-ES (the `cma` package); or sample it at
random with the same budget, for comparison.

The search space is the family's parameters that are not fixed, each scaled to [0, 1] of its
range (integers rounded). Every candidate is drawn as layout 0 of the search's seed with all its
parameters fixed (husky_sim.families.generate.draw_layout), so the layout's placement randomness
is the same for every candidate and the score is a function of the parameters alone. The score
(lower is worse for the controller) is the run's smallest clearance (m), less 1 for a collision
while standing and less 2 for one at fault: any collision ranks below every near miss, and the
controller's own collisions first. A candidate with no feasible layout scores
`INFEASIBLE_SCORE` and is kept in the history as such.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from husky_sim.campaign.runner import RunTask, run_task
from husky_sim.campaign.stats import run_class
from husky_sim.families.base import Family
from husky_sim.families.generate import draw_layout
from husky_sim.families.registry import family as family_named
from husky_sim.runs.parallel import Backend, parallel_map
from husky_sim.runs.run_folder import prepare_out_dir
from husky_sim.scenario_file import scenario_yaml

Method = Literal["cma", "random"]
METHODS: tuple[Method, ...] = ("cma", "random")
#: The score of a candidate without a feasible layout: above any clearance a run reports.
INFEASIBLE_SCORE = 100.0
#: CMA-ES's population per generation (runs evaluated in parallel) and initial step (of [0, 1]).
POPULATION = 6
SIGMA0 = 0.3
HISTORY_FILE = "falsify.csv"


@dataclass(frozen=True)
class Evaluation:
    """One candidate run: its number, method, parameters, score, clearance and class."""

    run: int
    method: str
    params: dict[str, float]
    score: float
    min_clearance_m: float | None
    outcome: str
    run_class: str
    layout: str


def score_of(summary: Mapping[str, object]) -> float:
    """A run's score (see the module docstring)."""
    clearance = summary.get("min_clearance_m")
    c = float(clearance) if isinstance(clearance, int | float) else INFEASIBLE_SCORE
    cls = run_class(summary)
    return c - (2.0 if cls == "collision_at_fault" else 1.0 if cls == "hit_standing" else 0.0)


class Search:
    """Evaluates candidates of one family with one controller, writing each run's folder and
    the worst layout so far."""

    def __init__(
        self,
        fam: Family,
        controller: str,
        seed: int,
        horizon: int | None,
        fixed: Mapping[str, float],
        out_dir: Path,
        jobs: int,
        backend: Backend,
        scheduler: str | None,
    ) -> None:
        self.fam, self.controller, self.seed, self.horizon = fam, controller, seed, horizon
        self.fixed = dict(fixed)
        self.free = [p for p in fam.params if p.name not in self.fixed]
        self.out_dir, self.jobs, self.backend, self.scheduler = out_dir, jobs, backend, scheduler
        self.history: list[Evaluation] = []
        self.best: tuple[float, str] | None = None  # (score, layout text)

    def params_at(self, u: Sequence[float]) -> dict[str, float]:
        return {**self.fixed, **{p.name: p.from_unit(float(x)) for p, x in zip(self.free, u, strict=True)}}

    def evaluate(self, method: str, points: Sequence[Sequence[float]]) -> list[float]:
        """Run each point (in [0, 1]^d) and return its score."""
        tasks: list[RunTask | None] = []
        texts: list[str] = []
        params = [self.params_at(u) for u in points]
        for p in params:
            k = len(self.history) + len(tasks)
            try:
                layout = draw_layout(self.fam, self.seed, 0, p)
            except ValueError:
                tasks.append(None)
                texts.append("")
                continue
            name = f"{method}-{k:04d}"
            folder = self.out_dir / "layouts"
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / f"{name}.yaml"
            path.write_text(layout.text)
            texts.append(layout.text)
            tasks.append(
                RunTask(
                    self.fam.name,
                    0,
                    self.seed,
                    name,
                    str(path),
                    str(self.out_dir / "runs" / name),
                    self.controller,
                    self.horizon,
                    "",
                )
            )
        runnable = [t for t in tasks if t is not None]
        results = iter(parallel_map(run_task, runnable, self.jobs, None, self.backend, self.scheduler))
        scores = []
        for task, p, text in zip(tasks, params, texts, strict=True):
            k = len(self.history)
            if task is None:
                self.history.append(
                    Evaluation(k, method, p, INFEASIBLE_SCORE, None, "infeasible", "infeasible", "")
                )
                scores.append(INFEASIBLE_SCORE)
                continue
            result = next(results)
            summary = {"outcome": "error"} if isinstance(result, BaseException) else result
            score = score_of(summary)
            clearance = summary.get("min_clearance_m")
            self.history.append(
                Evaluation(
                    k,
                    method,
                    p,
                    score,
                    clearance if isinstance(clearance, float) else None,
                    str(summary.get("outcome")),
                    run_class(summary),
                    task.layout,
                )
            )
            if self.best is None or score < self.best[0]:
                self.best = (score, _worst_text(text, task, score, summary))
            scores.append(score)
        return scores


def _worst_text(text: str, task: RunTask, score: float, summary: Mapping[str, object]) -> str:
    """The layout file with a header line saying how it scored."""
    from husky_sim.scenario_file import read_scenario_data

    data = read_scenario_data(Path(task.layout_path))
    if task.horizon is not None:
        data["controller"] = {**data.get("controller", {}), "horizon": task.horizon}
    header = "\n".join(line[2:] for line in text.splitlines() if line.startswith("# "))
    return scenario_yaml(
        data,
        f"husky-sim falsify: worst layout found (score {score:.4f}, outcome {summary.get('outcome')}, "
        f"min clearance {summary.get('min_clearance_m')} m, run {task.layout})\n{header}",
    )


def search(
    family: str,
    controller: str,
    budget: int,
    seed: int,
    out_dir: Path,
    method: Method = "cma",
    horizon: int | None = None,
    fixed: Mapping[str, float] | None = None,
    jobs: int = 1,
    backend: Backend = "local",
    scheduler: str | None = None,
    log: Callable[[str], None] | None = None,
) -> Search:
    """Spend `budget` runs searching `family` for `controller`'s worst layout; write the worst
    layout (worst.yaml), the history (falsify.csv) and the best-so-far figure."""
    if not 1 <= budget <= 10_000:
        raise ValueError(f"--budget: must be in [1, 10000], got {budget}")
    if method not in METHODS:
        raise ValueError(f"--method: must be one of {METHODS}, got {method!r}")
    fam = family_named(family)
    for name in fixed or {}:
        fam.param(name).check(float((fixed or {})[name]))
    prepare_out_dir(out_dir)
    s = Search(fam, controller, seed, horizon, fixed or {}, out_dir, jobs, backend, scheduler)
    if len(s.free) < 2 and method == "cma":
        raise ValueError(
            f"--method cma: needs at least two free parameters, family {family} has {len(s.free)}"
        )
    if method == "cma":
        import cma

        es = cma.CMAEvolutionStrategy(
            [0.5] * len(s.free),
            SIGMA0,
            {"bounds": [0.0, 1.0], "seed": seed + 1, "popsize": POPULATION, "verbose": -9},
        )
        while len(s.history) < budget:
            points = es.ask()[: budget - len(s.history)]
            scores = s.evaluate("cma", points)
            if len(points) == es.popsize:
                es.tell(points, scores)
            if log is not None:
                log(f"cma: {len(s.history)}/{budget} runs, best score {min(e.score for e in s.history):.3f}")
    else:
        rng = np.random.default_rng(seed)
        while len(s.history) < budget:
            batch = min(POPULATION, budget - len(s.history))
            s.evaluate("random", rng.uniform(size=(batch, len(s.free))).tolist())
            if log is not None:
                best = min(e.score for e in s.history)
                log(f"random: {len(s.history)}/{budget} runs, best score {best:.3f}")
    write_outputs(s, out_dir)
    return s


def write_outputs(s: Search, out_dir: Path) -> None:
    names = [p.name for p in s.fam.params]
    with (out_dir / HISTORY_FILE).open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(
            ["run", "method", "score", "best_score", "min_clearance_m", "outcome", "class", "layout", *names]
        )
        best = math.inf
        for e in s.history:
            best = min(best, e.score)
            writer.writerow(
                [
                    e.run,
                    e.method,
                    round(e.score, 4),
                    round(best, 4),
                    "" if e.min_clearance_m is None else round(e.min_clearance_m, 4),
                    e.outcome,
                    e.run_class,
                    e.layout,
                    *(f"{e.params[n]:.6g}" for n in names),
                ]
            )
    if s.best is not None:
        (out_dir / "worst.yaml").write_text(s.best[1])
    _figure(s, out_dir)


def _figure(s: Search, out_dir: Path) -> None:
    from husky_sim.viz.figure_base import plt, save_figure

    scores = np.array([e.score for e in s.history])
    shown = np.where(scores >= INFEASIBLE_SCORE, np.nan, scores)
    fig, ax = plt.subplots(figsize=(6, 3.2))
    ax.plot(np.arange(1, len(scores) + 1), shown, ".", color="0.6", label="run")
    ax.plot(
        np.arange(1, len(scores) + 1),
        np.fmin.accumulate(np.where(np.isnan(shown), np.inf, shown)),
        color="tab:red",
        label="best so far",
    )
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("runs")
    ax.set_ylabel("score (clearance, m; < 0: collision)")
    ax.set_title(f"{s.fam.name}, {s.controller}: {s.history[0].method if s.history else ''}", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out_dir, "falsify")


@dataclass(frozen=True)
class SearchSummary:
    """What the comparison table reports of one search."""

    method: str
    runs: int
    first_collision_run: int | None  # 1-based
    first_at_fault_run: int | None  # the first collision while moving
    first_failure_run: int | None  # any class but reached (infeasible draws excluded)
    lowest_clearance_m: float | None
    best_score: float


def summarise(s: Search) -> SearchSummary:
    def first(pred: Callable[[Evaluation], bool]) -> int | None:
        return next((e.run + 1 for e in s.history if pred(e)), None)

    clearances = [e.min_clearance_m for e in s.history if e.min_clearance_m is not None]
    return SearchSummary(
        s.history[0].method if s.history else "",
        len(s.history),
        first(lambda e: e.run_class in ("collision_at_fault", "hit_standing")),
        first(lambda e: e.run_class == "collision_at_fault"),
        first(lambda e: e.run_class not in ("reached", "infeasible")),
        min(clearances) if clearances else None,
        min((e.score for e in s.history), default=INFEASIBLE_SCORE),
    )


def comparison_table(
    family: str, controller: str, horizon: int | None, searches: Sequence[tuple[SearchSummary, Path]]
) -> str:
    """A Markdown table of searches of one family and controller: a row per method."""
    lines = [
        "| family | controller | method | runs | first failure (run) | first collision (run) "
        "| first at-fault collision (run) | lowest clearance (m) | worst layout |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    label = controller if horizon is None else f"{controller}, N = {horizon}"
    for m, out in searches:
        lowest = "n/a" if m.lowest_clearance_m is None else f"{m.lowest_clearance_m:.3f}"
        lines.append(
            f"| {family} | {label} | {m.method} | {m.runs} | {m.first_failure_run or '-'} | "
            f"{m.first_collision_run or '-'} | {m.first_at_fault_run or '-'} | {lowest} | "
            f"`{out / 'worst.yaml'}` |"
        )
    return "\n".join(lines)
