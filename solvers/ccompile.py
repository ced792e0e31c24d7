"""CasADi functions compiled to C, cached on disk, with the SX virtual machine as the fallback.

An NLP window's derivatives are one SX function of a knot interval's checkpoints (``solvers.nlp.
_interval_function``) mapped over the window.  CasADi evaluates an SX function by its virtual machine,
one instruction at a time; the same function generated as C (``casadi.CodeGenerator``) and compiled
evaluates the same operations in the same order as straight-line code:

    2 moving axes, N = 4, mapped over 42 intervals:  derivatives 145 -> 12 us,  values 48 -> 7 us

(the same outputs bit for bit on random inputs: IEEE double arithmetic without fast-math, and no fused
multiply-adds, ``-ffp-contract=off``).  The C source is generated in the process, hashed with the compiler
command and the CasADi version, and its shared library is looked up in the cache directory (CACHE_ENV,
else ``$XDG_CACHE_HOME/feedsched`` or ``~/.cache/feedsched``); a missing one is compiled there once
(~0.1-0.3 s; written under a temporary name and renamed, so processes compiling at once do not read a
partial file).  Without a C compiler, with an unwritable cache directory or with DISABLE_ENV set, the
function is used as given: the same values, by the virtual machine.  (The cache and the compile step are
``geometry.native``'s, shared with its NURBS kernel.)
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import casadi as ca

from geometry import native
from geometry.native import CACHE_ENV, DISABLE_ENV, cache_dir

__all__ = ["CACHE_ENV", "CFLAGS", "DISABLE_ENV", "cache_dir", "compiled"]

#: compile command (after the compiler): optimised, position-independent, exact IEEE arithmetic
CFLAGS = ("-O1", "-fPIC", "-shared", "-ffp-contract=off", "-fno-fast-math")


def _compiler() -> str | None:
    return native.compiler()


def compiled(fun: Any) -> Any:
    """``fun`` (a CasADi Function) as a compiled external of the same name, inputs and outputs; ``fun``
    itself when it cannot be compiled or loaded (see the module's docstring)."""
    if native.disabled():
        return fun
    cc = _compiler()
    if cc is None:
        return fun
    name = str(fun.name())
    try:
        with tempfile.TemporaryDirectory(prefix="feedsched-cg-") as tmp:
            cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
            cg.add(fun)
            cg.generate(tmp + os.sep)
            source = (Path(tmp) / f"{name}.c").read_bytes()
        out = native.build(cc, name, source, CFLAGS, str(getattr(ca, "__version__", "")).encode())
        return ca.external(name, str(out))
    except (OSError, subprocess.SubprocessError, RuntimeError):
        return fun
