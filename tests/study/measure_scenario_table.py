"""Measure the scenario suite's expectation table (tests/study/scenario_expectations.yaml) anew:
every cell of husky_sim.study.suite.standard_matrix on the table's solver, as test_scenario_suite
runs it, and write the table. Run it after a change of the plant or the controllers, then say in the
commit what changed and why; the `why` of a collided cell is kept from the old table when it
collided there too, else it must be written by hand (the file says so until it is).

    .venv/bin/python tests/study/measure_scenario_table.py [--jobs 2] [--out FILE] [--add SCENARIO ...]

A full re-measure rewrites every entry (an `on_other_cpus` outcome must then be measured again on
the other machine); `--add` measures only a new scenario's cells and appends them.
"""

from __future__ import annotations

import argparse
import json
import sys
from multiprocessing import get_context
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from husky_sim.runs.run import run_scenario  # noqa: E402
from husky_sim.runs.scenario import shipped_scenarios  # noqa: E402
from husky_sim.study.suite import Cell, standard_matrix  # noqa: E402

TABLE = Path(__file__).with_name("scenario_expectations.yaml")
HEADER_END = "cells:\n"
TODO_WHY = "TO BE EXPLAINED: collided when the table was measured"


def _measure(cell: Cell) -> dict[str, object]:
    sys.path.insert(0, str(Path(__file__).parent))
    from test_scenario_suite import _on_table_solver

    m = run_scenario(_on_table_solver(cell.scenario), cell.controller, cell.horizon, cell.gamma).metrics
    return {"outcome": m.outcome, "converged": bool(m.converged), "min_clearance_m": m.min_clearance_m}


def _entry(cell: Cell, measured: dict[str, object], old: dict[str, object] | None) -> str:
    fields = {"scenario": cell.scenario, "controller": cell.controller, "horizon": cell.horizon}
    if cell.gamma is not None:
        fields["gamma"] = cell.gamma
    fields.update(outcome=measured["outcome"], converged=measured["converged"])
    if measured["outcome"] == "collided":
        keep = old is not None and old.get("outcome") == "collided" and old.get("why")
        clearance = measured["min_clearance_m"]
        fields["why"] = old["why"] if keep else f"{TODO_WHY} (min clearance {clearance:.3f} m)"
    return "  - " + yaml.safe_dump(fields, default_flow_style=True, width=10_000, sort_keys=False).strip()


Entry = dict[str, object]


def _lines(cells: list[Cell], results: list[Entry], old: dict[Cell, Entry]) -> list[str]:
    """The table's lines for these cells, a comment line before each scenario's."""
    lines, scenario = [], None
    for cell, measured in zip(cells, results, strict=True):
        if cell.scenario != scenario:
            scenario = cell.scenario
            lines.append(f"  # --- {scenario}")
        lines.append(_entry(cell, measured, old.get(cell)))
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=TABLE)
    parser.add_argument(
        "--add",
        nargs="+",
        metavar="SCENARIO",
        help="measure only these new shipped scenarios' cells and append them, the rest kept as written",
    )
    args = parser.parse_args()
    text = TABLE.read_text()
    header = text[: text.index(HEADER_END)]
    old = {
        Cell(e["scenario"], e["controller"], e["horizon"], e.get("gamma")): e
        for e in yaml.safe_load(text)["cells"]
    }
    cells = standard_matrix(args.add or [path.stem for path in shipped_scenarios()])
    if args.add and any(cell in old for cell in cells):
        print(f"--add: {', '.join(args.add)} already has cells in the table", file=sys.stderr)
        return 2
    with get_context("spawn").Pool(args.jobs) as pool:
        results = pool.map(_measure, cells, chunksize=1)
    if args.add:  # appended: the table's other entries (and their on_other_cpus) stay as written
        added = _lines(cells, results, {})
        args.out.write_text(text.rstrip("\n") + "\n" + "\n".join(added) + "\n")
        print(f"-> {args.out} (+{len(cells)} cells)")
        return 0
    (args.out.parent / f"{args.out.stem}.measured.json").write_text(
        json.dumps([{"cell": cell.label(), **r} for cell, r in zip(cells, results, strict=True)], indent=1)
    )
    lines = _lines(cells, results, old)
    for cell, measured in zip(cells, results, strict=True):
        before = old.get(cell)
        if before is not None and (before["outcome"], before["converged"]) != (
            measured["outcome"],
            measured["converged"],
        ):
            print(
                f"{cell.label()}: {before['outcome']}/{before['converged']} -> "
                f"{measured['outcome']}/{measured['converged']} (min clearance {measured['min_clearance_m']})"
            )
    args.out.write_text(header + HEADER_END + "\n".join(lines) + "\n")
    print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
