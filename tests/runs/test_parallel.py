"""The one parallel map of the suite and the sweep: local worker processes and a Dask cluster give
the same results in item order, an error in its item's place (no physics)."""

import pytest

from husky_sim.runs.parallel import parallel_map


@pytest.mark.parametrize("backend", ["local", "dask"])
def test_both_backends_keep_order_and_report_an_error_in_place(backend: str) -> None:
    finished: list[int] = []
    results = parallel_map(int, ["1", "x", "3", "4"], 2, lambda i, _r: finished.append(i), backend)
    assert results[0] == 1 and results[2:] == [3, 4]
    assert isinstance(results[1], ValueError) and "'x'" in str(results[1])
    assert sorted(finished) == [0, 1, 2, 3]


def test_a_scheduler_needs_the_dask_backend_and_a_backend_must_exist() -> None:
    with pytest.raises(ValueError, match="scheduler: needs backend dask"):
        parallel_map(int, ["1"], 1, backend="local", scheduler="tcp://127.0.0.1:8786")
    with pytest.raises(ValueError, match="backend: must be one of"):
        parallel_map(int, ["1"], 1, backend="ray")  # type: ignore[arg-type]
