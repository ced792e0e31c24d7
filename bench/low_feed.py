"""Low feed caps (session 53): the knot floor and the NLP's kept stretches past step-capped breaks, on and off.

    python -m bench.low_feed [--repeats N]

Under a low feed cap the default knots (0.1 x the stopping distance) fall as the cap squared while the motion only
grows as its inverse.  "on" is the pipeline as it is: a piece first solved on the knot floor
(``pipeline.floor_intervals``, kept within ``KNOT_FLOOR_TOL`` of its lower bound) and the NLP keeping the LP's feed
past breaks whose step cap it is far under (``nlp.LP_KEPT_STEP_CAP_SHARE``); "off" is both switched off
(``KNOT_FLOOR_MIN_GAIN`` inf, ``LP_KEPT_STEP_CAP_SHARE`` 0), as before session 53.  The settings alternate in one
process, one NLP worker; CPU is ``time.process_time`` of ``schedule()`` (the median).  Every schedule's samples are
checked by finite differences (tests/fdcheck.py): v, a, j (lp) or u, e (lp+nlp), their worst utilisation reported.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from typing import Any

import numpy as np

from bench._common import LIMIT_FACTOR, emit, env_info, row
from geometry import Toolpath
from geometry import examples as ex
from solvers import nlp, pipeline
from solvers.machine import Machine, router
from solvers.pipeline import Options, Schedule, schedule
from tests.fdcheck import fd_drive, utilisation

REPEATS = 1


def _set(on: bool) -> None:
    pipeline.KNOT_FLOOR_MIN_GAIN = 2 if on else math.inf  # type: ignore[assignment]
    nlp.LP_KEPT_STEP_CAP_SHARE = 0.9 if on else 0.0


def cases() -> dict[str, tuple[Toolpath, float, str]]:
    """name: (toolpath, feed cap mm/s, method)."""
    flower, wave = ex.flower(1), Toolpath([ex.wave3d()])
    line = Toolpath([ex.line((0.0, 0.0, 0.0), (30.0, 0.0, 0.0))])
    return {"flower at 10 mm/s, lp": (flower, 10.0, "lp"), "flower at 10 mm/s, lp+nlp": (flower, 10.0, "lp+nlp"),
            "flower at 30 mm/s, lp+nlp": (flower, 30.0, "lp+nlp"), "3-D wave at 5 mm/s, lp+nlp": (wave, 5.0, "lp+nlp"),
            "30 mm line at 1 mm/s, lp": (line, 1.0, "lp")}


def worst(m: Machine, sch: Schedule, method: str) -> float:
    """The samples' worst utilisation by finite differences: v, a, j (lp) or u, e (lp+nlp)."""
    Ts = sch.summary["sample_period"]
    if method == "lp":
        vmax, amax, jmax = m.limit_arrays()
        return max(utilisation(sch.samples.position, Ts, vmax, amax, jmax).values())
    dr = m.drive_arrays()
    u, e = fd_drive(sch.samples.position, Ts, dr)
    return float(max(np.max(np.abs(u) / dr["umax"]), np.max(np.abs(e) / dr["emax"])))


def begin(bench: str, doc: str | None, argv: list[str] | None) -> tuple[int, dict[str, Any]]:
    """An on / off bench's start (this one's and ``bench.f_words``'): its ``--repeats``, its result record, and a
    warm-up schedule (imports, the NLP's first shapes) before any timing."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=REPEATS)
    args = ap.parse_args(argv)
    schedule(ex.flower(1), router(), Options(nlp_workers=1))
    return int(args.repeats), {"bench": bench, "env": env_info(), "cases": {}, "rows": []}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    repeats, out = begin("low_feed", __doc__, argv)
    try:
        for name, (tp, cap, method) in cases().items():
            m = router().with_feed_max(cap)
            opts = Options(method=method, nlp_workers=1)
            cpu: dict[bool, list[float]] = {False: [], True: []}
            res: dict[bool, dict[str, Any]] = {}
            for _ in range(repeats):
                for on in (True, False):
                    _set(on)
                    t0 = time.process_time()
                    sch = schedule(tp, m, opts)
                    cpu[on].append(time.process_time() - t0)
                    res[on] = {"motion": float(sch.summary["motion_time"]), "knots": sch.summary["control_points"],
                               "nlp_windows": sch.summary.get("nlp_windows"), "util": worst(m, sch, method)}
            med = {on: statistics.median(cpu[on]) for on in cpu}
            out["cases"][name] = {"on": res[True] | {"cpu": med[True]}, "off": res[False] | {"cpu": med[False]}}
            on, off = res[True], res[False]
            out["rows"].append(row(
                f"low feed cap, {name}: CPU / motion (knots; NLP windows; worst sampled utilisation)",
                f"{med[True]:.2f} s / {on['motion']:.4f} s, {100 * med[True] / on['motion']:.2f} % ({on['knots']}; "
                f"{on['nlp_windows']}; {on['util']:.4f})",
                f"before session 53: {med[False]:.2f} s / {off['motion']:.4f} s ({off['knots']}; {off['nlp_windows']}; "
                f"{off['util']:.4f})",
                f"CPU {med[True] / med[False]:.2f}x, motion {100 * (on['motion'] / off['motion'] - 1):+.3f} %",
                "motion <= +0.2 % (KNOT_FLOOR_TOL), samples <= 1.01 x",
                "pass" if on["motion"] <= 1.002 * off["motion"] and on["util"] <= LIMIT_FACTOR else "FAIL"))
    finally:
        _set(True)
    emit(out)
    return out


if __name__ == "__main__":
    main()
