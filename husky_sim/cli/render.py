"""`husky-sim render`: an MP4 of a recorded run, and the render options `run --video` shares."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from husky_sim.cli.common import path_arg

if TYPE_CHECKING:
    from husky_sim.viz.rendering import RenderOptions


def add_render_arguments(parser: argparse.ArgumentParser) -> None:
    """The render options shared by `husky-sim run --video` and `husky-sim render`."""
    from husky_sim.viz.rendering import CAMERAS, RENDERERS, RenderOptions

    d = RenderOptions()
    parser.add_argument(
        "--camera",
        choices=CAMERAS,
        default=d.camera,
        help=f"view; both: top and chase side by side (default {d.camera})",
    )
    parser.add_argument(
        "--width", type=int, default=d.width, help=f"px of one view, even (default {d.width})"
    )
    parser.add_argument("--height", type=int, default=d.height, help=f"px, even (default {d.height})")
    parser.add_argument(
        "--fps", type=float, default=d.fps, help=f"frames per s of sim time (default {d.fps:g})"
    )
    parser.add_argument(
        "--renderer",
        choices=RENDERERS,
        default=d.renderer,
        help="auto: EGL if its plugin loads, else TinyRenderer (default auto)",
    )


def options_from_args(args: argparse.Namespace) -> RenderOptions:
    """RenderOptions from the options `add_render_arguments` declared."""
    from husky_sim.viz.rendering import RenderOptions

    return RenderOptions(
        width=args.width, height=args.height, fps=args.fps, camera=args.camera, renderer=args.renderer
    )


def cmd_render(args: argparse.Namespace) -> int:
    from husky_sim.viz.rendering import render_run

    result = render_run(args.run_dir, options_from_args(args), args.out)
    print(result.report())
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `render`."""
    render = sub.add_parser("render", help="render a recorded run directory to an MP4 (no re-solve)")
    render.add_argument("run_dir", help="a directory written by `husky-sim run` (needs its trace.npz)")
    render.add_argument(
        "--out", type=path_arg, default=None, help="video file, .mp4 (default RUN_DIR/video_CAMERA.mp4)"
    )
    add_render_arguments(render)
    render.set_defaults(func=cmd_render)
