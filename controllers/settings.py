"""A controller's tunable settings: each a dataclass field with its default and allowed range
(`setting`), checked when the config is made (`check_ranges`) and set from a scenario's
`controller.<name>` block (`apply_settings`). The scenario schema is generated from the same
fields, so a default, its range and its reason live in one place, the controller's config."""

from __future__ import annotations

import dataclasses
import math
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

    def text(self) -> str:
        """'[lo, hi] unit' ('(lo, hi]' when lo is open), in full up to ten digits."""
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.lo_open else '['}{self.lo:.10g}, {self.hi:.10g}]{unit}"


def setting(default: object, lo: float, hi: float, unit: str = "", *, lo_open: bool = False) -> object:
    """A tunable setting: its default and its allowed range, checked when the config is made
    (check_ranges) and shown by the scenario schema (`controller.<name>`)."""
    integer = isinstance(default, int) and not isinstance(default, bool)
    return field(default=default, metadata={"range": Range(lo, hi, unit, lo_open, integer)})


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
    fields made by a default factory whose type has ranged settings (husky-cbf's `guidance`)."""
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
