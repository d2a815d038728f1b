"""`gymnasium.make("HuskyNav-v0", scenario=...)`: the gymnasium environment built from a scenario
file, resolved by the same schema as every run (husky_sim.runs.scenario)."""

from __future__ import annotations

from husky_sim.runs.scenario import Scenario, load_scenario
from husky_sim.sim.environment import HuskyNavEnv


def make_husky_nav(
    scenario: str | Scenario = "husky_point_stabilisation", seed: int | None = None
) -> HuskyNavEnv:
    """HuskyNavEnv for a shipped scenario's name, a scenario file's path or a loaded Scenario;
    `seed` overrides the file's (the first reset's sensor seed, as `husky-sim run --seed`)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    if seed is not None:
        sc = sc.with_overrides(seed=seed)
    return HuskyNavEnv(sc.episode_config(), sc.reference_object())
