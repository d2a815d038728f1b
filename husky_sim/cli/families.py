"""`husky-sim families` (one line per scenario family) and `husky-sim generate` (a family's
layouts as scenario files, byte-identical for the same seed and code)."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import count_arg, path_arg, seed_arg


def param_arg(text: str) -> tuple[str, float]:
    """An argparse type: NAME=VALUE with a finite number."""
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text[:60]!r}")
    try:
        number = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name}: expected a number, got {value[:40]!r}") from None
    return name, number


def add_param_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--param",
        type=param_arg,
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="fix a family parameter (its range: husky-sim families --params)",
    )


def add_robot_arg(parser: argparse.ArgumentParser) -> None:
    from husky_sim.paths import DEFAULT_ROBOT
    from husky_sim.sim.robot_description import robot_names

    parser.add_argument(
        "--robot",
        choices=robot_names(),
        default=DEFAULT_ROBOT,
        help=f"the robot folder whose body sizes and checks the layouts (default {DEFAULT_ROBOT})",
    )


def cmd_families(args: argparse.Namespace) -> int:
    from husky_sim.families.registry import family, family_names

    for name in family_names():
        fam = family(name)
        print(f"{name:26s} {fam.summary}")
        if args.params:
            for p in fam.params:
                print(f"    {p.describe()}")
            print(f"    guarantees: {fam.guarantees}")
    if args.gallery is not None:
        from pathlib import Path

        from husky_sim.families.generate import generate
        from husky_sim.runs.run_folder import prepare_out_dir
        from husky_sim.viz.layout_figures import LayoutPanel, layout_gallery

        out = prepare_out_dir(Path(args.gallery))
        for name in family_names():
            panels = [LayoutPanel(x.scenario, x.name) for x in generate(name, 4, args.seed)]
            png, _ = layout_gallery(panels, out, name, f"{name}: layouts 0-3 of seed {args.seed}")
            print(f"-> {png}")
    return 0


def cmd_generate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from husky_sim.families.generate import generate
    from husky_sim.runs.run_folder import prepare_out_dir

    fixed = dict(args.param)
    layouts = generate(args.family, args.count, args.seed, fixed, args.robot)
    out = prepare_out_dir(Path(args.out))
    for layout in layouts:
        layout.write(out)
    if args.plot:
        from husky_sim.viz.layout_figures import LayoutPanel, layout_gallery

        panels = [LayoutPanel(layout.scenario, layout.name) for layout in layouts]
        png, _ = layout_gallery(panels, out, f"{args.family}-s{args.seed}", args.family)
        print(f"-> {png}")
    print(f"{len(layouts)} layouts of {args.family}, seed {args.seed} -> {out}")
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `families` and `generate`."""
    families = sub.add_parser("families", help="list the scenario families, a line each")
    families.add_argument("--params", action="store_true", help="also each family's parameters and ranges")
    families.add_argument("--gallery", type=path_arg, default=None, help="draw 4 layouts of each family here")
    families.add_argument("--seed", type=seed_arg, default=1, help="the gallery's seed (default 1)")
    families.set_defaults(func=cmd_families)

    generate = sub.add_parser("generate", help="write a family's seeded layouts as scenario files")
    generate.add_argument("family", help="a family name (husky-sim families)")
    generate.add_argument("--count", type=count_arg, default=10, help="layouts K >= 1 (default 10)")
    generate.add_argument("--seed", type=seed_arg, default=0, help="seed >= 0 (default 0)")
    add_param_arg(generate)
    add_robot_arg(generate)
    generate.add_argument("--out", type=path_arg, required=True, help="folder for the scenario files")
    generate.add_argument("--plot", action="store_true", help="also a gallery of the layouts (PNG, SVG)")
    generate.set_defaults(func=cmd_generate)
