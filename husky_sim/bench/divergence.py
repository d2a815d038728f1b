"""`husky-sim bench-divergence`: where the default solver's closed loop and the reference IPOPT's
part on one PyBullet cell, and whether that is a different local optimum.

The cell runs twice with every setting equal but the NLP backend (FATROP, the default, and IPOPT,
the backend the scenario table is measured with), recording each step's problem. At the first
control step whose commands differ by more than PART_TOL, the FATROP loop's problem is solved
again by cold IPOPT converged to 1e-10 (bench.solvers.converged_solver), and both answers' objectives
are given. If converged IPOPT gives FATROP's command there, the solvers agree on that problem and
the loops parted because their states had (`poses_part_step`: the first step whose positions
differ by more than 1e-6 m); if it gives the IPOPT loop's command from (nearly) the same pose, the
two loops took different local optima of the same problem.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from controllers import ControlResult, NMPCConfig, NMPCController, registry
from controllers.ocp import Plan, layout_for, paper_nlp
from husky_sim.bench.solvers import REFERENCE, converged_solver
from husky_sim.runs.scenario import Scenario
from husky_sim.sim.episode import EpisodeResult, run_episode

#: Commands (m/s, rad/s) further apart than this have parted.
PART_TOL = 1e-3
#: Positions (m) further apart than this differ.
POSE_TOL_M = 1e-6


@dataclass(frozen=True)
class Divergence:
    """The two loops of one cell and where they part (None: never by more than PART_TOL)."""

    label: str
    outcomes: dict[str, str]  # backend -> outcome
    solver_fallbacks: int  # FATROP problems handed to IPOPT in the FATROP loop
    poses_part_step: int | None
    part_step: int | None = None
    part_t_s: float | None = None
    pose_difference_m: float | None = None  # largest |x|, |y| difference at part_step (m)
    commands: dict[str, tuple[float, float]] | None = None  # backend -> (v m/s, omega rad/s)
    converged: tuple[float, float] | None = None  # cold IPOPT, 1e-10, on the FATROP loop's problem
    objectives: dict[str, float] | None = None  # "fatrop" and "converged": J of each answer there

    def report(self) -> str:
        head = (
            f"{self.label}: ipopt {self.outcomes[REFERENCE]}, fatrop {self.outcomes['fatrop']} "
            f"({self.solver_fallbacks} FATROP problems handed to IPOPT); positions first differ by "
            f"> {POSE_TOL_M:g} m at step {self.poses_part_step}"
        )
        if self.part_step is None or self.commands is None or self.converged is None:
            return head + f"; commands never part by > {PART_TOL:g}"
        ip, fa, cv = self.commands[REFERENCE], self.commands["fatrop"], self.converged
        assert self.objectives is not None
        return "\n".join(
            [
                head,
                f"commands part at step {self.part_step} (t {self.part_t_s:.1f} s), positions "
                f"{self.pose_difference_m:.1e} m apart: ipopt ({ip[0]:.4f}, {ip[1]:.4f}), fatrop "
                f"({fa[0]:.4f}, {fa[1]:.4f})",
                f"converged IPOPT on the FATROP loop's problem: ({cv[0]:.4f}, {cv[1]:.4f}), objective "
                f"{self.objectives['converged']:.6g} against FATROP's {self.objectives['fatrop']:.6g}",
            ]
        )


class _Answers:
    """Each step's answer as the NLP's decision vector (a StepObserver: it only reads)."""

    def __init__(self, config: NMPCConfig) -> None:
        self.layout, self.decisions = layout_for(config), []

    def on_step(self, row: dict[str, object], result: ControlResult, obstacle_xy: np.ndarray) -> None:
        plan = Plan(result.predicted_states, result.predicted_controls, result.clf_slack, result.decay_slack)
        self.decisions.append(plan.to_vector(self.layout))


def _loop(scenario: Scenario, controller: str, backend: str) -> tuple[NMPCConfig, EpisodeResult, list]:
    """The cell on `backend`: its config, its episode, and per step (parameters, guess, answer)."""
    spec = scenario.controller.model_copy(update={"solver": backend})
    sc = scenario.model_copy(update={"controller": spec})
    config = sc.controller_config(controller)
    nmpc = NMPCController(config)
    problems: list[tuple[np.ndarray, np.ndarray]] = []
    nmpc.on_solve = lambda p, guess: problems.append((p.copy(), guess.copy()))
    answers = _Answers(config)
    result = run_episode(
        nmpc,
        sc.reference_object(),
        sc.episode_config(),
        robot_radius_m=config.robot_radius_m,
        observer=answers,
    )
    return config, result, [(p, g, d) for (p, g), d in zip(problems, answers.decisions, strict=True)]


def _position_gap(a: dict[str, object], b: dict[str, object]) -> float:
    """The larger of the x and y differences (m) of two log rows."""
    return float(max(abs(a["x_m"] - b["x_m"]), abs(a["y_m"] - b["y_m"])))


def trace_divergence(scenario: Scenario, controller: str) -> Divergence:
    """Both loops of the resolved scenario (overrides applied) with one of the paper's controllers."""
    config, ipopt, _ = _loop(scenario, controller, REFERENCE)
    _, fatrop, fatrop_problems = _loop(scenario, controller, "fatrop")
    gamma = f" gamma={config.gamma:g}" if registry.entry(controller).decay_rate else ""  # BT has none
    label = f"{scenario.name} {controller} N={config.horizon}{gamma}"
    rows = list(zip(ipopt.rows, fatrop.rows, strict=False))
    poses_part = next(
        (k for k, (a, b) in enumerate(rows) if _position_gap(a, b) > POSE_TOL_M),
        None,
    )
    base = Divergence(
        label,
        {REFERENCE: ipopt.metrics.outcome, "fatrop": fatrop.metrics.outcome},
        fatrop.metrics.solver_fallbacks,
        poses_part,
    )

    def command(row: dict[str, object]) -> tuple[float, float]:
        return float(row["v_cmd_mps"]), float(row["omega_cmd_radps"])

    for k, (a, b) in enumerate(rows):
        if np.max(np.abs(np.subtract(command(a), command(b)))) <= PART_TOL:
            continue
        nlp = paper_nlp(config)
        objective = ca.Function("J", [nlp.problem["x"], nlp.problem["p"]], [nlp.problem["f"]])
        parameters, guess, answer = fatrop_problems[k]
        solved = converged_solver(config).solve(parameters, guess)
        converged = Plan.from_vector(solved.decision, layout_for(config)).controls[0]
        return replace(
            base,
            part_step=k,
            part_t_s=float(a["t_s"]),
            pose_difference_m=_position_gap(a, b),
            commands={REFERENCE: command(a), "fatrop": command(b)},
            converged=(float(converged[0]), float(converged[1])),
            objectives={
                "converged": float(objective(solved.decision, parameters)),
                "fatrop": float(objective(answer, parameters)),
            },
        )
    return base
