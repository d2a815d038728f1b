"""Schema fields that take a number in a range (controllers.settings.Range), decided once for the
scenario schema and for every controller's settings: strict (a bool, a string or 5.0 for an
integer is refused), finite, within the range, a one-line error naming the range, and the range
shown in the JSON schema that the docs' scenario reference is made from."""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BeforeValidator, Field

from controllers.settings import Range


def _valid(value: object, allowed: Range) -> float | int | None:
    """`value` as the range's kind if the range contains it, else None."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if not allowed.integer:
        try:
            value = float(value)
        except OverflowError:  # an integer beyond any float
            return None
    return value if allowed.contains(value) else None


def ranged(allowed: Range, length: int | None = None, optional: bool = False) -> Any:
    """A field taking one number in `allowed`, or `length` of them (a tuple); `optional`: None
    means not given (the default)."""
    kind = "an integer" if allowed.integer else "a finite number"
    message = f"must be {kind} in {allowed.text()}"
    if length is not None:
        message = f"must be {length} entries, each {kind} in {allowed.text()}"

    def check(value: object) -> object:
        if value is None and optional:
            return None
        if length is None:
            number = _valid(value, allowed)
            if number is None:
                raise ValueError(message)
            return number
        if not isinstance(value, list | tuple) or len(value) != length:
            raise ValueError(message)
        numbers = [_valid(v, allowed) for v in value]
        if any(n is None for n in numbers):
            raise ValueError(message)
        return tuple(numbers)

    number: Any = int if allowed.integer else float
    kind_type: Any = tuple[(number,) * length] if length is not None else number
    shown = {"json_schema_extra": {"range": allowed.text()}}
    if optional:
        return Annotated[kind_type | None, BeforeValidator(check), Field(default=None, **shown)]
    return Annotated[kind_type, BeforeValidator(check), Field(**shown)]
