"""Invalid configurations raise a ConfigError naming the field."""

import math

import pytest

from controllers import ConfigError, NMPCConfig, SolverOptions


def test_paper_defaults() -> None:
    cfg = NMPCConfig()
    assert cfg.tau_s == 0.1 and cfg.horizon == 5
    assert (cfg.v_min_mps, cfg.v_max_mps, cfg.omega_max_radps) == (-1.0, 1.0, math.pi / 4)
    assert [cfg.state_weight[i][i] for i in range(3)] == [10.0, 15.0, 0.7]
    assert [cfg.input_weight[i][i] for i in range(2)] == [1.0, 0.1]
    assert [cfg.clf_weight[i][i] for i in range(3)] == [1.0, 1.0, 1.0]
    assert (cfg.clf_slack_weight, cfg.decay_slack_weight, cfg.alpha) == (70.0, 10.0, 0.3)
    assert cfg.robot_radius_m == 0.25


@pytest.mark.parametrize(
    "changes,field",
    [
        ({"horizon": 0}, "horizon"),
        ({"horizon": -3}, "horizon"),
        ({"horizon": 2.5}, "horizon"),
        ({"tau_s": 0.0}, "tau_s"),
        ({"tau_s": -0.1}, "tau_s"),
        ({"tau_s": float("nan")}, "tau_s"),
        ({"gamma": -0.01}, "gamma"),
        ({"gamma": 1.5}, "gamma"),
        ({"alpha": -0.2}, "alpha"),
        ({"alpha": 1.01}, "alpha"),
        ({"robot_radius_m": -0.1}, "robot_radius_m"),
        ({"state_weight": (10.0, -1.0, 0.7)}, "state_weight"),
        ({"state_weight": (10.0, 0.0, 0.7)}, "state_weight"),
        ({"input_weight": ((1.0, 2.0), (2.0, 1.0))}, "input_weight"),
        ({"input_weight": ((1.0, 0.5), (0.0, 1.0))}, "input_weight"),
        ({"clf_weight": (1.0, 1.0)}, "clf_weight"),
        ({"clf_slack_weight": 0.0}, "clf_slack_weight"),
        ({"decay_slack_weight": -10.0}, "decay_slack_weight"),
        ({"omega_max_radps": 0.0}, "omega_max_radps"),
        ({"v_min_mps": 0.5}, "v_min_mps"),
        ({"obstacle_slots": -1}, "obstacle_slots"),
        ({"safety": "mode3"}, "safety"),
        ({"obstacle_prediction": "kalman"}, "obstacle_prediction"),
    ],
)
def test_invalid_config_raises_naming_field(changes: dict, field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        NMPCConfig(**changes)


def test_invalid_solver_options_raise() -> None:
    with pytest.raises(ConfigError, match="max_iter"):
        SolverOptions(max_iter=0)
    with pytest.raises(ConfigError, match="tol"):
        SolverOptions(tol=-1.0)


def test_full_matrix_weights_accepted() -> None:
    cfg = NMPCConfig(input_weight=((1.0, 0.2), (0.2, 0.5)))
    assert cfg.input_weight == ((1.0, 0.2), (0.2, 0.5))
