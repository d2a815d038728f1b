"""`husky-sim settings --controller NAME`: a controller's tunable settings as a Markdown table,
generated from its config dataclasses (controllers.settings.setting_rows): the dotted name a
scenario sets under `controller.<key>`, the default, the allowed range, the unit and the one-line
contract."""

from __future__ import annotations

import argparse

from husky_sim.cli.common import UsageError


def _cell(value: object) -> str:
    """A table cell: tuples as [a, b], numbers in full up to ten digits, no pipes."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return "[" + ", ".join(_cell(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:.10g}"
    return str(value).replace("|", "\\|")


def settings_table(controller: str) -> str:
    """The Markdown table of `controller`'s settings (a registered controller that has some)."""
    from controllers import registry
    from controllers.settings import setting_rows

    entry = registry.entry(controller)
    if entry.settings is None:
        raise UsageError(f"{controller} has no settings of its own")
    lines = [
        f"`{controller}`'s settings (`controller.{entry.settings_key}` in a scenario):",
        "",
        "| setting | default | range | unit | contract |",
        "|---|---|---|---|---|",
    ]
    for row in setting_rows(entry.settings):
        cells = (f"`{row.name}`", _cell(row.default), row.bounds, row.unit, _cell(row.doc))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def cmd_settings(args: argparse.Namespace) -> int:
    print(settings_table(args.controller))
    return 0


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Register `settings`."""
    from controllers import registry

    with_settings = tuple(e.name for e in registry.entries() if e.settings is not None)
    parser = sub.add_parser("settings", help="a controller's tunable settings as a Markdown table")
    default = registry.DEFAULT_ON_ROBOT if registry.DEFAULT_ON_ROBOT in with_settings else None
    parser.add_argument("--controller", choices=with_settings, default=default, required=default is None)
    parser.set_defaults(func=cmd_settings)
