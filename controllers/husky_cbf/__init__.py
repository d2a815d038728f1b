"""husky-cbf: a physics-aware Relax-CBF NMPC-CLF for the Husky, in layers as Nav2 is built: the
mover model (movers.py), the global planner (planner.py), the behaviours (behaviours/), the
arbiter that chooses among them (arbiter.py), and the NMPC (model.py, ocp.py, controller.py).
Like the rest of `controllers`, it never imports the simulator."""

from controllers.husky_cbf.config import Footprint, HuskyCBFConfig, RobotResponse
from controllers.husky_cbf.controller import HuskyCBFController

__all__ = ["Footprint", "HuskyCBFConfig", "HuskyCBFController", "RobotResponse"]
