"""Scenario families: seeded generators of validated, feasible scenario files (one module per
family, registered in husky_sim.families.registry), and the generator that draws and writes them
(husky_sim.families.generate)."""

from husky_sim.families.base import Family, Param
from husky_sim.families.registry import family, family_names, register

__all__ = ["Family", "Param", "family", "family_names", "register"]
