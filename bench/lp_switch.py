"""Method lp with one of its switches on and off, alternated in one process: motion time and CPU per schedule.

    python -m bench.lp_switch --switch rest_shapes   # pipeline.LP_REST_SHAPES (the LP's rest shapes, session 27)
    python -m bench.lp_switch --switch devex         # lp.DUAL_EDGE_WEIGHT 1 (Devex) against -1 (HiGHS's default)
    python -m bench.lp_switch --switch no_scale      # lp.SIMPLEX_SCALE 0 (HiGHS's scaling off) against 2 (its default)

Cases: one flower loop (v + a, and with jerk) and rest-to-rest router lines of 1, 20, 100 and 500 mm (with jerk).
Each case is scheduled REPEATS times per setting, the settings alternated so both see the same machine; CPU is
``time.process_time`` of ``schedule()`` (its median), HiGHS's share that of its ``run`` calls.  Reported as the
ratio on/off, and the motion times of both (the same path, the same limits).
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

from bench._common import emit, env_info, row
from geometry import Toolpath
from geometry import examples as ex
from solvers import lp, pipeline
from solvers.machine import router
from solvers.pipeline import Options, schedule

REPEATS = 7


def _set_rest_shapes(on: bool) -> None:
    pipeline.LP_REST_SHAPES = on


def _set_devex(on: bool) -> None:
    lp.DUAL_EDGE_WEIGHT = 1 if on else -1


def _set_no_scale(on: bool) -> None:
    lp.SIMPLEX_SCALE = 0 if on else 2


SWITCHES: dict[str, Callable[[bool], None]] = {"rest_shapes": _set_rest_shapes, "devex": _set_devex,
                                                "no_scale": _set_no_scale}


def cases() -> dict[str, tuple[Toolpath, Options]]:
    out = {"flower v+a": (ex.flower(1), Options(method="lp", jerk=False)),
           "flower jerk": (ex.flower(1), Options(method="lp"))}
    for length in (1.0, 20.0, 100.0, 500.0):
        tp = Toolpath([ex.line((0.0, 0.0, 0.0), (length, 0.3 * length, 0.1 * length))])
        out[f"line {length:g} mm"] = (tp, Options(method="lp"))
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--switch", choices=sorted(SWITCHES), default="rest_shapes")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    args = ap.parse_args(argv)
    setter = SWITCHES[args.switch]
    m = router()
    highs = {"t": 0.0}
    run = lp.WindowLP._timed_run

    def timed(h: Any) -> None:
        t0 = time.process_time()
        run(h)
        highs["t"] += time.process_time() - t0

    lp.WindowLP._timed_run = staticmethod(timed)  # type: ignore[method-assign]
    out: dict[str, Any] = {"bench": "lp_switch", "switch": args.switch, "env": env_info(), "cases": {}, "rows": []}
    try:
        for name, (tp, opts) in cases().items():
            cpu: dict[bool, list[float]] = {False: [], True: []}
            hig: dict[bool, list[float]] = {False: [], True: []}
            motion: dict[bool, float] = {}
            for on in (False, True):  # warm-up
                setter(on)
                schedule(tp, m, opts)
            for _ in range(args.repeats):
                for on in (False, True):
                    setter(on)
                    highs["t"] = 0.0
                    t0 = time.process_time()
                    sch = schedule(tp, m, opts)
                    cpu[on].append(time.process_time() - t0)
                    hig[on].append(highs["t"])
                    motion[on] = float(sch.summary["motion_time"])
            med = {on: statistics.median(cpu[on]) for on in cpu}
            hmed = {on: statistics.median(hig[on]) for on in hig}
            out["cases"][name] = {"motion_off": motion[False], "motion_on": motion[True], "cpu_off": med[False],
                                  "cpu_on": med[True], "highs_off": hmed[False], "highs_on": hmed[True]}
            out["rows"].append(row(
                f"lp {args.switch} on vs off, {name}: motion / CPU (HiGHS)",
                f"{motion[True]:.4f} s / {med[True] * 1e3:.1f} ms ({hmed[True] * 1e3:.1f} ms)",
                f"{motion[False]:.4f} s / {med[False] * 1e3:.1f} ms ({hmed[False] * 1e3:.1f} ms)",
                f"motion {100 * (motion[True] / motion[False] - 1):+.1f} %, CPU {med[True] / med[False]:.2f}x, "
                f"HiGHS {hmed[True] / max(hmed[False], 1e-12):.2f}x", "—", "info"))
    finally:
        lp.WindowLP._timed_run = staticmethod(run)  # type: ignore[method-assign]
        setter(True)
    emit(out)
    return out


if __name__ == "__main__":
    main()
