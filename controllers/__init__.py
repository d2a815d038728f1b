"""NMPC-CLF controllers with BT, CBF and Relax-CBF obstacle constraints (CasADi + IPOPT).

This package never imports the simulator; a simulator uses `Controller` from `interface`.
"""

from controllers.config import (
    HUSKY_EXPERIMENT,
    SAFETY_CONSTRAINTS,
    ConfigError,
    NMPCConfig,
    SafetyConstraint,
    SolverOptions,
)
from controllers.interface import Controller, ControlResult
from controllers.nmpc import NMPCController
from controllers.obstacles import Obstacle
from controllers.references import CircleTrajectory, Reference, SetPoint, Trajectory

__all__ = [
    "HUSKY_EXPERIMENT",
    "SAFETY_CONSTRAINTS",
    "CircleTrajectory",
    "ConfigError",
    "ControlResult",
    "Controller",
    "NMPCConfig",
    "NMPCController",
    "Obstacle",
    "Reference",
    "SafetyConstraint",
    "SetPoint",
    "SolverOptions",
    "Trajectory",
]
