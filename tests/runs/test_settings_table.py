"""`husky-sim settings --controller husky-cbf`: the controller's settings as a Markdown table,
generated from its config: every setting a scenario may set is listed, with its default, range,
unit and one-line contract, and husky-cbf keeps to at most 30 of them."""

from __future__ import annotations

import dataclasses

import pytest

from controllers.husky_cbf import HuskyCBFConfig
from controllers.husky_cbf.config import MoverConfig
from husky_sim.cli import main
from husky_sim.runs.settings_schema import settings_fields

#: husky-cbf's budget of tuning settings (robot facts excluded: they have no range and no switch)
MAX_SETTINGS = 30


def _schema_names(model: type, prefix: str = "") -> set[str]:
    """The dotted names the scenario schema accepts under `controller.husky_cbf`."""
    names: set[str] = set()
    for name, info in model.model_fields.items():
        inner = [a for a in getattr(info.annotation, "__args__", ()) if isinstance(a, type)]
        nested = next((a for a in inner if hasattr(a, "model_fields")), None)
        if nested is not None:
            names |= _schema_names(nested, f"{prefix}{name}.")
        else:
            names.add(f"{prefix}{name}")
    return names


def _config_names(config: type, prefix: str = "") -> set[str]:
    """The dotted names of the config's ranged settings and switches, nested blocks walked."""
    names: set[str] = set()
    for f in dataclasses.fields(config):
        if f.default_factory is not dataclasses.MISSING and dataclasses.is_dataclass(f.default_factory()):
            names |= _config_names(type(f.default_factory()), f"{prefix}{f.name}.")
        elif "range" in f.metadata or isinstance(f.default, bool):
            names.add(f"{prefix}{f.name}")
    return names


def _table(capsys: pytest.CaptureFixture[str]) -> dict[str, list[str]]:
    assert main(["settings", "--controller", "husky-cbf"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| `")]
    table = {}
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        table[cells[0].strip("`")] = cells[1:]
    return table


def test_the_table_lists_every_setting_of_husky_cbf_and_at_most_thirty(
    capsys: pytest.CaptureFixture[str],
) -> None:
    table = _table(capsys)
    schema = settings_fields()["husky_cbf"][0]
    model = next(a for a in schema.__args__ if hasattr(a, "model_fields"))
    assert set(table) == _config_names(HuskyCBFConfig) == _schema_names(model)
    assert len(table) <= MAX_SETTINGS
    for name, (default, bounds, _unit, contract) in table.items():
        assert default and len(contract.split()) >= 5, name  # a default and a one-line contract
        assert bounds or default in ("true", "false"), name  # a range, unless a switch


def test_the_table_shows_a_setting_s_default_range_and_unit(capsys: pytest.CaptureFixture[str]) -> None:
    table = _table(capsys)
    assert table["movers.sweep_s"][:3] == [f"{MoverConfig().sweep_s:g}", "[0, 10]", "s"]
    assert table["terminal_weight"][0] == "[20, 200, 5]"
    assert table["recovery.enabled"][:2] == ["true", ""]


def test_the_guide_s_settings_table_is_the_command_s(capsys: pytest.CaptureFixture[str]) -> None:
    """docs/husky_cbf.md prints the table `husky-sim settings --controller husky-cbf` writes."""
    from pathlib import Path

    assert main(["settings", "--controller", "husky-cbf"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("|")]
    guide = Path(__file__).resolve().parents[2] / "docs" / "husky_cbf.md"
    assert "\n".join(rows) in guide.read_text()
