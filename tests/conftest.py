"""The tests of an optional extra (husky_sim.extras) are left out where it is not installed, so the
core's tests run on a core install (`pip install -e . pytest pytest-xdist hypothesis`); `make
test` installs every extra and sets HUSKY_SIM_ALL_EXTRAS=1, and then a missing one is an error,
never a skip: CI runs every test."""

from __future__ import annotations

import importlib.util
import os

import pytest

#: The tests that need a module of an extra: files and folders under tests/, and test ids
#: (`path::name`, matched as a prefix) where only some tests of a file need it.
NEEDS = {
    "gymnasium": ("runs/test_environment.py",),
    "cyclonedds": ("ros2",),
    "mcap": ("ros2",),
    "foxglove": ("ros2",),
    "rosbags": ("realcheck/test_replay.py::bags",),  # `::NAME` of a fixture: the tests using it
    "distributed": (
        "realcheck/test_check.py::test_sweep_gives_identical_results_on_local_processes_and_dask",
        "runs/test_parallel.py::test_both_backends_keep_order_and_report_an_error_in_place[dask]",
        "study/test_suite_cli.py::test_parallel_serial_and_dask_suites_agree",
    ),
}
#: Set by `make test` (and so CI): every extra must be there.
REQUIRE_ALL = "HUSKY_SIM_ALL_EXTRAS"


def _missing() -> list[str]:
    return [m for m in NEEDS if importlib.util.find_spec(m) is None]


if os.environ.get(REQUIRE_ALL) and _missing():
    raise pytest.UsageError(
        f"{REQUIRE_ALL} is set but {', '.join(_missing())} is not installed: pip install -e '.[test]'"
    )

#: Whole files and folders of a missing extra: not even collected (they import it at the top).
collect_ignore = [p for m in _missing() for p in NEEDS[m] if "::" not in p]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Single tests of a missing extra: skipped, naming the extra's module."""
    prefixes = [(p, m) for m in _missing() for p in NEEDS[m] if "::" in p]
    for item in items:
        test_id = item.nodeid.removeprefix("tests/")
        path = test_id.split("::")[0]
        for prefix, module in prefixes:
            where, name = prefix.split("::")
            if test_id.startswith(prefix) or (path == where and name in getattr(item, "fixturenames", ())):
                item.add_marker(pytest.mark.skip(reason=f"needs {module} (an optional extra)"))
