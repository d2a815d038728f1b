"""The registry of scenario families: each is registered once, in its own module under
husky_sim.families, as a `Family`; every list of names and every look-up reads it here (as the
controllers' registry does for controllers)."""

from __future__ import annotations

import importlib

from husky_sim.families.base import Family

#: The modules that register the built-in families, in the order `husky-sim families` lists them.
BUILT_IN = (
    "husky_sim.families.static_clutter",
    "husky_sim.families.doorways",
    "husky_sim.families.crossing_walkers",
    "husky_sim.families.occluded_step_out",
    "husky_sim.families.corridor_oncoming",
    "husky_sim.families.dead_end",
    "husky_sim.families.docking",
    "husky_sim.families.tracking_among_obstacles",
    "husky_sim.families.crowd",
)

_FAMILIES: dict[str, Family] = {}
_loaded = False


def register(family: Family) -> Family:
    """Add a family (once per name); its module writes `FAMILY = register(Family(...))`."""
    if family.name in _FAMILIES and _FAMILIES[family.name] is not family:
        raise ValueError(f"family: {family.name!r} is registered already")
    _FAMILIES[family.name] = family
    return family


def _load() -> None:
    global _loaded
    if not _loaded:
        for module in BUILT_IN:
            importlib.import_module(module)
        _loaded = True


def family_names() -> list[str]:
    _load()
    return list(_FAMILIES)


def family(name: str) -> Family:
    """The family called `name`; a one-line ValueError naming the known ones otherwise."""
    _load()
    if name not in _FAMILIES:
        raise ValueError(f"family: no family named {name!r} (known: {', '.join(_FAMILIES)})")
    return _FAMILIES[name]
