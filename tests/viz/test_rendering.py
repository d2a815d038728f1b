"""Headless MP4 rendering of a recorded episode, in real PyBullet (EGL and TinyRenderer) and real
ffmpeg: the video is decoded back and its frame count, size and content are checked.

Frame-count rule under test: a trace ending at t_end s rendered at F frames per s of sim time has
floor(t_end * F) + 1 frames (t = 0, 1/F, ... <= t_end)."""

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import imageio.v2 as iio
import numpy as np
import pytest
import yaml
from PIL import ImageFont

from husky_sim.cli import main
from husky_sim.runs.run import run_scenario
from husky_sim.runs.run_folder import summary_or_empty
from husky_sim.runs.scenario import load_scenario, resolve
from husky_sim.sim.step_log import compare_logs
from husky_sim.viz.rendering import (
    RenderError,
    RenderOptions,
    Scene,
    camera_view,
    frame_times,
    load_run_trace,
    render_run,
    run_outcome,
)
from husky_sim.viz.video_annotations import (
    GOAL_DISC_RADIUS_M,
    GOAL_DISC_THICKNESS_M,
    annotate_frame,
    draw_scale_bar,
    frame_caption,
    ground_mask,
    legend_entries,
    legend_image,
    scale_bar_length_m,
)
from husky_sim.viz.video_cameras import camera_eye_m, ground_pixels_per_m, project_polyline, top_camera

pytestmark = pytest.mark.physics  # PyBullet or closed loops throughout (`make test-fast` skips)

DURATION_S = 2.0
FPS = 15.0
SMALL = {"width": 320, "height": 180, "fps": FPS}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s recorded run of the paper's Husky point stabilisation (goal 7 m ahead), CBF, no video."""
    out = tmp_path_factory.mktemp("run")
    sc = load_scenario("husky_point_stabilisation").model_copy(update={"duration_s": DURATION_S})
    run_scenario(sc, "cbf", out_dir=out)
    return out


@pytest.fixture(scope="module")
def egl_ok(run_dir: Path) -> None:
    """Skip the EGL tests only when the EGL plugin genuinely does not load here."""
    try:
        Scene(load_run_trace(run_dir), "egl").close()
    except RenderError as exc:
        pytest.skip(f"EGL renderer unavailable on this machine: {exc}")


def decode(path: Path) -> list[np.ndarray]:
    with iio.get_reader(path, format="FFMPEG") as reader:
        return [np.asarray(frame) for frame in reader]


def husky_centroid(frame: np.ndarray) -> np.ndarray:
    """(col, row) mean of the Husky's yellow pixels (0.95 0.75 0.05 in the URDF, shaded) within
    a quarter of the frame height of their median, which leaves out the legend's small robot swatch."""
    r, g, b = (frame[:, :, i].astype(int) for i in range(3))
    rows, cols = np.nonzero((r > 150) & (g > 100) & (b < 90) & (r - b > 100))
    assert len(rows) >= 20, "the Husky is not in the frame"
    near = np.hypot(cols - np.median(cols), rows - np.median(rows)) < frame.shape[0] / 4
    return np.array([cols[near].mean(), rows[near].mean()])


def projected_px(camera, xy_m: np.ndarray, z_m: float = 0.0) -> np.ndarray:
    """(col, row) of the ground point xy_m (m) at height z_m in the camera's image."""
    ((pixel,),) = project_polyline(camera, np.asarray(xy_m, dtype=float)[None, :2], z_m)
    return np.array(pixel)


def test_frame_times_rule() -> None:
    assert len(frame_times(2.0, 15.0)) == 31
    assert len(frame_times(2.0 - 1e-12, 15.0)) == 31  # float drift of the sim clock is tolerated
    assert len(frame_times(1.99, 15.0)) == 30
    assert len(frame_times(0.0, 30.0)) == 1
    assert frame_times(1.0, 4.0).tolist() == [0.0, 0.25, 0.5, 0.75, 1.0]


def test_options_are_validated() -> None:
    assert RenderOptions().frame_size == (1280, 720) and RenderOptions().fps == 30.0
    assert RenderOptions(camera="both", width=320, height=180).frame_size == (640, 180)
    for bad in ({"width": 321}, {"height": 8}, {"fps": 0.0}, {"camera": "side"}, {"renderer": "gl"}):
        with pytest.raises(ValueError):
            RenderOptions(**bad)


@pytest.mark.parametrize("renderer", ["egl", "tiny"])
def test_top_video_shows_the_husky_driving(run_dir: Path, tmp_path: Path, renderer: str, request) -> None:
    if renderer == "egl":
        request.getfixturevalue("egl_ok")
    out = tmp_path / f"top_{renderer}.mp4"
    result = render_run(run_dir, RenderOptions(**SMALL, renderer=renderer), out)
    trace = load_run_trace(run_dir)
    assert trace.sample_t_s[-1] == pytest.approx(DURATION_S, abs=1e-6)
    expected = math.floor(DURATION_S * FPS) + 1  # 31
    frames = decode(out)
    assert result.renderer == renderer and result.frames == expected
    assert len(frames) == expected
    assert frames[0].shape == (180, 320, 3)
    first, last = husky_centroid(frames[0]), husky_centroid(frames[-1])
    # the robot drives toward the goal at +x (right in the top view): it moved right, not sideways
    assert last[0] - first[0] > 10 and abs(last[1] - first[1]) < 10


def test_chase_and_both_cameras(run_dir: Path, tmp_path: Path) -> None:
    chase = decode(
        render_run(
            run_dir, RenderOptions(**SMALL, camera="chase", renderer="tiny"), tmp_path / "chase.mp4"
        ).file
    )
    for frame in (chase[0], chase[-1]):  # the chase camera keeps the Husky in the middle third
        col, _ = husky_centroid(frame)
        assert 320 / 3 < col < 2 * 320 / 3
    both = decode(
        render_run(
            run_dir, RenderOptions(**SMALL, camera="both", renderer="tiny"), tmp_path / "both.mp4"
        ).file
    )
    assert len(both) == len(chase) and both[0].shape == (180, 640, 3)
    # right half is the chase view: the Husky there is where it is in the chase-only video
    assert np.allclose(husky_centroid(both[-1][:, 320:]), husky_centroid(chase[-1]), atol=3)


@pytest.mark.parametrize("renderer", ["egl", "tiny"])
def test_depth_test_finds_ground_and_robot(run_dir: Path, renderer: str, request) -> None:
    """Overlays are hidden where the depth buffer says the surface is above ground: the Husky's
    centre is not ground, a point 1.5 m beside it is; a point behind the camera is cut away."""
    if renderer == "egl":
        request.getfixturevalue("egl_ok")
    trace = load_run_trace(run_dir)
    scene = Scene(trace, renderer)
    try:
        scene.pose(0)
        camera = top_camera(trace, RenderOptions(width=320, height=180))
        _, depth = scene.image(camera)
    finally:
        scene.close()
    x, y = trace.base_position_m[0, :2]
    (pixels,) = project_polyline(camera, np.array([[x, y], [x, y + 1.5]]), 0.0)
    cols = np.array([int(c) for c, _ in pixels])
    rows = np.array([int(r) for _, r in pixels])
    assert ground_mask(camera, depth, rows, cols).tolist() == [False, True]
    eye_height = np.linalg.inv(np.asarray(camera.view).reshape(4, 4).T)[2, 3]
    assert project_polyline(camera, np.array([[x, y]]), eye_height + 1.0) == []


def test_run_with_video_logs_the_same_and_records_it(run_dir: Path, tmp_path: Path, capsys) -> None:
    """`husky-sim run --video` renders after the run: its log equals the fixture's (no video)."""
    data = yaml.safe_load(resolve("husky_point_stabilisation").read_text())
    scenario = tmp_path / "short.yaml"
    scenario.write_text(yaml.safe_dump({**data, "duration_s": DURATION_S}))
    out = tmp_path / "with_video"
    argv = ["run", str(scenario), "--controller", "cbf", "--out", str(out), "--video", "--renderer", "tiny"]
    assert main([*argv, "--width", "320", "--height", "180", "--fps", str(FPS)]) == 0
    printed = capsys.readouterr().out
    assert "frames/s) via tiny" in printed

    def rows(d: Path) -> list[dict[str, str]]:
        with (d / "log.csv").open() as f:
            return list(csv.DictReader(f))

    assert len(rows(out)) == 10 and compare_logs(rows(out), rows(run_dir)) == []
    video = json.loads((out / "summary.json").read_text())["video"]
    assert video["renderer"] == "tiny" and video["frames"] == 31 and video["frames_per_s"] > 0
    assert len(decode(Path(video["file"]))) == 31


def test_render_cli_errors_are_one_line(run_dir: Path, tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "trace.npz").write_bytes((run_dir / "trace.npz").read_bytes()[:300])  # truncated zip
    (tmp_path / "empty").mkdir()
    cases = [
        [str(tmp_path / "missing")],
        [str(tmp_path / "empty")],
        [str(bad)],
        [str(run_dir), "--width", "321"],
        [str(run_dir), "--out", str(tmp_path / "v.avi")],
    ]
    for args in cases:
        assert main(["render", *args]) == 2, args
        err = capsys.readouterr().err
        assert err.startswith("husky-sim: error: ") and err.count("\n") == 1, err
    assert not list(tmp_path.glob("*.mp4"))


# ---------------------------------------------------------------------------------- goal and overlays


@pytest.mark.parametrize("renderer", ["egl", "tiny"])
def test_goal_marker_is_green_in_the_video(run_dir: Path, tmp_path: Path, renderer: str, request) -> None:
    """With a far top camera (6 m extra margin: about 20 m up, where a 0.1 m near plane made the
    EGL depth buffer z-fight the ground with a flat marker), the decoded video's frames show green
    pixels over most of the goal disc around the goal's projected position."""
    if renderer == "egl":
        request.getfixturevalue("egl_ok")
    options = RenderOptions(**SMALL, renderer=renderer, margin_m=6.0)
    frames = decode(render_run(run_dir, options, tmp_path / "goal.mp4").file)
    trace = load_run_trace(run_dir)
    camera = top_camera(trace, options)
    col, row = projected_px(camera, trace.goal, GOAL_DISC_THICKNESS_M)
    radius_px = GOAL_DISC_RADIUS_M * ground_pixels_per_m(camera, trace.goal)
    assert radius_px > 3
    rows, cols = np.mgrid[0:180, 0:320]
    disc = np.hypot(cols - col, rows - row) <= radius_px + 1
    for frame in (frames[0], frames[-1]):
        r, g, b = (frame[:, :, i].astype(int) for i in range(3))
        green = (g > 110) & (g - r > 60) & (g - b > 40)
        assert green[disc].sum() >= 0.4 * math.pi * radius_px**2, (green[disc].sum(), radius_px)


def test_safety_circle_is_drawn_at_the_robot_radius(run_dir: Path) -> None:
    """The dashed circle around the robot has the trace's robot_radius_m (the controller's robot
    circle), at the scale the top camera's projection gives, all around the robot."""
    trace = load_run_trace(run_dir)
    options = RenderOptions(width=640, height=360)
    camera = top_camera(trace, options)
    scene = Scene(trace, "tiny")
    try:
        t_s = 1.0
        scene.pose(trace.pose_index(t_s))
        image = camera_view(scene, camera, t_s, 3)
    finally:
        scene.close()
    centre_xy = trace.base_position_m[trace.pose_index(t_s), :2]
    col, row = projected_px(camera, centre_xy)
    radius_px = trace.robot_radius_m * ground_pixels_per_m(camera, centre_xy)
    r, g, b = (image[:, :, i].astype(int) for i in range(3))
    rows, cols = np.nonzero((r > 180) & (g < 70) & (b < 90))
    assert len(rows) > 40
    distance = np.hypot(cols - col, rows - row)
    assert np.median(distance) == pytest.approx(radius_px, abs=2.0)
    quadrants = {(bool(c > col), bool(q > row)) for c, q in zip(cols, rows, strict=True)}
    assert len(quadrants) == 4


def test_scale_bar_matches_the_top_camera_projection(run_dir: Path) -> None:
    """px per m on the ground equals the pinhole value H / (2 d tan(fov / 2)), and the bar drawn
    in the bottom left corner is that many px per m long."""
    trace = load_run_trace(run_dir)
    options = RenderOptions(width=640, height=360)
    camera = top_camera(trace, options)
    eye = camera_eye_m(camera)
    expected = 360 / (2 * eye[2] * math.tan(math.radians(options.top_fov_deg) / 2))
    pixels_per_m = ground_pixels_per_m(camera, eye[:2])
    assert pixels_per_m == pytest.approx(expected, rel=1e-6)
    assert scale_bar_length_m(57.0, 256) == 2.0 and scale_bar_length_m(1000.0, 10) == 0.1
    blank = np.full((360, 640, 3), 128, dtype=np.uint8)
    drawn = draw_scale_bar(blank, camera, ImageFont.load_default())
    changed_rows, changed_cols = np.nonzero(np.any(drawn != blank, axis=2))
    assert changed_rows.min() > 360 / 2 and changed_cols.max() < 640 / 2  # bottom left only
    black = np.all(drawn < 30, axis=2)
    bar_row = int(np.argmax(black.sum(axis=1)))
    length_m = scale_bar_length_m(pixels_per_m, 0.2 * 640)
    assert black[bar_row].sum() == pytest.approx(length_m * pixels_per_m, abs=4)


def test_caption_has_time_and_outcome_and_the_legend_lists_everything(run_dir: Path, tmp_path: Path) -> None:
    summary = json.loads((run_dir / "summary.json").read_text())
    assert run_outcome(summary_or_empty(run_dir)) == summary["outcome"] != ""
    assert run_outcome(summary_or_empty(tmp_path)) == ""  # no summary.json
    text = frame_caption(1.2, "husky_point_stabilisation  cbf  N=5", "stuck")
    assert text == "t =  1.20 s   run outcome: stuck\nhusky_point_stabilisation  cbf  N=5"
    assert frame_caption(0.0) == "t =  0.00 s"

    trace = load_run_trace(run_dir)
    labels = [entry.label for entry in legend_entries(trace)]
    assert labels[:3] == ["robot", "obstacle", "goal"]
    assert labels[3:5] == ["plan (NMPC)", "trail"]
    assert labels[5] == f"safety circle r={trace.robot_radius_m:.2f} m"
    font = ImageFont.load_default()
    legend = legend_image(legend_entries(trace), font, 200)
    assert legend.width <= 200 and legend.height > 2 * 11  # wrapped onto several rows

    blank = np.full((180, 320, 3), 128, dtype=np.uint8)
    stuck = annotate_frame(blank, frame_caption(1.2, "run", "stuck"), font, legend)
    reached = annotate_frame(blank, frame_caption(1.2, "run", "reached"), font, legend)
    differ_rows, differ_cols = np.nonzero(np.any(stuck != reached, axis=2))
    assert len(differ_rows) > 20  # the outcome text is drawn
    assert differ_rows.max() < 40 and differ_cols.max() < 200  # in the caption box, top left
    legend_rows, legend_cols = np.nonzero(np.any(annotate_frame(blank, "", font, legend) != blank, axis=2))
    assert legend_rows.min() >= 180 - legend.height - 8 and legend_cols.min() >= 320 - legend.width - 8


def test_video_frames_carry_caption_scale_bar_and_legend(run_dir: Path, tmp_path: Path) -> None:
    """In a decoded frame: the dark caption box at the top left, the scale bar's black bar at the
    bottom left, the light legend box at the bottom right."""
    frames = decode(render_run(run_dir, RenderOptions(**SMALL, renderer="tiny"), tmp_path / "v.mp4").file)
    frame = frames[-1].astype(int)
    assert np.mean(np.all(frame[4:12, 5:60] < 70, axis=2)) > 0.4  # caption box, behind white text
    bottom_left = np.all(frame[150:176, 4:120] < 50, axis=2)
    assert bottom_left.sum(axis=1).max() > 15  # the scale bar
    assert np.mean(frame[150:176, 200:316]) > 170  # the legend's white box over the checker


def test_egl_plugin_load_is_silent(run_dir: Path, egl_ok: None) -> None:
    """Loading the EGL plugin prints nothing ("EGL device choice" went to stderr at C level),
    and stderr works again afterwards."""
    code = (
        "import os, sys\n"
        "from husky_sim.viz.rendering import Scene, load_run_trace\n"
        "scene = Scene(load_run_trace(sys.argv[1]), 'egl')\n"
        "assert scene.renderer == 'egl'\n"
        "scene.close()\n"
        "os.write(2, b'stderr restored\\n')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(run_dir)], capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "EGL device choice" not in done.stderr and "stderr restored" in done.stderr, done.stderr
    assert "GL_VENDOR" not in done.stdout and "Destroy EGL" not in done.stdout, done.stdout
