"""The optional extras (pyproject's optional-dependencies): what each brings, and the one-line
error a feature gives when its extra is not installed. The core (runs, the suite, check, figures,
calibration) needs none of them."""

from __future__ import annotations

import importlib
from types import ModuleType

#: Each extra and what it is for; `pip install 'husky-nav-sim[NAME]'`.
EXTRAS = {
    "ros2": "`serve`, `rehearse` (Cyclone DDS) and `replay` of ROS bags (rosbags)",
    "rclpy": "`serve --transport rclpy`: ROS 2's own client library and Fast DDS, from PyPI",
    "foxglove": "run.mcap in a run folder and `--live` to Foxglove (the Foxglove SDK)",
    "gym": 'the gymnasium environment "HuskyNav-v0"',
    "cluster": "`check --backend dask` and `suite --backend dask` (Dask distributed)",
}


class MissingExtra(ImportError):
    """A feature's optional dependency is not installed; the message names the extra."""


def require(module: str, extra: str, feature: str) -> ModuleType:
    """`module` imported, or MissingExtra: '<feature> needs <module>: pip install ...[extra]'."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise missing(module, extra, feature) from None


def missing(module: str, extra: str, feature: str) -> MissingExtra:
    """The error for `feature` without `module` (from the extra `extra`)."""
    return MissingExtra(f"{feature} needs {module}: pip install 'husky-nav-sim[{extra}]'")
