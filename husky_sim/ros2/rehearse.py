"""`husky-sim rehearse`: the PyBullet Husky and a `husky-sim serve` node in separate processes,
the whole control loop crossing DDS.

The node is started as a subprocess on the resolved scenario (written to the run folder as
`scenario.yaml`), on a DDS domain of its own and with all traffic kept on 127.0.0.1, so a
rehearsal can never command a robot on the network. The episode is run, judged and written
exactly as `husky-sim run` does (husky_sim.runs.run.run_scenario, with husky_sim.ros2.sim_robot.DdsRobot
in the controller's place); the summary adds a `transport` section: latencies both ways, replies
that never came, and the node's own safety events (its serve.csv and serve_summary.json are in
`node/`, with its output in serve.out).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

from husky_sim import interrupts
from husky_sim.ros2.node import CONTROLLER_COUNTS, timing_stats
from husky_sim.ros2.settings import Ros2Settings, check_domain_id, lease_domain_id
from husky_sim.ros2.sim_robot import DdsRobot, NodeNotFound
from husky_sim.runs.run import run_scenario, run_settings
from husky_sim.runs.run_folder import SUMMARY_FILE, prepare_out_dir, read_summary, write_summary
from husky_sim.runs.scenario import Scenario
from husky_sim.scenario_file import scenario_yaml

#: Wall time (s) the node has to build its controller and appear on DDS.
NODE_START_TIMEOUT_S = 120.0


def rehearse(
    sc: Scenario,
    controller: str,
    out_dir: Path,
    domain_id: int | None = None,
    reply_timeout_s: float = 10.0,
    live_port: int | None = None,
    transport: str = "cyclonedds",
    cmd_vel_stamped: bool = False,
) -> dict[str, object]:
    """Run the rehearsal; return the summary (also written to out_dir/summary.json). `transport`
    is the node's (the robot's side is Cyclone DDS, announced in the graph layout of its peer)."""
    prepare_out_dir(out_dir)
    (out_dir / SUMMARY_FILE).unlink(missing_ok=True)  # only this rehearsal's may get its transport
    # by default a domain of its own: apart from ROS 2's default 0 and from other rehearsals
    domain = lease_domain_id() if domain_id is None else check_domain_id(domain_id, "--domain-id")
    settings = Ros2Settings(
        use_sim_time=True,
        domain_id=domain,
        localhost_only=True,
        cmd_vel_stamped=cmd_vel_stamped,
    )
    scenario_file = out_dir / "scenario.yaml"
    scenario_file.write_text(
        scenario_yaml(sc.model_dump(), f"the resolved scenario of this rehearsal ({sc.name})")
    )
    node_dir = out_dir / "node"
    command = [
        sys.executable, "-m", "husky_sim.cli", "serve", str(scenario_file), "--controller", controller,
        "--use-sim-time", "--localhost-only", "--domain-id", str(domain), "--out", str(node_dir),
        "--transport", transport, *(["--cmd-vel-stamped"] if cmd_vel_stamped else []),
    ]  # fmt: skip
    run, _ = run_settings(sc, controller)
    robot = DdsRobot(settings, sc.tau_s, run.horizon, reply_timeout_s)
    node_dir.mkdir(parents=True, exist_ok=True)
    node_output = node_dir / "serve.out"  # a file, not a pipe: a chatty node can never block on it
    with node_output.open("wb") as out:
        node = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
    summary: dict[str, object] | None = None
    try:
        try:
            robot.wait_for_node(NODE_START_TIMEOUT_S)
        except NodeNotFound as exc:
            node.kill()
            node.wait(timeout=10)
            output = node_output.read_text(errors="replace").strip().splitlines()
            raise NodeNotFound(f"{exc}; node said: {output[-1] if output else '(nothing)'}") from None
        summary = run_scenario(
            sc, controller, out_dir=out_dir, implementation=robot, live_port=live_port
        ).as_dict()
    finally:
        node_summary = _stop_node(node, node_dir)
        if summary is not None or (out_dir / SUMMARY_FILE).exists():
            summary = summary or read_summary(out_dir)
            # what only the controller knows comes from the node (the robot saw commands alone)
            for key in CONTROLLER_COUNTS:
                summary[key] = node_summary.get(key)
            summary["transport"] = {
                "node_transport": transport,
                "dds_domain_id": domain,
                "cmd_vel_latency_ms": timing_stats(robot.cmd_latency_ms),
                "odometry_latency_ms": node_summary.get("odometry_latency_ms"),
                "reply_timeouts": robot.reply_timeouts,
                # solve_ms_* above are round trips (odometry out to /cmd_vel in); the node's own:
                "node_solve_ms": node_summary.get("solve_ms"),
                "node": {
                    k: v for k, v in node_summary.items() if k.endswith("_events") or k == "goals_received"
                },
                "node_exit_code": node.returncode,
            }
            write_summary(out_dir, summary)
    return summary


def _stop_node(node: subprocess.Popen, node_dir: Path) -> dict[str, object]:
    """SIGINT the node (it sends a zero command and writes its summary), then read its summary."""
    with interrupts.deferred():
        if node.poll() is None:
            node.send_signal(signal.SIGINT)
        try:
            node.wait(timeout=30)
        except subprocess.TimeoutExpired:
            node.kill()
            node.wait()
    path = node_dir / "serve_summary.json"
    return json.loads(path.read_text()) if path.exists() else {}
