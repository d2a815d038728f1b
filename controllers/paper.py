"""The paper's controllers, registered: the NMPC-CLF (controllers.nmpc) with no obstacle
constraint (the baseline), BT, CBF or Relax-CBF, each reproduced unchanged. Each plans on the
paper's unicycle with one circle for the robot, no acceleration limits and an instant stop."""

from __future__ import annotations

import dataclasses

from controllers.config import NMPCConfig, SafetyConstraint
from controllers.interface import Controller
from controllers.registry import ControllerEntry, ControllerInputs, PlanProfile, register


def _entry(safety: SafetyConstraint, summary: str, **flags: bool) -> ControllerEntry:
    def configure(inputs: ControllerInputs) -> NMPCConfig:
        return dataclasses.replace(inputs.nmpc, safety=safety)

    def build(config: NMPCConfig) -> Controller:
        from controllers.nmpc import NMPCController  # CasADi: only once a controller is built

        return NMPCController(config)

    def profile(config: NMPCConfig) -> PlanProfile:
        return PlanProfile(config, config.omega_max_radps)

    return register(ControllerEntry(safety, summary, configure, build, profile, paper=True, **flags))


NONE = _entry(
    "none", "the paper's NMPC-CLF with no obstacle constraint", avoids_obstacles=False, decay_rate=False
)
BT = _entry("bt", "the paper's baseline: distance >= radii sum at every predicted step", decay_rate=False)
CBF = _entry("cbf", "the paper's CBF constraint B(k+1) >= (1 - gamma) B(k)")
RELAX_CBF = _entry(
    "relax-cbf", "the paper's Relax-CBF constraint B(k+1) >= s_h (1 - gamma) B(k)", decay_slack=True
)
