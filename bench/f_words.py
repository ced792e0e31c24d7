"""Programmed feeds (session 54): knots and the knot floor from each piece's F words, on and off.

    python -m bench.f_words [--repeats N]

A G-code program's feeds arrive as F words (``Toolpath`` ``feed_limits``), not as a machine feed cap.  "on" is the
pipeline as it is: under lp+nlp a piece's knots are 0.1 x the stopping distance at its programmed feed
(``Piece.feed``, ``pipeline.PIECE_FEED_KNOTS``), and the knot floor takes its top feed and stopping distance there
under both methods.  "off" is the same toolpath with every piece's feed set to inf, as before session 54: knots and
floor from the machine's top feed.  Cases: the router's pocket (``bench.stream_latency.pocket``: 3.1 m, 40 corners)
at F600, F1800 and F6000, and a random CAM program on a fast machine (cam-bench seed 48: 14 g, F words at 10-30 %
of its top feed).  The settings alternate in one process, one NLP worker; CPU is ``time.process_time`` of
``schedule()`` (the median).  Each schedule's samples are checked by finite differences (tests/fdcheck.py): v, a, j
(lp) or u, e (lp+nlp).  "intervals" is the service's budget count (``pipeline.total_intervals``:
the synchronous API's budget is 20,000).  A lp+nlp case over that budget gets one more row: the service's answer
since session 55, its knots coarsened to fit (``pipeline.fit_intervals``) against the job's and the machine's.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import time
from typing import Any

from bench._common import LIMIT_FACTOR, emit, row
from bench.low_feed import begin, worst
from bench.stream_latency import pocket
from geometry import Toolpath, gcode
from service.config import Settings
from solvers.machine import Machine, router
from solvers.pipeline import (
    KNOT_FLOOR_TOL,
    PIECE_FEED_KNOTS,
    Options,
    fit_intervals,
    schedule,
    total_intervals,
)
from tests.reliability import gen

#: The service's synchronous budget of knot intervals (``FEEDSCHED_SYNC_MAX_INTERVALS``, default 20,000).
SYNC_MAX_INTERVALS = Settings().sync_max_intervals


def cases() -> dict[str, tuple[Toolpath, Machine, str]]:
    """name: (toolpath with F words, machine, method)."""
    out: dict[str, tuple[Toolpath, Machine, str]] = {}
    for F, methods in ((600, ("lp+nlp",)), (1800, ("lp+nlp", "lp")), (6000, ("lp+nlp",))):
        tp = gcode.parse(pocket().replace("F6000", f"F{F}")).toolpath()
        for method in methods:
            out[f"router pocket at F{F}, {method}"] = (tp, router(), method)
    fast = gen.case(48, "cam-bench")
    out["cam-bench seed 48 (a 14 g machine), lp"] = (fast.toolpath(), fast.lp_machine, "lp")
    return out


def _without_feeds(tp: Toolpath) -> Toolpath:
    """The same toolpath (shared: the schedule reads only its pieces differently) with every piece's feed inf."""
    off = Toolpath.__new__(Toolpath)
    off.__dict__.update(tp.__dict__)
    off.pieces = [dataclasses.replace(p, feed=math.inf) for p in tp.pieces]
    return off


def main(argv: list[str] | None = None) -> dict[str, Any]:
    repeats, out = begin("f_words", __doc__, argv)
    for name, (tp_on, m, method) in cases().items():
        opts = Options(method=method, nlp_workers=1)
        tps = {True: tp_on, False: _without_feeds(tp_on)}
        cpu: dict[bool, list[float]] = {False: [], True: []}
        res: dict[bool, dict[str, Any]] = {}
        for _ in range(repeats):
            for on in (True, False):
                tp = tps[on]
                t0 = time.process_time()
                sch = schedule(tp, m, opts)
                cpu[on].append(time.process_time() - t0)
                res[on] = {"motion": float(sch.summary["motion_time"]), "knots": sch.summary["control_points"],
                           "intervals": total_intervals(tp, m, opts),
                           "floored": sch.summary["knot_floor_pieces"], "util": worst(m, sch, method)}
        med = {on: statistics.median(cpu[on]) for on in cpu}
        out["cases"][name] = {"on": res[True] | {"cpu": med[True]}, "off": res[False] | {"cpu": med[False]}}
        on, off = res[True], res[False]
        out["rows"].append(row(
            f"F words, {name}: CPU / motion (control points; budget intervals; pieces on the knot floor; worst "
            "sampled utilisation)",
            f"{med[True]:.2f} s / {on['motion']:.4f} s, {100 * med[True] / on['motion']:.2f} % ({on['knots']}; "
            f"{on['intervals']}; {on['floored']}; {on['util']:.4f})",
            f"before session 54 (the machine's top feed): {med[False]:.2f} s / {off['motion']:.4f} s ({off['knots']}; "
            f"{off['intervals']}; {off['floored']}; {off['util']:.4f})",
            f"CPU {med[True] / med[False]:.2f}x, motion {100 * (on['motion'] / off['motion'] - 1):+.3f} %",
            "motion <= +0.2 % (KNOT_FLOOR_TOL), samples <= 1.01 x",
            "pass" if on["motion"] <= (1.0 + KNOT_FLOOR_TOL) * off["motion"] and on["util"] <= LIMIT_FACTOR
            else "FAIL"))
        if method in PIECE_FEED_KNOTS and on["intervals"] > SYNC_MAX_INTERVALS:
            _fitted_row(out, name, tp_on, m, opts, repeats)
    emit(out)
    return out


def _fitted_row(out: dict[str, Any], name: str, tp: Toolpath, m: Machine, opts: Options, repeats: int) -> None:
    """The synchronous service's schedule of a case whose F-word knots are over its budget: the knots coarsened to
    fit (``pipeline.fit_intervals``, as ``service.convert.check_budget`` does), against the full F-word knots (a job)
    and the machine's (before session 54; session 54's service answered 413)."""
    fitted = fit_intervals(tp, m, opts, SYNC_MAX_INTERVALS)
    if fitted.knot_feed_floor is None:  # (over even on the machine's knots: the service refuses it)
        return
    cpu: list[float] = []
    for _ in range(repeats):
        t0 = time.process_time()
        sch = schedule(tp, m, fitted)
        cpu.append(time.process_time() - t0)
    res = {"motion": float(sch.summary["motion_time"]), "knots": sch.summary["control_points"],
           "intervals": total_intervals(tp, m, fitted), "floor": fitted.knot_feed_floor,
           "util": worst(m, sch, opts.method), "cpu": statistics.median(cpu)}
    out["cases"][name]["sync"] = res
    on, off = out["cases"][name]["on"], out["cases"][name]["off"]
    kept = (off["motion"] - res["motion"]) / (off["motion"] - on["motion"])
    out["rows"].append(row(
        f"F words over the synchronous budget ({SYNC_MAX_INTERVALS:,} intervals), {name}: the knots coarsened to fit "
        "(`fit_intervals`), CPU / motion (control points; budget intervals; knot_feed_floor; worst sampled "
        "utilisation)",
        f"{res['cpu']:.2f} s / {res['motion']:.4f} s ({res['knots']}; {res['intervals']}; "
        f"{res['floor']:.3f} mm/s; {res['util']:.4f})",
        f"a job (the F words' knots): {on['cpu']:.2f} s / {on['motion']:.4f} s; the machine's knots: "
        f"{off['cpu']:.2f} s / {off['motion']:.4f} s",
        f"{100 * kept:.0f} % of the F-word knots' gain kept, CPU {res['cpu'] / on['cpu']:.2f}x the job's",
        "motion <= the machine's knots', samples <= 1.01 x",
        "pass" if res["motion"] <= off["motion"] and res["util"] <= LIMIT_FACTOR else "FAIL"))


if __name__ == "__main__":
    main()
