"""How a scenario problem is reported: one line naming the field, the allowed range and at most
a short excerpt of the value (a 1 MB bad value is never echoed whole)."""

from __future__ import annotations

from pydantic import ValidationError

#: Most characters of a bad value quoted in an error.
EXCERPT_CHARS = 40


class ScenarioError(ValueError):
    """A scenario that cannot run; the message is one line naming the field."""


def excerpt(value: object, limit: int = EXCERPT_CHARS) -> str:
    """repr(value), cut to `limit` characters: a 1 MB bad value is not echoed whole."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}... ({len(text)} characters)"


def one_line(error: ValidationError, source: str) -> str:
    """The first validation error as one line: where, what, the value; the others named after."""
    first = error.errors()[0]
    loc = ".".join(str(x) for x in first["loc"])
    msg = first["msg"].removeprefix("Value error, ").replace("\n", " ")
    got = first.get("input")
    got_text = "" if isinstance(got, dict | list) or got is None else f" (got {excerpt(got)})"
    others = [".".join(str(x) for x in e["loc"]) or "scenario" for e in error.errors()[1:]]
    listed = ", ".join(others[:3]) + (", ..." if len(others) > 3 else "")
    more = f" [+{len(others)} more: {listed}]" if others else ""
    where = f"{loc}: " if loc else ""  # a whole-scenario check names its fields in its message
    return f"{source}: {where}{msg}{got_text}{more}"
