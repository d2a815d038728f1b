"""A run folder on disk, named, written and read in this one module: `summary.json` (the run's summary,
strict JSON), `log.csv` (one row per control step, written row by row by the episode: its columns
are husky_sim.sim.step_log.LOG_COLUMNS), `trace.npz` (husky_sim.sim.trace) and a suite's
`results.csv`. Plots, rendering, claims and the suite read runs only through here, and a file that
cannot be used is a RunFolderError: one line that names the file."""

from __future__ import annotations

import csv
import json
import math
import re
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from husky_sim import interrupts
from husky_sim.runs.summary import RunSummary
from husky_sim.sim.trace import EpisodeTrace

#: Where runs go unless --out says otherwise, and the default folders of the suite and the claims.
RESULTS_DIR = Path("results")
SUITE_DIR = RESULTS_DIR / "suite"
PAPER_DIR = RESULTS_DIR / "paper"

SUMMARY_FILE = "summary.json"
LOG_FILE = "log.csv"
TRACE_FILE = "trace.npz"
RESULTS_FILE = "results.csv"


def _safe_component(text: str) -> str:
    """A path component made of [A-Za-z0-9_.+-] that cannot climb out of its parent."""
    cleaned = re.sub(r"[^A-Za-z0-9_.+-]", "_", text).lstrip(".")
    return cleaned[:80] or "_"


def run_dir_name(
    scenario: str, controller: str, horizon: int, gamma: float, seed: int, kind: str = ""
) -> str:
    """The one name of a run's folder: never a path outside its parent, whatever the scenario's
    name holds (the schema already restricts names; this holds for any caller). `kind` prefixes
    folders of other commands than `run` (`serve`, `rehearse`)."""
    prefix = f"{kind}__" if kind else ""
    return _safe_component(f"{prefix}{scenario}__{controller}__N{horizon}__g{gamma:g}__s{seed}")


def default_run_dir(
    scenario: str, controller: str, horizon: int, gamma: float, seed: int, kind: str = ""
) -> Path:
    """results/<run_dir_name>: where `run`, `serve` and `rehearse` write unless told."""
    return RESULTS_DIR / run_dir_name(scenario, controller, horizon, gamma, seed, kind)


def default_check_dir(scenario: str, controller: str, horizon: int, samples: int, seed: int) -> Path:
    """Where `check` writes unless told: one folder per scenario, controller, N, samples and seed."""
    return RESULTS_DIR / _safe_component(f"check__{scenario}__{controller}__N{horizon}__K{samples}__s{seed}")


def default_replay_dir(recording: Path) -> Path:
    """Where `replay` writes unless told: one folder per recording."""
    return RESULTS_DIR / _safe_component(f"replay__{Path(recording).stem or 'bag'}")


class RunFolderError(ValueError):
    """A run folder or results file that cannot be used; the message is one line naming the file."""


def prepare_out_dir(out_dir: Path) -> Path:
    """Create the run directory before anything runs; one-line ValueError naming `--out` if it is
    an existing file, a special file, or cannot be created (too long a name, no permission)."""
    try:
        if out_dir.exists() and not out_dir.is_dir():
            raise ValueError(f"--out: {str(out_dir)[:120]} exists and is not a directory")
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out: cannot create {str(out_dir)[:120]!r} ({exc.strerror or exc})") from None
    return out_dir


def _json_safe(value: object) -> object:
    """JSON has no NaN or infinity: a non-finite number (a physics blow-up) is written as null."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    return value


def write_summary(out_dir: Path, summary: RunSummary | Mapping[str, object]) -> None:
    """summary.json (strict JSON; a RunSummary as its `as_dict()` record), written whole even if a
    signal arrives meanwhile."""
    if isinstance(summary, RunSummary):
        summary = summary.as_dict()
    with interrupts.deferred():
        tmp = out_dir / (SUMMARY_FILE + ".tmp")
        tmp.write_text(json.dumps(_json_safe(summary), indent=2, allow_nan=False) + "\n")
        tmp.replace(out_dir / SUMMARY_FILE)


def _run_dir(run_dir: Path | str) -> Path:
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunFolderError(f"{run_dir}: not a run directory")
    return run_dir


def read_summary(run_dir: Path | str, needed: Sequence[str] = ()) -> dict[str, object]:
    """The run's summary; RunFolderError if it is missing, unreadable or lacks a `needed` key."""
    path = _run_dir(run_dir) / SUMMARY_FILE
    try:
        summary = json.loads(path.read_text())
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunFolderError(f"{path}: not a readable JSON summary ({exc})") from None
    if not isinstance(summary, dict):
        raise RunFolderError(f"{path}: not a run summary (expected a JSON object)")
    missing = [k for k in needed if summary.get(k) is None]
    if missing:
        raise RunFolderError(f"{path}: not a run summary (missing {', '.join(missing)})")
    return summary


def summary_or_empty(run_dir: Path | str) -> dict[str, object]:
    """The run's summary, or {} when it has none readable (a trace renders without it)."""
    try:
        return read_summary(run_dir)
    except RunFolderError:
        return {}


def read_log(run_dir: Path | str, needed: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """The run's log as columns: numeric ones as float arrays, the others as str arrays;
    RunFolderError if it is missing, empty, or a `needed` column is absent or not numeric."""
    path = _run_dir(run_dir) / LOG_FILE
    try:
        with path.open(newline="") as handle:
            rows = list(csv.DictReader(handle))
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise RunFolderError(f"{path}: not a readable CSV log ({exc})") from None
    if not rows:
        raise RunFolderError(f"{path}: no control steps logged")
    missing = [c for c in needed if c not in rows[0]]
    if missing:
        raise RunFolderError(f"{path}: not a run log (missing columns {', '.join(missing)})")
    columns: dict[str, np.ndarray] = {}
    for name in rows[0]:
        values = [row[name] for row in rows]
        try:
            columns[name] = np.array([float(v) for v in values])
        except (TypeError, ValueError):
            if name in needed:
                raise RunFolderError(f"{path}: column {name} is not numeric") from None
            columns[name] = np.array(["" if v is None else v for v in values])
    return columns


def read_trace(run_dir: Path | str) -> EpisodeTrace:
    """The run's trace; RunFolderError if it is missing or not a readable trace."""
    path = _run_dir(run_dir) / TRACE_FILE
    if not path.is_file():
        raise RunFolderError(f"{path}: missing (a run directory written by `husky-sim run` has one)")
    try:
        return EpisodeTrace.load(path)
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise RunFolderError(
            str(exc) if str(path) in str(exc) else f"{path}: not a readable trace ({exc})"
        ) from None


def write_results_csv(rows: Sequence[dict[str, object]], out_dir: Path) -> Path:
    """A suite's results.csv: one row per run with every key any row has (lists and tracebacks
    left out, they are in the runs' folders)."""
    keys: list[str] = []
    for row in rows:
        keys += [k for k in row if k not in keys and k != "traceback" and not isinstance(row[k], list)]
    path = out_dir / RESULTS_FILE
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def read_results(results_csv: Path | str, needed: Sequence[str] = ()) -> list[dict[str, str]]:
    """Rows of a suite's results.csv; RunFolderError if it is unreadable, empty or lacks a
    `needed` column."""
    path = Path(results_csv)
    try:
        with path.open(newline="") as handle:
            reader = csv.DictReader(handle)
            rows = list(reader)
            fields = reader.fieldnames or []
    except FileNotFoundError:
        raise RunFolderError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise RunFolderError(f"{path}: not a readable CSV ({exc})") from None
    missing = [c for c in needed if c not in fields]
    if missing:
        raise RunFolderError(f"{path}: not a suite results file (missing columns {', '.join(missing)})")
    if not rows:
        raise RunFolderError(f"{path}: no runs listed")
    return rows
