"""Dense CAM output (issue 7 item 4): a finely tessellated spiral of N G01 moves (about 0.5 mm each).

Parses the program, blends the corners of the G01 run with clothoids (``corner_blend_mm``),
schedules it (method ``lp`` by default) and checks the sampled output against every
limit by finite differences (tests/fdcheck.py).  Reports parse / toolpath / schedule
time per metre and the process's peak memory, for the blended path and, for small N,
stop-at-every-vertex.

    python -m bench.dense_gcode --moves 150000       # the issue's size (several minutes)
"""

from __future__ import annotations

import argparse
import resource
import time
from typing import Any

import numpy as np

from bench._common import emit, env_info, row, verdict
from geometry import gcode
from solvers.machine import router
from solvers.pipeline import Options, schedule
from tests.fdcheck import utilisation

LIMIT_FACTOR = 1.01


def spiral_program(moves: int, step_mm: float = 0.5) -> str:
    """An Archimedean-like spiral (r 10 -> 60 mm) of ``moves`` G01 moves about ``step_mm`` long, F6000."""
    u = np.linspace(0.0, 1.0, moves + 1)
    turns = step_mm * moves / (2 * np.pi * 35.0)
    theta = u * turns * 2 * np.pi
    r = 10.0 + 50.0 * u
    x, y = r * np.cos(theta), r * np.sin(theta)
    body = [f"X{a:.4f} Y{b:.4f}" for a, b in zip(x[1:], y[1:], strict=True)]
    return "\n".join(["G21 G90", f"G00 X{x[0]:.4f} Y{y[0]:.4f}", "G01 F6000", *body])


def run(moves: int, blend_mm: float, method: str) -> dict[str, Any]:
    text = spiral_program(moves)
    t0 = time.perf_counter()
    prog = gcode.parse(text)
    t1 = time.perf_counter()
    tp = prog.toolpath(0.5, blend_mm=blend_mm)
    t2 = time.perf_counter()
    m = router()
    sch = schedule(tp, m, Options(method=method))
    t3 = time.perf_counter()
    vmax, amax, jmax = m.limit_arrays()
    util = utilisation(sch.samples.position, sch.summary["sample_period"], vmax, amax, jmax)
    metres = tp.length / 1000.0
    return {"moves": moves, "blend_mm": blend_mm, "method": method, "length_m": metres,
            "segments": len(tp.segments), "pieces": len(tp.pieces), "parse_s": t1 - t0, "toolpath_s": t2 - t1,
            "schedule_s": t3 - t2, "per_metre_s": (t3 - t0) / metres, "motion_s": sch.summary["motion_time"],
            "worst_fd_utilisation": max(util.values()),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, default=20_000)
    ap.add_argument("--blend-mm", type=float, default=0.02)
    a = ap.parse_args()
    out: dict[str, Any] = {"bench": "dense_gcode", "env": env_info(), "rows": []}
    small = min(a.moves, 2000)
    stop = run(small, 0.0, "lp")
    blended_small = run(small, a.blend_mm, "lp")
    big = run(a.moves, a.blend_mm, "lp")
    out.update({"stop_small": stop, "blend_small": blended_small, "blend": big})
    out["rows"] += [
        row(f"{small} G01 moves ({stop['length_m']:.2f} m): blended {a.blend_mm} mm vs stop at every vertex",
            f"{blended_small['motion_s']:.2f} s motion", f"stop {stop['motion_s']:.2f} s",
            f"{stop['motion_s'] / blended_small['motion_s']:.1f}x faster", "faster", verdict(True)),
        row(f"{a.moves} G01 moves ({big['length_m']:.1f} m), blended: time per metre (parse+toolpath+schedule)",
            f"{big['per_metre_s']:.2f} s/m (parse {big['parse_s']:.1f} s, toolpath {big['toolpath_s']:.1f} s, "
            f"schedule {big['schedule_s']:.1f} s)", f"{small} moves: {blended_small['per_metre_s']:.2f} s/m",
            f"{big['per_metre_s'] / blended_small['per_metre_s']:.2f}x", "linear (about 1x)", "info"),
        row(f"{a.moves} G01 moves, blended: sampled FD worst utilisation (v, a, j)",
            f"{big['worst_fd_utilisation']:.4f}", "—", "—", f"<= {LIMIT_FACTOR}",
            verdict(big["worst_fd_utilisation"] <= LIMIT_FACTOR)),
        row(f"{a.moves} G01 moves: peak memory (process)", f"{big['peak_rss_mb']:.0f} MB",
            f"{small} moves: {blended_small['peak_rss_mb']:.0f} MB", "—", "linear", "info"),
    ]
    emit(out)


if __name__ == "__main__":
    main()
