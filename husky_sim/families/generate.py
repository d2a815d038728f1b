"""Drawing a family's layouts and writing them as scenario files.

Layout `index` of seed `seed` is drawn from `numpy.random.default_rng([seed, index, attempt])`:
parameters first (Family.draw_params), then the family's placement. A draw that the schema
rejects or that fails the feasibility check (husky_sim.families.feasibility) is drawn again with
the next `attempt`, up to `MAX_ATTEMPTS`; the attempt is part of the file's header. The same
family, seed, index, fixed parameters and code give the same bytes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from husky_sim.families.base import Draw, Family, Robot
from husky_sim.families.feasibility import Feasibility, check_layout
from husky_sim.families.registry import family as family_named
from husky_sim.paths import DEFAULT_ROBOT
from husky_sim.runs.scenario import Scenario, scenario_from_data
from husky_sim.runs.scenario_errors import ScenarioError
from husky_sim.scenario_file import scenario_yaml
from husky_sim.sim.robot_description import load_robot

#: Draws tried for one layout before the generator gives up (a family whose parameters leave no
#: feasible layout: a one-line error naming the family and the parameters).
MAX_ATTEMPTS = 50
#: Largest seed (the schema's seed range).
MAX_SEED = 2**32 - 1


@dataclass(frozen=True)
class Layout:
    """One generated layout: where it came from, its validated scenario, its feasibility and
    the file text (header and scenario data)."""

    family: str
    seed: int
    index: int
    attempt: int
    params: dict[str, float]
    scenario: Scenario
    feasibility: Feasibility
    text: str

    @property
    def name(self) -> str:
        return self.scenario.name

    def write(self, out_dir: Path) -> Path:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / f"{self.name}.yaml"
        path.write_text(self.text)
        return path


def layout_name(family: str, seed: int, index: int) -> str:
    return f"{family}-s{seed}-{index:03d}"


def draw_layout(
    family: Family | str,
    seed: int,
    index: int,
    fixed: Mapping[str, float] | None = None,
    robot: str = DEFAULT_ROBOT,
) -> Layout:
    """Layout `index` of `seed` (see the module docstring); `fixed` parameters keep their value."""
    fam = family_named(family) if isinstance(family, str) else family
    if not (0 <= seed <= MAX_SEED and 0 <= index <= MAX_SEED):
        raise ValueError(f"--seed: must be in [0, {MAX_SEED}], got {seed}")
    body = Robot.of(load_robot(robot))
    reasons: list[str] = []
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng([seed, index, attempt])
        params = fam.draw_params(rng, fixed or {})
        draw = Draw(params, rng, body)
        data = fam.build(draw)
        name = layout_name(fam.name, seed, index)
        data = {
            "name": name,
            "description": f"{fam.name} layout {index} of seed {seed}: {fam.summary}"[:500],
            "seed": int(np.random.default_rng([seed, index]).integers(0, 2**31)),
            **data,
        }
        if robot != DEFAULT_ROBOT:
            data["robot"] = {"model": robot, **data["robot"]}
        try:
            scenario = scenario_from_data(data, name)
        except ScenarioError as exc:
            reasons.append(str(exc))
            continue
        verdict = check_layout(scenario)
        if not verdict.feasible:
            reasons.append(verdict.reason)
            continue
        header = _header(fam, seed, index, attempt, params, verdict, robot)
        return Layout(fam.name, seed, index, attempt, params, scenario, verdict, scenario_yaml(data, header))
    fixed_text = ", ".join(f"{k}={v:g}" for k, v in (fixed or {}).items()) or "none fixed"
    raise ValueError(
        f"family {fam.name}: no feasible layout in {MAX_ATTEMPTS} draws of seed {seed}, index {index} "
        f"(parameters: {fixed_text}); last reason: {reasons[-1] if reasons else 'none'}"
    )


def generate(
    family: Family | str,
    count: int,
    seed: int,
    fixed: Mapping[str, float] | None = None,
    robot: str = DEFAULT_ROBOT,
) -> list[Layout]:
    """Layouts 0 .. count-1 of `seed`."""
    if not 1 <= count <= 100_000:
        raise ValueError(f"--count: must be in [1, 100000], got {count}")
    return [draw_layout(family, seed, i, fixed, robot) for i in range(count)]


def _header(
    fam: Family,
    seed: int,
    index: int,
    attempt: int,
    params: Mapping[str, float],
    verdict: Feasibility,
    robot: str,
) -> str:
    values = ", ".join(f"{k}={_fmt(v)}" for k, v in params.items())
    way = "n/a" if verdict.path_length_m is None else f"{verdict.path_length_m:.2f} m"
    robot_arg = "" if robot == DEFAULT_ROBOT else f" --robot {robot}"
    return (
        f"family: {fam.name}\n"
        f"seed: {seed}\n"
        f"index: {index}\n"
        f"attempt: {attempt}\n"
        f"params: {values}\n"
        f"feasible: the body's circumscribed circle has a way of {way} among the static obstacles\n"
        f"regenerate: husky-sim generate {fam.name} --seed {seed} --count {index + 1}{robot_arg} "
        "(with the same --param values)"
    )


def _fmt(value: float) -> str:
    return f"{value:.6g}" if math.isfinite(value) else str(value)


def header_fields(text: str) -> dict[str, Any]:
    """The `key: value` lines of a generated file's comment header, as strings."""
    fields: dict[str, Any] = {}
    for line in text.splitlines():
        if not line.startswith("# "):
            break
        key, _, value = line[2:].partition(": ")
        fields[key] = value
    return fields
