"""How well one check sample's robot can steer: a short open-loop probe of the plant with that
sample's payload, ground (friction, tyre) and motor current limit, measured as `husky-sim
drive-response` measures it (husky_sim.calibration.drive_response). A sample that fails is then
told apart: a plant that could not make the manoeuvre, or a controller that failed with one that
could."""

from __future__ import annotations

from husky_sim.calibration.drive_response import drive_response
from husky_sim.runs.scenario import Scenario

#: A turn in place and a wide arc (v m/s, w rad/s), each held from rest: Clearpath rates the 20 kg
#: payload for turning in place in high friction and the 75 kg one for wide turns only
PROBE_COMMANDS = ((0.0, 1.0), (0.5, 0.5))
#: Each held this long (s), steady over the second half: the calibrated yaw rate settles within
#: about a second of the drive's dead time (`husky-sim drive-response`, t95)
PROBE_HOLD_S = 3.0


def steerability(scenario: Scenario) -> dict[str, float | None]:
    """The probe's answer for the robot of `scenario`: yaw rate in place (rad/s, of 1 commanded)
    and on the arc, their yaw ratios (measured / wheel-implied), and the motor current turning in
    place with its headroom below the current limit (A)."""
    episode = scenario.episode_config()
    in_place, arc = drive_response(
        episode.ground,
        list(PROBE_COMMANDS),
        payload_kg=episode.payload_kg,
        hold_s=PROBE_HOLD_S,
        drive=episode.drive,
        physics_hz=episode.world.physics_hz,
        robot=episode.robot,
    )
    return {
        "turn_in_place_radps": in_place.w,
        "yaw_ratio_in_place": in_place.yaw_ratio,
        "arc_yaw_radps": arc.w,
        "yaw_ratio_arc": arc.yaw_ratio,
        "current_in_place_a": in_place.current_a,
        "current_headroom_a": episode.drive.motor.current_limit_a - in_place.current_a,
    }


#: A robot that turns in place slower than this (rad/s, of the probe's 1 rad/s; the calibrated
#: unloaded Husky makes about 1) cannot pivot: a failed sample with such a robot is put down to the
#: plant, any other to the controller
CAN_PIVOT_RADPS = 0.3


def failure_class(probe: dict[str, float | None]) -> str:
    """Why a failed sample failed, judged from its robot's probe: "plant" (it cannot turn in
    place, or turning in place takes all the current the drive may draw) or "controller"."""
    pivots = (probe["turn_in_place_radps"] or 0.0) >= CAN_PIVOT_RADPS
    return "controller" if pivots and (probe["current_headroom_a"] or 0.0) > 0.0 else "plant"
