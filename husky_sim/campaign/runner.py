"""Running a campaign: generate `count` layouts of each family, run each with one controller in
PyBullet, and keep one row per run.

A campaign folder holds `layouts/<family>/<layout>.yaml` (the generated files), `runs/<layout>/`
(each run's summary.json and log.csv), `campaign.csv`, `campaign.md`, `figures/` and `failures/`
(husky_sim.campaign.report). It is resumable: a run whose summary.json holds a final outcome is
done and is not run again, so a killed campaign, started again with the same command, runs only
what is missing and writes the same `campaign.csv` (its one wall-clock column, `solve_ms_p99`,
is the machine's). A campaign started in a folder that holds another campaign's runs is refused.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from husky_sim.campaign.stats import run_class
from husky_sim.families.generate import Layout, generate
from husky_sim.families.registry import family
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.runs.parallel import Backend, parallel_map
from husky_sim.runs.run_folder import SUMMARY_FILE, prepare_out_dir, write_summary

#: The campaign's own record of what it was asked (a restart must ask the same).
SPEC_FILE = "campaign.json"
CSV_FILE = "campaign.csv"
#: campaign.csv's columns, in order.
CSV_COLUMNS = (
    "family",
    "index",
    "seed",
    "layout",
    "controller",
    "horizon",
    "outcome",
    "class",
    "collided",
    "collision_at_fault",
    "min_clearance_m",
    "time_to_goal_s",
    "solve_ms_p99",
    "filter_interventions",
    "mode_changes",
    "params",
)
#: Outcomes that a restart runs again (the run did not finish).
UNFINISHED = ("interrupted",)


@dataclass(frozen=True)
class CampaignSpec:
    """What a campaign runs: `count` layouts (indices 0 .. count-1 of `seed`) of each family, with
    `controller` at `horizon` (None: each layout's own), some family parameters fixed, for the
    robot folder `robot` (the layouts' body and feasibility are its)."""

    families: tuple[str, ...]
    controller: str
    count: int
    seed: int
    horizon: int | None = None
    fixed: Mapping[str, float] = field(default_factory=dict)
    robot: str = DEFAULT_ROBOT

    def __post_init__(self) -> None:
        if not self.families:
            raise ValueError("--families: name at least one family")
        for name in self.families:
            family(name)
        unknown = [k for k in self.fixed if not any(k in _param_names(f) for f in self.families)]
        if unknown:
            raise ValueError(f"--param {unknown[0]}: no family of this campaign has such a parameter")
        for name in self.families:
            for key, value in self.fixed_for(name).items():
                family(name).param(key).check(value)  # out of range: one line, before any file
        if not 1 <= self.count <= 10_000:
            raise ValueError(f"--count: must be in [1, 10000], got {self.count}")

    def fixed_for(self, name: str) -> dict[str, float]:
        return {k: v for k, v in self.fixed.items() if k in _param_names(name)}

    def record(self) -> dict[str, object]:
        return {**asdict(self), "families": list(self.families), "fixed": dict(self.fixed)}


def _param_names(name: str) -> set[str]:
    return {p.name for p in family(name).params}


@dataclass(frozen=True)
class RunTask:
    """One run of a campaign, as a worker process gets it (plain, picklable values)."""

    family: str
    index: int
    seed: int
    layout: str
    layout_path: str
    run_dir: str
    controller: str
    horizon: int | None
    params: str


def campaign_layouts(spec: CampaignSpec) -> list[Layout]:
    """Every layout of the campaign, family by family, index by index."""
    return [
        layout
        for name in spec.families
        for layout in generate(name, spec.count, spec.seed, spec.fixed_for(name), spec.robot)
    ]


def plan(spec: CampaignSpec, out_dir: Path) -> list[RunTask]:
    """Write the spec and the layouts; return one task per layout. A folder holding another
    campaign's spec is refused with a one-line error."""
    prepare_out_dir(out_dir)
    spec_path = out_dir / SPEC_FILE
    record = spec.record()
    if spec_path.exists():
        held = json.loads(spec_path.read_text())
        if held != json.loads(json.dumps(record)):
            raise ValueError(
                f"--out: {out_dir} holds another campaign ({SPEC_FILE} differs); use a new folder "
                "or the same command"
            )
    else:
        spec_path.write_text(json.dumps(record, indent=1) + "\n")
    tasks = []
    for layout in campaign_layouts(spec):
        path = layout.write(out_dir / "layouts" / layout.family)
        params = ";".join(f"{k}={v:.6g}" for k, v in layout.params.items())
        tasks.append(
            RunTask(
                layout.family,
                layout.index,
                layout.seed,
                layout.name,
                str(path),
                str(out_dir / "runs" / layout.name),
                spec.controller,
                spec.horizon,
                params,
            )
        )
    return tasks


def finished_summary(task: RunTask) -> dict[str, object] | None:
    """The task's summary if its run finished (any final outcome, an error included), else None."""
    path = Path(task.run_dir) / SUMMARY_FILE
    if not path.is_file():
        return None
    try:
        summary = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return None if summary.get("outcome") in UNFINISHED else summary


def run_task(task: RunTask) -> dict[str, object]:
    """Run one layout (in a worker); its summary, as written to its folder."""
    from husky_sim.runs.run import run_scenario
    from husky_sim.runs.scenario import load_scenario

    summary = run_scenario(
        load_scenario(task.layout_path),
        task.controller,
        horizon=task.horizon,
        out_dir=Path(task.run_dir),
        full_record=False,
    )
    return summary.as_dict()


def row_of(task: RunTask, summary: Mapping[str, object]) -> dict[str, object]:
    """campaign.csv's row of a finished task."""
    row = {
        "family": task.family,
        "index": task.index,
        "seed": task.seed,
        "layout": task.layout,
        "controller": task.controller,
        "horizon": summary.get("horizon", task.horizon),
        "outcome": summary.get("outcome"),
        "class": run_class(summary),
        "collided": summary.get("collided"),
        "collision_at_fault": summary.get("collision_at_fault"),
        "min_clearance_m": _rounded(summary.get("min_clearance_m")),
        "time_to_goal_s": _rounded(summary.get("time_to_goal_s")),
        "solve_ms_p99": _rounded(summary.get("solve_ms_p99")),
        "filter_interventions": summary.get("filter_interventions"),
        "mode_changes": summary.get("mode_changes"),
        "params": task.params,
    }
    return row


def _rounded(value: object) -> object:
    return round(value, 4) if isinstance(value, float) else value


def write_csv(rows: Sequence[Mapping[str, object]], out_dir: Path) -> Path:
    """campaign.csv: a row per finished run, in task order (so a resumed campaign's file equals
    a straight one's)."""
    import csv

    path = out_dir / CSV_FILE
    tmp = path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: "" if row.get(k) is None else row.get(k) for k in CSV_COLUMNS})
    tmp.replace(path)
    return path


def run_campaign(
    spec: CampaignSpec,
    out_dir: Path,
    jobs: int = 1,
    backend: Backend = "local",
    scheduler: str | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> list[dict[str, object]]:
    """Run what is missing of the campaign and write campaign.csv (after every finished run, so
    a killed campaign keeps its rows); return the rows in task order."""
    tasks = plan(spec, out_dir)
    summaries: list[dict[str, object] | None] = [finished_summary(t) for t in tasks]
    todo = [i for i, s in enumerate(summaries) if s is None]
    if log is not None:
        log(f"campaign: {len(tasks)} runs, {len(tasks) - len(todo)} done before, {len(todo)} to run")
    bar = _progress(len(tasks), len(tasks) - len(todo), progress)

    def rows() -> list[dict[str, object]]:
        return [row_of(t, s) for t, s in zip(tasks, summaries, strict=True) if s is not None]

    def on_done(k: int, result: dict[str, object] | BaseException) -> None:
        i = todo[k]
        if isinstance(result, BaseException):
            result = {"outcome": "error", "error": " ".join(str(result).split())[:300]}
            write_summary(prepare_out_dir(Path(tasks[i].run_dir)), result)
        summaries[i] = result
        write_csv(rows(), out_dir)
        if bar is not None:
            bar.update(1)

    try:
        parallel_map(run_task, [tasks[i] for i in todo], jobs, on_done, backend, scheduler)
    finally:
        if bar is not None:
            bar.close()
    final = rows()
    write_csv(final, out_dir)
    return final


def _progress(total: int, done: int, enabled: bool):  # noqa: ANN202 - tqdm's type
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=done, unit="run", file=sys.stderr, dynamic_ncols=True)
