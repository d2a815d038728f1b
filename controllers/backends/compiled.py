"""Generate a CasADi Function (a whole solver included) as C, compile it once, load it.

The shared library is cached in a user cache directory under a key that hashes the Function as
CasADi serialises it, the status shim, the CasADi version and the compiler command, so a problem is
compiled once per configuration and machine, and every process (suite and sweep workers) loads the
same file. A file lock makes concurrent workers wait for the one that compiles instead of compiling
too. Without a C compiler, or when compiling fails, the uncompiled Function is used and one warning
says so; it is slower, and for FATROP the exit flag is then not visible, so its acceptable exits go
to IPOPT (controllers.backends.fatrop).

A FATROP solver is compiled with a status shim (FATROP_STATUS_SHIM): its call of
`fatrop_ocp_c_solve` goes through a wrapper that keeps FATROP's own return flag and iteration
count (read with `FatropStatus`) and returns 0 unless FATROP raised, so the iterate is always
written out and the caller, not CasADi's collapsed 0/1 status, decides what to accept.

Cache directory: $HUSKY_SIM_SOLVER_CACHE, else $XDG_CACHE_HOME/husky-nav-sim/solvers, else
~/.cache/husky-nav-sim/solvers. Every problem, and every change to how one is built, is a new
library of about 0.3 MB (1204 of them, 366 MB, after a few weeks of this project's development):
a library is marked used (its mtime) each time it is looked up, and after each compile the ones
unused for CACHE_MAX_AGE_DAYS are deleted. A working set of any size is kept; a key compiled
again after a month costs one compile.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca

#: -O1, measured here: relax-cbf N = 5 with 7 obstacles solves in 0.89 ms (CPU median) against
#: 1.35 ms at -O0, and husky-cbf's largest problem (N = 12, 6 slots, soft) compiles in 16 s
#: against 40 s at -O2 (6.6 s at -O0).
C_FLAGS = ("-O1", "-shared", "-fPIC")

#: A compile that takes longer is abandoned (the solver then runs uncompiled); the largest
#: problem here (husky-cbf N = 12, soft) compiles in about 16 s.
COMPILE_TIMEOUT_S = 600.0

#: A cached library unused for longer is deleted after the next compile (prune_cache).
CACHE_MAX_AGE_DAYS = 30.0

_warned: set[str] = set()

#: FATROP's return flags as the shim reports them: fatrop::IpSolverReturnFlag in the order of the
#: header that ships in the CasADi wheel (casadi/include/fatrop/ip_algorithm/ip_algorithm.hpp).
FATROP_RETURN_FLAGS = (
    "Success",
    "MaxIterExceeded",
    "StopAtAcceptablePoint",
    "LocalInfeasibility",
    "LineSearchFailed",
    "ErrorInStepComputation",
    "Unknown",
)
#: The generated solver's call of fatrop_ocp_c_solve is renamed to the shim's wrapper.
_SHIM_DEFINE = "-Dfatrop_ocp_c_solve=husky_fatrop_ocp_c_solve"
FATROP_STATUS_SHIM = r"""
/* husky-nav-sim: keep FATROP's own return flag; see controllers/backends/compiled.py */
#undef fatrop_ocp_c_solve
#include <fatrop/ocp/OCPCInterface.h>
static _Thread_local int husky_flag = -1, husky_iterations = -1;
fatrop_int husky_fatrop_ocp_c_solve(struct FatropOcpCSolver* s) {
  fatrop_int ret = fatrop_ocp_c_solve(s);
  const struct FatropOcpCStats* stats = fatrop_ocp_c_get_stats(s);
  husky_flag = ret == -1 ? -1 : stats->return_flag;
  husky_iterations = stats->iterations_count;
  return ret == -1 ? -1 : 0;
}
int husky_fatrop_last_flag(void) { return husky_flag; }
int husky_fatrop_last_iterations(void) { return husky_iterations; }
"""


def cache_dir() -> Path:
    """Where compiled solvers are kept."""
    explicit = os.environ.get("HUSKY_SIM_SOLVER_CACHE")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "husky-nav-sim" / "solvers"


def _compiler() -> str | None:
    """$CC if set (None if it is not an executable), else cc or gcc on the PATH."""
    chosen = os.environ.get("CC")
    if chosen:
        return shutil.which(chosen)
    return shutil.which("cc") or shutil.which("gcc")


def _compile_command(compiler: str, sources: list[Path], target: Path) -> list[str]:
    casadi_dir = Path(ca.__file__).parent
    shim = [_SHIM_DEFINE] if len(sources) > 1 else []
    return [
        compiler,
        *C_FLAGS,
        *shim,
        *map(str, sources),
        f"-I{casadi_dir / 'include'}",
        f"-L{casadi_dir}",
        "-lfatrop",
        "-lblasfeo",
        f"-Wl,-rpath,{casadi_dir}",
        "-o",
        str(target),
    ]


def _warn_once(message: str) -> None:
    if message not in _warned:
        _warned.add(message)
        warnings.warn(message, RuntimeWarning, stacklevel=3)


def _generate(function: ca.Function, directory: str) -> list[Path]:
    """Write `function` as C into `directory`, plus the status shim if it calls FATROP."""
    name = function.name()
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    generator.add(function)
    generator.generate(f"{directory}/")
    sources = [Path(directory) / f"{name}.c"]
    if "fatrop_ocp_c_solve" in sources[0].read_text():
        sources.append(Path(directory) / f"{name}_status.c")
        sources[1].write_text(FATROP_STATUS_SHIM)
    return sources


def _build(compiler: str, sources: list[Path], target: Path) -> str:
    """Compile `sources` into `target` atomically; "" on success, else why not."""
    partial = sources[0].with_suffix(".so")
    command = _compile_command(compiler, sources, partial)
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=COMPILE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return f"took longer than {COMPILE_TIMEOUT_S:.0f} s"
    except OSError as exc:
        return str(exc)
    if result.returncode != 0 or not partial.exists():
        return (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[-1]
    shutil.copy2(partial, target.with_suffix(".so.part"))
    os.replace(target.with_suffix(".so.part"), target)
    return ""


def compiled_library(function: ca.Function) -> Path | None:
    """The shared library of `function` (compiled once, cached), or None when it cannot be built."""
    name = function.name()
    # the key: the Function as CasADi serialises it (the same for the same problem built again, in
    # any process), which is 5 times cheaper than generating its C; that is only done to compile
    key_material = function.serialize().encode() + FATROP_STATUS_SHIM.encode()
    # the library links CasADi's FATROP by its path (rpath), so the path is part of the key
    key_material += ca.__version__.encode() + str(Path(ca.__file__).parent).encode()
    key_material += " ".join((*C_FLAGS, _SHIM_DEFINE)).encode()
    key = hashlib.sha256(key_material).hexdigest()[:24]
    directory = cache_dir()
    target = directory / f"{name}_{key}.so"
    # marked used before it is looked for: a prune_cache in another process either sees the new
    # mtime and keeps it, or has deleted it already and it is compiled again here
    _mark_used(target)
    if target.exists() and not _loads(target):
        target.unlink(missing_ok=True)  # a damaged cache entry is rebuilt, never trusted
    if not target.exists():
        compiler = _compiler()
        if compiler is None:
            _warn_once("no C compiler found (cc, gcc or $CC): NMPC solvers run uncompiled, slower")
            return None
        directory.mkdir(parents=True, exist_ok=True)
        with open(directory / f"{name}_{key}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # one process compiles, the others wait and load
            if not target.exists():
                with tempfile.TemporaryDirectory(prefix="husky-sim-codegen-") as tmp:
                    failure = _build(compiler, _generate(function, tmp), target)
                if not failure and not _loads(target):
                    failure = "the compiled library does not load"
                if failure:
                    _warn_once(f"compiling the NMPC solver failed ({failure}); it runs uncompiled")
                    return None
        prune_cache(directory)
    return target


def _mark_used(library: Path) -> None:
    """Set the library's mtime to now: the cache's record of its last use (prune_cache)."""
    with contextlib.suppress(OSError):  # missing, or a read-only shared cache (never pruned)
        os.utime(library)


def prune_cache(directory: Path, max_age_days: float = CACHE_MAX_AGE_DAYS) -> list[Path]:
    """Delete the libraries in `directory` unused (by mtime) for more than max_age_days, each with
    its lock file when no process holds that lock; return the libraries deleted. A process that
    has one loaded keeps its mapping."""
    cutoff = time.time() - max_age_days * 86400.0
    deleted = []
    for library in sorted(directory.glob("*.so")):
        try:
            if library.stat().st_mtime >= cutoff:
                continue
            lock_path = library.with_suffix(".lock")
            with open(lock_path, "a") as lock:
                try:
                    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    continue  # being compiled or waited on now
                if library.stat().st_mtime >= cutoff:  # looked up since
                    continue
                library.unlink()
                lock_path.unlink()
            deleted.append(library)
        except OSError:  # deleted by another process meanwhile, or a read-only cache
            continue
    return deleted


def _loads(library: Path) -> bool:
    """Whether the shared library can be loaded (a truncated or foreign file cannot)."""
    try:
        ctypes.CDLL(str(library))
    except OSError:
        return False
    return True


def compiled(function: ca.Function) -> ca.Function:
    """`function` compiled to a shared library (cached), or `function` itself when it cannot be."""
    library = compiled_library(function)
    return function if library is None else ca.external(function.name(), str(library))


class FatropStatus:
    """FATROP's return flag and iteration count of the last solve on this thread, read from a
    compiled solver's status shim (the library is already loaded by `casadi.external`)."""

    def __init__(self, library: Path) -> None:
        handle = ctypes.CDLL(str(library))
        self._flag, self._iterations = handle.husky_fatrop_last_flag, handle.husky_fatrop_last_iterations
        self._flag.restype = self._iterations.restype = ctypes.c_int

    def last(self) -> tuple[str, int]:
        """(flag name, iterations); "SolverError" if FATROP raised."""
        flag = self._flag()
        name = FATROP_RETURN_FLAGS[flag] if 0 <= flag < len(FATROP_RETURN_FLAGS) else "SolverError"
        return name, int(self._iterations())
