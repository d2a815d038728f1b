"""A controller's tunable settings: each a dataclass field with its default, allowed range and
one-line contract (`setting`; a switch: `flag`), checked when the config is made (`check_ranges`)
and set from a scenario's `controller.<name>` block (`apply_settings`). The scenario schema and the
settings table (`setting_rows`, `husky-sim settings`) are generated from the same fields, so a
default, its range and its contract live in one place, the controller's config."""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

from controllers.config import ConfigError

C = TypeVar("C")


@dataclass(frozen=True)
class Range:
    """The values a setting may take: [lo, hi] ((lo, hi] when lo_open), in `unit`; a tuple
    setting's every entry."""

    lo: float
    hi: float
    unit: str = ""
    lo_open: bool = False
    integer: bool = False

    def contains(self, value: float) -> bool:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        if self.integer and not isinstance(value, int):
            return False
        if isinstance(value, float) and not math.isfinite(value):
            return False
        return (value > self.lo if self.lo_open else value >= self.lo) and value <= self.hi

    def bounds(self) -> str:
        """'[lo, hi]' ('(lo, hi]' when lo is open), in full up to ten digits."""
        return f"{'(' if self.lo_open else '['}{self.lo:.10g}, {self.hi:.10g}]"

    def text(self) -> str:
        """'[lo, hi] unit' ('(lo, hi]' when lo is open), in full up to ten digits."""
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.bounds()}{unit}"


def setting(
    default: object, lo: float, hi: float, unit: str = "", *, lo_open: bool = False, doc: str = ""
) -> object:
    """A tunable setting: its default, its allowed range and its one-line contract (`doc`: what
    it bounds and why), checked when the config is made (check_ranges) and shown by the scenario
    schema (`controller.<name>`) and the settings table (setting_rows)."""
    integer = isinstance(default, int) and not isinstance(default, bool)
    metadata: dict[str, object] = {"range": Range(lo, hi, unit, lo_open, integer)}
    if doc:
        metadata["doc"] = doc
    return field(default=default, metadata=metadata)


def flag(default: bool, *, doc: str) -> object:
    """A switch a scenario may set (true or false), with its one-line contract."""
    return field(default=default, metadata={"doc": doc})


def check_ranges(config: object, prefix: str) -> None:
    """ConfigError naming the first setting of `config` (a dataclass) outside its Range."""
    for f in fields(config):
        allowed = f.metadata.get("range")
        if allowed is None:
            continue
        value = getattr(config, f.name)
        values = value if isinstance(value, tuple) else (value,)
        if not all(allowed.contains(v) for v in values):
            raise ConfigError(f"{prefix}{f.name}: must be in {allowed.text()}, got {value}")


def nested_settings(config: type) -> dict[str, type]:
    """The fields of `config` (a dataclass type) that are settings blocks of their own: dataclass
    fields made by a default factory whose type has ranged settings (husky-cbf's `planner`)."""
    out: dict[str, type] = {}
    for f in fields(config):
        if f.default_factory is dataclasses.MISSING:  # type: ignore[misc]
            continue
        kind = type(f.default_factory())  # type: ignore[misc]
        if dataclasses.is_dataclass(kind) and any("range" in g.metadata for g in fields(kind)):
            out[f.name] = kind
    return out


def apply_settings(config: C, given: Mapping[str, Any] | None) -> C:
    """`config` with the settings a scenario gave (already validated against their ranges by the
    schema, checked again by the config itself); nested blocks are applied field by field."""
    if not given:
        return config
    changes = dict(given)
    for name in nested_settings(type(config)):
        if name in changes:
            changes[name] = apply_settings(getattr(config, name), changes[name])
    return dataclasses.replace(config, **changes)  # type: ignore[type-var]


@dataclass(frozen=True)
class SettingRow:
    """One setting of a controller's config: its dotted name, default, range ('' for a switch),
    unit and one-line contract."""

    name: str
    default: object
    bounds: str
    unit: str
    doc: str


def setting_rows(config: type, prefix: str = "") -> list[SettingRow]:
    """Every setting of `config` (a dataclass type) that a scenario may set, in declaration order,
    nested blocks' as `block.name`: the ranged ones and the switches. A setting's contract is its
    `doc`, else the `#:` comment above its field (or the comment after it) in the source."""
    nested = nested_settings(config)
    comments = _field_comments(config)
    rows: list[SettingRow] = []
    for f in fields(config):
        if f.name in nested:
            rows += setting_rows(nested[f.name], f"{prefix}{f.name}.")
            continue
        allowed = f.metadata.get("range")
        if allowed is None and not isinstance(f.default, bool):
            continue
        doc = str(f.metadata.get("doc") or comments.get(f.name, ""))
        bounds = "" if allowed is None else allowed.bounds()
        unit = "" if allowed is None else allowed.unit
        rows.append(SettingRow(f"{prefix}{f.name}", f.default, bounds, unit, doc))
    return rows


def _field_comments(config: type) -> dict[str, str]:
    """Each field's comment in the source of `config`: the `#:` lines right above it, else the
    comment at the end of its line; {} where the source cannot be read."""
    try:
        lines = inspect.getsource(config).splitlines()
    except (OSError, TypeError):
        return {}
    out: dict[str, str] = {}
    above: list[str] = []
    for line in lines:
        text = line.strip()
        if text.startswith("#:"):
            above.append(text[2:].strip())
            continue
        match = re.match(r"(\w+)\s*:[^=]*=.*?(?:#\s*(.*))?$", text)
        if match and not text.startswith(("def ", "class ", "@")):
            comment = " ".join(above) or (match.group(2) or "").strip()
            if comment:
                out.setdefault(match.group(1), comment)
        above = []
    return out
