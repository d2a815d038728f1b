"""Generate a CasADi Function (a whole solver included) as C, compile it once, load it.

The shared library is cached in a user cache directory under a key that hashes the generated C
source, the CasADi version and the compiler command, so a problem is compiled once per
configuration and machine, and every process (suite and sweep workers) loads the same file. A
file lock makes concurrent workers wait for the one that compiles instead of compiling too.
Without a C compiler, or when compiling fails, the uncompiled Function is used and one warning
says so; results are the same, only slower.

Cache directory: $HUSKY_SIM_SOLVER_CACHE, else $XDG_CACHE_HOME/husky-nav-sim/solvers, else
~/.cache/husky-nav-sim/solvers.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

#: -O1, measured here: relax-cbf N = 5 with 7 obstacles solves in 0.89 ms (CPU median) against
#: 1.35 ms at -O0, and husky-cbf's largest problem (N = 12, 6 slots, soft) compiles in 16 s
#: against 40 s at -O2 (6.6 s at -O0).
C_FLAGS = ("-O1", "-shared", "-fPIC")

_warned: set[str] = set()


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


def _compile_command(compiler: str, source: Path, target: Path) -> list[str]:
    casadi_dir = Path(ca.__file__).parent
    return [
        compiler,
        *C_FLAGS,
        str(source),
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


def _generate(function: ca.Function, directory: str) -> Path:
    """Write `function` as C into `directory` (CodeGenerator writes into the working directory)."""
    source_name = f"{function.name()}.c"
    generator = ca.CodeGenerator(source_name, {"with_header": False})
    generator.add(function)
    cwd = os.getcwd()
    try:
        os.chdir(directory)
        generator.generate()
    finally:
        os.chdir(cwd)
    return Path(directory) / source_name


def _build(compiler: str, source: Path, target: Path) -> str:
    """Compile `source` into `target` atomically; "" on success, else why not."""
    partial = source.with_suffix(".so")
    try:
        result = subprocess.run(_compile_command(compiler, source, partial), capture_output=True, text=True)
    except OSError as exc:
        return str(exc)
    if result.returncode != 0 or not partial.exists():
        return (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[-1]
    shutil.copy2(partial, target.with_suffix(".so.part"))
    os.replace(target.with_suffix(".so.part"), target)
    return ""


def compiled(function: ca.Function) -> ca.Function:
    """`function` compiled to a shared library (cached), or `function` itself when it cannot be."""
    name = function.name()
    with tempfile.TemporaryDirectory(prefix="husky-sim-codegen-") as tmp:
        source = _generate(function, tmp)
        key_material = source.read_bytes() + ca.__version__.encode() + " ".join(C_FLAGS).encode()
        key = hashlib.sha256(key_material).hexdigest()[:24]
        directory = cache_dir()
        target = directory / f"{name}_{key}.so"
        if not target.exists():
            compiler = _compiler()
            if compiler is None:
                _warn_once("no C compiler found (cc, gcc or $CC): NMPC solvers run uncompiled, slower")
                return function
            directory.mkdir(parents=True, exist_ok=True)
            with open(directory / f"{name}_{key}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)  # one process compiles, the others wait and load
                if not target.exists():
                    failure = _build(compiler, source, target)
                    if failure:
                        _warn_once(f"compiling the NMPC solver failed ({failure}); it runs uncompiled")
                        return function
    return ca.external(name, str(target))
