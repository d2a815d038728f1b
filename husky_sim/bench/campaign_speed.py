"""How fast a campaign's closed loops ran: the real-time factor of each run (simulated over wall
time) and the controller's per-step compute time (solve plus guidance and filter, the log's
`solve_ms`, which times the whole of `Controller.solve`), pooled over every step of every run.

A campaign is the benchmark: hundreds of layouts of every family give a distribution no single
scenario does. Wall time is the machine's, so quote it with the machine and the number of workers
that ran beside each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from husky_sim.runs.run_folder import RunFolderError, read_log, read_summary

#: The targets a campaign's speed is held to: real time times this, and this p99 step time (ms).
TARGET_REAL_TIME_FACTOR = 10.0
TARGET_STEP_P99_MS = 25.0


@dataclass(frozen=True)
class CampaignSpeed:
    """Speed figures of one campaign folder's runs."""

    folder: str
    runs: int
    steps: int
    tau_s: float
    real_time_factor_median: float
    real_time_factor_p10: float
    step_ms_median: float
    step_ms_p99: float
    step_ms_max: float
    over_tau: int  # steps whose compute took longer than one control period

    def report(self) -> str:
        def verdict(ok: bool) -> str:
            return "meets" if ok else "misses"

        rt_ok = self.real_time_factor_median >= TARGET_REAL_TIME_FACTOR
        p99_ok = self.step_ms_p99 <= TARGET_STEP_P99_MS
        return "\n".join(
            [
                f"campaign {self.folder}: {self.runs} runs, {self.steps} control steps at tau = "
                f"{self.tau_s * 1e3:.0f} ms",
                f"real-time factor: median {self.real_time_factor_median:.1f}x, 10th percentile "
                f"{self.real_time_factor_p10:.1f}x ({verdict(rt_ok)} >= {TARGET_REAL_TIME_FACTOR:.0f}x)",
                f"controller step (solve + guidance + filter): median {self.step_ms_median:.1f} ms, "
                f"p99 {self.step_ms_p99:.1f} ms ({verdict(p99_ok)} <= {TARGET_STEP_P99_MS:.0f} ms), "
                f"max {self.step_ms_max:.1f} ms, {self.over_tau} steps over tau",
            ]
        )


def campaign_speed(folder: Path | str) -> CampaignSpeed:
    """The speed figures of the runs under `folder`/runs (a `husky-sim campaign` folder);
    RunFolderError when it holds no finished run."""
    root = Path(folder)
    factors, step_ms, taus = [], [], []
    for run_dir in sorted((root / "runs").glob("*")):
        try:
            summary = read_summary(run_dir)
            log = read_log(run_dir, needed=("solve_ms",))
        except RunFolderError:
            continue
        wall_s, sim_s = float(summary.get("wall_time_s") or 0.0), float(summary.get("sim_time_s") or 0.0)
        if wall_s <= 0.0:
            continue
        factors.append(sim_s / wall_s)
        step_ms.append(log["solve_ms"])
        taus.append(float(summary["tau_s"]))
    if not factors:
        raise RunFolderError(f"{root}: no finished run under runs/ (a `husky-sim campaign` folder)")
    steps = np.concatenate(step_ms)
    tau_s = float(np.median(taus))
    return CampaignSpeed(
        folder=str(root),
        runs=len(factors),
        steps=int(steps.size),
        tau_s=tau_s,
        real_time_factor_median=float(np.median(factors)),
        real_time_factor_p10=float(np.percentile(factors, 10)),
        step_ms_median=float(np.median(steps)),
        step_ms_p99=float(np.percentile(steps, 99)),
        step_ms_max=float(np.max(steps)),
        over_tau=int(np.sum(steps > tau_s * 1e3)),
    )
