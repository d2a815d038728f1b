"""husky-cbf: a physics-aware Relax-CBF NMPC-CLF for the Husky (config, model, footprint discs,
guidance, OCP, controller). Like the rest of `controllers`, it never imports the simulator."""

from controllers.husky_cbf.config import Footprint, GuidanceConfig, HuskyCBFConfig, RobotResponse
from controllers.husky_cbf.controller import HuskyCBFController

__all__ = ["Footprint", "GuidanceConfig", "HuskyCBFConfig", "HuskyCBFController", "RobotResponse"]
