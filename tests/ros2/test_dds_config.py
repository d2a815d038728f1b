"""The user's own Cyclone DDS configuration (CYCLONEDDS_URI) under `serve` and `rehearse`: merged
with ours, honoured where it does not conflict, set aside and named where a localhost-only
participant must keep to 127.0.0.1, refused in one line where Cyclone DDS refuses it. Real Cyclone
DDS throughout: real domains, a real node process, real rehearsals."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from husky_sim.ros2.dds_config import (
    LOCALHOST_ONLY_CONFIG,
    URI_VARIABLE,
    DdsConfigError,
    merged_config,
    refusal,
    split_uri,
)
from husky_sim.ros2.settings import lease_domain_id

pytest.importorskip("cyclonedds")

NAMESPACE = 'xmlns="https://cdds.io/config" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
INTERFACE_PINNED = (
    '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces></General></Domain></CycloneDDS>"
)
#: The configuration a Cyclone DDS user on one machine commonly sets (interface, peers, no multicast).
PEERS_LISTED = (
    '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    '<MaxAutoParticipantIndex>40</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers>'
    "</Discovery></Domain></CycloneDDS>"
)
MULTICAST_OFF = (
    '<CycloneDDS><Domain id="any"><General><AllowMulticast>false</AllowMulticast></General>'
    '<Discovery><Peers><Peer address="localhost"/></Peers></Discovery></Domain></CycloneDDS>'
)
INVALID = "<General><MaxMessageSize>perhaps</MaxMessageSize></General>"  # Cyclone DDS takes fragments


def _file_config(tmp_path: Path) -> str:
    """A configuration file as users write them (namespaced, a tracing section with a comma)."""
    path = tmp_path / "cyclonedds.xml"
    path.write_text(
        f'<?xml version="1.0" encoding="UTF-8" ?>\n<CycloneDDS {NAMESPACE}>\n<Domain id="any">\n'
        '  <General><Interfaces><NetworkInterface address="127.0.0.1" multicast="false"/></Interfaces>\n'
        "  <AllowMulticast>false</AllowMulticast></General>\n"
        '  <Discovery><Peers><Peer address="127.0.0.1"/></Peers></Discovery>\n'
        f"  <Tracing><Category>config,discovery</Category><OutputFile>{tmp_path / 'cdds.log'}</OutputFile>"
        "</Tracing>\n</Domain>\n</CycloneDDS>\n"
    )
    return f"file://{path}"


# -- merging (no DDS) ------------------------------------------------------------------------------
def test_the_uri_splits_into_fragments_and_files_keeping_commas_inside_xml() -> None:
    xml = "<CycloneDDS><Domain><Tracing><Category>config,discovery</Category></Tracing></Domain></CycloneDDS>"
    assert split_uri(f" {xml}, file:///a.xml,/b.xml ,{INTERFACE_PINNED}") == [
        xml,
        "file:///a.xml",
        "/b.xml",
        INTERFACE_PINNED,
    ]
    assert split_uri("") == [] and split_uri('<a x="1"/>,<b/>') == ['<a x="1"/>', "<b/>"]


def test_without_a_user_configuration_ours_alone() -> None:
    merged = merged_config(localhost_only=True, environ={})
    assert merged.xml.endswith(LOCALHOST_ONLY_CONFIG) and merged.set_aside == () and merged.notice() is None
    assert "IgnoreTypeInformation>1.15<" in merged_config(False, {}).xml


def test_a_localhost_only_participant_sets_the_users_network_placement_aside(tmp_path: Path) -> None:
    """Rehearsals keep to 127.0.0.1: the user's interfaces, multicast and peers are set aside (and
    named), the rest of their configuration stays, ahead of ours."""
    uri = f"{PEERS_LISTED},{_file_config(tmp_path)}"
    merged = merged_config(localhost_only=True, environ={URI_VARIABLE: uri})
    assert merged.set_aside == ("Interfaces", "AllowMulticast", "Peers")
    assert "<Interfaces>, <AllowMulticast>, <Peers> set aside" in merged.notice()
    user_part = merged.xml[: merged.xml.index(LOCALHOST_ONLY_CONFIG)]
    assert "Interfaces" not in user_part and "Peer " not in user_part and "AllowMulticast" not in user_part
    assert "<MaxAutoParticipantIndex>40<" in user_part and "<Category>config,discovery<" in user_part
    assert "ns0:" not in merged.xml and "xmlns" not in merged.xml  # namespaces dropped, no prefixes
    # the same configuration on a networked node is the user's as written
    networked = merged_config(localhost_only=False, environ={URI_VARIABLE: PEERS_LISTED})
    assert networked.xml.startswith(PEERS_LISTED) and networked.set_aside == ()


def test_the_users_type_information_vendors_are_kept_beside_ours() -> None:
    uri = "<Compatibility><IgnoreTypeInformation>1.16</IgnoreTypeInformation></Compatibility>"
    assert (
        "<IgnoreTypeInformation>1.16,1.15</IgnoreTypeInformation>"
        in merged_config(False, {URI_VARIABLE: uri}).xml
    )


def test_what_a_localhost_only_participant_cannot_read_is_refused_and_the_rest_handed_on(
    tmp_path: Path,
) -> None:
    """Cyclone DDS's `</>` shorthand passes through on the network but is refused (one line) where
    the placement must be set aside; a fragment that is nothing but placement disappears; a file
    with nothing to set aside is handed on by name (`${VAR}`s expanded); one rewritten with
    non-ASCII text comes out as ASCII, as Cyclone DDS's binding needs."""
    shorthand = '<General><Interfaces><NetworkInterface name="eth0"/></></>'
    assert merged_config(False, {URI_VARIABLE: shorthand}).xml.startswith(shorthand)
    with pytest.raises(DdsConfigError, match=r"^CYCLONEDDS_URI: item 1 is not strict XML \("):
        merged_config(True, {URI_VARIABLE: shorthand})
    only = merged_config(True, {URI_VARIABLE: '<Peers><Peer address="10.0.0.2"/></Peers>'})
    assert only.set_aside == ("Peers",) and "10.0.0.2" not in only.xml
    plain = tmp_path / "plain.xml"
    plain.write_text(
        "<CycloneDDS><Domain><Tracing><Verbosity>warning</Verbosity></Tracing></Domain></CycloneDDS>"
    )
    os.environ["HUSKY_SIM_TEST_DIR"] = str(tmp_path)
    try:
        handed_on = merged_config(True, {URI_VARIABLE: "file://${HUSKY_SIM_TEST_DIR}/plain.xml"})
    finally:
        del os.environ["HUSKY_SIM_TEST_DIR"]
    assert handed_on.xml.startswith(f"file://{plain}") and handed_on.set_aside == ()
    accented = tmp_path / "réseau.xml"
    accented.write_text(
        '<?xml version="1.0" encoding="UTF-8"?><CycloneDDS><Domain><!-- Straße -->'
        "<General><AllowMulticast>false</AllowMulticast><MaxMessageSize>1400B</MaxMessageSize>"
        "</General><Tracing><OutputFile>/tmp/café.log</OutputFile></Tracing></Domain></CycloneDDS>",
        encoding="utf-8",
    )
    rewritten = merged_config(True, {URI_VARIABLE: f"file://{accented}"})
    user_part = rewritten.xml[: rewritten.xml.index(LOCALHOST_ONLY_CONFIG)]
    assert rewritten.xml.isascii() and "caf&#233;.log" in user_part and "AllowMulticast" not in user_part


def test_cyclone_ddss_reason_is_its_configuration_line_not_a_users_trace() -> None:
    said = (
        "1796587285.1 [66]     python: trace line one\n"
        "1796587285.2 [66]     python: config: //CycloneDDS/Domain/General: Bogus: unknown element\n"
        "1796587285.3 [66]     python: trace line two\n"
    )
    assert refusal(said) == "config: //CycloneDDS/Domain/General: Bogus: unknown element"
    assert refusal("") == "no reason given (see its log)"


def test_an_unreadable_file_is_a_one_line_error() -> None:
    with pytest.raises(
        DdsConfigError, match=r"^CYCLONEDDS_URI: cannot read file:///nonexistent/c.xml: No such file"
    ):
        merged_config(False, {URI_VARIABLE: "file:///nonexistent/c.xml"})


# -- real Cyclone DDS ------------------------------------------------------------------------------
@pytest.mark.parametrize("localhost_only", [True, False])
def test_cyclone_dds_refuses_an_invalid_configuration_in_one_line(
    monkeypatch, capfd, localhost_only: bool
) -> None:
    from husky_sim.ros2.cyclone_transport import open_domain

    monkeypatch.setenv(URI_VARIABLE, INVALID)
    with pytest.raises(DdsConfigError) as error:
        open_domain(lease_domain_id(200, 232), localhost_only)
    message = str(error.value)
    os.write(2, b"stderr is ours again\n")
    assert "stderr is ours again" in capfd.readouterr().err  # the redirect ended with the refusal
    assert "\n" not in message and message.startswith("CYCLONEDDS_URI: Cyclone DDS refused the configuration")
    assert "MaxMessageSize/#text: perhaps: invalid value" in message and message.endswith(
        "fix it or unset CYCLONEDDS_URI"
    )


def _husky_sim(*args: str, env: dict[str, str], timeout_s: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "husky_sim.cli", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def _uri(name: str, tmp_path: Path) -> str:
    return {
        "interface pinned": INTERFACE_PINNED,
        "peers listed, multicast off": PEERS_LISTED,
        "multicast off": MULTICAST_OFF,
        "a file and a fragment": f"{_file_config(tmp_path)},{MULTICAST_OFF}",
    }[name]


USER_CONFIGURATIONS = (
    "interface pinned",
    "peers listed, multicast off",
    "multicast off",
    "a file and a fragment",
)


@pytest.mark.physics
@pytest.mark.parametrize("name", USER_CONFIGURATIONS)
def test_rehearse_reaches_the_goal_under_the_users_configuration(tmp_path: Path, name: str) -> None:
    """`husky-sim rehearse` (a node process and the PyBullet robot over DDS, loopback only) under
    each configuration: the goal is reached, and what was set aside is named in one line."""
    env = {**os.environ, URI_VARIABLE: _uri(name, tmp_path)}
    done = _husky_sim(
        "rehearse",
        "head_on_moving_obstacle",
        "--controller",
        "husky-cbf",
        "--out",
        str(tmp_path / "r"),
        env=env,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["outcome"] == "reached" and summary["transport"]["reply_timeouts"] == 0
    notices = [line for line in done.stderr.splitlines() if "set aside" in line]
    assert len(notices) == 1 and "keeps DDS on 127.0.0.1" in notices[0]


@pytest.mark.physics
@pytest.mark.parametrize("name", USER_CONFIGURATIONS)
def test_serve_serves_a_peer_under_the_users_configuration(monkeypatch, tmp_path: Path, name: str) -> None:
    """`husky-sim serve` on the network (not localhost-only), the user's configuration as written,
    and a peer in this process under the same configuration: the peer's odometry reaches the
    node and its commands come back."""
    from husky_sim.ros2.cyclone_transport import CycloneTransport
    from husky_sim.ros2.settings import Ros2Settings

    uri = _uri(name, tmp_path)
    monkeypatch.setenv(URI_VARIABLE, uri)
    domain = lease_domain_id(200, 232)
    node = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "husky_sim.cli",
            "serve",
            "husky_point_stabilisation",
            "--controller",
            "husky-cbf",
            "--horizon",
            "5",
            "--domain-id",
            str(domain),
            "--duration",
            "20",
            "--out",
            str(tmp_path / "node"),
        ],  # fmt: skip
        env={**os.environ},
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    peer = CycloneTransport(Ros2Settings(domain_id=domain))
    odometry = peer.publish("odometry", "nav_msgs/msg/Odometry")
    commands = peer.subscribe("cmd_vel", "geometry_msgs/msg/Twist")
    received, moving = 0, 0
    end = time.monotonic() + 90
    try:
        while (received < 5 or moving < 1) and time.monotonic() < end and node.poll() is None:
            message = peer.messages.make("nav_msgs/msg/Odometry")
            message.header = peer.messages.header(time.time(), "odom")
            message.child_frame_id = "base_link"
            message.pose.pose = peer.messages.pose(0.0, 0.0, 0.0)
            odometry.write(message)
            peer.wait(0.05)
            for r in commands.take():
                received += 1
                moving += r.message.linear.x != 0.0 or r.message.angular.z != 0.0
    finally:
        node.terminate()
        output = node.communicate(timeout=60)[0].decode(errors="replace")
    assert received >= 5 and moving >= 1, output[-2000:]
    assert "Traceback" not in output and "set aside" not in output
    summary = json.loads((tmp_path / "node" / "serve_summary.json").read_text())
    assert summary["command_events"] >= 1


@pytest.mark.physics
@pytest.mark.parametrize("command", ["rehearse", "serve"])
def test_an_invalid_configuration_is_a_one_line_error_and_a_nonzero_exit(
    tmp_path: Path, command: str
) -> None:
    env = {**os.environ, URI_VARIABLE: INVALID}
    scenario = "head_on_moving_obstacle" if command == "rehearse" else "husky_point_stabilisation"
    done = _husky_sim(
        command, scenario, "--controller", "husky-cbf", "--out", str(tmp_path / "out"),
        *(["--duration", "5", "--domain-id", str(lease_domain_id(200, 232))] if command == "serve" else []),
        env=env,
    )  # fmt: skip
    errors = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert errors == [
        "husky-sim: error: CYCLONEDDS_URI: Cyclone DDS refused the configuration "
        "(config: //CycloneDDS/Domain/General/MaxMessageSize/#text: perhaps: invalid value "
        "(CYCLONEDDS_URI+0 line 1)); fix it or unset CYCLONEDDS_URI"
    ]
