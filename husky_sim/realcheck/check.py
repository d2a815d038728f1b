"""`husky-sim check`: sim-to-real checks before a Husky trial.

1. Configuration audit (husky_sim.realcheck.audit), before anything runs in PyBullet: robot radius,
   velocity and acceleration limits, stopping distance, tau against the measured solve-time p99,
   obstacles and sensing.
2. Robustness sweep (husky_sim.realcheck.sweep): the scenario re-run over K seeded perturbations of what
   differs on a real robot, in parallel on local processes or on a Dask cluster (see that module
   for why Dask rather than Ray). Every failing sample is saved as a scenario file that reproduces
   it with ``husky-sim run``.
3. A verdict: FAIL when an audit finding fails, when any sample collides, or when the pass rate
   (no collision and converged) is below `min_pass_rate`; otherwise PASS. Written to
   DIR/check.md (tables and plots) and DIR/check.json.

Determinism: the same scenario, seed and K give the same samples and the same per-sample results,
except the wall-clock fields (sweep.WALL_CLOCK_KEYS) and the audit's measured solve times.
"""

from __future__ import annotations

import json
import math
import sys
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from controllers import registry
from husky_sim.realcheck.audit import AuditThresholds, Finding, audit, measure_solve_times
from husky_sim.realcheck.steerability import CAN_PIVOT_RADPS, failure_class
from husky_sim.realcheck.sweep import (
    SENSING_MODEL_FIELDS,
    Perturbation,
    PerturbationRanges,
    SampleTask,
    apply_perturbation,
    run_tasks,
    sample_perturbations,
)
from husky_sim.runs.parallel import BACKENDS, Backend
from husky_sim.runs.scenario import MAX_HORIZON, Scenario
from husky_sim.scenario_file import scenario_yaml

#: Clearance percentiles reported (of the per-sample minimum clearance, m).
PERCENTILES = (0, 5, 25, 50, 75, 95, 100)
#: Rows of the per-sample table in check.md (check.json always has every sample).
MD_SAMPLE_ROWS = 200
PAYLOAD_BINS = 5  # bars of the pass-rate-by-payload figure


@dataclass(frozen=True)
class CheckOptions:
    """What to check and how; validated on construction (a bad value is a one-line ValueError)."""

    controller: str = registry.DEFAULT  # a registered controller (controllers.registry)
    horizon: int | None = None  # None: the scenario's
    samples: int = 32  # K perturbed runs
    seed: int | None = None  # perturbation sampling seed; None: the scenario's seed
    jobs: int | None = None  # worker processes; None: every core available
    backend: Backend = "local"
    scheduler: str | None = None  # Dask scheduler address; None: a LocalCluster
    timing_solves: int = 100  # NMPC solves timed for the audit
    min_pass_rate: float = 0.95  # fraction of samples that must pass
    ranges: PerturbationRanges = field(default_factory=PerturbationRanges)
    thresholds: AuditThresholds = field(default_factory=AuditThresholds)

    def __post_init__(self) -> None:
        registry.entry(self.controller)  # ValueError naming the registered ones
        for name in ("samples", "timing_solves"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name}: must be >= 1, got {getattr(self, name)}")
        if self.horizon is not None and not 1 <= self.horizon <= MAX_HORIZON:
            raise ValueError(f"horizon: must be in [1, {MAX_HORIZON}], got {self.horizon}")
        if self.jobs is not None and self.jobs < 1:
            raise ValueError(f"jobs: must be >= 1, got {self.jobs}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend: must be one of {BACKENDS}, got {self.backend!r}")
        if self.scheduler is not None and self.backend != "dask":
            raise ValueError("scheduler: needs --backend dask")
        if not 0.0 <= self.min_pass_rate <= 1.0:
            raise ValueError(f"min_pass_rate: must be in [0, 1], got {self.min_pass_rate}")


@dataclass
class CheckReport:
    """Everything check.json holds."""

    scenario: str
    controller: str
    horizon: int
    tau_s: float
    seed: int
    samples: int
    backend: str
    verdict: str  # "PASS" or "FAIL"
    reason: str
    findings: list[Finding]
    nominal: dict[str, Any]  # the unperturbed scenario's run
    perturbations: list[Perturbation]
    results: list[dict[str, Any]]  # per sample, in sample order
    stats: dict[str, Any]
    ranges: PerturbationRanges
    failure_files: dict[int, str]  # sample index -> saved scenario file

    def as_dict(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["findings"] = [f.as_dict() for f in self.findings]
        out["perturbations"] = [p.as_dict() for p in self.perturbations]
        out["ranges"] = {  # strict JSON: an unlimited (not perturbed) range is null
            k: [None if isinstance(x, float) and math.isinf(x) else x for x in v]
            for k, v in asdict(self.ranges).items()
        }
        out["failure_files"] = {str(k): v for k, v in self.failure_files.items()}
        return out


def sweep_stats(results: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Pass rate, outcome counts and the distribution of the per-sample minimum clearance (m)."""
    passed = sum(bool(r["passed"]) for r in results)
    clear = [(r["min_clearance_m"], r["index"]) for r in results if r["min_clearance_m"] is not None]
    stats: dict[str, Any] = {
        "samples": len(results),
        "passed": passed,
        "pass_rate": passed / len(results),
        "collided": sum(bool(r["collided"]) for r in results),
        "outcomes": dict(sorted(Counter(r["outcome"] for r in results).items())),
        # failed samples by what failed: the plant (its robot cannot pivot, steerability) or
        # the controller
        "failures_by_class": dict(
            sorted(Counter(failure_class(r["steerability"]) for r in results if not r["passed"]).items())
        ),
        "clearance_percentiles_m": None,
        "worst_clearance_m": None,
        "worst_sample": None,
    }
    if clear:
        values = np.array([c for c, _ in clear])
        stats["clearance_percentiles_m"] = {f"p{q}": float(np.percentile(values, q)) for q in PERCENTILES}
        worst, index = min(clear)
        stats["worst_clearance_m"], stats["worst_sample"] = float(worst), int(index)
    return stats


def verdict(
    findings: Sequence[Finding],
    nominal: dict[str, Any],
    stats: dict[str, Any],
    perturbations: Sequence[Perturbation],
    min_pass_rate: float,
) -> tuple[str, str]:
    """("PASS" | "FAIL", reason). FAIL on a failed audit finding, a failing unperturbed run, any
    colliding sample, or a pass rate below min_pass_rate."""
    failed = [f for f in findings if f.status == "fail"]
    if failed:
        return "FAIL", "; ".join(f"audit {f.check}: {f.detail}" for f in failed)
    n, worst = stats["samples"], stats["worst_sample"]
    rate = f"{stats['passed']}/{n} = {stats['pass_rate']:.0%}"
    outcomes = ", ".join(f"{k} {v}" for k, v in stats["outcomes"].items())
    worst_text = (
        ""
        if worst is None
        else f"; worst clearance {stats['worst_clearance_m']:.3f} m in sample {worst} "
        f"({perturbations[worst].describe()})"
    )
    if not nominal["passed"]:
        return "FAIL", (
            f"the unperturbed scenario already fails ({nominal['outcome']}); pass rate {rate} "
            f"({outcomes}){worst_text}"
        )
    if stats["collided"]:
        return "FAIL", f"{stats['collided']}/{n} samples collided; pass rate {rate} ({outcomes}){worst_text}"
    if stats["pass_rate"] < min_pass_rate:
        return "FAIL", f"pass rate {rate} < {min_pass_rate:.0%} ({outcomes}){worst_text}"
    warns = sum(f.status == "warn" for f in findings)
    return "PASS", f"pass rate {rate} ({outcomes}){worst_text}; {warns} audit warnings"


def save_failure(scenario: Scenario, result: dict[str, Any], controller: str, out_dir: Path) -> Path:
    """Write a failing sample as a scenario file that `husky-sim run` reproduces; return its path."""
    path = out_dir / "failures" / f"sample_{result['index']}.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    clearance = result["min_clearance_m"]
    header = (
        f"husky-sim check failure: sample {result['index']}, outcome {result['outcome']}, min clearance "
        f"{'n/a' if clearance is None else f'{clearance:.4f} m'}\n"
        f"reproduce: husky-sim run {path} --controller {controller}"
    )
    path.write_text(scenario_yaml(scenario.model_dump(mode="json", exclude_none=True), header))
    return path


def run_check(
    scenario: Scenario,
    options: CheckOptions,
    out_dir: Path,
    log: Callable[[str], None] | None = None,
) -> CheckReport:
    """Audit, sweep, verdict; writes check.md, check.json, plots and failing samples to out_dir."""
    say = log or (lambda _msg: None)
    base = scenario.with_overrides(horizon=options.horizon)  # so saved samples carry it
    seed = base.seed if options.seed is None else options.seed
    ranges = options.ranges.for_robot(base.robot.description())  # before any work: may refuse
    say(f"audit: timing {options.timing_solves} NMPC solves on the kinematic loop ...")
    solve_times = measure_solve_times(base, options.controller, solves=options.timing_solves)
    findings = audit(base, solve_times, options.thresholds, options.controller)
    for f in findings:
        say(f"  [{f.status}] {f.check}: {f.detail}")

    perturbations = sample_perturbations(ranges, options.samples, seed)
    sample_scenarios = [apply_perturbation(base, p) for p in perturbations]
    tasks = [SampleTask(-1, base.model_dump(mode="json"), options.controller)] + [
        SampleTask(p.index, s.model_dump(mode="json"), options.controller)
        for p, s in zip(perturbations, sample_scenarios, strict=True)
    ]
    say(f"sweep: {options.samples} samples + nominal on backend {options.backend} ...")
    outputs = run_tasks(tasks, options.backend, options.jobs, options.scheduler, _progress(len(tasks)))
    nominal, results = outputs[0], outputs[1:]

    out_dir.mkdir(parents=True, exist_ok=True)
    failure_files = {
        r["index"]: str(save_failure(sample_scenarios[r["index"]], r, options.controller, out_dir))
        for r in results
        if not r["passed"]
    }
    stats = sweep_stats(results)
    decision, reason = verdict(findings, nominal, stats, perturbations, options.min_pass_rate)
    report = CheckReport(
        scenario=base.name,
        controller=options.controller,
        horizon=base.controller.horizon,
        tau_s=base.tau_s,
        seed=seed,
        samples=options.samples,
        backend=options.backend,
        verdict=decision,
        reason=reason,
        findings=findings,
        nominal=nominal,
        perturbations=perturbations,
        results=results,
        stats=stats,
        ranges=ranges,
        failure_files=failure_files,
    )
    plots = write_plots(report, out_dir)
    (out_dir / "check.json").write_text(json.dumps(report.as_dict(), indent=2) + "\n")
    (out_dir / "check.md").write_text(markdown(report, plots))
    return report


def _progress(total: int) -> Callable[[int], None] | None:
    """A progress line on stderr, only on a terminal."""
    if not sys.stderr.isatty():
        return None

    def show(done: int) -> None:
        end = "\n" if done == total else ""
        print(f"\r  {done}/{total} runs", end=end, file=sys.stderr, flush=True)

    return show


# -- plots and markdown -------------------------------------------------------------------------
PERTURBATION_AXES = (
    ("ground_friction", "ground friction"),
    ("payload_kg", "payload (kg)"),
    ("latency_steps", "latency (steps)"),
    ("pose_xy_std_m", "pose noise std (m)"),
    ("pose_yaw_std_rad", "yaw noise std (rad)"),
    ("obstacle_xy_std_m", "obstacle noise std (m)"),
    ("obstacle_velocity_scale", "obstacle speed told / true"),
    ("torque_scale", "torque limit / nominal"),
    ("yaw_ratio", "yaw ratio"),
)


def write_plots(report: CheckReport, out_dir: Path) -> dict[str, str]:
    """Clearance histogram and clearance-vs-perturbation scatter (PNG, Agg, no pyplot state)."""
    from matplotlib.figure import Figure

    pairs = [(r, p) for r, p in zip(report.results, report.perturbations, strict=True)]
    pairs = [(r, p) for r, p in pairs if r["min_clearance_m"] is not None]
    if not pairs:
        return {}
    clear = np.array([r["min_clearance_m"] for r, _ in pairs])
    ok = np.array([bool(r["passed"]) for r, _ in pairs])

    fig = Figure(figsize=(6.4, 3.6), layout="constrained")
    ax = fig.add_subplot()
    bins = np.histogram_bin_edges(clear, bins=min(max(len(clear) // 3, 5), 40))
    ax.hist(
        [clear[ok], clear[~ok]],
        bins=bins,
        stacked=True,
        color=["tab:green", "tab:red"],
        label=["pass", "fail"],
    )
    ax.axvline(0.0, color="k", lw=1, ls="--", label="contact")
    if report.nominal.get("min_clearance_m") is not None:
        ax.axvline(report.nominal["min_clearance_m"], color="tab:blue", lw=1, label="nominal")
    ax.set_xlabel("minimum clearance of the Husky body to obstacles (m)")
    ax.set_ylabel("samples")
    ax.set_title(f"{report.scenario} {report.controller}: {len(clear)} perturbed runs")
    ax.legend()
    fig.savefig(out_dir / "clearance_hist.png", dpi=110)

    columns = 5
    rows = -(-len(PERTURBATION_AXES) // columns)
    fig = Figure(figsize=(14, 2.75 * rows), layout="constrained")
    for k, (name, label) in enumerate(PERTURBATION_AXES):
        ax = fig.add_subplot(rows, columns, k + 1)
        x = np.array([getattr(p, name) for _, p in pairs])
        ax.scatter(x[ok], clear[ok], s=12, c="tab:green")
        ax.scatter(x[~ok], clear[~ok], s=16, c="tab:red", marker="x")
        ax.axhline(0.0, color="k", lw=0.8, ls="--")
        ax.set_xlabel(label)
        if k % columns == 0:
            ax.set_ylabel("min clearance (m)")
    fig.suptitle("minimum clearance against each perturbation (red: failing samples)")
    fig.savefig(out_dir / "sensitivity.png", dpi=90)
    _payload_figure(report, out_dir / "pass_rate_by_payload.png")
    return {
        "histogram": "clearance_hist.png",
        "sensitivity": "sensitivity.png",
        "payload": "pass_rate_by_payload.png",
    }


def _payload_figure(report: CheckReport, path: Path) -> None:
    """Pass rate per payload bin (bars, with the samples in each), and each sample's turn in place
    from its steerability probe against its payload (green passed, red failed)."""
    from matplotlib.figure import Figure

    payload = np.array([p.payload_kg for p in report.perturbations])
    passed = np.array([bool(r["passed"]) for r in report.results])
    turn = np.array([r["steerability"]["turn_in_place_radps"] for r in report.results], dtype=float)
    lo, hi = report.ranges.payload_kg
    edges = np.linspace(lo, hi if hi > lo else lo + 1.0, PAYLOAD_BINS + 1)
    bins = np.clip(np.digitize(payload, edges) - 1, 0, PAYLOAD_BINS - 1)
    fig = Figure(figsize=(9.6, 3.6), layout="constrained")
    ax, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    for b in range(PAYLOAD_BINS):
        members = bins == b
        if members.any():
            rate = float(np.mean(passed[members]))
            ax.bar(0.5 * (edges[b] + edges[b + 1]), rate, width=0.9 * (edges[1] - edges[0]), color="tab:blue")
            ax.text(0.5 * (edges[b] + edges[b + 1]), rate, f"{members.sum()}", ha="center", va="bottom")
    ax.axhline(report.stats["pass_rate"], color="k", lw=0.8, ls="--", label="all samples")
    ax.set_ylim(0.0, 1.1)
    ax.set_xlabel("payload (kg)")
    ax.set_ylabel("pass rate (samples per bar above it)")
    ax.legend()
    ax2.scatter(payload[passed], turn[passed], s=14, c="tab:green", label="passed")
    ax2.scatter(payload[~passed], turn[~passed], s=18, c="tab:red", marker="x", label="failed")
    ax2.axhline(CAN_PIVOT_RADPS, color="k", lw=0.8, ls="--", label="can pivot")
    ax2.set_xlabel("payload (kg)")
    ax2.set_ylabel("yaw rate turning in place (rad/s of 1)")
    ax2.legend()
    fig.suptitle(f"{report.scenario} {report.controller}: pass rate and steerability by payload")
    fig.savefig(path, dpi=90)


def _cell(text: str) -> str:
    """Text safe inside a markdown table cell."""
    return text.replace("|", "\\|")


def _num(value: float | None, fmt: str = ".3f") -> str:
    return "n/a" if value is None else format(value, fmt)


def _sample_row(r: dict[str, Any], p: Perturbation) -> str:
    steer = r["steerability"]
    failed = "" if r["passed"] else f" ({failure_class(steer)})"
    return (
        f"| {p.index} | {r['outcome']}{failed} | {'yes' if r['passed'] else 'no'} | "
        f"{_num(r['min_clearance_m'])} | {p.ground_friction:.2f} | {p.payload_kg:.1f} | {p.latency_steps} | "
        f"{p.pose_xy_std_m:.3f} | {p.pose_yaw_std_rad:.3f} | {p.obstacle_xy_std_m:.3f} | "
        f"{p.obstacle_velocity_scale:.2f} | {p.torque_scale:.2f} | {p.yaw_ratio:.2f} | "
        f"{_num(steer['turn_in_place_radps'], '.2f')} | {_num(steer['current_headroom_a'], '.1f')} | "
        f"{p.episode_seed} |"
    )


def markdown(report: CheckReport, plots: dict[str, str]) -> str:
    """check.md: verdict, audit table, sweep summary, plots, failing and all samples."""
    s, n = report.stats, report.nominal
    lines = [
        f"# husky-sim check: {report.scenario}",
        "",
        f"Controller {report.controller}, N = {report.horizon}, tau = {report.tau_s:g} s; "
        f"{report.samples} samples, seed {report.seed}, backend {report.backend}.",
        "",
        f"**Verdict: {report.verdict}**: {report.reason}",
        "",
        "## Configuration audit",
        "",
        "| check | status | numbers |",
        "|---|---|---|",
        *(f"| {f.check} | {f.status.upper()} | {_cell(f.detail)} |" for f in report.findings),
        "",
        "## Robustness sweep",
        "",
        "Each sample draws, uniformly and independently (numpy default_rng(seed)):",
        "",
        "| perturbation | range |",
        "|---|---|",
        *(
            f"| {k} | {v[0]:g} to {v[1]:g} |"
            for k, v in asdict(report.ranges).items()
            if k not in SENSING_MODEL_FIELDS or v[0] != v[1]  # the lidar model only when drawn
        ),
        "",
        "Obstacle speed error is on the sensing side: the controller is told velocity x scale while "
        "the obstacles keep their true motion. Friction, payload, latency and noise replace the "
        "scenario's values; the torque factor scales its motor current limit; the yaw ratio sets the "
        "tyres' lateral stiffness.",
        "",
        f"- nominal (unperturbed): {n['outcome']}, min clearance {_num(n['min_clearance_m'])} m",
        f"- pass rate (no collision and converged): {s['passed']}/{s['samples']} = {s['pass_rate']:.1%}",
        f"- outcomes: {', '.join(f'{k} {v}' for k, v in s['outcomes'].items())}",
    ]
    if s["worst_sample"] is not None:
        worst = report.perturbations[s["worst_sample"]]
        lines.append(
            f"- worst clearance: {s['worst_clearance_m']:.3f} m in sample {worst.index} ({worst.describe()})"
        )
        pct = s["clearance_percentiles_m"]
        lines += [
            "",
            "Minimum clearance (m) over the samples:",
            "",
            "| " + " | ".join(pct) + " |",
            "|" + "---|" * len(pct),
            "| " + " | ".join(f"{v:.3f}" for v in pct.values()) + " |",
        ]
    if s["failures_by_class"]:
        lines.append(
            "- failures by class (plant: the sample's robot cannot pivot, see steerability): "
            + ", ".join(f"{k} {v}" for k, v in s["failures_by_class"].items())
        )
    figures = (
        ("Clearance distribution", "histogram"),
        ("Sensitivity", "sensitivity"),
        ("Payload", "payload"),
    )
    for title, name in figures:
        if name in plots:
            lines += ["", f"![{title}]({plots[name]})"]
    header = [
        "| sample | outcome | passed | min clearance (m) | friction | payload (kg) | latency | pose std (m) "
        "| yaw std (rad) | obstacle std (m) | obstacle speed x | torque x | yaw ratio "
        "| turn in place (rad/s) | current headroom (A) | episode seed |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    if report.failure_files:
        lines += [
            "",
            "## Failing samples",
            "",
            f"Reproduce one with `husky-sim run FILE --controller {report.controller}`.",
            "",
            *header,
        ]
        for index in report.failure_files:
            lines.append(_sample_row(report.results[index], report.perturbations[index]))
        lines += ["", *(f"- sample {i}: `{path}`" for i, path in report.failure_files.items())]
    shown = min(len(report.results), MD_SAMPLE_ROWS)
    more = "" if shown == len(report.results) else f" (first {shown}; check.json has all)"
    lines += ["", f"## All samples{more}", "", *header]
    lines += [
        _sample_row(r, p) for r, p in list(zip(report.results, report.perturbations, strict=True))[:shown]
    ]
    return "\n".join(lines) + "\n"
