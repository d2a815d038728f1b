"""Reading and writing the project's YAML files (scenarios, and the robot's data files: its specs,
grounds and yaw response): the one place that turns bytes into plain data and back.

Reading is defensive, because a scenario file is user input: only a regular file of at most
`MAX_FILE_BYTES` is opened (a directory, FIFO or device is refused without blocking on it), it
must be UTF-8, and it is parsed as YAML 1.2 (ruamel.yaml), so `on`, `yes` and `1:30` stay strings
instead of becoming True or 90 as in YAML 1.1, and a duplicate key is an error instead of
silently keeping the last one. Nesting deeper than `MAX_DEPTH` and documents that expand (through
anchors and aliases) to more than `MAX_NODES` values are refused before anything is built from
them. Every problem is a one-line `ScenarioFileError` that names the file.
"""

from __future__ import annotations

import io
import stat
from pathlib import Path
from typing import Any

import yaml
from ruamel.yaml import YAML
from ruamel.yaml.error import MarkedYAMLError, YAMLError
from ruamel.yaml.events import (
    MappingEndEvent,
    MappingStartEvent,
    SequenceEndEvent,
    SequenceStartEvent,
)

#: Largest scenario file read (bytes); the shipped ones are under 2 kB.
MAX_FILE_BYTES = 1 << 20
#: Deepest nesting of mappings and sequences; the schema itself needs 4.
MAX_DEPTH = 20
#: Most values (scalars, mappings, sequences) after expanding aliases.
MAX_NODES = 100_000


class ScenarioFileError(ValueError):
    """A scenario file that cannot be read; the message is one line naming the file."""


def _yaml() -> YAML:
    reader = YAML(typ="safe", pure=True)
    reader.version = (1, 2)
    reader.allow_duplicate_keys = False
    return reader


def _check_is_regular_file(path: Path) -> None:
    try:
        info = path.stat()
    except FileNotFoundError:
        raise ScenarioFileError(f"{path}: no such file") from None
    except OSError as exc:
        raise ScenarioFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(info.st_mode):
        raise ScenarioFileError(f"{path}: is a directory, not a scenario file")
    if not stat.S_ISREG(info.st_mode):
        raise ScenarioFileError(f"{path}: is not a regular file (a FIFO, socket or device), not read")
    if info.st_size > MAX_FILE_BYTES:
        raise ScenarioFileError(
            f"{path}: {info.st_size} bytes, larger than the {MAX_FILE_BYTES} bytes a scenario may have"
        )


def _decode(path: Path, raw: bytes) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ScenarioFileError(
            f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at line {line}); save it as UTF-8"
        ) from None


def _check_shape(path: Path, text: str) -> None:
    """Refuse excessive nesting before composing (which recurses). Alias expansion is bounded
    after loading (`_check_size`), where shared values are visible."""
    depth = 0
    try:
        for event in _yaml().parse(io.StringIO(text)):
            if isinstance(event, MappingStartEvent | SequenceStartEvent):
                depth += 1
                if depth > MAX_DEPTH:
                    line = event.start_mark.line + 1 if event.start_mark else "?"
                    raise ScenarioFileError(
                        f"{path}: line {line}: nested deeper than {MAX_DEPTH} levels; "
                        "a scenario needs at most 4"
                    )
            elif isinstance(event, MappingEndEvent | SequenceEndEvent):
                depth -= 1
    except (MarkedYAMLError, YAMLError) as exc:
        raise ScenarioFileError(f"{path}: not valid YAML ({_first_line(exc)})") from None


def _first_line(exc: Exception) -> str:
    if isinstance(exc, MarkedYAMLError) and exc.problem:
        where = f"line {exc.problem_mark.line + 1}: " if exc.problem_mark is not None else ""
        context = f"{exc.context} " if exc.context else ""
        problem = exc.problem.split(" with value ")[0]  # a duplicate key: its name, not its value
        return f"{where}{context}{problem}".strip()[:200]
    text = str(exc).strip().splitlines()
    return (text[0] if text else type(exc).__name__)[:200]


#: Largest integer magnitude read (no field needs more; Python refuses to print ints over 4,300
#: digits, so larger ones could not even be quoted in an error).
MAX_INTEGER = 10**18


def _check_size(path: Path, data: Any) -> None:
    """Count values as they would be validated (aliases expanded), stopping at the budget, and
    refuse integers no field could hold, naming where they are."""
    count, stack = 0, [(data, "")]
    while stack:
        item, where = stack.pop()
        count += 1
        if count > MAX_NODES:
            raise ScenarioFileError(
                f"{path}: more than {MAX_NODES} values (after expanding anchors and aliases); "
                "a scenario holds at most 64 obstacles"
            )
        if isinstance(item, dict):
            stack.extend((key, where) for key in item)
            stack.extend((value, f"{where}.{key}".lstrip(".")) for key, value in item.items())
        elif isinstance(item, list):
            stack.extend((value, f"{where}.{i}") for i, value in enumerate(item))
        elif isinstance(item, int) and not isinstance(item, bool) and abs(item) > MAX_INTEGER:
            raise ScenarioFileError(
                f"{path}: {where or 'a key'}: an integer beyond +-1e18 (no field takes one)"
            )


def read_scenario_data(path: Path) -> dict[str, Any]:
    """The top-level mapping of a scenario file, as plain Python data."""
    _check_is_regular_file(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    text = _decode(path, raw)
    _check_shape(path, text)
    try:
        data = _yaml().load(text)
    except (MarkedYAMLError, YAMLError) as exc:
        raise ScenarioFileError(f"{path}: not valid YAML ({_first_line(exc)})") from None
    except (ValueError, TypeError, OverflowError) as exc:  # a scalar the constructor cannot build
        raise ScenarioFileError(f"{path}: a value YAML cannot read ({str(exc)[:120]})") from None
    except RecursionError:  # _check_shape bounds the depth; kept as a last line of defence
        raise ScenarioFileError(f"{path}: nested too deeply to read") from None
    if not isinstance(data, dict):
        raise ScenarioFileError(f"{path}: expected a mapping of fields at the top level")
    _check_size(path, data)
    return data


def scenario_yaml(data: dict[str, Any], header: str = "") -> str:
    """A scenario's plain data (`Scenario.model_dump(mode="json")`) as YAML text, with an
    optional comment header; `read_scenario_data` reads it back to the same values."""
    comment = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return comment + yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
