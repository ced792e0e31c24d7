"""The scheduling pipeline: toolpath -> windows -> feed profile -> time samples.

    schedule(toolpath, machine, options) -> Schedule
    schedule_stream(toolpath, machine, options) -> SampleBlock, ..., SampleBlock, ScheduleEnd

1. Split the path at rest points (ends, corners) into pieces.
2. Per piece, in path order: a uniform knot grid (spacing d), LP windows of
   ``lp_window`` knot intervals overlapping by ``lp_overlap`` (at least twice
   the stopping distance, spec §6); each window inherits c_k0, c_k0+1 from the
   previous one; then the NLP (method lp+nlp).
3. Time reconstruction at t_k = k Ts on one grid over the whole path (a piece
   starts where the previous one ended), axis kinematics at each sample, and
   the sampled re-check (``solvers.verify``) with repairs of the piece.  The
   samples of a piece are released (``SampleBlock``) once they have passed it,
   so a consumer has the first rows while later pieces are being solved.  A
   piece with more samples than ``block_samples`` is re-checked in blocks and
   sampled again to be released in blocks (``_piece_blocks``): the samples held
   at once are bounded by the block, not the piece.

Within one piece the rows leave when the piece is done: a path without corners
streams nothing early.  A finer grain is possible and is not built: with method
lp, the feed up to an LP window's committed knot (``joins``) no longer changes
once that window is solved, so its samples could be computed then (t(s) on the
committed intervals is final too); with lp+nlp the same holds per NLP chain
(chains end at the LP joins).  But a sample repair re-solves the piece from the
first window with a flagged point, which could lie in rows already sent, so
repairs would have to be restricted to the windows not yet released (or the
re-check done per window before release, with the held-sample rule at every
window seam) - a change of the repair semantics, not only of the plumbing.
"""

from __future__ import annotations

import math
import mmap
import multiprocessing
import os
import time
import weakref
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from geometry.toolpath import PathSamples, Piece, Toolpath
from solvers import blas, kinematics, lp, verify
from solvers.errors import (
    InfeasibleError,
    InvalidMachineError,
    InvalidOptionsError,
    LimitViolationError,
    OutputTooLargeError,
    ResolutionError,
    ScheduleError,
    SolverFailure,
)
from solvers.lp import (
    REST_SHARE,
    LimitSet,
    WindowLP,
    WindowResult,
    WindowSpec,
    acceleration_bound,
    step_cap,
    v_step_limit,
    velocity_bound,
)
from solvers.machine import AXES, Machine, drive_outputs, drive_speed_bound
from solvers.nlp import CONTEXT_SAMPLES as NLP_CONTEXT_SAMPLES
from solvers.nlp import CONTEXT_STEP as NLP_CONTEXT_STEP
from solvers.nlp import V_STEP_SHARE as NLP_V_STEP_SHARE
from solvers.nlp import VERIFY_TOL as NLP_VERIFY_TOL
from solvers.nlp import (
    ChainPipeline,
    ChainPool,
    GeometryFn,
    Motion,
    NlpLimits,
    NlpRefiner,
    NlpStats,
    chain_spans,
    rest_profile,
)
from solvers.timing import (
    PieceProfile,
    PieceTiming,
    interval_times,
    rest_dips,
    rest_interval_times,
    stalled_intervals,
    stuck,
)

FloatArray = NDArray[np.float64]
#: LP window results kept across the knot plans and repair rounds of one piece (``_solve_windows``): (n_int, k0,
#: k1, rest_floor, rest_shapes, rest_step_floor, at a rest end with ``LimitSet.rest_reach`` and with
#: ``LimitSet.rest_reach_ends``) -> (what the window inherits, its extra verification points, its result or the
#: error it failed with)
WindowCache = dict[tuple[int, int, int, bool, bool, bool, tuple[bool, bool]],
                   tuple[Any, FloatArray, "WindowResult | InfeasibleError | SolverFailure"]]

METHODS = ("lp+nlp", "lp")
SOLVERS = ("highs", "clarabel")
#: Fewest knot intervals in a piece (short pieces need knots to shape their
#: accelerate/decelerate ramps: 3 made 1-5 mm lines 2.1x slower than Ruckig).
MIN_INTERVALS = 16
#: ... and a piece on the default knot spacing is first solved on at least this many
#: (``rest_intervals``): its ramps from and to rest live in its first and last knot intervals,
#: where a quadratic q takes the acceleration from the rest step to amax linearly in s over a
#: whole interval (the jerk-limited optimum takes micrometres: a 100 mm line on 2.27 mm knots
#: took 1.295 s against Ruckig's 0.975 s, 1.067 s on 0.2 mm knots).  Bench seeds 0-199 against
#: 16 only: motion -3.0 % (lp) and -5.95 % (lp+nlp) in the geometric mean, none longer by more
#: than 2 %, CPU x1.07 (lp) and x1.11 (lp+nlp).
REST_MIN_INTERVALS = 64
#: ... and under lp+nlp a piece kept on that first profile (no control point at its floor, not stuck) is solved once
#: more on this many, which the NLP refines, with the first profile kept for ``_nlp_on_coarser_knots`` where it falls
#: back on them (``_finer_rest_plan``): the NLP's feed spline is f, not q, and a ramp out of or into rest (f ~ sqrt(s)
#: under a constant acceleration) is followed the closer the finer its knots.  The LP's refinement trigger (a control
#: point at its floor on the first profile) is the first profile's, as before.  A piece whose first samples on it
#: need a repair is solved again as without it, repairs and all (``_schedule_stream``: the repair rounds on the finer
#: knots took cam seed 2076 to a 422 that the rounds on 64 avoid).  None: off.  Measured in session 71
#: (docs/design.md, "Short pieces on finer knots").
NLP_REST_MIN_INTERVALS: int | None = 128
#: ... and so is a piece kept on its plan's own knots where they are fewer than NLP_REST_MIN_INTERVALS (the first
#: level of ``_refined``: no control point at its floor, not stuck; its profile kept for ``_nlp_on_coarser_knots``).
#: Session 72: the router's pocket at F6000 on its F words' knots (29 of 40 pieces plan 64-127 intervals) took
#: 34.786 s against 34.533 s on the machine's knots (where all 40 took the finer plan), now 34.533 s on both; lines
#: of 150 / 200 / 250 mm -0.61 / -0.29 / -0.15 %, circle R30 -0.96 %, wave3d +0.05 %, the flower unchanged (its
#: plan is finer).  A/B on random cases (1 NLP worker, checker on both): bench 0-79 6 shorter none longer, cam 0-44
#: 11 shorter none longer, 0 failures either side.  Found with it: ``REPAIR_OUTER`` (bench seed 18692).
NLP_FINER_OWN_PLANS = True
#: A piece on the default knot spacing is first solved on knots the machine's top feed (``Machine.top_feed``, at most
#: the piece's programmed feed, ``Piece.feed``) covers in KNOT_FLOOR_SAMPLES sample periods, where that is at least
#: KNOT_FLOOR_MIN_GAIN times coarser than its plan's (``floor_intervals``), and that profile is kept only if its
#: motion time is within KNOT_FLOOR_TOL of a lower bound on any motion along the piece (``piece_time_bound``; the
#: plan's knots cannot beat it either), else the piece is solved as without it.  The default knots are 0.1 x the
#: stopping distance, which under a low feed cap falls as the cap squared (the cap^1.5 where the jerk binds) while
#: the motion time only grows as its inverse:
#: the flower at a 10 mm/s cap ran on 14 um knots (29,193 control points), 1.9 s of CPU (lp) and 20.7 s (lp+nlp)
#: for 40.8 s of motion; a 30 mm line at 1 mm/s on 0.4 um knots, 3.7 / 6.1 s for 30 s.  Where the cap binds
#: along the whole piece the knots only shape the ramps at its rest ends (and the steps of its programmed
#: feeds), each worth a few sample periods.  An unconditional floor (session 52, branch ``tried-knot-floor``)
#: lost motion where the feed does not sit at its cap: lp bench seeds 0-149, 28 longer (seed 115 1.082x).
KNOT_FLOOR_SAMPLES = 10
KNOT_FLOOR_MIN_GAIN = 2
KNOT_FLOOR_TOL = 2e-3
#: ... and where the floor's profile is over its bound, the piece is solved on this many times its knots, and so on
#: while they stay KNOT_FLOOR_MIN_GAIN times coarser than the plan's (``solve_piece``): the ramps at the rest ends
#: cost up to ~5 sample periods each on the floor's knots, 0.55 % of a 2.1 s piece under lp+nlp, whose LP has no
#: rest shapes (bench seed 12 at an 8.3 mm/s cap: 209 floor intervals against a plan of 323,930)
KNOT_FLOOR_LEVEL_STEP = 4
#: ... on pieces at least 1 / KNOT_FLOOR_STOP_SHARE stopping distances long (at the piece's feed): on shorter ones
#: the ramps at the rest ends are much of the motion, where the floor's coarse knots cost the most (and the LP's own
#: pseudo-jerk ramps are over the S-curve even on the plan's knots), and its profile was rarely kept (lp bench seeds
#: 0-149: the pieces rejected had D / L 3.0e-3 to 7.8e-3, and 4 of 5 on 64-165 floor intervals; those kept 4.2e-4
#: and 1.2e-3; each rejected one a coarse solve wasted).  Since session 54 the bound holds the S-curve's ends (a
#: cruising line reads its S-curve move), and still a share of 1e-2 did not pay: cam 0-79 lp+nlp, 60 floors
#: rejected against 7, CPU 1.00x, 26 runs longer (at most +0.10 %), none shorter.
KNOT_FLOOR_STOP_SHARE = 2e-3
#: ``piece_time_bound``'s grid points per floor knot interval, and the most evaluated at once.
KNOT_FLOOR_GRID = 4
KNOT_FLOOR_CHUNK = 65536
KNOT_FLOOR_END_POINTS = 48
KNOT_FLOOR_END_FIRST = 1e-9
#: ``piece_time_bound``'s S-curve ends look this many times the longest ramp from each rest end (``_ramp_stretch``).
RAMP_EXTENT = 2.0
#: ``piece_time_bound``'s tangential jerk bound without jerk rows (mm/s^3: the reach is the acceleration's alone).
REACH_NO_JERK = 1e300
#: Turns passed at speed listed in ``diagnostics.passed_turns`` (those with the lowest feed caps).
PASSED_TURNS_LISTED = 10
#: Default knot spacing as a fraction of the machine's stopping distance; under method lp+nlp, of the stopping
#: distance at the piece's programmed feed (``Piece.feed``: its F words, as a machine feed cap of that value sets
#: it; ``PIECE_FEED_KNOTS``).
KNOT_SPACING_PER_STOP = 0.1
#: Why lp+nlp's knots follow the piece's F words: on the machine's knots a piece at a low F word had rest intervals
#: many ramps long, and the NLP's rest shapes (``bspline.REST_RISE_POWERS``) could not form the ramp inside one: the
#: router's 3.1 m pocket (40 corners, ``bench.stream_latency.pocket``) at F600 / F1800 / F6000 took 315.28 /
#: 105.90 / 35.05 s on 2.3 mm knots, 310.42 / 104.48 / 34.90 s on its feed's (-1.5 / -1.3 / -0.4 %) for 1.73 /
#: 1.34 / 1.34 -> 7.79 / 4.18 / 1.95 s of CPU; random CAM programs (cam 0-79) -0.72 % in the geometric mean, none
#: failed.  Coarser knots, 0.2-0.5 x the feed's stopping distance, kept less of it (F1800 104.66-104.97 s).  Method
#: lp's steep rest shapes (``bspline.LP_REST_RISE_POWERS``) form the ramp in one interval: the same pocket -0.05 /
#: -0.15 / +0.00 % at 6.4 / 4.0 / 1.1 x the CPU, so its knots stay the machine's (the knot floor follows the F words
#: under both).
PIECE_FEED_KNOTS = ("lp+nlp",)
#: ``fit_intervals``: the bisection on ``Options.knot_feed_floor`` stops once its bracket is this narrow (hi / lo - 1).
KNOT_FEED_FLOOR_REL = 1e-3
#: Default knots, knot phase: a sharp curvature peak (radius of curvature under PHASE_PEAK_RADIUS knot
#: spacings) costs far more motion time where it falls on a knot than mid-interval (the quadratic
#: feed's C1 joint there cannot form the narrow dip the peak wants).  Flower, one loop, its 5 petal
#: valleys (radius 1.77 mm) on 2.3 mm knots, lp+nlp: all 5 mid-interval (175 intervals) 3.0652 s, all
#: on knots (180) 3.1390 s, the plain default (177, phases 0.1-0.9) 3.1159 s; per valley against a
#: 4x finer full-horizon NLP: 44 ms lost at phase 0.1, 26 at 0.9, 10 at 0.3, 8 at 0.7, 4 at 0.5.
#: So the default knot count is chosen among n0 (1 +- PHASE_SEARCH) to put the peaks, weighted by
#: curvature, nearest mid-interval (``phase_intervals``), on pieces of 64 to PHASE_MAX_INTERVALS
#: intervals, under lp+nlp only.  Method lp gains too on the flower (4.4649 -> 4.4255 s), but on the 35
#: of bench seeds 0-299 whose knots it moves, lp's motion was 1.2 % longer in the geometric mean (seeds
#: 148 and 272 +30 %): lp refines the knots of many random pieces (stalls, floors), and doubling the
#: count puts a mid-interval peak on a knot.  lp+nlp (which refines rarely): 0.45 % shorter, none
#: failed, nlp fallbacks 5 and 5, worst +3.3 % (seed 188), best -3.1 % (seed 58).
PHASE_SEARCH = 0.03
PHASE_PEAK_RADIUS = 4.0
#: Peaks sharper than this (radius under d / PHASE_PEAK_SHARPEST: a turn the knots cannot resolve
#: anyway, e.g. a sub-micrometre one cut out as a corner) do not count.
PHASE_PEAK_SHARPEST = 4.0
#: Longer pieces keep n0: their many peaks cannot all be phased, and the search's curvature grid
#: (PHASE_GRID points per interval) would grow with the piece.
PHASE_MAX_INTERVALS = 2048
PHASE_GRID = 8
#: phase_intervals' result per toolpath (weakly held) and (piece index, n0): a piece is planned by the
#: LP's first plan, the NLP chain pipeline and the service's budget check (~5 ms a scan on the flower)
_PHASE_CACHE: weakref.WeakKeyDictionary[Toolpath, dict[tuple[int, int], int]] = weakref.WeakKeyDictionary()
#: Overlap safety factor over the stopping distance (spec §6).
OVERLAP_SAFETY = 2.0
#: Fewest knot intervals of an LP window's overlap (its last intervals, solved again by the next window).  Near a
#: window's own end, where it must stop, the LP's optimum is not unique when the stop fits inside an interval with
#: the acceleration and jerk rows slack (a low feed cap on the knot floor, or coarse explicit knots): every free
#: control point weighs d in the integral of q, so an up-down pattern of control points that keeps q under its
#: bound at the checkpoints costs nothing, and HiGHS returns one (1.3e-2 of q two intervals before the end,
#: decaying ~4x per interval back).  The next window inherited it with its start state at the join, and its
#: checkpoint rows turned it into a dip of 1.3 % of q two intervals after the join (session 57: a line at a
#: 1 mm/s feed cap dipped 0.48 % in feed at every join, against the 0.01 % a constant feed may ripple, and its
#: LP never cruised).  16 intervals back the pattern is ~1e-10 of q.  The default overlap is 23 at the default
#: knots (OVERLAP_SAFETY / KNOT_SPACING_PER_STOP + 3), so this floor only lengthens coarser knots' overlaps.
LP_OVERLAP_MIN = 16
#: LP window (``Options.lp_window`` None): DEFAULT_LP_WINDOW knot intervals, and on a long piece of method lp
#: n_int / LP_WINDOWS_PER_PIECE, at most LP_WINDOW_MAX (``lp_window``).  A window costs a fixed ~10 ms of row
#: building, checks and HiGHS set-up besides its simplex work, and its overlap (twice the stopping distance) is
#: solved twice: cam-bench seed 71 (method lp, 1.13 M knot intervals of 0.22 um in 169 pieces) ran 6,677
#: windows of 200 in 99 s of CPU, 2,166 of up to 800 in 75 s, the motion 275.90721 vs 275.90736 s.  18.35 m path,
#: 1 worker: default knots (7,945 intervals) 1.54-1.70 -> 1.29-1.37 s, 4.63 mm 1.05-1.21 -> 0.90 s, the motion
#: within 4e-6.  At least LP_WINDOWS_PER_PIECE windows keep a long piece's two chains (``_chain_split``).  Under
#: lp+nlp too since session 46: its NLP chains end at the LP's joins, and longer chains had more NLP windows
#: (random program cam 4: 286 instead of 173, CPU 1.3x) until stretches at the feed bound were kept unsolved
#: inside a chain (``nlp.kept_parts``), and the 18.35 m path at 4.63 mm knots had 2 NLP fallbacks and +0.38 %
#: motion until windows verified further past their commit and timed their overlap (``nlp.VERIFY_PAST_COMMIT``,
#: ``nlp.TAIL_TIME_WEIGHT``).  Now that path: 143.615 -> 143.110 s of motion at 4.63 mm knots (compute 2.54 ->
#: 2.50 s on 2 workers), 135.315 -> 134.778 s at the default knots (CPU 7.4 -> 7.0 s); cam-bench seed 132
#: (pieces of up to 211,595 intervals) ~218 -> ~170 s of CPU; cam 4 4.46 -> 4.22 s.  Not with Clarabel, whose
#: time per window grows with it (18.35 m at 4.63 mm, v+a: 23 windows of ~80 ms, 10 of ~200 ms; CPU 1.80-1.90
#: vs 1.78-1.82 s on 1 worker, and `make bench` with 2 read 0.99 -> 1.20 s: no gain to have).
DEFAULT_LP_WINDOW = 200
LP_WINDOWS_PER_PIECE = 8
LP_WINDOW_MAX = 800
#: Default NLP window as a multiple of its overlap.
NLP_WINDOW_PER_OVERLAP = 3
#: ... and in a chain that holds at least one window this long (``NlpRefiner.chain_window``): the share
#: of each window re-solved by the next (its overlap) drops from 1/3 to 1/6.  18.35 m path at 4.63 mm knots
#: (chains of ~170 intervals, overlap 13), 1 worker, against 3 x everywhere: 157 -> 68 NLP windows,
#: 4,105 -> 1,925 NLP iterations, 1 -> 0 fallbacks, 144.484 -> 143.687 s of motion, 11.0 -> 9.3-10.2 s;
#: every window 4 x: 144.768 s, 5 x: 143.996 s (1 fallback each), 8 x: 145.963 s (1 fallback).  Not for the
#: whole piece: a chain shorter than 6 overlaps would be one window of its own length and shape (bench seeds
#: 0-59 with every window 6 x: +26 % lp+nlp CPU).
NLP_LONG_WINDOW_PER_OVERLAP = 6
#: Most NLP workers ``Options()`` starts by default (``auto_nlp_workers``): 2, the configuration measured
#: (2 cores here).  With 2 the 18.35 m flower chain computed in 3.7-4.2 % of its motion time against 6.1-7.3 %
#: with 1 (session 22, README issue 3), and the parent's LP is then the critical path: more workers could
#: gain only on the NLP work left after the LP (~1.5 s of ~5.5 s).
NLP_AUTO_WORKERS_MAX = 2
#: ... and only on a piece of at least this many long windows, over which their shapes' builds (0.5-0.9 s
#: each at 78-145 intervals) pay off: bench seeds 30 and 47 (one chain of ~150 intervals each) took
#: 6.0 -> 10.7 s and 6.3 -> 12.0 s with long windows, for the same motion.
NLP_LONG_WINDOW_MIN_COUNT = 8
#: ... and at most this many knot intervals, the long window used only where that is still at least 4 x the
#: overlap: the dense method's Cholesky is cubic in the window's control points.  At the default knots
#: (2.31 mm, overlap 26) a 156-interval window took the NLP stage 11.2 -> 12.4 s (94 vs 172 windows),
#: with BLAS threads (27 s of CPU in 17.5 s).
NLP_LONG_WINDOW_MAX = 80
#: Share of the reported progress given to the LP stage when the NLP follows.
LP_PROGRESS_SHARE = 0.1
#: Utilisation at or above which a constraint is reported as binding.
BINDING_UTILISATION = 0.98
#: Times a piece whose feed stalls is solved again with twice the knots (the last time with a floor on
#: q' at its rest ends) ...
KNOT_REFINEMENTS = 3
#: ... and more times, with that floor, while it is still stuck and its knots stay at most this many: bench
#: seed 828, a 34 mm closed loop whose curvature jumps by 1.7e4 /mm at a knot 0.82 mm from its start
#: (q <= 0.019 there), still stalled at 128 intervals and moves at 512.
STUCK_REFINE_MAX_INTERVALS = 1024
#: A piece refined because the LP held control points at their q floor keeps refining only while
#: each refinement shortens its motion to under this share of the best so far, or shortens it at all against
#: the level before it (session 49; by this share until then: lp bench seeds 0-299, 3 shorter, 241 0.83x, 29
#: 0.97x, 96 0.99x, none longer, their CPU up to 1.9x: 0.14 -> 0.26 s) ...
FLOOR_REFINE_GAIN = 0.99
#: ... or while at most this many refinements in a row have not.  (Against the best alone, bench seed 54 lp
#: stopped at 128 intervals when its 16-interval profile (0.1558 s) was faster than 64's (0.1801) and 128's
#: (0.1570): 0.1894 s of motion, where 256 and 512 reach 0.1009 / 0.0952 s and the whole path 0.1288 s.
#: Session 47, method lp, bench seeds 0-149 / cam 0-59: 8 / 5 seeds shorter (46 -12 %, 126 -28 %), none
#: longer, their wall time up to 2.3x.)
FLOOR_REFINE_PATIENCE = 1
#: ... and only up to this many knot intervals, and only on the default knot spacing (an explicit
#: ``Options.knot_spacing`` is kept: the 45-loop flower at 4.63 mm went from 22 to 67 LP windows,
#: 4 % less motion for ~3 x the compute)
FLOOR_REFINE_MAX_INTERVALS = 1024
#: ... also past KNOT_REFINEMENTS doublings (the stalls' limit, after which only a stuck piece went on).  Session
#: 38, method lp, bench seeds 0-299 (A/B, one process each): 0 failures either way; motion geometric mean 0.929
#: (100 of 300 shorter, none longer: seed 71 0.20 x, 158 0.30 x, 298 0.36 x), CPU of the checked runs 1.43 x
#: (the most, seed 130's 19.1 s, unchanged; small cases up to 12 x: 0.2 -> 2.9 s); random program cam 20
#: (sub-micron corner blends) 6.34 -> 2.51 s.  The flower's samples bit-identical (no floored piece).
FLOOR_REFINE_PAST_PLAN = True
#: With method lp+nlp a floored piece is refined up to this many knot intervals only: the NLP works on the LP's
#: knots, and its windows cover the stopping distance whatever the knots, so its dense steps grow as the knots
#: shrink.  Session 40 (one BLAS thread, ``solvers.blas``), bench seeds 0-299 lp+nlp against 64: 256 motion
#: geometric mean 0.965, CPU 1.30 x; 512 0.954, 1.51 x (seed 44 1.8 -> 13.9 s); 1,024 (276 seeds) 0.950,
#: 2.48 x (seed 157 1.7 -> 83 s); none longer, no failure.  Seeds 300-599 at 512 against session 39's 64: 0.955,
#: 113 shorter but 5 longer (428 1.70 x, 566 1.31 x, 548 1.06 x: the NLP fell back on the refined knots, and the
#: plan's knots were all that ``_nlp_on_coarser_knots`` tried); with it walking the coarser levels: 0.951, 116
#: shorter, 1 longer (575 1.007 x).  The router zig-zag blended at 5 / 10 um
#: (60 degree turns) needs 280 intervals: 2.76 -> 1.79 s, 2.27 -> 1.61 s (stopping: 1.77 s).  Where the NLP
#: falls back on the refined knots, the coarser levels the LP solved (down to the plan's knots) are refined by
#: the NLP too, finest first until one holds, and the fastest kept (``_nlp_on_coarser_knots``).
NLP_FLOOR_REFINE_MAX_INTERVALS = 512
#: Method lp with jerk adds the rest shapes to q in each piece's first and last knot interval
#: (``lp.WindowSpec.rest_shapes``, ``_solve_windows``).
LP_REST_SHAPES = True
#: A refined span (``_slower_spans``) whose time exceeds the LP feed's over it by more than this share keeps
#: the LP's feed.  The NLP starts from the LP's feed (admissible for its limits) and minimises time, so a
#: slower span is a feed collapsing between its checkpoints, where its objective does not look (the
#: envside2 experiment on bench seed 1987: ~1 mm/s for 0.45 s, motion 0.37 -> 0.75 s, without a stall).
SLOWER_SPAN_TOL = 1e-3
#: Rounds of re-solving pieces whose samples exceed a limit (``solvers.verify``) before giving up.
SAMPLE_REPAIR_ROUNDS = 2
#: A piece whose last repair round leaves its samples over the promise, where an earlier round (its first solve
#: included) held it, gets the fastest such round's profile back (``summary.repairs_undone``) rather than a
#: LimitViolationError.  Repairs aim under 1 + REPAIR_TOL, so a piece within the promise is repaired too, and the
#: later rounds' step shares (``REPAIR_STEP_SHARE``) can move the feed elsewhere: bench seed 18692 lp+nlp read
#: e_x 1.0091, then 1.0091, 1.0158, 1.0168 at another point (session 66); cam seed 2076 as it was in session 58,
#: 1.0088 then 1.0219.  Pieces whose last round holds the promise are as before.
REPAIR_UNDO = True
#: A sample repair round's NLP chains read the feed beyond their ends from the round before, not the LP's
#: (``nlp.OUTER_JOIN_TOL``, ``NlpRefiner.outer``; session 72, bench seed 18692).
REPAIR_OUTER = True
#: The repair rounds but the last keep the cap on q* next to rest ends, with room for the step at path ends
#: (``_repair_limits``).
REPAIR_REACH_ENDS = True
#: Under lp+nlp the LP holds the acceleration step at a curvature jump to REST_SHARE of the servo-error
#: budget (``LimitSet.from_machine``) and leaves the servo error of v, a and j either side to the NLP.
#: Where the NLP falls back to the LP's feed over such a jump the samples can read over emax (bench seed
#: 7213: 1.020 x after both repair rounds, the NLP failing the whole piece each time).  The last repair
#: round of an lp+nlp piece solves its LP with the step at this share instead (0.6 passes 7213; as the
#: default share it cost 84 bench seeds +0.7 % of motion, geometric mean, up to +11 %).  The same round
#: holds the acceleration step at a rest end (``LimitSet.a_rest``, the same budget) to this share: bench seed
#: 122 (a 2.2 mm path on 1.27 um knots) read 1.0124 x servo error at its second-last sample, the stop,
#: through both repair rounds (1.0082 x before session 23's dfa0a7a moved the NLP's iterates by rounding).
REPAIR_STEP_SHARE = 0.6
#: An lp+nlp piece whose samples are still over the promise (1 + ``verify.FAIL_TOL``) after SAMPLE_REPAIR_ROUNDS gets
#: one round more, its steps at this share of the budget.  Cam seed 2076 (session 58): a corner stopped within one
#: sample at ~1,300 mm/s programmed feed, the third differences of the samples across it reading e_y 1.0219 x emax
#: (Kj j alone 0.99) through both rounds at 0.6, where the NLP's own sampled check read 1.0016; at 0.3: 0.962.
#: Pieces that pass within SAMPLE_REPAIR_ROUNDS are unchanged.
REPAIR_EXTRA_STEP_SHARE = 0.3
#: A method-lp piece whose samples are still over the promise after SAMPLE_REPAIR_ROUNDS, where they lie in one of its
#: rest intervals, gets one round more without the LP's rest shapes (``_repair_limits``, ``LimitSet.rest_shapes``).
#: Pieces that pass within SAMPLE_REPAIR_ROUNDS are unchanged.
REPAIR_REST_SHAPES_OFF = True
#: Points verified per sample gap next to a sample found over a limit.
REPAIR_SUBDIV = 8
#: Most points a piece's sample repairs verify (``verify_s``, all rounds): where more samples are flagged, an even
#: thinning of their points.  A machine whose x jmax was 3.8e-6 mm/s^3 (derived from a drive with Kj 1e3) flagged
#: nearly every sample of its 5 mm line: 1.1 M points, one LP window of 88 columns and 3.3 M rows, and HiGHS took
#: 23 GB before the kernel killed it (session 59).  Repairs flagging under 2,500 samples (REPAIR_SUBDIV points
#: each) are unchanged.
MAX_REPAIR_POINTS = 20_000
#: A ``precise`` point is off by at most this many units in the last place of the path's ``coordinate_scale`` (plus
#: its arc length's rounding): tests/geometry/test_point_precision.py's POINT_ULPS, measured there.
PRECISE_POINT_ULPS = 4.0
#: Where the points' rounding (``point_noise``) can read more than this share r of a promised kinematic limit in the
#: sampled differences (``verify.noise_shares``), method lp's LP holds that limit times (1 - r), at least
#: NOISE_ROOM_FLOOR (``_noise_room``); below it the LP's limits are the machine's, bit for bit.  Bench seed 17117
#: (lp): x jmax 0.0127 mm/s^3 on coordinates ~477 mm is 224 units in the last place per Ts^3, and the samples' third
#: differences read 1.046-1.060 x it through both repair rounds, the LP's own jerk there at most 1.0005 x: rounding
#: of 5-11 units on a feed at 0.98-0.99 x (r = 0.143; LP at 0.857 x jmax: passes).
NOISE_MARGIN_SHARE = 1e-3
#: ... the LP's limit is at least this share of the machine's.  r is a bound (each point off by the most, in
#: alternate directions) and the samples' check, not the room, is what holds the promise: past r = 1 - this the
#: room would cost motion for a reading the samples do not show.  Bench seed 5029 lp: x jmax at r = 0.88 read
#: 0.31 x in its samples without any room; bench 17828 lp: z jmax at r = 1.77 read 0.44 x.
NOISE_ROOM_FLOOR = 0.5
#: Refused up front (``_noise_room``): an axis the path moves whose limit is under what one unit in the last place
#: of its coordinates reads in the differences as they are checked (a step of one unit u reads u / Ts as a
#: velocity, u / Ts^2 as an acceleration, 2 u / Ts^3 as a jerk): no float64 positions can show it held.  Read as
#: ``verify.noise_shares`` of u / NOISE_FLOOR_UNITS (1 / 4: v u / (2 Ts), a u / Ts^2, j 2 u / Ts^3) against 1, u
#: the unit of the axis's smallest |coordinate| on the path (0 where the axis crosses 0: never refused).  Bench
#: seed 16950 (lp): x jmax 5.1e-5 mm/s^3 on x 479-499 mm, one unit there reads 2.2 x it: 23.6 x jmax in the samples
#: after 3 repair rounds and 11 s of compute.
NOISE_FLOOR_UNITS = 4.0
#: Samples computed per chunk (bounds memory in the reconstruction).
SAMPLE_CHUNK = 100_000
#: The noise of plain sample positions (``Toolpath.evaluate`` without ``precise``), in units in the last place of
#: the path's ``coordinate_scale``: second differences of 1 um steps on segments long in mm and short in u read up
#: to 154 such units (tests/geometry/test_point_precision.py), so a point ~40; the margin covers other shapes.
POINT_NOISE_ULPS = 256.0
#: ... and the share of a promised limit that noise may reach in the sampled differences before the samples take
#: precise points (``precise_points``).
PRECISE_POINTS_SHARE = 1e-4


def auto_nlp_workers() -> int:
    """NLP workers by default: the cores this process may run on (its CPU affinity), at most
    NLP_AUTO_WORKERS_MAX; 1 in a daemonic process, which may not start a pool (the service's solver
    processes, and the benches' case workers, each of which is one job on one core already)."""
    if not _may_fork_pool():
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, NLP_AUTO_WORKERS_MAX))


#: The shortest output period (s; the service's schema: 1e-5): a 1e-300 s period overflowed the knot floor's count.
MIN_SAMPLE_PERIOD_S = 1e-6


@dataclass(frozen=True)
class Options:
    """Scheduling options (all lengths mm, times s).

    Attributes:
        method: "lp+nlp" (default: the LP's feed refined under the drive's control-signal and
            servo-error limits, spec §5) or "lp" (velocity/acceleration/pseudo-jerk only).
        sample_period: Ts of the output, s.
        knot_spacing: feed-profile knot spacing d, mm; default 0.1 x stopping distance (2.3 mm on the router;
            under lp+nlp at each piece's F words, ``PIECE_FEED_KNOTS``; the knot floor, ``floor_intervals``).
        knot_feed_floor: under lp+nlp's default knots, the lowest feed (mm/s) whose stopping distance sizes a
            piece's knots and overlaps: a piece whose F words are lower is planned as if they were this
            (``knot_feed``).  None: no floor.  ``fit_intervals`` sets it to fit a budget of knot intervals
            (the service's), and the schedule's summary reports it.
        checkpoints_per_interval: N, constraint checkpoints per knot interval.
        lp_window: LP window size in knot intervals; default DEFAULT_LP_WINDOW, and on a long piece with HiGHS
            up to LP_WINDOW_MAX (at least LP_WINDOWS_PER_PIECE windows a piece: ``lp_window``).
        lp_overlap: LP window overlap in knot intervals; default from the stopping distance.
        jerk: include the pseudo-jerk stage (off: method lp only; lp+nlp's LP always has it).
        solver: "highs" or "clarabel".
        nlp_window: NLP window size in knot intervals; default 3 x nlp_overlap, and 6 x in a chain of at
            least that many intervals on a piece of at least 8 such windows, where that is at most 80
            intervals (NLP_LONG_WINDOW_PER_OVERLAP, _MIN_COUNT, _MAX); given, it is used everywhere.
        nlp_overlap: NLP window overlap in knot intervals; default from the stopping distance.
        nlp_workers: processes solving independent NLP chains in parallel (forked; 1: in this process);
            with more than 1, a piece's chains are handed to them while the LP still solves its later
            windows (``nlp.ChainPipeline``).  The feed is the same bit for bit.  Default
            ``auto_nlp_workers()``: the cores this process may run on, at most NLP_AUTO_WORKERS_MAX, and 1
            in a daemonic process (the service's solver processes, which run one job per core already).
            A daemonic process solves the chains itself whatever is given (it may not start a pool).
            With more than 1 the second core also takes, in one forked process each, the second chain of
            a long piece's LP windows under method lp (``_chain_split``) and the second half of a
            piece's time samples (``_sample_piece``): again the same output bit for bit.
        nlp_checkpoints_per_interval: N of the NLP (each interval is also checked at both knots,
            and the limits are verified between checkpoints).
        nlp_axis_velocity: also hold |v| <= the LP's vmax per axis in the NLP (off: the NLP limits
            speed through the control signal, servo error and the drive's own vmax if given).
        nlp_kinematic: keep the velocity, acceleration and true-jerk limits in the NLP too (the rest and step
            accelerations held by the jerk as method lp's: ``lp.KINEMATIC_REST_FROM_JERK``; not offered by the
            service).
        max_samples: most time samples the schedule may have (None: no cap); a piece whose samples
            would take the total over it raises ``OutputTooLargeError`` before they are built (the
            service sets its budget here: the motion time is known only once the pieces are solved).
    """

    method: str = "lp+nlp"
    sample_period: float = 1e-3
    knot_spacing: float | None = None
    knot_feed_floor: float | None = None
    checkpoints_per_interval: int = 5
    lp_window: int | None = None
    lp_overlap: int | None = None
    jerk: bool = True
    solver: str = "highs"
    nlp_window: int | None = None
    nlp_overlap: int | None = None
    nlp_checkpoints_per_interval: int = 4
    nlp_workers: int = field(default_factory=auto_nlp_workers)
    nlp_axis_velocity: bool = False
    nlp_kinematic: bool = False
    max_samples: int | None = None
    #: test hook: called with each NLP window's index before it is solved (may raise to inject a fault)
    nlp_fault: Callable[[int], None] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise InvalidOptionsError(f"method must be one of {METHODS}", field="options.method", value=self.method)
        if self.solver not in SOLVERS:
            raise InvalidOptionsError(f"solver must be one of {SOLVERS}", field="options.solver", value=self.solver)
        if not self.jerk and self.method != "lp":
            # lp+nlp keeps the LP's feed in places (its rest intervals, NLP windows that fail), whose servo error
            # only the drive-made jerk limit holds: without the jerk stage bench seeds 2, 14 and 29 of 0-39 read
            # 1.15-6.2 x emax after their repair rounds (session 67, the "+opts" random cases)
            raise InvalidOptionsError(
                "jerk false (no pseudo-jerk stage) needs method lp: method lp+nlp keeps the LP's feed in places, and "
                "only its jerk stage holds the servo error there", field="options.jerk", value=self.jerk,
            )
        _pos(self.sample_period, "options.sample_period")
        if not MIN_SAMPLE_PERIOD_S <= self.sample_period <= 0.1:
            raise InvalidOptionsError(f"must be in [{MIN_SAMPLE_PERIOD_S:g}, 0.1] s", field="options.sample_period",
                                      value=self.sample_period)
        if self.knot_spacing is not None:
            _pos(self.knot_spacing, "options.knot_spacing")
        if self.knot_feed_floor is not None:
            _pos(self.knot_feed_floor, "options.knot_feed_floor")
        if not (isinstance(self.checkpoints_per_interval, int) and 1 <= self.checkpoints_per_interval <= 64):
            raise InvalidOptionsError(
                "must be an integer in [1, 64]", field="options.checkpoints_per_interval",
                value=self.checkpoints_per_interval,
            )
        if self.lp_window is not None and not (isinstance(self.lp_window, int) and 8 <= self.lp_window <= 100_000):
            raise InvalidOptionsError(
                "must be an integer in [8, 100000]", field="options.lp_window", value=self.lp_window
            )
        if self.lp_overlap is not None and not (
            isinstance(self.lp_overlap, int)
            and 3 <= self.lp_overlap <= (DEFAULT_LP_WINDOW if self.lp_window is None else self.lp_window) // 2
        ):
            raise InvalidOptionsError(
                "must be an integer in [3, lp_window / 2]", field="options.lp_overlap", value=self.lp_overlap
            )
        if self.max_samples is not None and not (
            isinstance(self.max_samples, int) and not isinstance(self.max_samples, bool) and self.max_samples >= 1
        ):
            raise InvalidOptionsError("must be a positive integer or None", field="options.max_samples",
                                      value=self.max_samples)
        if not (isinstance(self.nlp_workers, int) and not isinstance(self.nlp_workers, bool)
                and 1 <= self.nlp_workers <= 64):
            raise InvalidOptionsError("must be an integer in [1, 64]", field="options.nlp_workers",
                                      value=self.nlp_workers)
        if not (isinstance(self.nlp_checkpoints_per_interval, int) and 1 <= self.nlp_checkpoints_per_interval <= 64):
            raise InvalidOptionsError(
                "must be an integer in [1, 64]", field="options.nlp_checkpoints_per_interval",
                value=self.nlp_checkpoints_per_interval,
            )
        if self.nlp_overlap is not None and not (isinstance(self.nlp_overlap, int) and 2 <= self.nlp_overlap <= 10_000):
            raise InvalidOptionsError(
                "must be an integer in [2, 10000]", field="options.nlp_overlap", value=self.nlp_overlap
            )
        if self.nlp_window is not None and not (
            isinstance(self.nlp_window, int) and 4 <= self.nlp_window <= 100_000
            and (self.nlp_overlap is None or self.nlp_window >= 2 * self.nlp_overlap)
        ):
            raise InvalidOptionsError(
                "must be an integer in [4, 100000] and at least 2 x nlp_overlap", field="options.nlp_window",
                value=self.nlp_window,
            )


def _pos(v: object, fld: str) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise InvalidOptionsError("must be a finite number > 0", field=fld, value=v)


@dataclass(frozen=True)
class TimeSamples:
    """Axis commands at t_k = k Ts.

    Attributes:
        t: (K,) s.  s: (K,) arc length, mm.  feed: (K,) mm/s.
        position, velocity, acceleration, jerk: (K, 3) per axis x, y, z in
            mm, mm/s, mm/s^2, mm/s^3.
        control_signal, servo_error: (K, 3) predicted by the drive model, V and
            mm (spec §5); None when the machine has no drive model.
    """

    t: FloatArray
    s: FloatArray
    feed: FloatArray
    position: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray
    control_signal: FloatArray | None = None
    servo_error: FloatArray | None = None


@dataclass(frozen=True)
class Schedule:
    samples: TimeSamples
    summary: dict[str, Any]
    diagnostics: dict[str, Any]
    profiles: tuple[PieceProfile, ...] = field(repr=False, default=())


def _rows(smp: TimeSamples, a: int, b: int) -> TimeSamples:
    """Samples [a, b) (views)."""
    return TimeSamples(
        smp.t[a:b], smp.s[a:b], smp.feed[a:b], smp.position[a:b], smp.velocity[a:b], smp.acceleration[a:b],
        smp.jerk[a:b],
        None if smp.control_signal is None else smp.control_signal[a:b],
        None if smp.servo_error is None else smp.servo_error[a:b],
    )


def concat_samples(parts: list[TimeSamples], consume: bool = False) -> TimeSamples:
    """Consecutive sample runs joined into one (u and e only if every part has them).

    ``consume``: empty ``parts`` and join column by column, each part's column released once joined, so
    the peak is the samples plus one column, not twice the samples (bench seed 615: 15.3 M samples,
    21 columns of float64 = 2.6 GB)."""
    if not parts:
        z, z3 = np.zeros(0), np.zeros((0, 3))
        return TimeSamples(z, z, z, z3, z3, z3, z3)
    if len(parts) == 1:
        return parts[0]
    drive = all(p.control_signal is not None and p.servo_error is not None for p in parts)
    names = [f.name for f in fields(TimeSamples) if drive or f.name not in ("control_signal", "servo_error")]
    cols = [{n: getattr(p, n) for n in names} for p in parts]
    if consume:
        parts.clear()
    out: dict[str, FloatArray] = {}
    for n in names:
        out[n] = np.concatenate([c.pop(n) for c in cols])
    return TimeSamples(**out)


@dataclass(frozen=True)
class SampleBlock:
    """Consecutive samples of a schedule that have passed the sampled re-check (``solvers.verify``).

    ``schedule_stream`` yields these in time order; they tile the samples 0 .. K-1 without gap or
    overlap, and their rows are bit for bit ``schedule(...).samples[k0 : k0 + n]``.

    Attributes:
        k0: global index of the first sample (its time is k0 Ts, s).
        piece: index of the piece whose solve released the block.  It holds that piece's samples
            except its last ``HELD_SAMPLES`` (whose differences reach into the next piece), preceded by
            the held samples of the pieces before it; a piece longer than ``block_samples`` releases
            several blocks, each holding back its last HELD_SAMPLES for the next one.
        samples: the rows: t, s, feed, position, velocity, acceleration, jerk and, with a drive model,
            control signal and servo error (``TimeSamples``; units there).
    """

    k0: int
    piece: int
    samples: TimeSamples

    @property
    def n(self) -> int:
        return int(self.samples.t.size)


@dataclass(frozen=True)
class ScheduleEnd:
    """The last item of ``schedule_stream``: what ``Schedule`` carries besides the samples."""

    summary: dict[str, Any]
    diagnostics: dict[str, Any]
    profiles: tuple[PieceProfile, ...] = field(repr=False, default=())


@dataclass(frozen=True)
class WindowPlan:
    d: float
    n_int: int
    window: int
    overlap: int
    nlp_window: int
    nlp_overlap: int
    #: the window of a chain that holds one (``NlpRefiner.chain_window``); None: ``nlp_window`` everywhere
    nlp_long_window: int | None = None


def plan_piece(
    piece: Piece, machine: Machine, opt: Options, n_int: int | None = None, toolpath: Toolpath | None = None,
) -> WindowPlan:
    """Knots and window sizes of one piece; ``n_int`` overrides the knot count (a refined piece).  With
    ``toolpath`` and the default knot spacing, the knot count is phased to the piece's curvature peaks
    (``phase_intervals``; method lp+nlp only, see PHASE_SEARCH).  The stopping distance D that sizes the default
    knots and the overlaps is the machine's, under lp+nlp at the piece's programmed feed (``knot_feed``)."""
    D = machine.stopping_distance(knot_feed(piece, opt))
    d_target = opt.knot_spacing if opt.knot_spacing is not None else KNOT_SPACING_PER_STOP * D
    if n_int is None:
        n_int = max(MIN_INTERVALS, math.ceil(piece.length / d_target - 1e-9))
        if toolpath is not None and opt.knot_spacing is None and opt.method == "lp+nlp":
            n_int = phase_intervals(toolpath, piece, n_int)
    d = piece.length / n_int
    overlap = opt.lp_overlap if opt.lp_overlap is not None else max(LP_OVERLAP_MIN,
                                                                     math.ceil(OVERLAP_SAFETY * D / d) + 3)
    window = max(opt.lp_window if opt.lp_window is not None else lp_window(n_int, opt), 3 * overlap)
    nlp_overlap = opt.nlp_overlap if opt.nlp_overlap is not None else math.ceil(OVERLAP_SAFETY * D / d) + 3
    nlp_window = opt.nlp_window if opt.nlp_window is not None else NLP_WINDOW_PER_OVERLAP * nlp_overlap
    long = min(NLP_LONG_WINDOW_PER_OVERLAP * nlp_overlap, NLP_LONG_WINDOW_MAX)
    use_long = opt.nlp_window is None and long >= 4 * nlp_overlap and n_int >= NLP_LONG_WINDOW_MIN_COUNT * long
    return WindowPlan(d, n_int, window, overlap, max(nlp_window, 2 * nlp_overlap), nlp_overlap,
                      long if use_long else None)


def knot_feed(piece: Piece, opt: Options) -> float:
    """The feed (mm/s) whose stopping distance sizes a piece's default knots and overlaps (``plan_piece``): under
    the methods of PIECE_FEED_KNOTS its programmed feed (``Piece.feed``), at least ``Options.knot_feed_floor``;
    else inf (the machine's own)."""
    if opt.method not in PIECE_FEED_KNOTS:
        return math.inf
    return piece.feed if opt.knot_feed_floor is None else max(piece.feed, opt.knot_feed_floor)


def total_intervals(toolpath: Toolpath, machine: Machine, opt: Options) -> int:
    """The fewest knot intervals the whole toolpath is solved on (``least_intervals`` over its pieces)."""
    return sum(least_intervals(toolpath, p, machine, opt) for p in toolpath.pieces)


def fit_intervals(toolpath: Toolpath, machine: Machine, opt: Options, max_intervals: int) -> Options:
    """``opt``, with the knots coarsened if needed so that ``total_intervals`` is at most ``max_intervals``.

    Only lp+nlp's default knots at the pieces' F words (``knot_feed``) are coarsened: ``Options.knot_feed_floor``
    is raised, by bisection on its logarithm (to KNOT_FEED_FLOOR_REL), from the lowest F word towards the machine's
    top feed, where the knots are the machine's own.  The floor returned is one whose count fits (the count is not
    monotone in it everywhere: the knot floor, ``floor_count``, may stop applying as the plan coarsens).  ``opt``
    is returned as it is where it fits already, where the knots are not the F words' (an explicit
    ``knot_spacing``, method lp), or where even the machine's knots are over: the caller refuses the work then.
    """
    feeds = [p.feed for p in toolpath.pieces if math.isfinite(p.feed)]
    hi = machine.top_feed()
    lo = min(feeds, default=hi)
    if (opt.knot_spacing is not None or opt.method not in PIECE_FEED_KNOTS or lo >= hi
            or total_intervals(toolpath, machine, opt) <= max_intervals):
        return opt
    if opt.knot_feed_floor is not None:
        lo = max(lo, opt.knot_feed_floor)
    if total_intervals(toolpath, machine, replace(opt, knot_feed_floor=hi)) > max_intervals:
        return opt
    while hi > lo * (1.0 + KNOT_FEED_FLOOR_REL):
        mid = math.sqrt(lo * hi)
        if total_intervals(toolpath, machine, replace(opt, knot_feed_floor=mid)) <= max_intervals:
            hi = mid
        else:
            lo = mid
    return replace(opt, knot_feed_floor=hi)


def lp_window(n_int: int, opt: Options) -> int:
    """The default LP window (knot intervals) of a piece of n_int intervals (``LP_WINDOWS_PER_PIECE``)."""
    if opt.solver != "highs":
        return DEFAULT_LP_WINDOW
    return min(LP_WINDOW_MAX, max(DEFAULT_LP_WINDOW, math.ceil(n_int / LP_WINDOWS_PER_PIECE)))


def phase_intervals(toolpath: Toolpath, piece: Piece, n0: int) -> int:
    """The knot count in n0 (1 +- PHASE_SEARCH), at least MIN_INTERVALS, whose knots leave the piece's sharp
    curvature peaks nearest mid-interval (see PHASE_SEARCH); n0 if the piece has none, more than
    PHASE_MAX_INTERVALS intervals, or fewer than REST_MIN_INTERVALS.

    Peaks: local maxima of the curvature kappa = |x_ss| on PHASE_GRID points per interval with
    1 / PHASE_PEAK_RADIUS <= kappa d0 <= PHASE_PEAK_SHARPEST (d0 = L / n0).  For n intervals a peak at
    piece-local s has the phase phi = s n / L mod 1; the score is sum kappa sin^2(pi phi) (1 mid-interval, 0 on a knot),
    and the highest score wins (ties: the count nearest n0)."""
    if n0 > PHASE_MAX_INTERVALS or n0 < REST_MIN_INTERVALS:  # (shorter pieces are solved on REST_MIN_INTERVALS)
        return n0
    memo = _PHASE_CACHE.setdefault(toolpath, {})
    key = (piece.index, n0)
    if key not in memo:
        memo[key] = _phase_search(toolpath, piece, n0)
    return memo[key]


def _phase_search(toolpath: Toolpath, piece: Piece, n0: int) -> int:
    """``phase_intervals`` without its cache."""
    L = piece.length
    s = np.linspace(0.0, L, PHASE_GRID * n0 + 1)
    kap = np.linalg.norm(toolpath.evaluate(piece.s_start + s).d2, axis=1)
    kd = kap[1:-1] * (L / n0)
    inner = (kap[1:-1] > kap[:-2]) & (kap[1:-1] >= kap[2:])
    inner &= (kd >= 1.0 / PHASE_PEAK_RADIUS) & (kd <= PHASE_PEAK_SHARPEST)
    peaks = np.flatnonzero(inner) + 1
    if peaks.size == 0:
        return n0
    lo = max(MIN_INTERVALS, math.floor(n0 * (1.0 - PHASE_SEARCH)))
    cand = np.arange(lo, math.ceil(n0 * (1.0 + PHASE_SEARCH)) + 1)
    phase = np.mod(s[peaks][None, :] * cand[:, None] / L, 1.0)
    score = np.sin(np.pi * phase) ** 2 @ kap[peaks]
    best = np.flatnonzero(score >= score.max() * (1.0 - 1e-12))
    return int(cand[best[np.argmin(np.abs(cand[best] - n0))]])


def rest_intervals(piece: Piece, machine: Machine, opt: Options) -> int | None:
    """Knot intervals of a piece's first LP solve where more than its plan's (``REST_MIN_INTERVALS``, on
    the default knot spacing only; an explicit ``Options.knot_spacing`` is kept), else None."""
    if opt.knot_spacing is not None:
        return None
    n_int = plan_piece(piece, machine, opt).n_int
    return REST_MIN_INTERVALS if n_int < REST_MIN_INTERVALS else None


def first_plan(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lim: LimitSet,
) -> tuple[int | None, float | None]:
    """The knot intervals a piece is first solved on and the bound that profile must keep to be kept
    (``solve_piece``'s ``first_n_int``, ``first_bound``): ``rest_intervals`` (no bound), else
    ``floor_intervals``, else (None, None)."""
    first = rest_intervals(piece, machine, opt)
    if first is not None:
        return first, None
    knot_floor = floor_intervals(toolpath, piece, machine, opt, lim)
    return (None, None) if knot_floor is None else knot_floor


def floor_intervals(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lim: LimitSet,
) -> tuple[int, float] | None:
    """The knot floor's first plan of a piece (``KNOT_FLOOR_SAMPLES``): (knot intervals, the most motion time (s)
    its profile may take to be kept: KNOT_FLOOR_TOL over ``piece_time_bound``), or None where the floor does not
    apply (``floor_count``)."""
    n_f = floor_count(piece, machine, opt)
    if n_f is None:
        return None
    return n_f, (1.0 + KNOT_FLOOR_TOL) * piece_time_bound(toolpath, piece, lim, KNOT_FLOOR_GRID * n_f)


def floor_count(piece: Piece, machine: Machine, opt: Options) -> int | None:
    """The knot intervals of a piece on the knot floor (``KNOT_FLOOR_SAMPLES``), or None where the floor does not
    apply: an explicit ``Options.knot_spacing``; a piece under 1 / KNOT_FLOOR_STOP_SHARE stopping distances long;
    knots (at least REST_MIN_INTERVALS) not at least KNOT_FLOOR_MIN_GAIN times coarser than the plan's.  The top
    feed and the stopping distance are at the piece's programmed feed (``Piece.feed``), under both methods."""
    if opt.knot_spacing is not None:
        return None
    if machine.stopping_distance(piece.feed) > KNOT_FLOOR_STOP_SHARE * piece.length:
        return None
    n0 = plan_piece(piece, machine, opt).n_int
    n_f = max(REST_MIN_INTERVALS,
              math.ceil(piece.length / (KNOT_FLOOR_SAMPLES * opt.sample_period * machine.top_feed(piece.feed)) - 1e-9))
    if KNOT_FLOOR_MIN_GAIN * n_f > n0:
        return None
    return n_f


def least_intervals(toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options) -> int:
    """The fewest knot intervals a piece is solved on (a lower bound on its LP's work): the knot floor's where it
    applies (``floor_count``; its profile may yet be rejected), else its plan's."""
    n_f = floor_count(piece, machine, opt)
    return n_f if n_f is not None else plan_piece(piece, machine, opt, toolpath=toolpath).n_int


def piece_time_bound(toolpath: Toolpath, piece: Piece, lim: LimitSet, m: int) -> float:
    """A lower bound (s) on the time of any motion along the piece under ``lim``'s limits, from rest to rest, on m
    uniform intervals:

        T = sum_i (s_i+1 - s_i) / sqrt(max(q(s_i), q(s_i+1))),
        q = min(q_v, q_a, reach from the start, reach to the end)

    q_v: ``lp.velocity_bound`` (the feed caps and every axis' vmax); q_a: ``lp.acceleration_bound`` (amax);
    the reach: ``lp.reach_q``, the fastest feed from rest under the tangential bounds of the acceleration step
    at rest, the acceleration and the jerk (min_x a_rest_x, amax_x, jmax_x / |x_s,x|, the latter two their
    largest from the rest end to the point, as ``WindowLP._rest_reach``).  A bound where q is monotone over
    each interval (it is piecewise constant on lines and under a binding feed cap, between the ramps at the
    ends).  The first interval at each end is split geometrically (KNOT_FLOOR_END_POINTS points from
    KNOT_FLOOR_END_FIRST of it): the reach's 1 / sqrt(q) is singular at rest (q ~ sigma^(2/3) under the jerk),
    and one interval read the first one's time 1.5 x short.

    With jerk rows, at each end the sum over [0, x_k] may give way to the S-curve's time over it, a lower bound
    too (``_ramp_gain``): the reach leaves out the jerk's rounding into the cruise, so that a straight line that
    cruises read 0.97-0.99 of its S-curve move at the router's feeds, and reads it now (with the step at rest).

    In bounded memory: the grid is walked KNOT_FLOOR_CHUNK intervals at a time, and the reach is taken only
    within ``_reach_extent`` of each end (beyond it, it is over every q_v); the end's running maxima come from a
    pass over that stretch first.  The S-curve's ends keep the points within ``_ramp_stretch`` of each end."""
    geometry = _local(toolpath, piece)
    L = piece.length
    ends = L / m * np.geomspace(KNOT_FLOOR_END_FIRST, 1.0, KNOT_FLOOR_END_POINTS, endpoint=False)
    reach = _reach_extent(lim)

    def grid(i0: int, i1: int) -> FloatArray:
        """The points of uniform intervals [i0, i1) and the end points among them."""
        s = L * np.arange(i0, i1 + 1, dtype=np.float64) / m
        if i0 == 0:
            s = np.union1d(s, ends)
        if i1 == m:
            s = np.union1d(s, L - ends)
        return s

    def bounds(g: PathSamples) -> tuple[FloatArray, FloatArray]:
        """The tangential bounds (A, J) at g (K,) each."""
        A = lp.tangential_bound(g.d1, lim.amax)
        J = lp.tangential_bound(g.d1, lim.jmax) if lim.jerk else np.full(A.size, REACH_NO_JERK)
        return A, J

    # the end's stretch: its running maxima from the end
    k_tail = max(0, min(m, math.floor((L - reach) / L * m)))
    s_tail = grid(k_tail, m)
    g_tail = geometry(s_tail)
    A_tail, J_tail = (np.maximum.accumulate(x[::-1])[::-1] for x in bounds(g_tail))
    a0_end = float(lp.tangential_bound(g_tail.d1[-1:], lim.a_rest)[0])
    del g_tail
    total = 0.0
    A_run = J_run = 0.0
    a0_start = 0.0
    # the S-curve's ends (``_ramp_gain``): the points within its stretch and a margin of each end
    extent, margin = _ramp_stretch(lim, piece.feed, reach)
    near = min(L, extent + margin + L / m)  # (a uniform point past the margin of every candidate)
    ends_at: list[list[FloatArray]] = [[], []]  # (head, tail): per chunk, [s, the sum up to s, q_va, A, J]
    for i0 in range(0, m, KNOT_FLOOR_CHUNK):
        i1 = min(m, i0 + KNOT_FLOOR_CHUNK)
        s = grid(i0, i1)
        g = geometry(s)
        q_va = np.minimum(velocity_bound(g, lim), acceleration_bound(g, lim.amax))
        q = q_va.copy()
        if i0 == 0:
            a0_start = float(lp.tangential_bound(g.d1[:1], lim.a_rest)[0])
        keep = lim.jerk and (s[0] <= near or s[-1] >= L - near)  # (the chunk holds points of the S-curve's ends)
        if s[0] <= reach or keep:
            A_pt, J_pt = bounds(g)
        if s[0] <= reach:
            A = np.maximum(np.maximum.accumulate(A_pt), A_run)
            J = np.maximum(np.maximum.accumulate(J_pt), J_run)
            A_run, J_run = float(A[-1]), float(J[-1])
            head = s <= reach
            q[head] = np.minimum(q[head], lp.reach_q(s[head], a0_start, J[head], A[head]))
        tail = s >= s_tail[0]
        if tail.any():
            at = np.searchsorted(s_tail, s[tail])
            q[tail] = np.minimum(q[tail], lp.reach_q(L - s[tail], a0_end, J_tail[at], A_tail[at]))
        with np.errstate(divide="ignore"):
            terms = np.diff(s) / np.sqrt(np.maximum(q[1:], q[:-1]))
        upto = total + np.concatenate([[0.0], np.cumsum(terms)])
        total += float(np.sum(terms))
        if keep:
            new = s > s[0] if i0 > 0 else np.ones(s.size, dtype=bool)  # (a chunk's first point is the last one's)
            for side, at_end in enumerate((new & (s <= near), new & (s >= L - near))):
                if at_end.any():
                    ends_at[side].append(np.stack([s[at_end], upto[at_end], q_va[at_end], A_pt[at_end], J_pt[at_end]]))
    gain = 0.0
    if lim.jerk:
        for side, a0 in enumerate((a0_start, a0_end)):
            s, upto, q_va, A_pt, J_pt = np.concatenate(ends_at[side], axis=1)
            if side == 1:  # (from the end: the distance to it, and the sum from it)
                s, upto, q_va, A_pt, J_pt = L - s[::-1], total - upto[::-1], q_va[::-1], A_pt[::-1], J_pt[::-1]
            gain += _ramp_gain(s, upto, q_va, A_pt, J_pt, a0, margin, min(L / 2.0, extent))
    return total + gain


def _ramp_stretch(lim: LimitSet, feed: float, reach: float) -> tuple[float, float]:
    """How far (mm) from a rest end ``_ramp_gain`` looks, and its margin (mm); ``reach``: ``_reach_extent(lim)``.

    The extent: RAMP_EXTENT times the S-curve (``lp.s_curve``) to q_top^(1/2) under the smallest tangential bounds
    any path has (as in ``_reach_extent``; q_top at most the piece's programmed feed squared too), the longest ramp
    any point's bounds make (so that some points past it are candidates).  The margin: how far any feed can travel
    while its tangential acceleration ramps down to 0, at most q_top^(1/2) for tau = max_x amax_x / jmax_x (the
    tangential bounds' A / J, each taken at its largest over a stretch, is at most A_x / J_x at the point of the
    largest A)."""
    V = math.sqrt(_q_top(lim, feed))
    _, D = lp.s_curve(np.array([V]), float(np.min(lim.a_rest)), np.array([float(np.min(lim.jmax))]),
                      np.array([float(np.min(lim.amax))]))
    extent = float(D[0]) if np.isfinite(D[0]) else 0.0
    return RAMP_EXTENT * max(extent, reach), V * float(np.max(lim.amax / lim.jmax))


def _ramp_gain(x: FloatArray, cum: FloatArray, q_va: FloatArray, A: FloatArray, J: FloatArray, a0: float,
               margin: float, extent: float) -> float:
    """What ``piece_time_bound`` may add at one rest end for the S-curve (``lp.s_curve``): the most, over the points
    x_k <= extent (K,, mm from rest, increasing, x_0 = 0) whose stretch [0, x_k + margin] the points cover, of

        T_S(x_k) - cum_k,     T_S(x_k) = T_r + (x_k - D_r) / V   (x_k >= D_r, the S-curve's ramp distance)

    and 0: cum_k (K,) is what the bound's sum takes over [0, x_k], and T_S(x_k) a lower bound on the time of any
    motion over [0, x_k] from rest too.  V, A and J are the largest over [0, x_k + margin] of q_va^(1/2) (K,, the
    velocity and acceleration bounds on q), A (K,) and J (K,) (the tangential bounds): a motion with the tangential
    acceleration a > 0 at x <= x_k ramps it down within ``margin`` and passes v + a^2 / (2 J) meanwhile, so it has
    v + a^2 / (2 J) <= V on [0, x_k], which the S-curve covers fastest.  (Its acceleration stays > 0 for at least
    a / J, the jerk being at most J there; a / J <= tau, and over that time it travels at most q_top^(1/2) tau, the
    margin, and its feed gains at least a^2 / (2 J).)  What the reach (``lp.reach_q``) leaves out is the jerk's
    rounding into the cruise: with it a straight line's bound reads its S-curve move instead of 0.95-0.99 of it."""
    if x.size < 2:
        return 0.0
    reach = np.searchsorted(x, x + margin)  # (the first point at or past x_k + margin)
    inside = (reach < x.size) & (x <= extent)
    if not inside.any():
        return 0.0
    at = reach[inside]
    V = np.sqrt(np.maximum.accumulate(q_va)[at])
    T_r, D_r = lp.s_curve(V, a0, np.maximum.accumulate(J)[at], np.maximum.accumulate(A)[at])
    xk = x[inside]
    with np.errstate(invalid="ignore"):
        gain = T_r + (xk - D_r) / V - cum[inside]
        gain = np.where(np.isfinite(gain) & (D_r <= xk), gain, 0.0)
    return max(0.0, float(np.max(gain)))


def _reach_extent(lim: LimitSet) -> float:
    """How far (mm) from a rest end the reach (``lp.reach_q``) can be under the largest q_v anywhere: the ramp to
    sqrt(q_top) under the smallest tangential bounds any path has (an axis' limit over |x_s,x| <= 1: the least of
    the axes' a_rest, amax, jmax), q_top = min(Fmax^2, 3 max_x vmax_x^2) (velocity_bound is min_x vmax_x^2 / x_s,x^2,
    and some |x_s,x| >= 1 / sqrt(3))."""
    J = float(np.min(lim.jmax)) if lim.jerk else REACH_NO_JERK
    return lp.reach_distance(math.sqrt(_q_top(lim)), float(np.min(lim.a_rest)), J, float(np.min(lim.amax)))


def _q_top(lim: LimitSet, feed: float = math.inf) -> float:
    """The largest q any point of any path has under ``lim`` (``_reach_extent``): min(Fmax^2, 3 max_x vmax_x^2), and
    ``feed`` (mm/s, a piece's programmed feed) squared."""
    q_top = min(3.0 * float(np.max(lim.vmax)) ** 2, feed * feed)
    return q_top if lim.feed_max is None else min(q_top, lim.feed_max**2)


def _local(toolpath: Toolpath, piece: Piece) -> Any:
    """The piece's geometry at piece-local s, as the solvers see it.

    At the two rest ends x_ss and x_sss are set to 0: there q = 0 exactly, so they only ever
    multiply 0 in the kinematics, and at a cusp (a zero-speed knot made a corner) they are
    rounding residues of 0/0 (~1e17 and ~1e37) that would wreck the LP's scaling."""
    def geometry(s_local: FloatArray) -> PathSamples:
        s_local = np.asarray(s_local, dtype=np.float64)
        # u(s) from the arc-length tables' guess (1e-10 mm): the constraint rows need no more
        g = toolpath.evaluate(s_local + piece.s_start, piece, exact=False)
        rest = (s_local <= 0.0) | (s_local >= piece.length)
        d2, d3 = g.d2, g.d3
        if rest.any():
            d2, d3 = d2.copy(), d3.copy()
            d2[rest] = 0.0
            d3[rest] = 0.0
        return PathSamples(s_local, g.position, g.d1, d2, d3, g.feed_limit)

    return geometry


def solve_piece(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lim: LimitSet, stats: dict[str, Any],
    on_window: Callable[[float], None] | None = None, verify: FloatArray | None = None,
    cache: WindowCache | None = None,
    on_lp: Callable[[FloatArray, list[int]], None] | None = None,
    first_n_int: int | None = None,
    plain: list[tuple[PieceProfile, list[int]]] | None = None,
    first_bound: float | None = None,
    finer: bool = False,
) -> tuple[PieceProfile, list[int]]:
    """Walk LP windows over one piece and assemble its control points.

    Returns the profile and the knots where consecutive LP windows meet.
    ``on_window(s_done)``, if given, is called after each window with the piece-local arc length (mm) fixed so far.
    ``verify``: piece-local s verified besides each window's fine grid (samples found over a limit).
    ``on_lp(c, joins)``, if given, is called after each window but the last of the first knot plan with
    the piece's control points so far (final up to the last join) and the joins so far
    (``nlp.ChainPipeline.lp_progress``).

    ``first_n_int`` (``rest_intervals``, ``floor_intervals``), if given: the piece is solved on that many knot
    intervals first, and that profile is kept unless it is stuck, holds control points at a q floor, takes
    longer than ``first_bound`` (s), if given, or an LP fails on it (with ``finer``, under lp+nlp, a kept
    ``rest_intervals`` profile gives way to ``_finer_rest_plan``'s, and goes to ``plain``, as does one kept on the
    plan's own knots with ``NLP_FINER_OWN_PLANS``); with ``first_bound``
    (the knot floor, ``floor_intervals``) then on KNOT_FLOOR_LEVEL_STEP times the knots, and so on while they stay
    KNOT_FLOOR_MIN_GAIN times coarser than the plan's; then the piece is solved as without it (below), from its
    plan's knots.  (Refining
    on from the first knots instead, bench seeds 0-199: the same 0 failures and -12 % / -17 % motion
    in the geometric mean, but 8 runs 1.7-8.3 x slower in motion (floors at rest reached on 512
    intervals) and up to 30 x the CPU; a cusp test case's LP failed numerically on 512 intervals.)

    Where the feed cannot move (it stalls inside the piece, or cannot leave or reach a rest end: a
    turn or a start curvature sharper than the knots resolve), the piece is solved again with
    twice the knots, up to KNOT_REFINEMENTS times, the last time with a floor on q' at the rest
    ends (``WindowSpec.rest_floor``: not earlier, as finer knots are the faster way off a sharp
    start: on test seeds 25, 76, 78 the floor on the default knots made the motion 3-15 x longer);
    ``PieceTiming`` rejects what is still stuck.  Where a window holds control points at their q
    floor (the feed is kept off 0 there only by the floor: the same coarse knots, solved without a
    stall) the knots are refined too, and the fastest profile that moves is kept (test seed 14:
    1.96 s on the default knots, 0.68 s on twice as many), on the default knot spacing, up to
    FLOOR_REFINE_MAX_INTERVALS (past KNOT_REFINEMENTS doublings too: ``FLOOR_REFINE_PAST_PLAN``), while
    each refinement pays (FLOOR_REFINE_GAIN, FLOOR_REFINE_PATIENCE).  With method lp+nlp only up to
    NLP_FLOOR_REFINE_MAX_INTERVALS: the NLP works on the LP's knots, and its cost grows fast as they
    shrink; ``plain`` then gets the profiles of the levels solved on fewer knots than the one kept, finest
    first, which the NLP refines instead where it falls back on the finer knots (``_nlp_on_coarser_knots``).
    """
    first: tuple[float, PieceProfile, list[int]] | None = None
    if first_n_int is not None:
        n_first = first_n_int
        # (the knot floor's levels stay KNOT_FLOOR_MIN_GAIN times coarser than this)
        n_plan = plan_piece(piece, machine, opt).n_int if first_bound is not None else 0
        while True:
            floored: list[int] = []
            try:
                prof, joins = _solve_windows(
                    toolpath, piece, plan_piece(piece, machine, opt, n_first), opt, lim, stats, on_window, verify,
                    cache, floored=floored, on_lp=on_lp,
                )
                is_stuck = stuck(prof)
                if not floored and not is_stuck and first_bound is None:
                    fine = (_finer_rest_plan(toolpath, piece, machine, opt, lim, stats, verify, cache, n_first)
                            if finer else None)
                    if fine is None:
                        return prof, joins
                    if plain is not None:
                        plain.append((prof, joins))
                    return fine
                duration = None if is_stuck else _moving_duration(prof)
                if not floored and duration is not None and first_bound is not None and duration <= first_bound:
                    return prof, joins
                if duration is not None and _floor_refines(opt) and (first is None or duration < first[0]):
                    # (a candidate besides the refinements': bench seed 198 lp, 13.3 ms on these 64 intervals,
                    # 20.3 ms on the plan's 16, 48.5 ms on 32, where the refinements stopped)
                    first = (duration, prof, joins)
            except (InfeasibleError, SolverFailure):
                pass
            # (progress and the chains handed out were the first plan's: the pipeline sees the knots change)
            on_window = on_lp = None
            # the knot floor's next level, while still KNOT_FLOOR_MIN_GAIN times coarser than the plan's
            n_next = KNOT_FLOOR_LEVEL_STEP * n_first
            if first_bound is None or KNOT_FLOOR_MIN_GAIN * n_next > n_plan:
                break
            n_first = n_next
            stats["knot_floor_levels"] = stats.get("knot_floor_levels", 0) + 1  # (0 in ``one_shot``'s stats)
        stats["rest_plan_fallbacks"] = stats.get("rest_plan_fallbacks", 0) + 1
    return _refined(toolpath, piece, machine, opt, lim, stats, on_window, verify, cache, on_lp, first, plain,
                    finer and NLP_FINER_OWN_PLANS)


def _finer_rest_plan(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lim: LimitSet, stats: dict[str, Any],
    verify: FloatArray | None, cache: WindowCache | None, n_first: int,
) -> tuple[PieceProfile, list[int]] | None:
    """Under lp+nlp, the LP profile and joins of a piece kept on its first ``REST_MIN_INTERVALS`` plan
    (``solve_piece``), or on its own plan of n_first intervals (``_refined``, ``NLP_FINER_OWN_PLANS``), on
    ``NLP_REST_MIN_INTERVALS`` instead, where that is more; None where it is not, is off or is not lp+nlp, where
    windows or overlaps are given (``Options.lp_window``, ``lp_overlap``, ``nlp_window``, ``nlp_overlap``: counted in
    knot intervals, on finer knots they would span less of the path; bench+opts seeds 3, 2 and 24 ran 37.5 / 3.0 /
    1.3 % longer so) or a knot feed floor is (``Options.knot_feed_floor``: knots coarsened on purpose, as
    ``fit_intervals`` does to fit a budget), or where the finer plan fails, is stuck or holds control points at
    their floor."""
    n_fine = NLP_REST_MIN_INTERVALS
    given = (opt.lp_window, opt.lp_overlap, opt.nlp_window, opt.nlp_overlap, opt.knot_feed_floor)
    if opt.method != "lp+nlp" or n_fine is None or n_fine <= n_first or any(x is not None for x in given):
        return None
    floored: list[int] = []
    try:
        prof, joins = _solve_windows(toolpath, piece, plan_piece(piece, machine, opt, n_fine), opt, lim, stats,
                                     None, verify, cache, floored=floored)
    except (InfeasibleError, SolverFailure):
        return None
    if floored or stuck(prof):
        return None
    stats["finer_rest_plans"] = stats.get("finer_rest_plans", 0) + 1
    return prof, joins


def _floor_refines(opt: Options) -> bool:
    """Whether pieces whose LP holds control points at their floor are refined (``solve_piece``)."""
    return opt.knot_spacing is None


def _floor_refine_cap(opt: Options) -> int:
    """The most knot intervals a floored piece is refined to."""
    return FLOOR_REFINE_MAX_INTERVALS if opt.method == "lp" else NLP_FLOOR_REFINE_MAX_INTERVALS


def _refined(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lim: LimitSet, stats: dict[str, Any],
    on_window: Callable[[float], None] | None, verify: FloatArray | None,
    cache: WindowCache | None,
    on_lp: Callable[[FloatArray, list[int]], None] | None,
    first: tuple[float, PieceProfile, list[int]] | None = None,
    plain: list[tuple[PieceProfile, list[int]]] | None = None,
    finer: bool = False,
) -> tuple[PieceProfile, list[int]]:
    """``solve_piece``'s knot refinements, from the piece's plan's knots; ``first``, if given, is a candidate
    already solved (duration, profile, joins), kept if faster than what the refinements end with (it does not
    stop them: taken as their yardstick, it cut refinements short that went on to faster profiles, bench
    seeds 23, 80, 86, 111 lp +63-75 %; and a plan on fewer knots than it and no faster does not stop them
    either, bench seed 97).  ``plain``, if given, gets the profiles and joins of the levels solved on fewer knots
    than the one kept, finest first (``_nlp_on_coarser_knots``).  ``finer``: a piece kept on its plan's knots
    gives way to ``_finer_rest_plan``'s (``NLP_FINER_OWN_PLANS``; that plan's profile goes to ``plain``)."""
    n_int: int | None = None
    best: tuple[float, PieceProfile, list[int]] | None = None
    prof: PieceProfile | None = None
    joins: list[int] = []
    levels: list[tuple[float, PieceProfile, list[int]]] = []  # every level solved and not stuck (for ``plain``)
    attempt = misses = 0
    prev_duration: float | None = None
    while True:
        plan = plan_piece(piece, machine, opt, n_int, toolpath)
        floor_refine = _floor_refines(opt) and 2 * plan.n_int <= _floor_refine_cap(opt)
        floored: list[int] = []
        try:
            prof, joins = _solve_windows(
                toolpath, piece, plan, opt, lim, stats, on_window if attempt == 0 else None, verify, cache,
                rest_floor=attempt >= KNOT_REFINEMENTS, floored=floored if floor_refine else None,
                on_lp=on_lp if attempt == 0 else None,
            )
        except (InfeasibleError, SolverFailure):
            if best is None and first is None:  # (a refinement for a floor only: keep what moved)
                raise
            break
        is_stuck = stuck(prof)
        if not is_stuck and not floored and best is None and first is None:
            if finer and attempt == 0:
                fine = _finer_rest_plan(toolpath, piece, machine, opt, lim, stats, verify, cache, plan.n_int)
                if fine is not None:
                    if plain is not None:
                        plain.append((prof, joins))
                    return fine
            break
        duration = None if is_stuck else _moving_duration(prof)
        is_stuck = duration is None  # (or its time table cannot be built: a stall ``stuck`` does not see)
        if duration is not None:
            levels.append((duration, prof, joins))
            # A plan coarser than ``first``'s and no faster than it ends nothing (neither as clean nor as "finer
            # knots no longer pay"): it says nothing about knots finer than first's.  Bench seed 97 lp, a 110.6 mm
            # piece first solved on 64 intervals (2.02 s, a control point at its floor): 16 / 32 intervals, 3.85 /
            # 4.00 s, stopped refinements that on 128 (with the rest floor) reach 1.16 s; so did a clean 16-interval
            # profile of 2.51 s (which of two equally good stage-2 vertices HiGHS met decided between them).
            behind = first is not None and plan.n_int < first[1].n_int and duration >= first[0]
            # A plan on first's own knots and no faster than it is no miss either: it is first solved again (until
            # session 50 it counted: bench seed 201's second piece, 16 / 32 / 64 / 128 intervals 4.40 / 2.36 / 5.06
            # / 5.35 s, two misses, stopped where 256 / 512 / 1,024 reach 1.76 / 1.39 / 1.30 s)
            again = first is not None and plan.n_int == first[1].n_int and duration >= first[0]
            if not floored and best is None and not behind:
                break
            # (a level faster than the one before it is no miss, even if not the fastest yet; until session 49 only
            # one faster by the gain: bench seed 46 went 2.86 / 3.09 / 3.05 s on 34 / 68 / 136 intervals, 0.9876 of
            # the level before, and on to 2.52 s on 544, but stopped at 136 where that step read 0.9907)
            if (not behind and not again and best is not None and duration > FLOOR_REFINE_GAIN * best[0]
                    and not (prev_duration is not None and duration < prev_duration)):
                misses += 1
                if misses > FLOOR_REFINE_PATIENCE:
                    break  # finer knots no longer pay
            elif not behind and not again and best is not None:
                misses = 0
            prev_duration = duration
            if best is None or duration < best[0]:
                best = (duration, prof, joins)
            if not floored and not behind:
                break
        # after KNOT_REFINEMENTS doublings (the last with the rest floor) only a piece still stuck goes on,
        # with the rest floor, while its knots stay at most STUCK_REFINE_MAX_INTERVALS, or one still held at
        # its floor whose refinements pay (FLOOR_REFINE_PAST_PLAN; up to FLOOR_REFINE_MAX_INTERVALS)
        if (attempt >= KNOT_REFINEMENTS and (not is_stuck or 2 * plan.n_int > STUCK_REFINE_MAX_INTERVALS)
                and not (FLOOR_REFINE_PAST_PLAN and floored and floor_refine and not is_stuck)):
            break
        n_int = 2 * plan.n_int
        attempt += 1
        stats["knot_refinements"] = stats.get("knot_refinements", 0) + 1
    result = (prof, joins)
    if first is not None:
        if best is None and prof is not None and not stuck(prof):
            last = _moving_duration(prof)
            if last is not None:
                best = (last, prof, joins)
        if best is None or first[0] < best[0]:
            best = first
    if best is not None:
        result = (best[1], best[2])
    if result[0] is None:  # (unreachable: without ``first`` the first solve's failure is raised)
        raise SolverFailure("no knot plan of the piece could be solved")
    if plain is not None:
        # the levels coarser than the one kept, finest first, one per knot count (the faster LP of equal counts)
        if first is not None:
            levels.append(first)
        kept_n = result[0].n_int
        by_n: dict[int, tuple[float, PieceProfile, list[int]]] = {}
        for lv in levels:
            n = lv[1].n_int
            if n < kept_n and (n not in by_n or lv[0] < by_n[n][0]):
                by_n[n] = lv
        plain.extend((by_n[n][1], by_n[n][2]) for n in sorted(by_n, reverse=True))
    return result[0], result[1]


#: LP windows are not solved along a straight stretch at a constant velocity bound that the walk enters at that
#: bound (``_WindowWalk.cruise``): there q = the bound is the LP's optimum (every checkpoint at its upper bound, the
#: acceleration and jerk rows 0), so the control points are set to it, and the next window starts OVERLAP before the
#: stretch ends (as far as a window's artificial end: the stop it plans for is forgotten by then).  The walk enters
#: at the bound when q and q' = 0 at its join are within CRUISE_TOL of it; the stretch is straight while the
#: curvature's acceleration and jerk at the bound stay under CRUISE_TOL of every axis's limits.  Why: lp+nlp's F-word
#: knots put many windows on such stretches: the router's pocket at F1800 / F600 took 4.16 / 7.28 s of CPU, 2.54 /
#: 4.33 s without them (185 -> 93 / 249 -> 121 LP windows); random CAM programs (cam 0-79) 0.90x, every motion
#: within 3.4e-4 (75 of 80 within 1e-6).
CRUISE_TOL = 1e-9
#: A piece whose LP plan (method lp) has at least this many windows is solved as two chains of windows
#: joined by a seam window (``_solve_windows``): the second chain in a forked process when
#: ``Options.nlp_workers`` > 1, else after the first in this one (the same feed either way).
LP_CHAIN_MIN_WINDOWS = 4


#: An LP window that Options.solver other than HiGHS (Clarabel) cannot solve (SolverFailure, InfeasibleError) or
#: whose q comes to rest inside (``_dips_to_rest``) is solved again with HiGHS (``summary.solver_fallbacks``).
#: The "+opts" random cases found it (test seeds 25, 33, 142 of 20 with Clarabel: two feeds that stalled at every
#: knot refinement, one NumericalError); HiGHS's own failures are raised as they were.
SOLVER_FALLBACK = True
#: The share of its largest control point under which an inner control point of a window's q (all but the two at
#: each end) reads as the feed reaching rest inside the window (``_dips_to_rest``; the time table's stall share).
SOLVER_DIP_SHARE = 1e-12


def _dips_to_rest(c: FloatArray) -> bool:
    """Whether an LP window's q (control points (n,), mm^2/s^2) comes to rest inside: an inner control point under
    SOLVER_DIP_SHARE of the largest.  SOLVER_FALLBACK: Clarabel's interior point holds q's rows to ~1e-8 of their
    scale, and where the path's turns slow the feed to ~1e-10 of its peak (test seed 25, a near-cusp: HiGHS's q
    1.6e-4 mm^2/s^2 under a peak of 1.0e6) it returned -83, and the piece stalled at every knot refinement."""
    inner = c[2:-2]
    return bool(inner.size and float(np.min(inner)) < SOLVER_DIP_SHARE * float(np.max(c)))


@dataclass(frozen=True)
class _WindowWalk:
    """What every LP window of one knot plan of a piece shares (``_solve_windows``)."""

    geometry: Any
    breaks: FloatArray
    plan: WindowPlan
    opt: Options
    lim: LimitSet
    verify: FloatArray | None
    cache: WindowCache | None
    rest_floor: bool
    a_rest_start: FloatArray | None
    a_rest_end: FloatArray | None
    #: ``WindowSpec.rest_shapes``, ``WindowSpec.rest_step_floor``
    rest_shapes: bool = False
    rest_step_floor: bool = False

    def window(
        self, stats: dict[str, Any], k0: int, k1: int, start: tuple[float, float] | None,
        prev_qstar: tuple[int, FloatArray] | None, prev_c: tuple[int, FloatArray] | None,
        end_fixed: tuple[int, FloatArray, FloatArray] | None = None,
    ) -> tuple[WindowSpec, WindowResult]:
        """One window over knot intervals [k0, k1) (from the cache if its inputs are bit-equal to a cached
        one's).  ``end_fixed``: (k0_next, c_next, c*_next), the control points and stage-1 q* (both from
        knot k0_next on) of the solution a seam window joins at k1."""
        plan, N = self.plan, self.opt.checkpoints_per_interval
        spec = WindowSpec(stats["windows"], k0, k1, plan.d, plan.n_int, start, k1 == plan.n_int, prev_qstar, prev_c,
                          self.a_rest_start if k0 == 0 else None, self.a_rest_end, self.rest_floor,
                          rest_shapes=self.rest_shapes, rest_step_floor=self.rest_step_floor)
        if end_fixed is not None:
            kn, cn, qn = end_fixed
            spec = replace(spec, end_fixed=(float(cn[k1 - kn]), float(cn[k1 - kn + 1])), next_c=(kn, cn),
                           next_qstar=(kn, qn))
        s_check = np.linspace(k0 * plan.d, k1 * plan.d, (k1 - k0) * N + 1)
        verify = self.verify
        v_in = np.zeros(0) if verify is None else verify[(verify > k0 * plan.d) & (verify < k1 * plan.d)]
        # everything the window inherits: its start state and the previous window's c and q* over
        # the inherited intervals, and a seam window's next c and q* (bit-equal inputs give the same LP,
        # so its result is reused)
        st0 = np.array(start if start is not None else (np.nan, np.nan))
        st = [st0, _inherited(prev_c, k0), _inherited(prev_qstar, k0)]
        if end_fixed is not None:
            st += [end_fixed[1][k0 - end_fixed[0]: k1 + 2 - end_fixed[0]],
                   end_fixed[2][k0 - end_fixed[0]: k1 + 2 - end_fixed[0]]]
        at_rest = start is None or k1 == plan.n_int
        key = (plan.n_int, k0, k1, self.rest_floor, self.rest_shapes, self.rest_step_floor,
               (self.lim.rest_reach and at_rest, self.lim.rest_reach and self.lim.rest_reach_ends and at_rest))
        stv = np.concatenate(st)
        cache = self.cache
        hit = cache.get(key) if cache is not None else None
        if hit is not None and np.array_equal(hit[0], stv, equal_nan=True) and np.array_equal(hit[1], v_in):
            if isinstance(hit[2], (InfeasibleError, SolverFailure)):
                raise hit[2]  # (failed on these inputs before: bench seed 11994's stalling windows, ~11 s each)
            return spec, hit[2]
        t0 = time.perf_counter()
        # only the window's own breaks (WindowLP looks at no others): masking all of a long piece's
        # breaks in every window grew with the square of the path length
        b0, b1 = np.searchsorted(self.breaks, (k0 * plan.d, k1 * plan.d))

        def solve(solver: str) -> WindowResult:
            return WindowLP(spec, self.lim, self.geometry, solver, self.breaks[b0:b1], v_in).solve(s_check)

        try:
            try:
                res = solve(self.opt.solver)
                if self.opt.solver != "highs" and SOLVER_FALLBACK and _dips_to_rest(res.c):
                    raise SolverFailure(f"{self.opt.solver}'s feed reaches 0 inside the window", window=spec.index,
                                        status="stall")
            except (InfeasibleError, SolverFailure) as exc:
                if self.opt.solver == "highs" or not SOLVER_FALLBACK:
                    raise
                # (SOLVER_FALLBACK: the window again with HiGHS, which fails as it would have on its own)
                stats["solver_fallbacks"] = stats.get("solver_fallbacks", 0) + 1  # (callers' own stats too)
                stats.setdefault("solver_fallback_reasons", []).append(
                    {"window": spec.index, "status": exc.status, "reason": str(exc)})
                res = solve("highs")
        except (InfeasibleError, SolverFailure) as exc:
            if cache is not None:
                cache[key] = (stv, v_in, exc)
            raise
        stats["window_times"].append(time.perf_counter() - t0)
        stats["windows"] += 1
        stats["iterations"] += res.iterations
        stats["cut_rounds"] += res.cut_rounds
        stats["cut_points"] += res.added_points
        stats["unverified"] += res.unverified
        if cache is not None:
            cache[key] = (stv, v_in, res)
        return spec, res

    def walk(
        self, c: FloatArray, stats: dict[str, Any], k0: int, start: tuple[float, float] | None,
        prev_qstar: tuple[int, FloatArray] | None, prev_c: tuple[int, FloatArray] | None,
        on_window: Callable[[float], None] | None, floored: list[int] | None,
        on_lp: Callable[[FloatArray, list[int]], None] | None = None, stop: int | None = None,
        solved: list[WindowResult] | None = None, shapes: list[FloatArray | None] | None = None,
    ) -> tuple[list[int], _WalkState | None]:
        """Windows from knot k0 on, each starting where the previous one's overlap begins, into c (the piece's
        control points): to the piece end, or (``stop``) until they are final up to knot ``stop``.
        Returns the knots where consecutive windows meet and, with ``stop``, the state a window starting
        there inherits (None if the piece end came first).  ``solved``, if given, gets each window's result;
        ``shapes``, if given, the rest shapes' amplitudes of the piece's start and end ([head, tail],
        ``WindowResult.shapes``) where a window has them."""
        plan = self.plan
        joins: list[int] = []
        while True:
            k1 = _window_end(plan, k0)
            spec, res = self.window(stats, k0, k1, start, prev_qstar, prev_c)
            if solved is not None:
                solved.append(res)
            if shapes is not None:
                for i, amp in enumerate(res.shapes):
                    if amp is not None:
                        shapes[i] = amp
            if floored is not None and res.floored:
                floored.append(spec.index)
            if spec.end_rest:
                c[k0 : k1 + 2] = res.c
                return joins, None
            k_next = k1 - plan.overlap
            if self.opt.method == "lp+nlp":
                k_next = _join_knot(self.geometry, res.c, k0, k_next, plan, self.lim)
            joins.append(k_next)
            if on_window is not None:
                on_window(k_next * plan.d)
            c[k0 : k_next + 2] = res.c[: k_next - k0 + 2]
            if k0 == 0 and start is None:
                c[0] = -c[1]  # (rest at the piece start, as below: set now for on_lp's first chain)
            if on_lp is not None:
                on_lp(c, joins)
            start = (float(res.c[k_next - k0]), float(res.c[k_next - k0 + 1]))
            prev_qstar = (k0, res.c_star)
            prev_c = (k0, res.c)
            k0 = k_next
            if stop is not None and k0 >= stop:
                return joins, _WalkState(k0, start, prev_qstar, prev_c)
            # (not in a chain split's first chain: the seam window starts where the plan's windows do)
            jump = self.cruise(k0, start) if stop is None else None
            if jump is not None:
                k_jump, q_top = jump
                c[k0 + 2 : k_jump + 2] = q_top
                stats["lp_cruise_jumps"] = stats.get("lp_cruise_jumps", 0) + 1
                stats["lp_cruise_intervals"] = stats.get("lp_cruise_intervals", 0) + k_jump - k0
                joins.append(k_jump)
                if on_window is not None:
                    on_window(k_jump * plan.d)
                if on_lp is not None:
                    on_lp(c, joins)
                start = (q_top, q_top)
                flat = np.full(plan.window + 2, q_top)
                prev_qstar, prev_c = (k_jump, flat), (k_jump, flat)
                k0 = k_jump

    def cruise(self, k0: int, start: tuple[float, float]) -> tuple[int, float] | None:
        """(k_jump, q_top): where the walk from knot k0 at state ``start`` (c_k0, c_k0+1) may go on past a cruise
        (see CRUISE_TOL), with q = q_top over [k0, k_jump]; None where it may not save a window (``walk``).

        The stretch is scanned from k0 in windows' lengths of knot intervals (the geometry at the windows' own
        checkpoints) until an interval is not straight, changes the velocity bound, holds a curvature break or a
        verification point, or the piece ends; k_jump is an overlap and 3 intervals before that interval, and
        at least a window's final stretch (window - overlap) past k0."""
        plan, lim, N = self.plan, self.lim, self.opt.checkpoints_per_interval
        q_top = start[0]
        if not (q_top > 0.0 and abs(start[1] - q_top) <= CRUISE_TOL * q_top):
            return None
        need = plan.window - plan.overlap
        k = k0
        while k < plan.n_int:
            k_hi = min(k + plan.window, plan.n_int)
            s = np.linspace(k * plan.d, k_hi * plan.d, (k_hi - k) * N + 1)
            g = self.geometry(s)
            ok = np.abs(velocity_bound(g, lim) - q_top) <= CRUISE_TOL * q_top
            ok &= np.all(np.abs(g.d2) * q_top <= CRUISE_TOL * lim.amax, axis=1)
            ok &= np.all(np.abs(g.d3) * q_top**1.5 <= CRUISE_TOL * lim.jmax, axis=1)
            for extra in (self.breaks, self.verify):
                if extra is not None and extra.size:
                    inside = extra[(extra > s[0]) & (extra <= s[-1])]
                    ok[np.searchsorted(s, inside)] = False
            bad = np.flatnonzero(~ok)
            if bad.size:
                k_end = k + int(bad[0] - 1) // N if bad[0] > 0 else k - 1
                break
            k = k_hi
        else:
            k_end = plan.n_int
        k_jump = k_end - plan.overlap - 3
        return (k_jump, q_top) if k_jump - k0 >= need else None


@dataclass(frozen=True)
class _WalkState:
    """Where a walk of LP windows stopped (``_WindowWalk.walk``): the next window's start knot and inheritance."""

    k0: int
    start: tuple[float, float]
    prev_qstar: tuple[int, FloatArray]
    prev_c: tuple[int, FloatArray]


def _window_end(plan: WindowPlan, k0: int) -> int:
    """The end knot of the LP window starting at knot k0: plan.window intervals on, or the piece end if
    that would leave a last window shorter than the overlap (this one is stretched instead)."""
    k1 = min(k0 + plan.window, plan.n_int)
    return plan.n_int if 0 < plan.n_int - k1 < plan.overlap + 3 else k1


def _plan_starts(plan: WindowPlan) -> list[int]:
    """The knots where a method-lp walk over the whole piece starts its windows (``_WindowWalk.walk``)."""
    k0, out = 0, []
    while True:
        out.append(k0)
        k1 = _window_end(plan, k0)
        if k1 == plan.n_int:
            return out
        k0 = k1 - plan.overlap


def _chain_split(plan: WindowPlan, opt: Options) -> tuple[int, int, int] | None:
    """Two chains of LP windows for a piece of method lp with at least LP_CHAIN_MIN_WINDOWS windows:
    (k_split, k_b, k_seam) -- the first chain's windows are final up to knot k_split, the second chain
    starts at rest at k_b = k_split - overlap, and the seam window spans [k_split, k_seam]; None: one chain.

    The second chain's start at rest reaches the feed it would have had within the overlap (twice the
    stopping distance, the same argument as for a window's artificial end), so from k_split on it is the
    feed the first chain would have walked into, up to the LP's choices among equal optima; the seam
    window joins the two states (c_k, c_k+1 fixed at both ends).  Balanced for two processes: the first
    chain has ceil((n + 1) / 2) of the n windows (it also solves the short seam).

    Only on the overlap derived from the stopping distance: with a shorter ``Options.lp_overlap`` the
    second chain's start is not forgotten by the split knot (random bench paths, overlap 10 intervals: most
    seams infeasible, and the others up to +0.9 % of motion against one chain)."""
    if opt.method != "lp" or opt.lp_overlap is not None:
        return None
    starts = _plan_starts(plan)
    if len(starts) < LP_CHAIN_MIN_WINDOWS:
        return None
    k_split = starts[(len(starts) + 1) // 2]
    ov = plan.overlap
    seam = min(ov, plan.window - 2 * ov - 2)  # (inside the second chain's first final stretch)
    if seam < 4:
        return None
    return k_split, k_split - ov, k_split + seam


def _solve_windows(
    toolpath: Toolpath, piece: Piece, plan: WindowPlan, opt: Options, lim: LimitSet, stats: dict[str, Any],
    on_window: Callable[[float], None] | None, verify: FloatArray | None,
    cache: WindowCache | None = None,
    rest_floor: bool = False, floored: list[int] | None = None,
    on_lp: Callable[[FloatArray, list[int]], None] | None = None,
) -> tuple[PieceProfile, list[int]]:
    """The LP windows of ``solve_piece`` on one knot plan (``rest_floor``: ``WindowSpec.rest_floor``;
    ``floored``, if given, gets the index of every window that holds control points at a q floor;
    ``on_lp`` as in ``solve_piece``).

    ``cache`` (kept across calls for one piece) maps (n_int, k0, k1, rest_floor) to what the window inherits,
    the extra verification points inside it and its result: a window whose inputs are bit-equal
    to a cached one is not solved again (a repair round re-solves the windows with new
    verification points and those whose inherited state they changed).

    A long piece of method lp is walked as two chains (``_chain_split``), the second one in a forked
    process with ``Options.nlp_workers`` > 1 (the same feed as in this process).  If the second chain or
    the seam window fails, the first chain walks on over the second one's knots instead (counted in
    ``stats["lp_seam_fallbacks"]``).

    Method lp with jerk adds the rest shapes to q in the piece's first and last knot intervals
    (``WindowSpec.rest_shapes``; not with ``rest_floor``, whose floor is on the control point next to rest, nor
    without jerk, where a quadratic leaves rest at amax already).  Should q dip to 0 inside such an interval
    between the points the LP holds it at (``timing.rest_dips``), the piece is walked again with a floor on the
    acceleration step at rest (``lp.REST_STEP_FLOOR_SHARE``; counted in ``stats["rest_step_floor_walks"]``), and
    should that dip, stall or fail too, without them (counted in ``stats["rest_shape_fallbacks"]``)."""
    shaped = LP_REST_SHAPES and opt.method == "lp" and opt.jerk and not rest_floor and lim.rest_shapes
    prof, joins = _walk_plan(toolpath, piece, plan, opt, lim, stats, on_window, verify, cache, rest_floor, floored,
                             on_lp, shaped)
    if shaped and rest_dips(prof):
        stats["rest_step_floor_walks"] = stats.get("rest_step_floor_walks", 0) + 1
        if floored is not None:
            floored.clear()
        try:
            prof, joins = _walk_plan(toolpath, piece, plan, opt, lim, stats, None, verify, cache, rest_floor,
                                     floored, on_lp, True, rest_step_floor=True)
            # (stalls as the time table reads them: bench seed 14's second piece on 16 intervals, the step floored
            # next to a turn of 3.6 um radius 0.067 mm from rest, passed ``stuck`` and stalled in the table)
            fell = rest_dips(prof) or stuck(prof) or not _table_moves(prof)
        except (InfeasibleError, SolverFailure):
            fell = True
        if fell:
            stats["rest_shape_fallbacks"] = stats.get("rest_shape_fallbacks", 0) + 1
            if floored is not None:
                floored.clear()
            prof, joins = _walk_plan(toolpath, piece, plan, opt, lim, stats, None, verify, cache, rest_floor,
                                     floored, on_lp, False)
    return prof, joins


def _table_moves(profile: PieceProfile) -> bool:
    """Whether the time table of ``profile`` can be built (the feed neither stalls nor is stuck at rest)."""
    return _moving_duration(profile) is not None


def _moving_duration(profile: PieceProfile) -> float | None:
    """The motion time (s) of ``profile``, or None where its time table cannot be built: the feed stalls where
    ``stuck`` does not look (q at 0 inside a rest interval, between the points the LP held it at).  A knot plan
    whose profile does so is no candidate (``solve_piece``, ``_refined``): the refinements go on past it.  With
    rises of power 512 in the rest shapes (tried, session 49) bench seed 276's 64-interval profile dipped to 0 at
    r = 0.17 of its last interval, and the schedule failed there instead of refining."""
    try:
        return PieceTiming.build(profile, inverse=False).duration
    except ScheduleError:
        return None


def _walk_plan(
    toolpath: Toolpath, piece: Piece, plan: WindowPlan, opt: Options, lim: LimitSet, stats: dict[str, Any],
    on_window: Callable[[float], None] | None, verify: FloatArray | None, cache: WindowCache | None,
    rest_floor: bool, floored: list[int] | None, on_lp: Callable[[FloatArray, list[int]], None] | None,
    rest_shapes: bool, rest_step_floor: bool = False,
) -> tuple[PieceProfile, list[int]]:
    """``_solve_windows``'s walk over the windows of one knot plan, with or without the rest shapes (and with
    ``rest_step_floor``, ``WindowSpec.rest_step_floor``)."""
    # the step at a corner is shared by the pieces on both sides, under either method (until session 6
    # only under lp+nlp: bench seed 1723, lp, a 5.8 degree corner with x moving on through it, stepped by
    # 2 a_rest = jmax Ts and the third difference across it read 1.018 x jmax; sharing costs test-profile
    # lp cases with corners 1.4 % of motion time, geometric mean over 47)
    ww = _WindowWalk(_local(toolpath, piece), _breaks(toolpath, piece), plan, opt, lim, verify, cache, rest_floor,
                     _corner_rest(toolpath, piece, lim, at_end=False), _corner_rest(toolpath, piece, lim, at_end=True),
                     rest_shapes, rest_step_floor)
    c = np.zeros(plan.n_int + 2)
    shapes: list[FloatArray | None] = [None, None]
    split = _chain_split(plan, opt) if on_lp is None else None
    if split is None:
        joins = ww.walk(c, stats, 0, None, None, None, on_window, floored, on_lp, shapes=shapes)[0]
    else:
        joins = _walk_chains(ww, c, split, stats, on_window, floored, shapes)
    # rest at both piece ends holds exactly (the LP meets it to solver tolerance)
    c[0] = -c[1]
    c[-1] = -c[-2]
    head, tail = shapes
    return PieceProfile(
        s_start=piece.s_start, length=piece.length, d=plan.d, c=c,
        rest_g=(0.0 if head is None else float(head[0]), 0.0 if tail is None else float(tail[0])),
        rest_h=(() if head is None else tuple(float(x) for x in head[1:]),
                () if tail is None else tuple(float(x) for x in tail[1:])),
    ), joins


def _second_chain(ww: _WindowWalk, k_b: int, stats: dict[str, Any], floored: bool) -> dict[str, Any]:
    """The second chain of ``_walk_chains`` from rest at knot k_b to the piece end: its control points
    and its first window's stage-1 q* (both from k_b on), joins, the stats it added, the windows it solved
    (cache entries) and whether any held control points at a floor."""
    c = np.zeros(ww.plan.n_int + 2)
    cache0 = dict(ww.cache) if ww.cache is not None else None
    st = {k: (list(v) if isinstance(v, list) else v) for k, v in stats.items()}
    fl: list[int] = []
    solved: list[WindowResult] = []
    shapes: list[FloatArray | None] = [None, None]
    joins = ww.walk(c, st, k_b, None, None, None, None, fl if floored else None, solved=solved, shapes=shapes)[0]
    new = {k: v for k, v in (ww.cache or {}).items() if cache0 is None or cache0.get(k) is not v}
    return {"c": c[k_b:], "c_star": solved[0].c_star, "joins": joins, "floored": fl, "cache": new,
            "tail": shapes[1],
            "stats": {k: (v[len(stats.get(k, [])):] if isinstance(v, list) else v - stats.get(k, 0))
                      for k, v in st.items() if isinstance(v, (int, float, list))}}


def _walk_chains(
    ww: _WindowWalk, c: FloatArray, split: tuple[int, int, int], stats: dict[str, Any],
    on_window: Callable[[float], None] | None, floored: list[int] | None, shapes: list[FloatArray | None],
) -> list[int]:
    """``_solve_windows`` on two chains (``_chain_split``): the first from the piece start to k_split, the
    second from rest at k_b to the end (forked with ``Options.nlp_workers`` > 1), then the seam window
    [k_split, k_seam] from the first chain's state to the second chain's control points.  ``shapes`` gets the
    rest shapes' amplitudes as in ``_WindowWalk.walk``."""
    k_split, k_b, k_seam = split
    stats["lp_chains"] = stats.get("lp_chains", 0) + 1
    pipe = proc = None
    if _workers(ww.opt) > 1:
        ctx = multiprocessing.get_context("fork")
        pipe, child_end = ctx.Pipe(duplex=False)

        def run() -> None:
            try:
                out: Any = ("ok", _second_chain(ww, k_b, stats, floored is not None))
            except Exception as exc:  # (reported to the parent, which then walks on itself)
                out = ("error", repr(exc))
            child_end.send(out)
            child_end.close()

        proc = ctx.Process(target=run, daemon=True)
        proc.start()
        child_end.close()
    second: dict[str, Any] | None = None
    try:
        joins, state = ww.walk(c, stats, 0, None, None, None, on_window, floored, stop=k_split, shapes=shapes)
        if pipe is not None:
            try:
                tag, payload = pipe.recv()
            except EOFError:  # (the process died)
                tag, payload = "error", "the second chain's process ended without a result"
            second = payload if tag == "ok" else None
        else:
            try:
                second = _second_chain(ww, k_b, stats, floored is not None)
            except (InfeasibleError, SolverFailure):
                second = None
    finally:
        if proc is not None and pipe is not None:
            if proc.is_alive() and second is None:
                proc.terminate()
            proc.join()
            pipe.close()
    if state is None:  # pragma: no cover - k_split is a window start inside the piece (_chain_split)
        raise SolverFailure("LP chain split past the piece end", window=stats["windows"])
    if second is not None:
        for k, v in second["stats"].items():
            stats[k] = stats.get(k, [] if isinstance(v, list) else 0) + v
        if ww.cache is not None:
            ww.cache.update(second["cache"])
        try:
            spec, res = ww.window(stats, k_split, k_seam, state.start, state.prev_qstar, state.prev_c,
                                  end_fixed=(k_b, second["c"], second["c_star"]))
        except (InfeasibleError, SolverFailure):
            second = None
    if second is None:  # the first chain walks on
        stats["lp_seam_fallbacks"] = stats.get("lp_seam_fallbacks", 0) + 1
        more, _ = ww.walk(c, stats, state.k0, state.start, state.prev_qstar, state.prev_c, on_window, floored,
                          shapes=shapes)
        return joins + more
    shapes[1] = second["tail"]
    if floored is not None:
        floored += second["floored"] + ([spec.index] if res.floored else [])
    c[k_split:k_seam] = res.c[: k_seam - k_split]
    c[k_seam:] = second["c"][k_seam - k_b :]
    if on_window is not None:
        on_window(float(ww.plan.n_int * ww.plan.d))
    return joins + [k_split, k_seam] + [k for k in second["joins"] if k > k_seam]


def _corner_rest(toolpath: Toolpath, piece: Piece, lim: LimitSet, at_end: bool) -> FloatArray | None:
    """Per-axis rest acceleration at the corner at one end of ``piece`` (None at a path end).

    Across a corner the sampled axis acceleration steps from a_in (the piece before, braking) to
    a_out (the piece after, starting), and the servo error sees the step a_out - a_in (Kj / (2 Ts)
    per unit, ``LimitSet.a_rest``).  Where the axis moves the same way on both sides the two
    accelerations have opposite signs and add up, so each side gets half of a_rest; where it
    reverses (or stands still on one side) they have the same sign and |a_out - a_in| <= max of
    the two, so each side keeps all of it.  Either way |a_out - a_in| <= a_rest per axis.
    """
    pieces = toolpath.pieces
    nb = piece.index + 1 if at_end else piece.index - 1
    if not 0 <= nb < len(pieces):
        return None
    s = np.array([piece.s_end if at_end else piece.s_start])
    same_way = toolpath.evaluate(s, piece).d1[0] * toolpath.evaluate(s, pieces[nb]).d1[0] > 0.0
    return np.asarray(np.where(same_way, 0.5, 1.0) * lim.a_rest, dtype=np.float64)


def _inherited(prev: tuple[int, FloatArray] | None, k0: int) -> FloatArray:
    """The previous window's control points that a window starting at knot k0 reads (its
    inherited intervals), or nothing."""
    if prev is None:
        return np.zeros(0)
    k_prev, arr = prev
    # all of them from k0 on: a window whose stage 2 is infeasible inherits more than INHERITED_INTERVALS
    # (``WindowLP.inherited``), up to the whole overlap
    return np.asarray(arr[k0 - k_prev :], dtype=np.float64)


def _join_knot(geometry: Any, c_win: FloatArray, k0: int, k_last: int, plan: WindowPlan, lim: LimitSet) -> int:
    """Where the next LP window starts when the NLP follows: the knot in
    [k_last - overlap, k_last] where the LP feed is closest to the velocity bound.

    NLP chains end and start at the LP's state at these knots; where the LP is
    velocity-bound the NLP (same axis velocity limits) is too, so the join costs
    little motion time.
    """
    lo = max(k0 + 1, k_last - plan.overlap)
    ks = np.arange(lo, k_last + 1)
    q = 0.5 * (c_win[ks - k0] + c_win[ks - k0 + 1])
    ub = velocity_bound(geometry(ks * plan.d), lim)
    score = np.where(np.isfinite(ub) & (ub > 0), q / np.where(ub > 0, ub, 1.0), 0.0)
    return int(ks[len(ks) - 1 - int(np.argmax(score[::-1]))])


def _breaks(toolpath: Toolpath, piece: Piece) -> FloatArray:
    """Piece-local arc lengths strictly inside the piece where the geometry's third derivative (or a
    programmed feed limit) may jump: knots inside segments and junctions between them."""
    ks = toolpath.knot_s  # sorted and unique: knots inside segments and the junctions between them
    lo, hi = np.searchsorted(ks, piece.s_start, side="right"), np.searchsorted(ks, piece.s_end, side="left")
    return np.asarray(ks[lo:hi] - piece.s_start, dtype=np.float64)


def _nlp_on_coarser_knots(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, refined: tuple[PieceProfile, PieceProfile],
    coarser: list[tuple[PieceProfile, list[int]]], nlp_lim: NlpLimits,
    refiners: dict[tuple[int, int, int | None], NlpRefiner], stats: NlpStats, n_failed: int, lead_in: Motion | None,
    pool: ChainPool | None = None,
) -> tuple[PieceProfile, PieceProfile]:
    """The NLP on coarser knots where it fell back on a piece the LP refined for a floor (``refined``: that LP
    profile and the NLP's): ``coarser`` holds the LP's profiles and joins of the levels it solved on fewer
    knots, finest first, and they are tried in that order until the NLP holds on one without a fallback;
    returns the (LP, NLP) profiles of the fastest of those run, and keeps only its fallbacks in
    ``stats.failures`` (those from ``n_failed`` on).

    Bench seeds 153 and 154 (session 39): the NLP fell back ("unverified") on the refined knots and kept their
    LP feed, 0.286 and 0.399 s, where on the plan's knots it refined a floored LP feed to 0.156 and 0.184 s.
    Bench seeds 428 and 566 (session 40, cap 512): it fell back on 256 intervals, where 128 gives 0.082 and
    0.145 s against the plan knots' 0.188 and 0.218 s.  ``pool``: as ``_refine_piece``'s."""
    best = (PieceTiming.build(refined[1], inverse=False).duration, refined, stats.failures[n_failed:])
    del stats.failures[n_failed:]
    for lp_prof, joins in coarser:
        prof = _refine_piece(toolpath, piece, machine, opt, lp_prof, joins, nlp_lim, refiners, stats, lead_in=lead_in,
                             pool=pool)
        duration = PieceTiming.build(prof, inverse=False).duration
        mine = stats.failures[n_failed:]
        del stats.failures[n_failed:]
        if duration < best[0]:
            best = (duration, (lp_prof, prof), mine)
        if not mine:
            break
    stats.failures[n_failed:] = best[2]
    return best[1]


def _refine_piece(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, lp_prof: PieceProfile, joins: list[int],
    nlp_lim: NlpLimits, refiners: dict[tuple[int, int, int | None], NlpRefiner], stats: NlpStats,
    on_chain: Callable[[float], None] | None = None, verify_s: FloatArray | None = None,
    pipe: ChainPipeline | None = None, lead_in: Motion | None = None, pool: ChainPool | None = None,
    outer: PieceProfile | None = None,
) -> PieceProfile:
    """The NLP stage (spec §5-6) on one piece: its LP feed refined under the drive limits.

    ``refiners`` maps an NLP window plan to its refiner (the keys of the shapes it used; a chain's feed does not
    depend on what the refiner solved before, so the pool's workers solve chains on their own copies);
    ``on_chain(s_done)``, if given, is called after each NLP chain with the piece-local arc length
    (mm) done; ``verify_s``: piece-local s verified besides the fine grid; ``pipe``: the chains
    already handed out while the LP ran (``_chain_pipeline``; used if the LP kept its first knot plan);
    ``lead_in``: the previous piece's motion up to the corner the piece starts at (``_lead_in``); ``pool``: the
    schedule's NLP workers (``_chain_pool``; None: the chains are solved in this process); ``outer``: the piece's
    profile as the round before solved it (a sample repair round's: ``NlpRefiner.outer``)."""
    geometry, breaks = _local(toolpath, piece), _breaks(toolpath, piece)
    if pipe is not None and verify_s is None and pipe.n_int == lp_prof.n_int and pipe.d == lp_prof.d:
        refiner = pipe.refiner
        p, mask, rise = pipe.finish(lp_prof.c, joins, on_chain)
    else:
        if pipe is not None:
            pipe.close()  # (its chains were on other knots)
        shape, refiner = _refiner(piece, machine, opt, lp_prof.n_int, nlp_lim, refiners, stats)
        key: _PoolKey = (piece.index, shape)
        p, mask, rise = refiner.refine(geometry, lp_prof.c, lp_prof.d, joins, breaks, on_chain,
                                       None if pool is None else (pool, key), verify_s,
                                       _standing_ends(toolpath, piece), lead_in, outer)
    # the rest intervals the NLP solved (``solvers.nlp.REST_ENDS``) as q control points; a span reverted to
    # the LP's feed below takes the LP's rest interval next to it back too
    c, mask, g, h = rest_profile(lp_prof.c, p, mask, lp_prof.d, rise)
    n_int = lp_prof.n_int

    def revert(lo: int, hi: int) -> None:
        mask[lo:hi] = False
        if lo == 1:
            c[:3] = lp_prof.c[:3]
            g[0], h[0] = 0.0, ()
        if hi == n_int - 1:
            c[-3:] = lp_prof.c[-3:]
            g[1], h[1] = 0.0, ()

    def refined() -> PieceProfile:
        return replace(lp_prof, c=c, p=p, f_mask=mask, rest_g=(g[0], g[1]), rest_h=(h[0], h[1]))

    # A refined feed that stalls between its verification points (its quadratic dips to ~0 inside a knot
    # interval: bench seeds 1978, 1987) keeps the LP's feed over that NLP span (unless the LP's stalls too):
    # a run of refined intervals starts and ends on the LP's state, so the feed stays continuous
    stalled = stalled_intervals(refined())
    for k in stalled if stalled.size and not stuck(lp_prof) else ():
        if not mask[k]:
            continue
        lo, hi = int(k), int(k) + 1
        while lo > 0 and mask[lo - 1]:
            lo -= 1
        while hi < mask.size and mask[hi]:
            hi += 1
        revert(lo, hi)
        stats.failures.append({
            "nlp_window": -1, "s_range": [lo * lp_prof.d, hi * lp_prof.d],
            "reason": "the refined feed stalls inside a knot interval", "status": "stall",
            "fallback": "lp feed over the span",
        })
    # A refined span slower than the LP's feed over it (SLOWER_SPAN_TOL) keeps the LP's feed too, where that
    # feed is within the NLP's limits over the span (``NlpRefiner.lp_worst``: lp+nlp's LP leaves part of the
    # drive limits to the NLP, which may have to be slower there)
    refiner.verify = np.zeros(0) if verify_s is None else np.asarray(verify_s, dtype=np.float64)
    for lo, hi, t_f, t_lp in _slower_spans(lp_prof, refined(), joins):
        if refiner.lp_worst(geometry, lp_prof.c, lp_prof.d, lo, hi, breaks) > 1.0 + NLP_VERIFY_TOL:
            stats.slower_kept += 1
            continue
        revert(lo, hi)
        stats.failures.append({
            "nlp_window": -1, "s_range": [lo * lp_prof.d, hi * lp_prof.d],
            "reason": f"the refined feed takes {t_f:.6g} s over the span, the lp feed {t_lp:.6g} s",
            "status": "slower than lp", "fallback": "lp feed over the span",
        })
    return refined()


def _same_rise(x: tuple[float, ...], y: tuple[float, ...]) -> bool:
    """Whether two rest ends' rise amplitudes (``PieceProfile.rest_h``) are the same shape: equal, or both
    none or all 0."""
    return x == y or not (any(x) or any(y))


def _same_rest_end(a: PieceProfile, b: PieceProfile, end: int) -> bool:
    """Whether two profiles have the same first (``end`` 0) or last (1) rest interval: its three q control
    points, bump and rise."""
    cp = slice(0, 3) if end == 0 else slice(-3, None)
    return (np.array_equal(a.c[cp], b.c[cp]) and a.rest_g[end] == b.rest_g[end]
            and _same_rise(a.rest_h[end], b.rest_h[end]))


def _slower_spans(lp_prof: PieceProfile, prof: PieceProfile, joins: list[int]) -> list[tuple[int, int, float, float]]:
    """Refined spans (lo, hi, refined time, LP time; knot intervals [lo, hi), s) slower than the LP's feed.

    A span is a run of refined intervals cut at the chains' ends (``solvers.nlp.chain_spans``): each
    refined run starts and ends on the LP's state (``NlpRefiner._spans``: the chain's ends, a bridge's
    join, the knots around a window kept on the LP feed), and so does each chain inside a run, so reverting
    one keeps the feed and its slope continuous (p at its ends reproduces q and q' there).  Times are the
    integrals of d / f and d / sqrt(q) over each interval (``interval_times``: exact for the quadratics).
    ``prof``: the refined profile; a span next to a rest interval the NLP solved (its q differs from the
    LP's) counts that interval too (``rest_interval_times``), as it goes back to the LP's with the span."""
    mask = prof.f_mask
    if mask is None:
        return []
    on = np.flatnonzero(mask)
    if not on.size:
        return []
    cut = np.zeros(mask.size + 1, dtype=bool)
    cut[[A for A, _ in chain_spans(lp_prof.n_int, joins)]] = True
    first = np.flatnonzero(cut[on] | np.concatenate([[True], np.diff(on) > 1]))
    t_f = np.add.reduceat(interval_times(prof, on), first)
    t_lp = np.add.reduceat(interval_times(lp_prof, on), first)
    last = np.append(first[1:], on.size) - 1
    rest_f, rest_lp = rest_interval_times(prof), rest_interval_times(lp_prof)
    for j, k, same in ((0, 1, _same_rest_end(prof, lp_prof, 0)),
                       (-1, lp_prof.n_int - 2, _same_rest_end(prof, lp_prof, 1))):
        at = first if j == 0 else last
        hit = np.flatnonzero(on[at] == k)
        if not same and hit.size:
            t_f[hit] += rest_f[j]
            t_lp[hit] += rest_lp[j]
    slow = np.flatnonzero(~(t_f <= (1.0 + SLOWER_SPAN_TOL) * t_lp))
    return [(int(on[first[j]]), int(on[last[j]]) + 1, float(t_f[j]), float(t_lp[j])) for j in slow]


def _refiner(
    piece: Piece, machine: Machine, opt: Options, n_int: int | None, nlp_lim: NlpLimits,
    refiners: dict[tuple[int, int, int | None], NlpRefiner], stats: NlpStats,
) -> tuple[tuple[int, int, int | None], NlpRefiner]:
    """The piece's NLP window plan on n_int knot intervals (nlp_window, nlp_overlap, nlp_long_window) and its
    refiner (from ``refiners``, or new)."""
    plan = plan_piece(piece, machine, opt, n_int)
    shape = (plan.nlp_window, plan.nlp_overlap, plan.nlp_long_window)
    return shape, _shape_refiner(shape, opt, nlp_lim, refiners, stats)


def _shape_refiner(
    key: tuple[int, int, int | None], opt: Options, nlp_lim: NlpLimits,
    refiners: dict[tuple[int, int, int | None], NlpRefiner], stats: NlpStats,
) -> NlpRefiner:
    """The refiner of NLP window plan ``key`` (nlp_window, nlp_overlap, nlp_long_window) from ``refiners``, or new."""
    if key not in refiners:
        refiners[key] = NlpRefiner(nlp_lim, opt.nlp_checkpoints_per_interval, key[0], key[1],
                                   fault=opt.nlp_fault, stats=stats, long_window=key[2])
    return refiners[key]


#: A piece's key in the schedule's ``ChainPool``: (piece index, its refiner's ``refiners`` key).
_PoolKey = tuple[int, tuple[int, int, int | None]]


def _chain_pool(
    toolpath: Toolpath, opt: Options, nlp_lim: NlpLimits, refiners: dict[tuple[int, int, int | None], NlpRefiner],
    stats: NlpStats,
) -> ChainPool:
    """The schedule's NLP workers (``_workers(opt)`` of them), reading a piece's refiner and geometry from its
    ``_PoolKey`` (in a worker: its forked copy of ``refiners``, new refiners added there)."""

    def context(key: _PoolKey) -> tuple[NlpRefiner, GeometryFn]:
        index, shape = key
        return _shape_refiner(shape, opt, nlp_lim, refiners, stats), _local(toolpath, toolpath.pieces[index])

    return ChainPool(_workers(opt), context)


def _chain_pipeline(
    toolpath: Toolpath, piece: Piece, machine: Machine, opt: Options, nlp_lim: NlpLimits,
    refiners: dict[tuple[int, int, int | None], NlpRefiner], stats: NlpStats, n_int: int | None,
    pool: ChainPool, lead_in: Motion | None = None,
) -> ChainPipeline:
    """NLP chains solved by the schedule's workers (``pool``) as the LP's windows make them final, on the
    piece's first knot plan, ``n_int`` intervals (None: its plan's; ``_refine_piece`` falls back to solving
    after the LP if the LP ends on other knots)."""
    plan = plan_piece(piece, machine, opt, n_int, toolpath)
    shape, refiner = _refiner(piece, machine, opt, plan.n_int, nlp_lim, refiners, stats)
    key: _PoolKey = (piece.index, shape)
    return ChainPipeline(refiner, _local(toolpath, piece), plan.d, plan.n_int, _breaks(toolpath, piece), pool, key,
                         _standing_ends(toolpath, piece), lead_in)


def _lead_in(toolpath: Toolpath, piece: Piece, prof: PieceProfile, timing: PieceTiming, Ts: float) -> Motion:
    """The axis motion of ``piece`` (final: ``prof``, ``timing``) over its last CONTEXT_SAMPLES sample periods,
    on the NLP's context grid, t < 0 from its end: what the next piece's NLP sees before the corner between them
    (``solvers.nlp._standing``).  A piece shorter than that reads as standing before its start."""
    n = math.ceil(NLP_CONTEXT_SAMPLES / NLP_CONTEXT_STEP)
    t = -(NLP_CONTEXT_STEP * Ts) * np.arange(n, 0, -1, dtype=np.float64)
    s_local = np.clip(timing.s_at(np.clip(timing.duration + t, 0.0, timing.duration)), 0.0, piece.length)
    _, _, v, a, _ = _kinematics(toolpath, piece, prof, s_local)
    before = timing.duration + t < 0.0
    v[before] = 0.0
    a[before] = 0.0
    return t, v, a


def _may_fork_pool() -> bool:
    """Whether this process may start a pool: not a daemonic one (multiprocessing forbids it children)."""
    return not multiprocessing.current_process().daemon


def _workers(opt: Options) -> int:
    """The NLP workers to start: opt.nlp_workers, 1 in a daemonic process (which may not start a pool)."""
    return opt.nlp_workers if _may_fork_pool() else 1


def _standing_ends(toolpath: Toolpath, piece: Piece) -> tuple[bool, bool]:
    """Whether the machine stands before / after the piece (the path's start / end), rather than passing a
    corner from (to) another piece: where the NLP may give a rest interval its bump (``NlpRefiner.bump``)."""
    return piece.index == 0, piece.index == len(toolpath.pieces) - 1


def first_sample_at(t: float, Ts: float) -> int:
    """The first k >= 0 with k Ts >= t (k Ts as float64 products, like ``np.arange(K) * Ts``)."""
    k = max(0, math.ceil(t / Ts))
    while k > 0 and (k - 1) * Ts >= t:
        k -= 1
    while k * Ts < t:
        k += 1
    return k


#: Samples from which ``_sample_piece`` gives the second half of a piece's samples to a forked process
#: (``Options.nlp_workers`` > 1): the values are elementwise in t (the same bit for bit however they are
#: split), and below this the fork (~5-15 ms) costs about what it saves.
SAMPLE_SPLIT_MIN = 20_000


def _sample_piece(
    toolpath: Toolpath, piece: Piece, prof: PieceProfile, tm: PieceTiming, t0: float, k_lo: int, k_hi: int,
    Ts: float, workers: int = 1, precise: bool = False, held: TimeSamples | None = None,
) -> TimeSamples:
    """Time reconstruction (spec §7) of one piece at t_k = k Ts, k_lo <= k < k_hi, the piece starting at t0 (s).

    The global grid continues across pieces: t_k is k Ts, never re-based per piece.  Without u and e
    (elementwise in v, a, j: added where the samples are released).  With ``workers`` > 1 and at least
    SAMPLE_SPLIT_MIN samples, a forked process computes the second half (if it fails, this one does).
    ``held``: samples computed before these and not yet released (``_Carry.held``), placed first in the same
    columns: ``concat_samples([held, own])`` without u and e, but without a copy of the piece's own samples,
    which held its columns twice while it was made (timed, the CPU saved was within the machine's noise)."""
    t_own = np.arange(k_lo, k_hi, dtype=np.float64) * Ts
    H = 0 if held is None else held.t.size
    K = H + t_own.size
    widths = (1, 1, 3, 3, 3, 3)  # s, feed, position, velocity, acceleration, jerk
    split = workers > 1 and t_own.size >= SAMPLE_SPLIT_MIN and _may_fork_pool()
    if split:  # in one shared anonymous mapping, which the forked process fills too (nothing copied back)
        buf = mmap.mmap(-1, 8 * K * sum(widths))
        offs = np.cumsum([0, *widths]) * 8 * K
        cols = tuple(np.frombuffer(buf, dtype=np.float64, count=K * w, offset=int(o)).reshape((K, w) if w > 1 else K)
                     for w, o in zip(widths, offs, strict=False))
    else:
        # filled chunk by chunk (no list of chunks joined at the end: that held the piece's columns twice)
        cols = tuple(np.empty((K, w) if w > 1 else K) for w in widths)
    t = t_own
    if held is not None:
        t = np.concatenate([held.t, t_own])
        for col, h in zip(cols, (held.s, held.feed, held.position, held.velocity, held.acceleration, held.jerk),
                          strict=True):
            col[:H] = h
    own = tuple(c[H:] for c in cols)  # (this piece's rows)
    mid = t_own.size // 2 if split else t_own.size
    proc = None
    if split:
        proc = multiprocessing.get_context("fork").Process(
            target=_fill_samples,
            args=(toolpath, piece, prof, tm, t0, t_own[mid:], tuple(c[mid:] for c in own), precise),
            daemon=True,
        )
        proc.start()
    try:
        _fill_samples(toolpath, piece, prof, tm, t0, t_own[:mid], tuple(c[:mid] for c in own), precise)
    except BaseException:
        if proc is not None:
            proc.terminate()
            proc.join()
        raise
    if proc is not None:
        proc.join()
        if proc.exitcode != 0:  # (the process failed: this one samples its half)
            _fill_samples(toolpath, piece, prof, tm, t0, t_own[mid:], tuple(c[mid:] for c in own), precise)
    s_out, feed, pos, vel, acc, jerk = cols
    return TimeSamples(t=t, s=s_out, feed=feed, position=pos, velocity=vel, acceleration=acc, jerk=jerk)


def _fill_samples(
    toolpath: Toolpath, piece: Piece, prof: PieceProfile, tm: PieceTiming, t0: float, t: FloatArray,
    cols: tuple[FloatArray, ...], precise: bool = False,
) -> None:
    """``_sample_piece``'s columns (s, feed, position, velocity, acceleration, jerk) at global times t, into
    cols, SAMPLE_CHUNK samples at a time (``precise``: ``Toolpath.evaluate``'s)."""
    s_out, feed, pos, vel, acc, jerk = cols
    for a in range(0, t.size, SAMPLE_CHUNK):
        b = min(t.size, a + SAMPLE_CHUNK)
        s_local = np.clip(tm.s_at(t[a:b] - t0), 0.0, piece.length)
        g, f, v, ac, jk = _kinematics(toolpath, piece, prof, s_local, precise)
        s_out[a:b] = s_local + piece.s_start
        feed[a:b] = f
        pos[a:b] = g.position
        vel[a:b] = v
        acc[a:b] = ac
        jerk[a:b] = jk


def _promised(lim: LimitSet, opt: Options, machine: Machine) -> verify.Limits:
    """The limits the schedule holds (what ``diagnostics.binding`` reports): lp -> v, a, j (j with
    the jerk stage); lp+nlp -> u, e, the drive's vmax (and the LP's v, a, j where the NLP keeps them)."""
    if opt.method == "lp" or not machine.has_drives:
        return verify.Limits(lim.vmax, lim.amax, lim.jmax if opt.jerk else None, None, None)
    dr = machine.drive_arrays()
    vmax: FloatArray | None = dr["vmax"] if np.isfinite(dr["vmax"]).any() else None
    if opt.nlp_axis_velocity or opt.nlp_kinematic:
        vmax = np.minimum(lim.vmax, dr["vmax"])
    kin = opt.nlp_kinematic
    return verify.Limits(vmax, lim.amax if kin else None, lim.jmax if kin else None, dr, None)


def _feed_cap(lim: LimitSet, toolpath: Toolpath, s: FloatArray) -> FloatArray | None:
    """Tangential feed cap (mm/s) at global s: Fmax and the programmed feed limits; None if neither."""
    cap = toolpath.feed_limit(s)
    if lim.feed_max is not None:
        cap = np.full(s.size, lim.feed_max) if cap is None else np.minimum(cap, lim.feed_max)
    return cap


#: ``motion_time_floor`` is this share of the path's time at its feed caps: the schedule's feed may pass a
#: cap by a hair between its checkpoints (the sampled feed reads up to 1.002 x an F word in the random cases).
MOTION_FLOOR_SHARE = 0.99
#: ``motion_time_floor``'s acceleration bound reads each axis's amax times this (the samples hold it within 1.01 x).
ACCEL_FLOOR_SLACK = 1.1


def _motion_time_floor(toolpath: Toolpath, lim: LimitSet, vmax: FloatArray | None,
                       amax: FloatArray | None = None) -> float:
    r"""A lower bound of the motion time (s), known before any solve: MOTION_FLOOR_SHARE of the path's time
    with every sub-segment at its feed cap, or with its slowest axis at its speed bound if that takes longer,
    or of the path's rest-to-rest time at its acceleration bounds if that is longer still,

        T >= share * max(sum_k max(L_k / min(F_k, Fmax, ||vmax||_2), max_i |dx_ki| / vmax_i),
                         2 sqrt(L / ||A||_2), max_i 2 sqrt(|D_i| / A_i)),

    with L_k (mm) the k-th sub-segment's length, F_k its programmed feed limit (mm/s, inf where none), Fmax
    the machine's tangential feed limit, vmax (3,) the speed bound of each axis (a feed f along a unit
    tangent moves the axes at f x_s, so f^2 = sum v_i^2 <= ||vmax||^2; left out unless every axis has a
    finite one) and dx_k (3,) the sub-segment's end minus its start (axis i travels at least |dx_ki| there, at
    most at vmax_i: an axis at 1e-8 mm/s took the feed-cap bound alone to 0.08 s for 1e9 s of motion, and the
    time table of that motion did not finish, session 58).  The acceleration term, where the schedule promises
    axis accelerations ``amax`` (3,), mm/s^2 (method lp): A = ACCEL_FLOOR_SLACK x amax (the samples hold amax
    within 1.01 x); the path's acceleration sddot = x_s . a (x_s . x_ss = 0 at unit speed) is at most ||A||, and
    the path (length L, mm) starts and ends at rest, so T >= 2 sqrt(L / ||A||); axis i moves |D_i| (mm, end
    minus start) from rest to rest at |a_i| <= A_i, so T >= 2 sqrt(|D_i| / A_i) (amax 1e-12 on a 5 mm line:
    3.4e6 s of motion read "cannot leave rest" after a solve, session 59's probe).  Corners, jerk and curvature
    only add to the time; 0 when nothing caps the feed or the acceleration."""
    off = toolpath.offsets
    length = np.diff(off)
    cap = _feed_cap(lim, toolpath, 0.5 * (off[:-1] + off[1:]))
    bound = np.inf
    if vmax is not None and bool(np.all(np.isfinite(vmax))):
        bound = float(np.linalg.norm(vmax))
    caps = np.minimum(np.inf if cap is None else cap, bound)
    t = length / caps
    if vmax is not None:
        dx = np.abs(np.diff(toolpath.positions(off), axis=0))
        t = np.maximum(t, np.max(dx / vmax[None, :], axis=1))
    floor = float(np.sum(t))
    if amax is not None:
        a = ACCEL_FLOOR_SLACK * np.asarray(amax, dtype=np.float64)
        travel = np.abs(np.diff(toolpath.positions(off[[0, -1]]), axis=0)[0])
        floor = max(floor, 2.0 * math.sqrt(float(off[-1] - off[0]) / float(np.linalg.norm(a))),
                    float(np.max(2.0 * np.sqrt(travel / a))))
    return MOTION_FLOOR_SHARE * floor


def motion_time_floor(toolpath: Toolpath, machine: Machine, options: Options | None = None) -> float:
    """A lower bound (s) of the motion time ``schedule(toolpath, machine, options)`` returns, from the feed
    caps and the promised accelerations (``_motion_time_floor``): lp's axis vmax and amax; lp+nlp's speed under
    the control signal (``machine.drive_speed_bound``) and the axis vmax it promises.  ``schedule`` refuses up front
    what this takes over ``Options.max_samples``, and so does the service's budget."""
    opt = options or Options()
    lim = _limit_set(machine, opt)
    return _promised_floor(toolpath, lim, _promised(lim, opt, machine), opt, machine)


def _promised_floor(toolpath: Toolpath, lim: LimitSet, promised: verify.Limits, opt: Options,
                    machine: Machine) -> float:
    """``_motion_time_floor`` under the limits the schedule promises (``_promised``): its speed bound and amax."""
    return _motion_time_floor(toolpath, lim, _speed_bound(promised.vmax, opt, machine), promised.amax)


def _limit_set(machine: Machine, opt: Options) -> LimitSet:
    """The LP's limits of ``machine`` under ``opt`` (lp+nlp: rest and step limits from the drive model, and no cap on
    q* next to rest ends, ``LimitSet.rest_reach``)."""
    lim = LimitSet.from_machine(
        machine, opt.sample_period, opt.jerk, rest_from_drive=opt.method == "lp+nlp" and machine.has_drives,
        kinematic=opt.nlp_kinematic,
    )
    return lim if opt.method == "lp" else replace(lim, rest_reach=False)


def _in_rest_intervals(s_loc: FloatArray, prof: PieceProfile) -> bool:
    """Whether any of the piece-local s lies in the piece's first or last knot interval (its rest intervals)."""
    return bool(np.any((s_loc < prof.d) | (s_loc > prof.length - prof.d)))


#: With ``Options.nlp_kinematic`` the repair rounds that hold a piece's steps at REPAIR_STEP_SHARE of the budget do
#: so in its NLP too (the LP's alone otherwise): bench seed 14 read 1.0117, 1.0127, then 1.0525 and 1.0521 x jmax
#: at s = 0.52 mm in its rounds 0-3, a refusal; with it it passes (session 67).  Default options: unchanged.
REPAIR_NLP_STEP = True


def _overlap_hint(exc: InfeasibleError, piece: Piece, machine: Machine, opt: Options) -> InfeasibleError:
    """``exc`` (an LP window of ``piece`` found infeasible), naming ``options.lp_overlap`` where it was given under the
    overlap the piece's stopping distance sizes (``plan_piece``'s default): a window joined to the next that close
    may have to stop where it cannot (cam seed 109 with lp_overlap 3 where 24 is the default: window 256 infeasible,
    feasible with the default).  Otherwise ``exc`` itself."""
    if opt.lp_overlap is None:
        return exc
    default = plan_piece(piece, machine, replace(opt, lp_overlap=None)).overlap
    given = plan_piece(piece, machine, opt).overlap
    if given >= default:
        return exc
    return InfeasibleError(
        f"an LP window of piece {piece.index} is infeasible with windows overlapping by {given} knot intervals, under "
        f"the {default} that the machine's stopping distance needs there (the default overlap)",
        field="options.lp_overlap", value=opt.lp_overlap, window=exc.window, status=exc.status,
    )


def _repair_limits(lim: LimitSet, rounds: int, at_rest: bool = False) -> LimitSet:
    """The LP's limits in a piece's repair round ``rounds`` (1, 2, ..) for its samples (``SAMPLE_REPAIR_ROUNDS``);
    ``at_rest``: samples over a limit lie in a rest interval of the piece.

    The cap on q* next to rest ends (``lp.QSTAR_REST_REACH``, ``LimitSet.rest_reach``) lets the jerk rows read the
    jerk leaving rest as it is, and on top of the acceleration step there the samples' third differences can
    exceed jmax (bench seed 125, lp: 1.025 x at its start).  The first round keeps the cap but leaves the step its
    room within 3 Ts of travel of the path ends too (``LimitSet.rest_reach_ends``; corners have it always), the
    last goes without the cap.  Without the cap in every round (session 48) the repaired pieces were longer: lp
    bench seeds 0-149 against it, 8 shorter (seeds 55 0.975x, 51 0.987x, 5 0.988x), none longer.
    The round past them (for samples still over the promise, ``_schedule_stream``) also goes without the rest shapes
    where ``at_rest`` (``LimitSet.rest_shapes``; method lp, whose LP has them): a rest interval whose cut rounds
    could not hold the rises' bends is then a quadratic."""
    if REPAIR_REACH_ENDS and rounds < SAMPLE_REPAIR_ROUNDS:
        return replace(lim, rest_reach_ends=True)
    shapes = not (REPAIR_REST_SHAPES_OFF and at_rest and rounds > SAMPLE_REPAIR_ROUNDS)
    return replace(lim, rest_reach=False, rest_shapes=shapes)


def _speed_bound(vmax: FloatArray | None, opt: Options, machine: Machine) -> FloatArray | None:
    """Per-axis speed no schedule of ``opt.method`` passes (3,), from the promised axis ``vmax``
    (``_promised``): lp, that vmax; lp+nlp, it (if any) and the control signal's bound."""
    if opt.method == "lp" or not machine.has_drives:
        return vmax
    u_bound = drive_speed_bound(machine.drive_arrays())
    return u_bound if vmax is None else np.minimum(vmax, u_bound)


def _kinematics(
    toolpath: Toolpath, piece: Piece, prof: PieceProfile, s_local: FloatArray, precise: bool = False
) -> tuple[PathSamples, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Geometry and v, a, j (K, 3) and feed (K,) at piece-local s (``precise``: ``Toolpath.evaluate``'s)."""
    g = toolpath.evaluate(s_local + piece.s_start, piece, precise=precise)
    fd = prof.feed(s_local)
    return (g, fd[0], *kinematics.axis_kinematics(g, *fd))


def schedule(
    toolpath: Toolpath, machine: Machine, options: Options | None = None,
    progress: Callable[[float], None] | None = None,
) -> Schedule:
    """Fastest feed along ``toolpath`` within ``machine``'s limits, sampled at Ts.

    ``progress(fraction)``, if given, is called after each LP window and NLP chain with the fraction of the
    path length done.  All of ``schedule_stream`` at once.
    """
    parts: list[TimeSamples] = []
    end: ScheduleEnd | None = None
    for item in schedule_stream(toolpath, machine, options, progress, block_samples=None):
        if isinstance(item, SampleBlock):
            parts.append(item.samples)
        else:
            end = item
    assert end is not None
    return Schedule(samples=concat_samples(parts, consume=True), summary=end.summary, diagnostics=end.diagnostics,
                    profiles=end.profiles)


#: Samples at the end of a piece that ``schedule_stream`` holds back until the next piece is sampled: the
#: differences at the last REST_PAD samples read the next piece's first samples, and the sample before
#: them is sent back for repair when one of them is over a limit (``verify.spread``).
HELD_SAMPLES = verify.REST_PAD + 1


@dataclass(frozen=True)
class _Recheck:
    """The re-check of the samples not yet released (``seq``), as far as it is decided.

    ``rows``: utilisations of seq[0 : n_rows] (the samples whose differences are known); ``repair``:
    (n_released,) flags of seq[0 : n_released] after the neighbour spread (final: both neighbours known)."""

    rows: verify.RowCheck
    repair: NDArray[np.bool_]
    #: (n - n_released,) the samples not released yet whose emitted values alone are over a limit: the
    #: current piece can still be repaired for them (their differences are checked with the next piece)
    held_over: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def n_released(self) -> int:
        return int(self.repair.size)


def _recheck(
    seq: TimeSamples, before: FloatArray | None, left_over: bool, last: bool, limits: verify.Limits,
    lim: LimitSet, toolpath: Toolpath, Ts: float,
) -> _Recheck:
    """Re-check the samples ``seq`` (every one not yet released, in time order) with their true neighbours.

    ``before``: (REST_PAD, 3) positions of the samples released just before seq (None at the path start:
    rest at seq's first position, as the one-shot check pads); ``left_over``: whether the sample just
    before seq was over a limit.  Unless ``last`` (seq ends the path: rest after it), the last REST_PAD
    samples of seq only serve as the neighbours of the others, and the one before them is not released
    either (its repair flag depends on the next sample's check)."""
    n = seq.t.size
    n_rows = n if last else max(0, n - verify.REST_PAD)
    part = _rows(seq, 0, n_rows)
    if n_rows == 0:  # (a piece shorter than a few samples: everything waits for the next one)
        empty = verify.check_rows(Ts, np.zeros((2 * verify.REST_PAD, 3)), part.feed, part.velocity,
                                  part.acceleration, part.jerk, limits)
        return _Recheck(empty, np.zeros(0, dtype=bool))
    pre = before if before is not None else np.repeat(seq.position[:1], verify.REST_PAD, axis=0)
    if last:
        padded = np.concatenate([pre, seq.position, np.repeat(seq.position[-1:], verify.REST_PAD, axis=0)])
    else:
        padded = np.concatenate([pre, seq.position])
    rows = verify.check_rows(Ts, padded, part.feed, part.velocity, part.acceleration, part.jerk,
                             replace(limits, feed_cap=_feed_cap(lim, toolpath, part.s)))
    flags = verify.spread(rows.over, left=left_over)
    n_rel = n_rows if last else max(0, n_rows - 1)
    held = _rows(seq, n_rel, n)
    held_over = verify.analytic_over(held.feed, held.velocity, held.acceleration, held.jerk,
                                     replace(limits, feed_cap=_feed_cap(lim, toolpath, held.s)))
    return _Recheck(rows, flags[:n_rel], held_over)


def _repair_points(seq: TimeSamples, repair: NDArray[np.bool_], last: bool) -> FloatArray:
    """Global s to verify next to the flagged samples: each flagged sample and REPAIR_SUBDIV points in the
    gap after it (a peak between two samples is what a difference over neighbouring samples sees); the
    path's last sample has no gap after it."""
    k_bad = np.flatnonzero(repair[:-1] if last else repair)
    gap = seq.s[np.minimum(k_bad + 1, seq.s.size - 1)] - seq.s[k_bad]  # (none after seq's last sample)
    return np.asarray((seq.s[k_bad, None] + gap[:, None] * (np.arange(REPAIR_SUBDIV) / REPAIR_SUBDIV)).ravel(),
                      dtype=np.float64)


@dataclass(frozen=True)
class _Carry:
    """What the re-check of the next samples needs from the ones before them (``_recheck``): the samples
    computed and not yet released (``held``, copies: a view would keep its whole block alive), the
    positions of the last REST_PAD released samples (``before``, None at the path start) and whether the
    last released sample was over a limit (``left_over``)."""

    held: TimeSamples | None = None
    before: FloatArray | None = None
    left_over: bool = False

    def after(self, seq: TimeSamples, chk: _Recheck) -> _Carry:
        """The carry once seq[0 : chk.n_released] is released."""
        n_rel = chk.n_released
        h = _rows(seq, n_rel, seq.t.size)
        held = TimeSamples(
            h.t.copy(), h.s.copy(), h.feed.copy(), h.position.copy(), h.velocity.copy(), h.acceleration.copy(),
            h.jerk.copy(), None if h.control_signal is None else h.control_signal.copy(),
            None if h.servo_error is None else h.servo_error.copy(),
        )
        if not n_rel:
            return _Carry(held, self.before, self.left_over)
        pre = self.before if self.before is not None else np.repeat(seq.position[:1], verify.REST_PAD, axis=0)
        before = np.concatenate([pre, seq.position[:n_rel]])[-verify.REST_PAD:]
        return _Carry(held, before, bool(chk.rows.over[n_rel - 1]))


def precise_points(toolpath: Toolpath, limits: verify.Limits, Ts: float) -> bool:
    """Whether the samples' positions need ``Toolpath.evaluate``'s ``precise`` points: when the plain points' noise,
    POINT_NOISE_ULPS units in the last place of the path's ``coordinate_scale``, can reach PRECISE_POINTS_SHARE of a
    promised limit in the differences of ``solvers.verify`` (never on the router: ~1e-8 of its amax; bench
    seed 5029, amax_x = 9.7e-6 mm/s^2: 6 x).  Precise points cost about twice the geometry of a sample (flower:
    +13 % of the schedule's compute)."""
    return verify.noise_share(limits, Ts, point_noise(toolpath, precise=False)) > PRECISE_POINTS_SHARE


def point_noise(toolpath: Toolpath, precise: bool) -> float:
    """The most a sample's position (mm) is off by rounding: ``precise`` points PRECISE_POINT_ULPS units in the last
    place of the path's ``coordinate_scale`` plus the arc length's unit (|C_s| = 1), plain ones POINT_NOISE_ULPS."""
    unit = float(np.spacing(toolpath.coordinate_scale))
    if precise:
        return PRECISE_POINT_ULPS * unit + float(np.spacing(toolpath.length))
    return POINT_NOISE_ULPS * unit


#: The machine's field of each limit ``verify.noise_shares`` reads (``{}``: the axis name) and its unit.
_NOISE_FIELDS = {
    "velocity": ("machine.axes.{}.vmax", "mm/s"), "acceleration": ("machine.axes.{}.amax", "mm/s^2"),
    "jerk": ("machine.axes.{}.jmax", "mm/s^3"), "control_signal": ("machine.axes.{}.drive.umax", "V"),
    "servo_error": ("machine.axes.{}.drive.emax", "mm"),
}


def _noise_room(toolpath: Toolpath, lim: LimitSet, promised: verify.Limits, opt: Options,
                precise: bool) -> LimitSet:
    r"""The LP's limits with room for the rounding of the samples' positions.

    A position off by up to n mm (``point_noise``) moves the sampled differences by up to
    :math:`\sigma_v = 2n/T_s`, :math:`\sigma_a = 4n/T_s^2`, :math:`\sigma_j = 8n/T_s^3` (``verify.noise_shares``,
    per axis as a share r of the promised limit).  Method lp's LP holds vmax f_v, amax f_a, jmax f_j,
    f = max(1 - r, NOISE_ROOM_FLOOR) where r > NOISE_MARGIN_SHARE (else 1), and the limits made from them in
    proportion (a_rest, a_step, v_step).  A limit on an axis the path moves under what one unit in the last place of
    its coordinates reads (NOISE_FLOOR_UNITS) refuses the schedule (``ResolutionError`` naming it).  lp+nlp gets the
    refusal here and its room from ``_drive_room``.  The promise, the sampled checks and
    ``motion_time_floor`` keep the machine's limits; ``diagnostics.binding`` reads the LP's (where its rows bind)."""
    Ts = opt.sample_period
    noise = point_noise(toolpath, precise)
    if verify.noise_share(promised, Ts, noise) <= NOISE_MARGIN_SHARE:
        return lim  # (the router: r ~1e-8)
    per_mm = verify.noise_shares(promised, Ts, 1.0)  # (linear in the noise: the shares of 1 mm)
    lo, hi = toolpath.axis_range
    unit = np.where((lo <= 0.0) & (hi >= 0.0), 0.0, np.spacing(np.minimum(np.abs(lo), np.abs(hi))))
    given = {kind: arr for kind, arr in (("velocity", promised.vmax), ("acceleration", promised.amax),
                                         ("jerk", promised.jmax)) if arr is not None}
    if promised.drive is not None:
        given.update(control_signal=promised.drive["umax"], servo_error=promised.drive["emax"])
    for kind, share in per_mm.items():
        floor = share * unit / NOISE_FLOOR_UNITS
        over = np.flatnonzero((floor >= 1.0) & (hi > lo))
        if over.size:
            k = int(over[np.argmax(floor[over])])
            fld, what = _NOISE_FIELDS[kind]
            limit = float(given[kind][k])
            near = float(min(abs(lo[k]), abs(hi[k])))
            raise ResolutionError(
                f"{limit:.6g} {what} is too small for float64 positions sampled every {Ts:g} s to show held: one unit "
                f"in the last place of the axis's coordinates ({float(unit[k]):.3g} mm at {near:.6g} mm and beyond) "
                f"alone reads {float(floor[k]):.4g} x it in the sampled {kind.replace('_', ' ')}; raise the limit or "
                "options.sample_period",
                field=fld.format(AXES[k]), value=limit, axis=AXES[k],
            )
    if opt.method != "lp":
        return lim
    shares = verify.noise_shares(promised, Ts, noise)
    fv, fa, fj = (_room_factors(shares, kind) for kind in ("velocity", "acceleration", "jerk"))
    faj = np.minimum(fa, fj)
    return replace(lim, vmax=lim.vmax * fv, amax=lim.amax * fa, jmax=lim.jmax * fj, a_rest=lim.a_rest * faj,
                   a_step=None if lim.a_step is None else lim.a_step * fj,
                   v_step=None if lim.v_step is None else lim.v_step * faj)


def _room_factors(shares: dict[str, FloatArray], kind: str) -> FloatArray:
    """Per axis (3,), the share of a limit its LP or NLP holds for ``noise_shares`` r of the kind:
    max(1 - r, NOISE_ROOM_FLOOR) where r > NOISE_MARGIN_SHARE, else 1 (and 1 for a kind not promised)."""
    r = shares.get(kind)
    if r is None:
        return np.ones(3)
    return np.asarray(np.where(r > NOISE_MARGIN_SHARE, np.maximum(1.0 - r, NOISE_ROOM_FLOOR), 1.0), dtype=np.float64)


def _drive_room(toolpath: Toolpath, machine: Machine, promised: verify.Limits, opt: Options,
                precise: bool) -> Machine:
    r"""lp+nlp: the machine its NLP and LP hold, with room for the rounding of the samples' positions (method lp's
    is ``_noise_room``); ``machine`` itself where every share is under NOISE_MARGIN_SHARE (the router).

    Position noise of n mm (``point_noise``) reads up to r = (|M| 4n/T_s^2 + |b| 2n/T_s) / u_max in the sampled
    control signal and r = (K_v 2n/T_s + K_a 4n/T_s^2 + K_j 8n/T_s^3) / e_max in the servo error
    (``verify.noise_shares``).  Each drive holds

    .. math:: e'_{max} = e_{max} f_e, \qquad u'_{max} = |c| + |d| + (u_{max} - |c| - |d|) f_u,

    f = max(1 - r, NOISE_ROOM_FLOOR), with u's r taken over its dynamic part u_max - |c| - |d| (the bias and the
    friction are no differences: all of the noise comes off what the motion may use); the drive's and, where they
    are promised, the axes' vmax (and amax, jmax with ``Options.nlp_kinematic``) f_v, f_a, f_j as in
    ``_noise_room``.  Everything the solvers make from the machine follows: the NLP's limits
    (``NlpLimits.from_machine``), its velocity steps (``v_step_limit``) and the LP's limits at rest and at steps
    (``LimitSet.from_machine`` with ``rest_from_drive``).  The promise, the output's u and e, the knot plans and
    ``motion_time_floor`` keep ``machine``.  Arguments as ``_noise_room``'s, after its refusal."""
    if opt.method != "lp+nlp" or not machine.has_drives:
        return machine
    Ts = opt.sample_period
    noise = point_noise(toolpath, precise)
    if verify.noise_share(promised, Ts, noise) <= NOISE_MARGIN_SHARE:
        return machine
    shares = verify.noise_shares(promised, Ts, noise)
    dr = machine.drive_arrays()
    fixed = np.abs(dr["c"]) + np.abs(dr["d"])
    dyn = dr["umax"] - fixed
    if "control_signal" in shares:  # (over the dynamic part; none where friction takes all of umax)
        shares["control_signal"] = np.where(dyn > 0.0, shares["control_signal"] * dr["umax"] / np.where(
            dyn > 0.0, dyn, 1.0), 0.0)
    fv, fa, fj, fu, fe = (_room_factors(shares, kind) for kind in (
        "velocity", "acceleration", "jerk", "control_signal", "servo_error"))
    axis_v = opt.nlp_axis_velocity or opt.nlp_kinematic  # (the axes' vmax promised, ``_promised``)
    axes = []
    for k, ax in enumerate(machine.axes):
        drive = ax.drive
        assert drive is not None  # (``has_drives``)
        drive = replace(drive, umax=float(fixed[k] + dyn[k] * fu[k]) if fu[k] < 1.0 else drive.umax,
                        emax=drive.emax * float(fe[k]), vmax=None if drive.vmax is None else drive.vmax * float(fv[k]))
        limits = replace(ax.limits, vmax=ax.limits.vmax * float(fv[k] if axis_v else 1.0),
                         amax=ax.limits.amax * float(fa[k]), jmax=ax.limits.jmax * float(fj[k]))
        axes.append(replace(ax, limits=limits, drive=drive))
    return replace(machine, axes=(axes[0], axes[1], axes[2]))


def _piece_blocks(
    toolpath: Toolpath, piece: Piece, prof: PieceProfile, timing: PieceTiming, t0: float, k_lo: int, k_hi: int,
    block: int, carry: _Carry, last: bool, limits: verify.Limits, lim: LimitSet, Ts: float, workers: int = 1,
    precise: bool = False,
) -> Iterator[tuple[TimeSamples, _Recheck, _Carry, bool]]:
    """The piece's own samples k_lo <= k < k_hi in blocks of ``block`` (a multiple of SAMPLE_CHUNK, so the
    chunks of ``_sample_piece`` and hence every value are those of the piece sampled at once), each
    re-checked after the samples held before it: yields (seq, its re-check, the carry after releasing
    its decided samples, whether it is the piece's final block).

    A block boundary is checked as a piece boundary is: the block's last HELD_SAMPLES wait for the next
    block's, and the flags and repair points of the released samples are those of one re-check of the
    whole piece.  The held samples' analytic flags (``_Recheck.held_over``) count only at the piece's final
    block; inside the piece those samples are re-checked in full with the next block."""
    starts = list(range(k_lo, k_hi, block)) or [k_lo]
    for a in starts:
        b = min(k_hi, a + block)
        final = b >= k_hi
        seq = _sample_piece(toolpath, piece, prof, timing, t0, a, b, Ts, workers, precise, carry.held)
        if last and final and seq.t.size:
            # the last sample sits exactly on the path end, at rest
            feed, vel = seq.feed.copy(), seq.velocity.copy()
            feed[-1] = 0.0
            vel[-1] = 0.0
            seq = replace(seq, feed=feed, velocity=vel)
        chk = _recheck(seq, carry.before, carry.left_over, last and final, limits, lim, toolpath, Ts)
        if not final:
            chk = replace(chk, held_over=np.zeros(0, dtype=bool))
        carry = carry.after(seq, chk)
        yield seq, chk, carry, final
        del seq, chk  # (before the next block is sampled)


#: Samples of a long piece ``schedule_stream`` holds at once by default (``block_samples``): about 34 MB of
#: columns.  A piece with more is re-checked block by block and sampled twice.
STREAM_BLOCK_SAMPLES = 2 * SAMPLE_CHUNK


def schedule_stream(
    toolpath: Toolpath, machine: Machine, options: Options | None = None,
    progress: Callable[[float], None] | None = None,
    events: Callable[[str, int], None] | None = None,
    block_samples: int | None = STREAM_BLOCK_SAMPLES,
) -> Iterator[SampleBlock | ScheduleEnd]:
    """The schedule piece by piece: ``SampleBlock``s as soon as they are final, then one ``ScheduleEnd``.

    Pieces (rest to rest, split at corners) are solved in path order: LP windows, the NLP with method
    lp+nlp, time samples at t_k = k Ts on the global grid (piece i starts where piece i-1 ended), then
    the sampled re-check (``solvers.verify``) of its samples against every promised limit, with the
    finite differences reading the true neighbouring samples (the previous piece's last ones; the next
    piece's first ones for this piece's last HELD_SAMPLES, which are therefore released with the next
    piece).  Samples over a limit send their arc lengths back: the piece is solved again with them
    verified (at most SAMPLE_REPAIR_ROUNDS times) and re-sampled; a sample still over 1 + FAIL_TOL is a
    ``LimitViolationError`` raised before that piece's samples are released.  So a block is yielded only
    once it has passed the re-check, and the concatenated blocks, summary and diagnostics are those
    ``schedule`` returns (it consumes this generator).

    Against checking the whole schedule at once (before streaming): the values checked are bit-identical
    (same neighbours), and the flags too; what differs is only when a repair can happen.  A piece is
    repaired before the next one is sampled, so (a) a flag at a piece's held last samples, known only with
    the next piece, can repair only the next piece (points in the released piece are not verified again),
    and (b) each piece gets its own SAMPLE_REPAIR_ROUNDS with its final start time, where the one-shot
    rounds re-solved every flagged piece together and re-sampled the later ones with shifted times.
    Without repairs, or with repairs inside one piece, the output is the one-shot one bit for bit.

    Latency: the first block leaves once the first piece is solved and re-checked; a path without corners is
    one piece, so its rows leave at the end.  ``progress(fraction)`` as for ``schedule``; ``events(name,
    piece)``, if given, is called with "piece_start" and "piece_solved" (LP and NLP done, before sampling)
    and "block" (just before a block with samples of that piece is yielded).

    Memory: ``block_samples`` bounds the samples held at once.  A piece with more own samples is sampled
    and re-checked in blocks of that many (rounded up to whole SAMPLE_CHUNKs; ``_piece_blocks``), keeping
    only its repair points and worst utilisation, and once it needs no more repair it is sampled again,
    block by block, to be released: the same rows bit for bit, for one more time reconstruction of the
    piece.  None: each piece at once (``schedule``, which keeps every sample anyway).  A piece's time table
    is held one segment of ``timing.TABLE_SEGMENT_INTERVALS`` knot intervals at a time (``PieceTiming``), so
    what a corner-free piece holds grows only with its control points (a few floats per knot interval).

    BLAS: the whole computation runs with every loaded OpenBLAS on one thread (``solvers.blas``), restored when
    the generator ends or is closed (the consumer's code between blocks runs with one thread too).
    """
    restore = blas.one_thread()
    try:
        yield from _schedule_stream(toolpath, machine, options, progress, events, block_samples)
    finally:
        restore()


def _schedule_stream(
    toolpath: Toolpath, machine: Machine, options: Options | None = None,
    progress: Callable[[float], None] | None = None,
    events: Callable[[str, int], None] | None = None,
    block_samples: int | None = STREAM_BLOCK_SAMPLES,
) -> Iterator[SampleBlock | ScheduleEnd]:
    """``schedule_stream`` without its BLAS setting."""
    opt = options or Options()
    block = None if block_samples is None else max(1, math.ceil(block_samples / SAMPLE_CHUNK)) * SAMPLE_CHUNK
    t_start = time.perf_counter()
    paused = 0.0  # time spent suspended at a yield (the consumer's), not compute
    lim = _limit_set(machine, opt)
    stats: dict[str, Any] = {
        "windows": 0, "iterations": 0, "cut_rounds": 0, "cut_points": 0,
        "unverified": 0, "window_times": [], "sample_repairs": 0, "lp_chains": 0, "lp_seam_fallbacks": 0,
        "rest_shape_fallbacks": 0, "rest_shape_repairs": 0, "repairs_undone": 0, "rest_step_floor_walks": 0,
        "knot_floor_pieces": 0, "knot_floor_fallbacks": 0, "knot_floor_levels": 0, "finer_rest_plans": 0,
        "finer_rest_retries": 0, "lp_cruise_jumps": 0, "lp_cruise_intervals": 0, "solver_fallbacks": 0,
        "solver_fallback_reasons": [],
    }
    if opt.method == "lp+nlp" and not machine.has_drives:
        raise InvalidMachineError(
            "method lp+nlp needs a drive model on every axis (use method lp otherwise)", field="machine.axes"
        )
    nlp = opt.method == "lp+nlp"
    nlp_stats = NlpStats() if nlp else None
    # shared by the first NLP solve of every piece, in path order (repairs get their own)
    refiners: dict[tuple[int, int, int | None], NlpRefiner] = {}
    # progress: the LP stage is LP_PROGRESS_SHARE of each piece's work when the NLP follows
    lp_share = LP_PROGRESS_SHARE if nlp else 1.0
    total = toolpath.length

    def report(fraction: float) -> None:
        if progress is not None:
            progress(min(1.0, fraction))

    def emit(name: str, index: int) -> None:
        if events is not None:
            events(name, index)

    limits = _promised(lim, opt, machine)
    if opt.max_samples is not None:
        # refused up front when even the feed caps (or the accelerations) alone take the samples over the cap
        # (cam-bench seed 35: F words of 0.02-0.4 mm/s over 2,718 mm, 22,164 s; lp+nlp used to spend minutes on
        # the pieces first)
        t_floor = _promised_floor(toolpath, lim, limits, opt, machine)
        k_floor = math.floor(t_floor / opt.sample_period) + 1
        if k_floor > opt.max_samples:
            raise OutputTooLargeError(
                f"the schedule needs at least {k_floor} time samples (the path takes at least {t_floor:.6g} s "
                f"at its feed and acceleration limits, every {opt.sample_period:g} s), over the {opt.max_samples} "
                "allowed",
                field="options.max_samples", value=opt.max_samples,
            )
    precise = precise_points(toolpath, limits, opt.sample_period)  # (the samples' positions, once per schedule)
    lim = _noise_room(toolpath, lim, limits, opt, precise)  # (promised and floor keep the machine's limits)
    held = _drive_room(toolpath, machine, limits, opt, precise)  # (lp+nlp: the limits its solvers hold)
    if held is not machine:
        lim = _limit_set(held, opt)
    nlp_lim = NlpLimits.from_machine(
        held, opt.nlp_axis_velocity, opt.nlp_kinematic, lim.a_step, opt.sample_period,
        v_step_limit(held, opt.sample_period, opt.jerk, True, opt.nlp_kinematic, share=NLP_V_STEP_SHARE),
    ) if nlp else None
    drives = machine.drive_arrays() if machine.has_drives else None
    Ts = opt.sample_period
    starts = np.array([p.s_start for p in toolpath.pieces])
    n_pieces = len(toolpath.pieces)
    lp_profiles: list[PieceProfile] = []
    profiles: list[PieceProfile] = []
    t_lp = t_nlp = 0.0
    t_end = 0.0  # where the next piece starts, s (the cumulative sum of the piece durations)
    lp_motion_time = 0.0
    k_next = 0  # first sample of the next piece
    carry = _Carry()  # what the re-check of the next samples needs from the released ones
    n_released = 0
    peaks: dict[str, float] = {}
    lead_in: Motion | None = None  # the previous piece's motion up to the corner (lp+nlp: ``_lead_in``)
    # one pool of NLP workers for the whole schedule (forked at its first chain; ``nlp.ChainPool``)
    pool = (_chain_pool(toolpath, opt, nlp_lim, refiners, nlp_stats)
            if nlp_stats is not None and nlp_lim is not None and _workers(opt) > 1 else None)
    try:
        for piece in toolpath.pieces:
            i = piece.index
            last = i == n_pieces - 1
            emit("piece_start", i)
            cache: WindowCache = {}

            def on_window(s_done: float, s0: float = piece.s_start) -> None:
                report((s0 + lp_share * s_done) / total)

            first0, first_bound0 = first_plan(toolpath, piece, machine, opt, lim)
            n_failed0 = len(nlp_stats.failures) if nlp_stats is not None else 0

            def solve_first(
                finer: bool, piece: Piece = piece, cache: WindowCache = cache, on_window: Any = on_window,
                first0: int | None = first0, first_bound0: float | None = first_bound0,
                lead_in: Motion | None = lead_in,
            ) -> tuple[PieceProfile, list[int], PieceProfile, int | None, float | None]:
                """The piece's first LP and NLP solve (``finer``: ``_finer_rest_plan`` may be taken, and the NLP
                workers get the chains while the LP still solves); (LP profile, joins, profile, the knots and
                bound its repairs start from)."""
                nonlocal t_lp, t_nlp
                first, first_bound = first0, first_bound0
                # with NLP workers, the chains go to them while the LP still solves the later windows
                pipe = (_chain_pipeline(toolpath, piece, machine, opt, nlp_lim, refiners, nlp_stats, first, pool,
                                        lead_in)
                        if finer and pool is not None and nlp_stats is not None and nlp_lim is not None else None)
                plain: list[tuple[PieceProfile, list[int]]] = []
                try:
                    t0 = time.perf_counter()
                    fallbacks = stats.get("rest_plan_fallbacks", 0)
                    lp_prof, joins = solve_piece(toolpath, piece, machine, opt, lim, stats, on_window, None, cache,
                                                 pipe.lp_progress if pipe is not None else None, first,
                                                 plain if nlp_stats is not None else None, first_bound, finer)
                    t_lp += time.perf_counter() - t0
                    # repairs start from the knots the first solve started from
                    if first_bound is not None:
                        on_floor = stats.get("rest_plan_fallbacks", 0) == fallbacks
                        stats["knot_floor_pieces" if on_floor else "knot_floor_fallbacks"] += 1
                        if on_floor:
                            first = lp_prof.n_int  # (the level kept: its repairs start there)
                    if stats.get("rest_plan_fallbacks", 0) != fallbacks:
                        first = first_bound = None
                    prof = lp_prof
                    if nlp_stats is not None and nlp_lim is not None:
                        def on_chain(s_done: float, s0: float = piece.s_start, length: float = piece.length) -> None:
                            report((s0 + lp_share * length + (1.0 - lp_share) * s_done) / total)

                        t0 = time.perf_counter()
                        n_failed = len(nlp_stats.failures)
                        prof = _refine_piece(toolpath, piece, machine, opt, lp_prof, joins, nlp_lim, refiners,
                                             nlp_stats, on_chain, pipe=pipe, lead_in=lead_in, pool=pool)
                        if plain and len(nlp_stats.failures) > n_failed:
                            lp_prof, prof = _nlp_on_coarser_knots(toolpath, piece, machine, opt, (lp_prof, prof),
                                                               plain, nlp_lim, refiners, nlp_stats, n_failed,
                                                               lead_in, pool)
                        t_nlp += time.perf_counter() - t0
                except InfeasibleError as exc:
                    raise _overlap_hint(exc, piece, machine, opt) from exc
                finally:
                    if pipe is not None:
                        pipe.close()
                return lp_prof, joins, prof, first, first_bound

            finer_before = stats["finer_rest_plans"]
            lp_prof, joins, prof, first, first_bound = solve_first(True)
            # the finer plan (``_finer_rest_plan``) is kept where its first samples need no repair; else the piece
            # is solved as without it, repairs and all (pieces that held without it hold as they did)
            finer_retry = stats["finer_rest_plans"] > finer_before
            emit("piece_solved", i)
            verify_s = np.zeros(0)
            rounds = 0
            # the fastest round so far whose samples held the promise, (duration, lp_prof, prof); and whether this
            # round samples it again because the rounds after it did not hold it (REPAIR_UNDO)
            passed: tuple[float, PieceProfile, PieceProfile] | None = None
            undo = False
            while True:
                timing = PieceTiming.build(prof)
                t_next = t_end + timing.duration
                k_hi = max(k_next, math.ceil(t_next / Ts - 1e-9) + 1) if last else first_sample_at(t_next, Ts)
                if opt.max_samples is not None and k_hi > opt.max_samples:
                    raise OutputTooLargeError(
                        f"the schedule needs at least {k_hi} time samples ({t_next:.6g} s of motion up to the end of "
                        f"piece {i}, every {Ts:g} s), over the {opt.max_samples} allowed",
                        field="options.max_samples", value=opt.max_samples,
                    )
                n_block = block if block is not None else max(1, k_hi - k_next)
                kept: list[tuple[TimeSamples, _Recheck, _Carry, bool]] = []  # (a piece in one block)
                bad: list[FloatArray] = []
                worst: tuple[str, str, float, float, float] = ("", "", -np.inf, 0.0, 0.0)
                for item in _piece_blocks(toolpath, piece, prof, timing, t_end, k_next, k_hi, n_block, carry, last,
                                          limits, lim, Ts, _workers(opt), precise):
                    seq, chk, _, final = item
                    # (bench seed 1291: the jerk 1.29 x of a piece's last samples, found only once they were
                    # checked with the next piece, which could not repair them)
                    bad.append(_repair_points(seq, np.concatenate([chk.repair, chk.held_over]), last and final))
                    kind, axis, util, k = chk.rows.worst(0, chk.n_released)
                    if util > worst[2]:
                        worst = (kind, axis, util, float(seq.s[k]), float(seq.t[k]))
                    if k_hi - k_next <= n_block:  # (one block: released as checked)
                        kept.append(item)
                    del seq, chk, item
                s_bad = np.concatenate(bad)
                owner = np.clip(np.searchsorted(starts, s_bad, side="right") - 1, 0, n_pieces - 1)
                s_loc = s_bad[owner == i] - piece.s_start
                s_loc = s_loc[(s_loc > 0.0) & (s_loc < piece.length)]
                # a round more where the samples are still over the promise after SAMPLE_REPAIR_ROUNDS: lp+nlp's
                # steps at REPAIR_EXTRA_STEP_SHARE, lp's rest intervals without the rest shapes where the samples
                # over a limit lie in one (``_repair_limits``)
                at_rest = _in_rest_intervals(s_loc, prof)
                extra = (rounds == SAMPLE_REPAIR_ROUNDS and worst[2] > 1.0 + verify.FAIL_TOL
                         and (nlp or (REPAIR_REST_SHAPES_OFF and at_rest and LP_REST_SHAPES and opt.jerk)))
                if finer_retry and s_loc.size:
                    finer_retry = False
                    if nlp_stats is not None:
                        del nlp_stats.failures[n_failed0:]  # (the finer plan's NLP fallbacks: not the output's)
                    stats["finer_rest_retries"] += 1
                    lp_prof, joins, prof, first, first_bound = solve_first(False)
                    continue
                if worst[2] <= 1.0 + verify.FAIL_TOL and (passed is None or timing.duration < passed[0]):
                    passed = (timing.duration, lp_prof, prof)
                if undo or not s_loc.size or rounds >= SAMPLE_REPAIR_ROUNDS + int(extra):
                    if REPAIR_UNDO and not undo and worst[2] > 1.0 + verify.FAIL_TOL and passed is not None:
                        _, lp_prof, prof = passed  # (sampled again: the same samples)
                        undo = True
                        stats["repairs_undone"] += 1
                        continue
                    break
                # the piece again with those points verified (LP windows before the first changed one are
                # reused), then re-sampled
                rounds += 1
                verify_s = np.union1d(verify_s, s_loc)
                if verify_s.size > MAX_REPAIR_POINTS:  # (an even thinning: the rows a point adds are per point)
                    verify_s = verify_s[np.linspace(0, verify_s.size - 1, MAX_REPAIR_POINTS).round().astype(np.int64)]
                lim_r = _repair_limits(lim, rounds, at_rest and not nlp)
                if not lim_r.rest_shapes:
                    cache = {}  # (its windows were solved with the rest shapes)
                    stats["rest_shape_repairs"] += 1
                if nlp and rounds >= SAMPLE_REPAIR_ROUNDS:  # the steps at REPAIR_STEP_SHARE of the budget
                    share = (REPAIR_STEP_SHARE if rounds == SAMPLE_REPAIR_ROUNDS else REPAIR_EXTRA_STEP_SHARE)
                    share /= REST_SHARE
                    lim_r = replace(lim_r, a_rest=lim.a_rest * share,
                                    a_step=None if lim.a_step is None else lim.a_step * share)
                    cache = {}  # (its windows were solved with the full share)
                before = prof
                lp_prof, joins = solve_piece(toolpath, piece, machine, opt, lim_r, stats, None, verify_s, cache,
                                             None, first, first_bound=first_bound)
                prof = lp_prof
                if nlp_stats is not None and nlp_lim is not None:
                    nlp_r = nlp_lim
                    if (REPAIR_NLP_STEP and opt.nlp_kinematic and rounds >= SAMPLE_REPAIR_ROUNDS
                            and nlp_lim.a_step is not None):
                        nlp_r = replace(nlp_lim, a_step=lim_r.a_step)  # (the NLP's steps as the LP's)
                    # (the chains read their neighbours beyond their ends as this round's were: ``nlp.OUTER_JOIN_TOL``)
                    prof = _refine_piece(toolpath, piece, machine, opt, lp_prof, joins, nlp_r, {}, nlp_stats,
                                         None, verify_s, lead_in=lead_in, pool=pool,
                                         outer=before if REPAIR_OUTER else None)
            stats["sample_repairs"] = max(stats["sample_repairs"], rounds)
            kind, axis, util, s_worst, t_worst = worst
            if util > 1.0 + verify.FAIL_TOL:
                raise LimitViolationError(
                    (f"the sampled {kind.replace('_', ' ')} reaches {util:.4f} x its limit" if math.isfinite(util)
                     else f"the sampled {kind.replace('_', ' ')} is not finite (the path's derivatives could not be "
                     "evaluated there)")
                    + f" after {rounds} repair rounds (limits are promised within {1.0 + verify.FAIL_TOL:g} x)",
                    field="toolpath", value={"s": s_worst, "t": t_worst, "utilisation": util},
                    axis=axis or None,
                )
            lp_profiles.append(lp_prof)
            profiles.append(prof)
            if nlp:
                lp_motion_time += PieceTiming.build(lp_prof, inverse=False).duration
                lead_in = _lead_in(toolpath, piece, prof, timing, Ts)
            k_lo = k_next
            t0_piece = t_end
            t_end, k_next = t_next, k_hi
            report(piece.s_end / total)
            # the piece held at once is released as checked; a longer one is sampled again, block by block
            blocks = kept if kept else _piece_blocks(toolpath, piece, prof, timing, t0_piece, k_lo, k_hi, n_block,
                                                     carry, last, limits, lim, Ts, _workers(opt), precise)
            for seq, chk, carry_b, _ in blocks:
                n_rel = chk.n_released
                carry = carry_b
                if not n_rel:
                    continue
                out = _rows(seq, 0, n_rel)
                if drives is not None:
                    u, e = drive_outputs(drives, out.velocity, out.acceleration, out.jerk)
                    out = replace(out, control_signal=u, servo_error=e)
                _merge_peaks(peaks, _peak_utilisation(out, lim, drives, _feed_cap(lim, toolpath, out.s)))
                released = SampleBlock(n_released, i, out)
                n_released += n_rel
                del seq, chk, out
                emit("block", i)
                t_y = time.perf_counter()
                yield released
                paused += time.perf_counter() - t_y
                del released  # (the consumer's now: not held while the next block is sampled)
            del blocks, kept  # (not held while the next piece is solved)
    finally:
        if pool is not None:
            pool.close()
    motion_time = t_end
    if not nlp:
        lp_motion_time = motion_time  # (with method lp the LP profiles are the sampled ones)
    compute_time = time.perf_counter() - t_start - paused
    summary = {
        "method": opt.method,
        "solver": opt.solver,
        "path_length": toolpath.length,
        "motion_time": motion_time,
        "compute_time": compute_time,
        "lp_time": t_lp,
        "nlp_time": t_nlp,
        "lp_motion_time": lp_motion_time,
        "windows": stats["windows"],
        "solver_iterations": stats["iterations"],
        "cut_rounds": stats["cut_rounds"],
        "cut_points": stats["cut_points"],
        "unverified_points": stats["unverified"],
        # pieces whose LP windows were walked as two chains joined by a seam window (``_chain_split``), and
        # those of them whose second chain or seam failed (the first chain then walked on alone)
        "lp_chains": stats["lp_chains"],
        "lp_seam_fallbacks": stats["lp_seam_fallbacks"],
        # stretches the LP windows were not solved on (at a constant velocity bound on a straight line,
        # ``_WindowWalk.cruise``), and their knot intervals
        "lp_cruise_jumps": stats["lp_cruise_jumps"],
        "lp_cruise_intervals": stats["lp_cruise_intervals"],
        # knot plans of method lp walked again with a floor on the step at rest, whose q dipped to 0 next to rest
        # with the rest shapes, and those walked without the shapes at last (``_solve_windows``)
        "rest_step_floor_walks": stats["rest_step_floor_walks"],
        "rest_shape_fallbacks": stats["rest_shape_fallbacks"],
        "rest_shape_repairs": stats["rest_shape_repairs"],
        # pieces whose last repair rounds took their samples over the promise where an earlier round of theirs
        # held it: that round's profile is the piece's (the fastest such; REPAIR_UNDO)
        "repairs_undone": stats["repairs_undone"],
        # LP windows that Options.solver (Clarabel) failed on, solved again with HiGHS (SOLVER_FALLBACK; their
        # window, status and reason in diagnostics.solver_fallbacks)
        "solver_fallbacks": stats["solver_fallbacks"],
        # pieces first solved on the knot floor (``KNOT_FLOOR_SAMPLES``) and kept on it, and those solved again
        # on their plan's knots (the floor's motion over its bound)
        "knot_floor_pieces": stats["knot_floor_pieces"],
        "knot_floor_fallbacks": stats["knot_floor_fallbacks"],
        # ... and the finer levels of the floor solved (``KNOT_FLOOR_LEVEL_STEP``), repairs included
        "knot_floor_levels": stats["knot_floor_levels"],
        # lp+nlp pieces kept on their first REST_MIN_INTERVALS plan and solved on NLP_REST_MIN_INTERVALS instead
        # (``_finer_rest_plan``; their first solve only, never a repair round)
        "finer_rest_plans": stats["finer_rest_plans"],
        # ... of those, the pieces whose first samples needed repairs, solved again as without it
        "finer_rest_retries": stats["finer_rest_retries"],
        # most rounds of re-solving a piece whose samples were over a limit (solvers.verify)
        "sample_repairs": stats["sample_repairs"],
        "control_points": int(sum(p.c.size for p in profiles)),
        "checkpoints": int(sum(p.n_int * opt.checkpoints_per_interval + 1 for p in profiles)),
        "knot_spacing": float(min(p.d for p in profiles)),
        # lp+nlp's knots planned as if no F word were lower (mm/s; ``Options.knot_feed_floor``), or None
        "knot_feed_floor": opt.knot_feed_floor,
        "samples": n_released,
        "sample_period": opt.sample_period,
        "peak_utilisation": peaks,
        "window_times": stats["window_times"],
    }
    if nlp_stats is not None:
        summary.update({
            "nlp_windows": nlp_stats.windows,
            "nlp_iterations": nlp_stats.iterations,
            # of which the dense interior point's (solvers.ipm), and its solves handed to Ipopt
            "nlp_ipm_iterations": nlp_stats.ipm_iterations,
            "nlp_ipm_handed": nlp_stats.ipm_handed,
            # ... and its solves found locally infeasible by its elastic attempt (not handed to Ipopt)
            "nlp_ipm_infeasible": nlp_stats.ipm_infeasible,
            "nlp_cut_rounds": nlp_stats.cut_rounds,
            "nlp_failures": len(nlp_stats.failures),
            "nlp_softer_retries": nlp_stats.softer_retries,
            "nlp_handover_shrink_steps": nlp_stats.handover_scaled,
            "nlp_handover_unscaled": nlp_stats.handover_unscaled,
            # chains whose LP feed was kept unsolved: at the feed bound, well inside the other limits
            "nlp_lp_kept_chains": nlp_stats.lp_kept_chains,
            # ... and stretches inside solved chains that kept it, and their knot intervals
            "nlp_lp_kept_spans": nlp_stats.lp_kept_spans,
            "nlp_lp_kept_intervals": nlp_stats.lp_kept_intervals,
            "nlp_slower_kept_spans": nlp_stats.slower_kept,
            # windows that solved a rest interval and failed, solved again from (to) the LP's state next to it
            "nlp_rest_retries": nlp_stats.rest_retries,
            # rest ends solved without their rises: the LP's feed reaches its bound in the rest interval
            "nlp_rest_rises_capped": nlp_stats.rest_rises_capped,
            # worst fine-grid utilisation (u, e, feed, ...) of any accepted NLP window
            "nlp_worst_verified_utilisation": nlp_stats.worst_verified,
            "nlp_window_times": nlp_stats.window_times,
        })
    diagnostics = {
        "corners": [
            {"s": c.s, "angle_deg": c.angle_deg, "segment": c.segment, "position": list(c.position)}
            for c in toolpath.corners
        ],
        # corners a blend (corner_blend_mm) left as they were, and why
        "unblended_corners": [
            {"segment": u.segment, "position": list(u.position), "angle_deg": u.angle_deg, "reason": u.reason}
            for u in getattr(toolpath, "unblended", ())
        ],
        # corners made of turns inside a segment sharper than a micrometre radius (cut out, within
        # geometry.nurbs.SHARP_TURN_CUT_MM of the apex): also listed in corners
        "sharp_turns": [{"s": c.s, "angle_deg": c.angle_deg, "segment": c.segment}
                        for c in getattr(toolpath, "sharp_turns", ())],
        # gaps within the gap tolerance closed by moving the end control points to their midpoint
        "closed_gaps": [{"segment": i, "gap_mm": g} for i, g in getattr(toolpath, "closed_gaps", ())],
        "passed_turns": _passed_turns(toolpath, nlp_lim.v_step if nlp_lim is not None else lim.v_step),
        "binding": _binding(toolpath, profiles, lim, opt, machine),
        "rest_acceleration": {ax: float(v) for ax, v in zip(AXES, lim.a_rest, strict=True)},
    }
    if stats["solver_fallback_reasons"]:
        diagnostics["solver_fallbacks"] = stats["solver_fallback_reasons"]
    if nlp_stats is not None:
        diagnostics["nlp_fallbacks"] = nlp_stats.failures
    yield ScheduleEnd(summary=summary, diagnostics=diagnostics, profiles=tuple(profiles))


def _merge_peaks(into: dict[str, float], part: dict[str, float]) -> None:
    """Running maxima of ``_peak_utilisation`` over consecutive sample blocks (a max of maxima: the same
    bits as over all samples at once, since dividing by a positive limit keeps the order)."""
    for key, v in part.items():
        into[key] = max(into[key], v) if key in into else v


def _peak_utilisation(
    smp: TimeSamples, lim: LimitSet, drives: dict[str, FloatArray] | None = None, feed_cap: FloatArray | None = None
) -> dict[str, float]:
    out: dict[str, float] = {}
    for i, ax in enumerate(AXES):
        out[f"velocity_{ax}"] = float(np.max(np.abs(smp.velocity[:, i])) / lim.vmax[i])
        out[f"acceleration_{ax}"] = float(np.max(np.abs(smp.acceleration[:, i])) / lim.amax[i])
        out[f"jerk_{ax}"] = float(np.max(np.abs(smp.jerk[:, i])) / lim.jmax[i])
    if drives is not None and smp.control_signal is not None and smp.servo_error is not None:
        for i, ax in enumerate(AXES):
            out[f"control_signal_{ax}"] = float(np.max(np.abs(smp.control_signal[:, i])) / drives["umax"][i])
            out[f"servo_error_{ax}"] = float(np.max(np.abs(smp.servo_error[:, i])) / drives["emax"][i])
    if feed_cap is not None and np.isfinite(feed_cap).any():  # Fmax and programmed feeds (_feed_cap)
        out["feed"] = float(np.max(smp.feed / feed_cap))
    return out


def _passed_turns(toolpath: Toolpath, v_step: FloatArray | None) -> dict[str, Any]:
    """Junctions turning by less than the corner tolerance, passed at speed: how many, the largest
    turn, and the PASSED_TURNS_LISTED with the lowest feed cap there (the velocity step's,
    ``solvers.lp.v_step_limit``: feed x |jump of x_s| <= v_step per axis).  A dense polyline of small
    turns is as slow as its caps; blending it (``corner_blend_mm``) removes them."""
    pt = getattr(toolpath, "passed_turns", None)
    if pt is None or pt.s.size == 0:
        return {"count": 0}
    cap = step_cap(v_step, pt.jump) if v_step is not None else np.full(pt.s.size, np.inf)
    order = np.argsort(cap, kind="stable")[:PASSED_TURNS_LISTED]
    return {
        "count": int(pt.s.size),
        "largest_angle_deg": float(np.max(pt.angle_deg)),
        "lowest_feed_cap": [
            {"s": float(pt.s[k]), "angle_deg": float(pt.angle_deg[k]),
             "feed_cap": float(cap[k]) if np.isfinite(cap[k]) else None}
            for k in order.tolist()
        ],
    }


def _binding(
    toolpath: Toolpath, profiles: list[PieceProfile], lim: LimitSet, opt: Options, machine: Machine
) -> dict[str, Any]:
    """Where each constraint is within 2% of its limit, at the checkpoints.

    Kinds: velocity, feed, and with method lp acceleration and jerk, with lp+nlp
    control_signal and servo_error (and acceleration/jerk when kept in the NLP)."""
    found: dict[str, list[FloatArray]] = {}
    nlp = opt.method == "lp+nlp" and machine.has_drives
    dr = machine.drive_arrays() if nlp else None
    for piece, prof in zip(toolpath.pieces, profiles, strict=True):
        s_piece = np.linspace(0.0, piece.length, prof.n_int * opt.checkpoints_per_interval + 1)
        # SAMPLE_CHUNK checkpoints at a time (elementwise: the same values): a 367 m piece has 0.4 M, whose
        # geometry and kinematics at once were the streamed schedule's peak (+151 MB over +131 MB)
        for c0 in range(0, s_piece.size, SAMPLE_CHUNK):
            _binding_at(toolpath, piece, prof, s_piece[c0 : c0 + SAMPLE_CHUNK], lim, opt, nlp, dr, found)
    out: dict[str, Any] = {}
    for kind, parts in found.items():
        s_all = np.concatenate(parts)
        out[kind] = {"count": int(s_all.size), "s": [float(x) for x in s_all[:: max(1, s_all.size // 50)]]}
    return out


def _binding_at(
    toolpath: Toolpath, piece: Piece, prof: PieceProfile, s_local: FloatArray, lim: LimitSet, opt: Options,
    nlp: bool, dr: dict[str, FloatArray] | None, found: dict[str, list[FloatArray]],
) -> None:
    """Appends to ``found`` the global s of the checkpoints s_local of ``piece`` where each kind is binding."""
    g, f, v, a, j = _kinematics(toolpath, piece, prof, s_local)
    s_glob = s_local + piece.s_start
    util: dict[str, FloatArray] = {}
    if not nlp or opt.nlp_axis_velocity or opt.nlp_kinematic:
        util["velocity"] = kinematics.row_max(np.abs(v) / lim.vmax)
    elif dr is not None and np.isfinite(dr["vmax"]).any():
        util["velocity"] = kinematics.row_max(np.abs(v) / dr["vmax"])
    if not nlp or opt.nlp_kinematic:
        util["acceleration"] = kinematics.row_max(np.abs(a) / lim.amax)
        if opt.jerk or opt.nlp_kinematic:
            util["jerk"] = kinematics.row_max(np.abs(j) / lim.jmax)
    if dr is not None:
        u, e = drive_outputs(dr, v, a, j)
        util["control_signal"] = kinematics.row_max(np.abs(u) / dr["umax"])
        util["servo_error"] = kinematics.row_max(np.abs(e) / dr["emax"])
    cap = np.full(s_local.size, np.inf if lim.feed_max is None else lim.feed_max)
    if g.feed_limit is not None:
        cap = np.minimum(cap, g.feed_limit)
    if np.isfinite(cap).any():
        util["feed"] = f / cap
    for kind, uu in util.items():
        found.setdefault(kind, []).append(s_glob[uu >= BINDING_UTILISATION])
