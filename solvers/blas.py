"""One BLAS thread while a schedule is computed: the solvers parallelise by processes, not inside BLAS.

numpy and scipy each load their own OpenBLAS (``numpy.libs``, ``scipy.libs``), which by default starts a
thread per core and spins its threads while it waits for work.  Where every core already runs a solver process
(the service's pool, the NLP's forked workers, ``pytest -n 2``), those threads fight the other processes for
the cores: a 290 x 290 Cholesky (``scipy.linalg.lapack.dpotrf``, the dense interior-point step of an NLP window
on refined knots, ``solvers/ipm.py``) took 184 ms with the other core busy against 0.37 ms on one thread
(session 40, 2 cores), and the router zig-zag blended at 10 um on 512 refined intervals 5.3 s of CPU against
0.86 s.  With a core idle one thread is as fast at the median and 10x steadier at the 90th percentile.

``one_thread()`` sets every loaded OpenBLAS to one thread and returns what restores the counts found; the
libraries are found once (``/proc/self/maps`` on Linux, else the wheels' ``*.libs`` folders) and each call is a
few ctypes calls.  Without OpenBLAS (another BLAS, or none found) it does nothing.
"""

from __future__ import annotations

import ctypes
import glob
import os
from collections.abc import Callable

import numpy as np
import scipy

#: OpenBLAS's (get, set) thread-count functions under the names its builds export (plain, numpy's 64-bit
#: ``scipy_openblas64_`` and scipy's ``scipy_openblas``), as threadpoolctl looks them up.
_NAMES = tuple((f"{p}_get_num_threads{s}", f"{p}_set_num_threads{s}")
               for p in ("openblas", "scipy_openblas") for s in ("", "64_"))

_Pair = tuple[Callable[[], int], Callable[[int], None]]
_found: list[_Pair] | None = None


def _paths() -> list[str]:
    """Files of the OpenBLAS libraries this process has loaded (or that numpy and scipy ship)."""
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split(maxsplit=5)[5].strip() for line in maps if "openblas" in line.lower()
                     and len(line.split(maxsplit=5)) == 6}
        if paths:
            return sorted(paths)
    except OSError:
        pass
    roots = [os.path.dirname(os.path.dirname(m.__file__ or "")) for m in (np, scipy)]
    return sorted({p for r in roots for p in glob.glob(os.path.join(r, "*.libs", "*openblas*"))})


def _libraries() -> list[_Pair]:
    global _found
    if _found is None:
        found: list[_Pair] = []
        for path in _paths():
            try:
                # (only a library already loaded: RTLD_NOLOAD fails on any other)
                lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0) | getattr(os, "RTLD_NOW", 0))
            except OSError:
                continue
            for get_name, set_name in _NAMES:
                get, put = getattr(lib, get_name, None), getattr(lib, set_name, None)
                if get is not None and put is not None:
                    get.restype, get.argtypes = ctypes.c_int, []
                    put.restype, put.argtypes = None, [ctypes.c_int]
                    found.append((get, put))
                    break
        _found = found
    return _found


def one_thread() -> Callable[[], None]:
    """Every loaded OpenBLAS on one thread; returns the call that restores the thread counts found."""
    libs = _libraries()
    before = [get() for get, _ in libs]
    for _, put in libs:
        put(1)

    def restore() -> None:
        for (_, put), n in zip(libs, before, strict=True):
            put(n)

    return restore


def thread_counts() -> list[int]:
    """The thread count of each OpenBLAS found (tests)."""
    return [get() for get, _ in _libraries()]
