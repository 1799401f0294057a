"""Theta NLPs compiled to C and cached on disk (``ThetaOptions.jit``).

CasADi generates C for the NLP's functions (objective, constraints and their exact
gradient, Jacobian and Lagrangian Hessian), the system C compiler builds a shared library,
and IPOPT is created from that library (``nlpsol(name, "ipopt", "lib.so")``, CasADi's
documented route for generated NLPs). The derivatives are the same; only their evaluation
is faster than CasADi's SX virtual machine (bench/results/theta.md: Theta2 5.1 -> 3.7 ms
on flat ground, 9.0 -> 5.3 ms on rough2cm, where every clearance point costs 40 cosines
and their Hessian; Theta4 2x).

Compiling takes seconds per problem (2-4 s for Theta2 on flat ground, about 20 s on rough
ground, 34 s for Theta4, at -O1), so
libraries are cached under ``$STRATAWALK_CACHE`` (default ``~/.cache/stratawalk``)/nlp,
keyed by a hash of the CasADi version, the compiler flags and the serialised NLP: a new
terrain, robot or option means a new library, an unchanged problem is compiled once per
machine. Without a C compiler, or if compiling fails, :func:`compiled_library` warns and
returns None and the problem keeps its SX functions.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

COMPILER_FLAGS = ("-O1", "-fPIC", "-shared")
CACHE_ENV = "STRATAWALK_CACHE"


def cache_dir() -> Path:
    """Folder of the compiled NLP libraries."""
    root = os.environ.get(CACHE_ENV) or Path.home() / ".cache" / "stratawalk"
    return Path(root) / "nlp"


def compiled_library(solver: ca.Function, nlp: ca.Function) -> Path | None:
    """Shared library of ``solver``'s NLP functions, from the cache or compiled now.

    ``solver`` is the SX-based ``nlpsol`` whose functions are generated; ``nlp`` the
    function (x, p) -> (f, g) whose serialisation keys the cache.
    """
    compiler = shutil.which(os.environ.get("CC") or "cc") or shutil.which("gcc")
    if compiler is None:
        warnings.warn(
            f"ThetaOptions.jit: no C compiler found (CC={os.environ.get('CC', '')!r}, no cc or "
            "gcc on PATH; install gcc or set CC); using CasADi's SX functions",
            stacklevel=3,
        )
        return None
    key = hashlib.sha256(
        "\n".join([ca.__version__, " ".join(COMPILER_FLAGS), nlp.serialize()]).encode()
    ).hexdigest()[:24]
    folder = cache_dir()
    lib = folder / f"nlp_{key}.so"
    if lib.exists():
        return lib
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        gen = ca.CodeGenerator(f"nlp_{key}.c", {"with_header": False})
        gen.add(solver.oracle())
        for name in solver.get_function():
            gen.add(solver.get_function(name))
        source = gen.generate(tmp + os.sep)
        built = Path(tmp) / lib.name
        done = subprocess.run(
            [compiler, *COMPILER_FLAGS, source, "-o", str(built), "-lm"],
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            warnings.warn(
                f"ThetaOptions.jit: compiling {source} with {compiler} failed "
                f"({' / '.join(tail)}); using CasADi's SX functions",
                stacklevel=3,
            )
            return None
        os.replace(built, lib)  # atomic: concurrent planners see the whole file or none
    return lib
