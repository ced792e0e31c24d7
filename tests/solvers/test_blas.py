"""solvers.blas: the schedule computes with one BLAS thread and gives the thread counts back."""

from __future__ import annotations

import pytest

from geometry import primitives
from geometry.toolpath import Toolpath
from solvers import blas
from solvers.machine import router
from solvers.pipeline import Options, schedule, schedule_stream


def _need_openblas() -> list[int]:
    counts = blas.thread_counts()
    if not counts:
        pytest.skip("no OpenBLAS loaded (another BLAS): nothing to set")
    return counts


def _put_back(counts: list[int]) -> None:
    for (_, put), n in zip(blas._libraries(), counts, strict=True):
        put(n)


def test_one_thread_sets_every_openblas_and_restores_the_counts() -> None:
    before = _need_openblas()
    restore = blas.one_thread()
    try:
        assert blas.thread_counts() == [1] * len(blas.thread_counts())
    finally:
        restore()
    # whatever the counts were (2 on a 2-core machine, 1 where OPENBLAS_NUM_THREADS=1), a count set by the
    # caller comes back
    restore = blas.one_thread()
    restore()
    for _, put in blas._libraries():
        put(3)
    try:
        restore = blas.one_thread()
        assert set(blas.thread_counts()) == {1}
        restore()
        assert set(blas.thread_counts()) == {3}
    finally:
        _put_back(before)


def test_the_schedule_runs_on_one_blas_thread_and_gives_the_counts_back() -> None:
    """Seen from inside the computation (the progress callback runs in it): one thread; after ``schedule``
    and after a stream closed early: the caller's counts."""
    before = _need_openblas()
    for _, put in blas._libraries():
        put(2)
    try:
        seen: list[list[int]] = []
        tp = Toolpath([primitives.line([0, 0, 0], [30, 10, 0]), primitives.line([30, 10, 0], [0, 20, 0])])
        schedule(tp, router(), Options(method="lp"), progress=lambda f: seen.append(blas.thread_counts()))
        assert seen and all(set(c) == {1} for c in seen)
        assert set(blas.thread_counts()) == {2}
        stream = schedule_stream(tp, router(), Options(method="lp"), block_samples=1)
        next(stream)
        assert set(blas.thread_counts()) == {1}
        stream.close()
        assert set(blas.thread_counts()) == {2}
    finally:
        _put_back(before)
