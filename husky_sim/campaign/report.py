"""A campaign's report: campaign.md (per family, the reach rate and every failure class's rate
with its exact 95 % upper bound), a figure per family (outcome bars and a gallery of the failing
layouts with the path the robot drove) and every failing layout as a scenario file in
`failures/` that `husky-sim run` reproduces (the campaign's horizon written into it)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from husky_sim.campaign.runner import CSV_FILE, CampaignSpec, RunTask
from husky_sim.campaign.stats import CLASSES, CONFIDENCE, FAILURES, rate_text, upper_bound
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.runs.run_folder import read_log
from husky_sim.runs.scenario import load_scenario
from husky_sim.scenario_file import read_scenario_data, scenario_yaml
from husky_sim.viz.figure_base import plt, save_figure
from husky_sim.viz.layout_figures import LayoutPanel, draw_layout

REPORT_FILE = "campaign.md"
#: Failing layouts drawn in a family's figure (all are saved in failures/).
GALLERY_PANELS = 8
#: The classes' colours in the outcome bars.
CLASS_COLOURS = {
    "reached": "tab:green",
    "collision_at_fault": "tab:red",
    "hit_standing": "tab:orange",
    "stuck": "tab:purple",
    "timeout": "tab:gray",
    "tracking_lost": "tab:olive",
    "error": "black",
}


def command_line(spec: CampaignSpec, out_dir: Path) -> str:
    parts = [
        "husky-sim campaign --families",
        " ".join(spec.families),
        f"--controller {spec.controller} --count {spec.count} --seed {spec.seed}",
    ]
    if spec.horizon is not None:
        parts.append(f"--horizon {spec.horizon}")
    for k, v in spec.fixed.items():
        parts.append(f"--param {k}={v:g}")
    if spec.robot != DEFAULT_ROBOT:
        parts.append(f"--robot {spec.robot}")
    parts.append(f"--out {out_dir}")
    return " ".join(parts)


def write_report(
    spec: CampaignSpec, tasks: Sequence[RunTask], rows: Sequence[Mapping[str, object]], out_dir: Path
) -> Path:
    """campaign.md, figures/<family>.png and failures/*.yaml from the campaign's rows."""
    by_layout = {t.layout: t for t in tasks}
    failures = [r for r in rows if r["class"] != "reached"]
    saved = {str(r["layout"]): save_failure(by_layout[str(r["layout"])], r, out_dir) for r in failures}
    lines = [
        f"# Campaign: {spec.controller}" + (f", N = {spec.horizon}" if spec.horizon is not None else ""),
        "",
        "```sh",
        command_line(spec, out_dir),
        "```",
        "",
        f"{len(rows)} runs of {len(tasks)}; {spec.count} layouts per family, seed {spec.seed}. Each failure "
        f"rate is `failures/runs (rate, <= its exact one-sided {CONFIDENCE:.0%} upper bound)` "
        "(Clopper-Pearson). `filtered runs`: runs in which a safety filter intervened at least once "
        "(it sent another command than the plan's first); `solve p99`: the median over the runs of "
        "each run's 99th percentile solve time (wall clock, this machine).",
        "",
        "| family | runs | reached | "
        + " | ".join(c.replace("_", " ") for c in FAILURES)
        + " | filtered runs | solve p99 (median, ms) |",
        "|---|---|---|" + "---|" * len(FAILURES) + "---|---|",
    ]
    families = list(dict.fromkeys(t.family for t in tasks))
    for name in [*families, "all"]:
        chosen = [r for r in rows if name == "all" or r["family"] == name]
        counts = Counter(str(r["class"]) for r in chosen)
        n = len(chosen)
        reached = f"{counts['reached']}/{n} ({100 * counts['reached'] / n:.0f} %)" if n else "0/0"
        cells = [rate_text(counts[c], n) if counts[c] else "0" for c in FAILURES]
        label = f"**{name}**" if name == "all" else name
        filtered = sum(_number(r.get("filter_interventions")) > 0 for r in chosen)
        p99 = [_number(r.get("solve_ms_p99")) for r in chosen if r.get("solve_ms_p99") not in (None, "")]
        p99_text = f"{np.median(p99):.1f}" if p99 else "n/a"
        lines.append(f"| {label} | {n} | {reached} | " + " | ".join(cells) + f" | {filtered} | {p99_text} |")
    lines += [
        "",
        f"A class with no failure in a family shows 0: with {spec.count} runs that bounds its rate at "
        f"{100 * upper_bound(0, spec.count):.0f} % ({CONFIDENCE:.0%}).",
    ]
    lines += ["", "Classes:", ""] + [f"- `{c}`: {meaning}" for c, meaning in CLASSES.items()]
    lines += ["", "## Failing layouts", ""]
    if not failures:
        lines.append("None.")
    for r in failures:
        path = saved[str(r["layout"])].relative_to(out_dir)
        clearance = r["min_clearance_m"]
        lines.append(
            f"- `{r['layout']}`: {r['class']} (min clearance {clearance} m): "
            f"`husky-sim run {out_dir / path} --controller {spec.controller}`"
        )
    lines += ["", "## Figures", ""]
    for name in families:
        family_rows = [r for r in rows if r["family"] == name]
        stem = draw_family_figure(name, family_rows, by_layout, out_dir)
        lines.append(f"![{name}](figures/{stem}.png)")
    report = out_dir / REPORT_FILE
    report.write_text("\n".join(lines) + "\n")
    return report


def _number(value: object) -> float:
    """A number of a row (campaign.csv holds strings; a missing value is 0)."""
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return 0.0


def save_failure(task: RunTask, row: Mapping[str, object], out_dir: Path) -> Path:
    """The failing layout with the campaign's horizon in it, and a header saying how it failed
    and how to run it again."""
    data = read_scenario_data(Path(task.layout_path))
    if task.horizon is not None:
        data["controller"] = {**data.get("controller", {}), "horizon": task.horizon}
    folder = out_dir / "failures"
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{task.layout}.yaml"
    header = (
        f"husky-sim campaign failure: {task.layout} ({task.family}, seed {task.seed}, index "
        f"{task.index}), class {row['class']}, outcome {row['outcome']}, min clearance "
        f"{row['min_clearance_m']} m\n"
        f"params: {task.params}\n"
        f"reproduce: husky-sim run {path} --controller {task.controller}"
    )
    path.write_text(scenario_yaml(data, header))
    return path


def draw_family_figure(
    name: str, rows: Sequence[Mapping[str, object]], by_layout: Mapping[str, RunTask], out_dir: Path
) -> str:
    """figures/<name>.png: the family's outcome bars, then its failing layouts with the path the
    robot drove (a red cross where it first touched)."""
    failing = [r for r in rows if r["class"] != "reached"][:GALLERY_PANELS]
    columns = 4
    gallery_rows = -(-len(failing) // columns)
    fig = plt.figure(figsize=(13, 2.0 + 3.2 * gallery_rows))
    grid = fig.add_gridspec(1 + gallery_rows, columns, height_ratios=[0.55] + [1.0] * gallery_rows)
    bars = fig.add_subplot(grid[0, :])
    counts = Counter(str(r["class"]) for r in rows)
    classes = list(CLASSES)
    bars.bar(range(len(classes)), [counts[c] for c in classes], color=[CLASS_COLOURS[c] for c in classes])
    bars.set_xticks(range(len(classes)), [c.replace("_", " ") for c in classes], fontsize=8)
    bars.set_ylabel("runs")
    bars.set_title(f"{name}: {len(rows)} runs", fontsize=9)
    for k, r in enumerate(failing):
        ax = fig.add_subplot(grid[1 + k // columns, k % columns])
        task = by_layout[str(r["layout"])]
        path, contact, t_contact = _driven(Path(task.run_dir))
        title = f"{r['layout']}: {r['class']}"
        panel = LayoutPanel(load_scenario(task.layout_path), title, path, contact, t_contact)
        draw_layout(ax, panel)
    fig.tight_layout()
    stem = f"{name}"
    save_figure(fig, out_dir / "figures", stem)
    return stem


def _driven(run_dir: Path) -> tuple[np.ndarray | None, tuple[float, float] | None, float | None]:
    """The path the robot drove (m), and where and when (s) it first touched something, from the
    run's log (the control step whose period held the first contact)."""
    try:
        log = read_log(run_dir, ("t_s", "x_m", "y_m", "clearance_m"))
    except (OSError, ValueError):
        return None, None, None
    path = np.stack([log["x_m"], log["y_m"]], axis=1)
    touched = np.flatnonzero(log["clearance_m"] <= 0)
    if not touched.size:
        return path, None, None
    k = int(touched[0])
    return path, (float(path[k, 0]), float(path[k, 1])), float(log["t_s"][k])


def read_rows(out_dir: Path) -> list[dict[str, str]]:
    """campaign.csv's rows, as strings."""
    import csv

    with (out_dir / CSV_FILE).open(newline="") as f:
        return list(csv.DictReader(f))
