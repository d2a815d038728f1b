"""MkDocs hook: the scenario file's reference, made from the schema itself at every build
(husky_sim.runs.scenario.Scenario's JSON schema), so it can never disagree with what `husky-sim`
accepts."""

from __future__ import annotations

import json
from typing import Any

MARKER = "<!-- scenario-schema -->"


def on_page_markdown(markdown: str, **_: Any) -> str:
    if MARKER not in markdown:
        return markdown
    from husky_sim.runs.scenario import Scenario

    return markdown.replace(MARKER, scenario_reference(Scenario.model_json_schema()))


def scenario_reference(schema: dict) -> str:
    """A Markdown table: one row per field (dotted path), its type, allowed values and default."""
    defs = schema.get("$defs", {})
    rows: list[tuple[str, str, str, str]] = []

    def walk(node: dict, path: str) -> None:
        required = set(node.get("required", ()))
        for name, field in node.get("properties", {}).items():
            # pydantic leaves a default_factory out of the schema: each in Scenario is an empty list
            default = "(required)" if name in required else field.get("default", "(empty)")
            visit(field, f"{path}.{name}" if path else name, default)

    def visit(field: dict, path: str, default: object) -> None:
        options = [f for f in field.get("anyOf", [field]) if f.get("type") != "null"]
        optional = len(options) < len(field.get("anyOf", [field]))
        target = options[0] if len(options) == 1 else field
        if "$ref" in target:
            ref = defs[target["$ref"].split("/")[-1]]
            rows.append((path, ref.get("title", "") + (" or null" if optional else ""), "", _text(default)))
            walk(ref, path)
            return
        if target.get("type") == "array" and "$ref" in target.get("items", {}):
            rows.append((f"{path}[]", "list", f"at most {target.get('maxItems', 'any')}", _text(default)))
            walk(defs[target["items"]["$ref"].split("/")[-1]], f"{path}[]")
            return
        kinds = " or ".join(sorted({o.get("type", "?") for o in options})) + (" or null" if optional else "")
        allowed = "; ".join(
            str(x)
            for x in (
                target.get("range"),
                ", ".join(map(str, target["enum"])) if "enum" in target else None,
                f"pattern {target['pattern']}" if "pattern" in target else None,
            )
            if x
        )
        rows.append((path, kinds, allowed, _text(default)))

    walk(schema, "")
    lines = ["| field | type | allowed | default |", "|---|---|---|---|"]
    bar = "\\|"  # a literal | inside a table cell
    lines += [f"| `{p}` | {t} | {a.replace('|', bar)} | {d.replace('|', bar)} |" for p, t, a, d in rows]
    return "\n".join(lines)


def _text(value: object) -> str:
    text = value if isinstance(value, str) and value.startswith("(") else json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."
