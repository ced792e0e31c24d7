r"""LP on one window: the feed-squared profile q = sdot^2 (spec §4).

Variables: control points c (ncols,) of the uniform quadratic B-spline q(s)
(``solvers.bspline``), scaled as c = Q chat with Q the window's largest
velocity bound (mm^2/s^2), so all rows are O(1).

    maximise    integral of q ds over the window             (w . c)
    subject to, at every checkpoint s_k and axis x:
        0 <= q <= ub_k,  ub_k = min(Fmax^2, min_x vmax_x^2 / x_s^2)    (velocity, feed)
        -amax_x <= x_ss q + x_s q'/2 <= amax_x                          (acceleration)
      and in stage 2, with q* the stage-1 optimum:
        q <= q*_k
        -jmax_x <= sqrt(q*_k) (x_sss q + 1.5 x_ss q' + 0.5 x_s q'') <= jmax_x  (pseudo-jerk)
      rest at a piece end (s = 0 or L):  q = 0 and |x_s q'/2| <= a_rest_x,
        a_rest_x = min(amax_x, jmax_x Ts / 2) (the acceleration step at rest,
        seen over one sample period, stays inside jmax); when the NLP refines
        the feed (jerk is then limited through the servo error instead),
        a_rest_x = min(amax_x, REST_SHARE emax_x / (Ka_x + Kj_x / (2 Ts))), which
        keeps the servo error of that step, seen over one sample, inside emax;
        at a corner the step is a_out - a_in (both pieces' rest accelerations), so
        the window may be given a smaller per-axis a_rest there (``WindowSpec.a_rest_start/end``)
      artificial window end: c_{k1} = c_{k1+1} = 0 (q = q' = 0, discarded)
      inherited window start: c_{k0}, c_{k0+1} fixed (q, q' continuous)
      seam window end (``WindowSpec.end_fixed``): c_{k1}, c_{k1+1} fixed to the
        solution that goes on from there (q, q' continuous)

Since q <= q*, the true jerk |sqrt(q)(...)| <= the pseudo-jerk, so jmax holds
at checkpoints.  Between checkpoints the limits are verified on a 4x finer
grid and violated points are added as rows (cutting planes) and re-solved.

Solvers: HiGHS (dual simplex, stage 2 re-solved from stage 1's basis) or
Clarabel (interior point), both fed the same sparse rows.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import clarabel
import highspy
import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from geometry.toolpath import PathSamples
from solvers import bspline, csr, kinematics, native
from solvers.errors import InfeasibleError, SolverFailure
from solvers.machine import Machine

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: A HiGHS run is stopped after this much wall time plus HIGHS_TIME_PER_ROW_S a row, and the window is
#: solved once more from scratch with the other presolve setting (``_highs_run``).  Bench seed 949 (lp): a
#: cut round's hot-started dual simplex on 5,730 rows ran for minutes (243 iterations in 5 s when
#: limited; it never returned otherwise); the cold re-solve takes 431 iterations and 0.03 s.  A
#: 4,000-interval full-horizon window (flower at 0.1 mm) runs 1.2 s.  Until session 49 10 s + 1 ms a row: bench
#: seed 11994 (lp) ran over the random bench's 120 s of CPU, a 64-interval window of 4,203 rows and 88 columns
#: (the rest shapes' numbers) stalling at 13-30 ms an iteration in each of its walks, 10.9-14.2 s a run, every
#: run ending unknown, at the time limit or infeasible.  The slowest solves that end optimal, lp bench seeds
#: 0-149 and cam 0-59 with both scans on the 2 cores: 1.43 s on 53,300 rows, at most 0.13 of 0.5 s + 0.2 ms a
#: row (the limit allows 1 s + 0.2 ms); the only run over 0.5 s + 0.2 ms, bench seed 142's 1.27 s on 2,211 rows,
#: ended unknown.
HIGHS_TIME_LIMIT_S = 1.0
HIGHS_TIME_PER_ROW_S = 2e-4
#: Coefficients below this (after scaling) are dropped (HiGHS presolve trap, spec §10).
TINY_COEF = 1e-9
#: A row whose bound as given is at least this is passed with that bound at least this large (``_Rows.build``), its
#: coefficients at most ROW_COEF_CAP: HiGHS holds a row to its absolute primal feasibility tolerance (1e-7), so a
#: bound scaled down to ~1e-6 by the row's largest coefficient was held to ~1 % of the limit only.  Bench seed
#: 16610 (lp; x amax 5.9e-4 mm/s^2, knots 0.0102 mm): an acceleration row next to a corner's rest end, coefficients up
#: to 2.8e5 against its bound 1 (the rest shapes' rises), passed as |.| <= 3.5e-6, read 1.0098 x amax in the solution
#: and in its 1 kHz samples; the cut rounds added the same row again 38 times (1,859 points left "unverified", 1.8 s
#: of CPU) and the samples were repaired twice.  Floored: 2 cut rounds, nothing unverified, no repair, 0.41 s; the
#: flower's models (bounds of ~1 against coefficients <= ~30) unchanged.
#: Only bounds of at least the floor as given are lifted (the rows' units: a limit is 1, q is in units of Q); a
#: smaller one is ~0: lifting stage 2's q <= q* next to a rest end (q* ~1e-12 Q) held q there to ~1e-11 Q, not
#: ~1e-7 Q, and stage 2 from scratch (STAGE2_WARM off) lost 0.9 % of the flower's motion and 5 % of a 21 mm line's.
ROW_BOUND_FLOOR = 1e-3
#: See ROW_BOUND_FLOOR: the floor does not scale a row's largest coefficient above this.
ROW_COEF_CAP = 1e4
#: The q reachable from rest over a window, which caps its scale Q, reads the acceleration limits of the axes the
#: window moves only (False: all three, as before session 59).  A/B in one run (session 59): cam 0-59 and bench
#: 0-99, both methods, 0 failures either side; 57/60, 57/60, 89/100, 90/100 motions identical, the rest within
#: 0.13 ms.  An x line on a machine whose x amax is 1e-3 and y, z 1000 failed (2.11 x amax): 141.43 s now.
Q_REACH_MOVING_AXES = True
#: Jerk rows whose sqrt(q*) is below this fraction of sqrt(Q) are dropped (spec §10).
TINY_SQRT_QSTAR = 1e-6
#: A point whose recomputed v/a/j exceeds its limit by more than this fraction gets a row.
VERIFY_TOL = 2e-3
#: Stage 2's q* is at most this many times the q at which the jerk's curvature term alone reaches jmax
#: (``WindowLP._capped_qstar``).  Smaller caps gained more on bench seed 1864 (lp: 1.0 0.0789 s, 1.5 0.0833 s,
#: 2 0.0882 s, none 0.1006 s) but cost the flower with jerk, where x_ss q' cancels part of x_sss q: 1.0 +0.44 %
#: at default knots, 1.5 +0.29 % at 1 and 0.5 mm knots; at 2 its samples are those of no cap at all three.
QSTAR_JERK_CAP = 2.0
#: Next to a rest end stage 2's q* is at most this many times the q a feed leaving (reaching) rest can have
#: there at all (``WindowLP._rest_reach``; 0: no such cap).  Stage 1 (v + a) leaves rest at amax, q* ~ 2 amax
#: sigma at a distance sigma from rest, where a feed under jmax has q ~ sigma^(4/3): the pseudo-jerk rows,
#: sqrt(q*) x ... <= jmax, over-read the jerk there by sqrt(q* / q), ~3x at the rest step's end and ~1.2x where
#: the jerk ramp meets amax, and the feed left rest at 0.4-0.75 jmax (session 48).  Lines of 1 / 5 mm, the
#: square corner, the flower (method lp): 0.10426 / 0.21504 / 1.07774 / 4.21709 s -> 0.09959 / 0.21279 / 1.07002
#: / 4.21011 s (at a corner the cap is ``WindowLP._step_reach_factor`` x the reach; at the reach 1.06210 s).
#: The third differences of the samples see the acceleration step at rest on top of the jerk after it, which the
#: over-read left room for: a piece solved again for its samples keeps the cap with room for the step at every
#: rest end in its first repair round and goes without it in the last (``pipeline._repair_limits``).
#: Holding the step's share in the jerk rows within 3 Ts of rest instead cost the lines more than the cap gained
#: (1 mm: 0.1034 s; 0.1003 s with the share at a path end derived for its kernel, 0.2 a_rest / Ts) and left two
#: windows infeasible (bench seeds 10, 59).
QSTAR_REST_REACH = 1.0
#: With the rest shapes and ``WindowSpec.rest_step_floor`` the acceleration step leaving (reaching) rest is at
#: least this share of its bound a_rest (q' >= 0 there without it).  The steep rises (``bspline.LP_REST_RISE_POWERS``)
#: can lift q just past rest so far that the LP meets its integral of q with q' = 0 at rest, a feed that never
#: leaves: the alternating-F zig-zag of ``tests/geometry/test_arc_blend.py`` (0.05 mm blends) ended so, and its
#: piece was walked again without shapes, 5.4318 -> 5.6924 s.  Such a piece is now walked with this floor first
#: (``pipeline._solve_windows``): with 0.25 / 0.5 / 0.9 5.3815 / 5.3792 / 5.3772 s.  Not on every walk: on bench
#: seed 14 (a turn of 3.6 um radius 0.067 mm from a rest end) any floor > 0 left the feed stalling.
REST_STEP_FLOOR_SHARE = 0.5
#: Verification points between consecutive checkpoints.
VERIFY_SUBDIV = 8
#: Where the tangent turns by more than this (rad) between neighbouring verification points, VERIFY_SUBDIV - 1 more
#: points go between them for the cut rounds, up to VERIFY_TURN_LEVELS times (``WindowLP._check_geometry``): a turn
#: narrower than the grid (bench seed 331: a 0.2 mm cusp of ~20 um radius in a 4.2 m path, its points ~3 mm apart)
#: is otherwise seen only if a point happens to land on it, and the samples see it only if they do.  A flower
#: loop's grid turns by at most ~1.3 degrees between points: no point is added on smooth paths.  The added points
#: are checked only: the floors, column scales and implied bounds read the plain grid (``_fine_geometry``).
VERIFY_TURN_RAD = math.radians(10.0)
VERIFY_TURN_LEVELS = 6
#: Points across a rest interval with shapes (``WindowSpec.rest_shapes``) and towards its rest end where the LP has
#: its rows besides the checkpoints (``WindowLP._row_points``).
REST_SHAPE_POINTS = 32
REST_SHAPE_ZOOM = 30
#: Unit distances r from rest where a rest interval with shapes has rows too (``_row_points``): 2^(-j/4), j = 1 .. 40
#: (r from 0.84 to 1e-3).  The steepest rises (``bspline.LP_REST_RISE_POWERS``) bend within r ~ 0.005-0.05, where
#: the other rows sit at 2^-k and 1 / 33 apart: cam seed 668 (lp) read a_x 1.0135 x amax at r = 0.0107 of a 2.3 um
#: rest interval, between the rows at 2^-6 and 2^-7, and the sampled 1.0113 x after two repair rounds was a 422.
#: Check points there at 2^(-j/8) instead (the cut rounds' grid) did not do it: the rounds ran out (6 rounds, 48-54
#: points added, 8-9 still over), each row moving the overshoot to its neighbours; with these rows they are not
#: needed (and cost the 1-loop flower with jerk ~15 ms of cut rounds).
REST_ROW_R = 2.0 ** -(np.arange(1, 41) / 4.0)
#: ... and below how much of Q a q of the verification grid counts as under 0 there.
REST_SHAPE_Q_TOL = 1e-9
#: Verification points next to a rest end, at h 2^-k (h: the checkpoint gap there), k = 4 .. this
#: (``WindowLP._fine``).
REST_ZOOM_LEVELS = 40
MAX_CUT_ROUNDS = 6
#: Offset (mm) used to evaluate the left side of a geometry knot.
BREAK_EPS_MM = 1e-6
#: Knot intervals after an inherited window start whose jerk rows use the previous q*.
INHERITED_INTERVALS = 2
#: Share of the servo-error budget the acceleration step at rest may use (lp+nlp).
REST_SHARE = 0.9
#: Floor of q away from rest ends, as a share of the largest constant q that meets every limit
#: in the window (keeps the feed from stalling at a knot; see ``WindowLP.solve``).
FLOOR_SHARE = 1e-2
#: Each control point's own floor, as a share of its reach (``WindowLP._col_scale``).
LOCAL_FLOOR_SHARE = 1e-2
#: Floors next to a rest end at most this share of what the ramp from rest reaches there (``WindowLP._ramp_reach``).
RAMP_FLOOR_SHARE = 0.5
#: A control point within this share above its floor counts as held there (``WindowResult.floored``).
FLOORED_TOL = 1e-3
#: At a curvature jump the axis acceleration steps by x_ss jump x q; seen in a sampled third
#: difference the step adds up to 0.75 step / Ts to the jerk, so it is kept to STEP_SHARE jmax Ts.
STEP_SHARE = 0.25
#: Peak of the third-difference kernel (a quadratic B-spline over 3 Ts) times Ts: a step A of the
#: axis acceleration between samples adds up to STEP_KERNEL A / Ts to a sampled jerk.
STEP_KERNEL = 0.75
#: At a path end an axis's acceleration steps from 0 to its rest step A at the rest instant, on one side only:
#: a sampled third difference whose span holds the instant reads the step's share plus the jerk j of the moving
#: side.  Over every offset of the instant between samples it stays within jmax while j <= jmax (1 - k A / (Ts
#: jmax)), k at most this (computed: 0.2016 for the full step A = jmax Ts / 2, where j = jmax reads 1.083 x;
#: 0.043 for A = jmax Ts / 4).  ``WindowLP._step_reach_factor`` turns it into room over the reach.
END_STEP_KERNEL = 0.21
#: Curvature jumps whose step term would stay below this share of jmax even at their largest q (``_break_qmax``) add
#: nothing to the jerk rows (``WindowLP._step_jerk``).
STEP_JERK_MIN = 1e-3
#: ... and each break's q is capped so that at any point the terms of the breaks within reach add up to at most
#: this share of jmax at their caps (``WindowLP._step_crowd_factor``), each charged as a constant there
STEP_CONST_TOTAL = 0.5
#: At a tangent break passed at speed (a junction turning by less than the corner tolerance) the
#: axis velocity steps by f |jump of x_s|.  Sampled at Ts that step is an impulse: it adds up to
#: V_KERNEL_A |step| / Ts to a second difference (the acceleration), up to V_KERNEL_J |step| / Ts^2
#: to a plain third difference (the jerk) and V_KERNEL_JC |step| / Ts^2 to the mean of two adjacent
#: ones (the drive model's central jerk); peaks over the break's phase between two samples.
V_KERNEL_A = 1.0
V_KERNEL_J = 1.0
V_KERNEL_JC = 0.5
#: Share of the sampled acceleration and jerk budgets the impulse of a velocity step may take under
#: method lp: the acceleration and jerk rows within reach of the break are coupled to the feed at it
#: (``WindowLP._vstep_coupling``), so the impulse and the motion around it share the budget.
V_STEP_SHARE = 0.98
#: The same for the LP of lp+nlp, of the servo-error and control-signal budgets: its rows hold a and j,
#: not e and u, so it only caps the feed at the break, leaving room for the motion around it; the
#: NLP verifies the impulse on top of e and u (``solvers.nlp.V_STEP_SHARE``).
V_STEP_SHARE_DRIVE = 0.5
#: The servo error a velocity step's impulse adds to the samples (``vstep_servo_error``): its own peak,
#: max(Ka V_KERNEL_A / Ts, Kj V_KERNEL_JC / Ts^2) |step| (the hat mean of a peaks at the break, the central jerk
#: Ts either side of it, where the other is 0), not the sum of the two peaks (session 69; the sum read the router's
#: x and z impulse at 1.77 x, y at 1.17 x its peak).  False: the sum.  Not kept: both are bounds for one break, but
#: the LP of lp+nlp holds no e rows, and where breaks crowd (a dense polyline: a step every 2-5 Ts, their impulses
#: adding up like a curve's acceleration) its faster feed at the breaks was over e: an unblended G01 spiral of
#: 0.2 mm chords, 8 of 25 NLP windows fell back to it, 3 repair rounds, e 1.006 x in the samples (1.0 x with the
#: sum); with the peak only in the NLP's caps, the spiral of 1.0 mm chords ran 7.64 s against 4.81 s (3 NLP windows'
#: tightening did not converge and fell back to the LP's feed; 5.88 s with ``nlp.STEP_BOUND_VSTEP`` on).
V_STEP_E_PEAK = False
#: Velocity steps whose impulse stays below this share of a limit even at the break's largest feed
#: get no coupled rows.
V_STEP_MIN = 1e-3
#: HiGHS presolve on the first try (a window that does not reach optimality is solved once more with
#: the other setting).  Off: 26 % less HiGHS CPU over 100 random test-profile lp cases (4.97 -> 3.66 s,
#: no failures, motion times within +-0.07 %: other optimal vertices); the LP's rows are already
#: scaled and have no redundancy presolve could remove cheaply.
PRESOLVE = "off"
#: HiGHS's dual simplex edge weights (``simplex_dual_edge_weight_strategy``): Devex (1) since session 27; -1 is
#: HiGHS's own choice, its default.  Devex takes 24-30 % less HiGHS time (session 27, alternated in one process:
#: one flower loop v+a 24.4 -> 18.5 ms, with jerk 70.0 -> 50.1 ms; the 18.35 m path with jerk, 1 worker, 0.80-1.01
#: -> 0.57-0.73 s) for a few % more iterations.  Session 25 tried it and went back: its other optimal vertices
#: broke bench seeds 894 lp (the feed stalled) and 664 lp (129.8 s of CPU, a ``CaseTimeout``), 2 of ~1,500 seeds.
#: Both pass since session 26's bounded break couplings (``_step_jerk``), and session 27's random bench (with
#: the rest shapes) found no failure: seeds 0-999 lp and 0-299 lp+nlp, 1,300 runs; lp motion geometric mean
#: 0.9985 x against the default (seeds 550 and 566 0.45 x and 0.54 x, 663 +2.9 %, the rest within 2.4 %), lp+nlp
#: within 0.5 % in all 200 compared.  Dantzig (0) was not faster (session 24).
DUAL_EDGE_WEIGHT = 1
#: HiGHS's simplex scaling (``simplex_scale_strategy``): off (0) since session 34; 2, equilibration, is HiGHS's
#: default and what a window that does not reach optimality is solved with once more (``_highs_run``).  The rows
#: reach HiGHS scaled already (each by its largest coefficient, ``_Rows.build``; each column by its reach,
#: ``_col_scale``), and HiGHS's own equilibration on top costs simplex iterations: flower v+a 511 -> 391, with
#: jerk 616 -> 460.  Session 29 tried it and did not keep it (motion over bench seeds 0-80, lp: never shorter, up
#: to +2.7 %, geometric mean +0.08 %).  Session 34, random bench seeds 0-999 but 388 and 615, both methods, A/B
#: (with COL_HI_FACTOR 1): 0 failures; lp motion geometric mean 0.9988 (960 of 997 the same, 29 shorter, 7 longer:
#: 276 1.81x, 302 +6.2 %, 340 +4.5 %), lp+nlp 0.9996 (979 of 998 the same); worker time 0.79x / 0.85x.  The
#: outliers go both ways, each another optimal vertex of integral q sending the rest-shape fallback or a sample
#: repair down another path.  ``python -m bench.lp_switch --switch no_scale`` compares the two.
SIMPLEX_SCALE = 0
#: ... and the scaling of the second try of a window that did not reach optimality (with the other presolve).
SIMPLEX_SCALE_RETRY = 2
#: HiGHS's simplex (``simplex_strategy``): the dual (1, HiGHS's default) ...
SIMPLEX_STRATEGY = 1
#: ... and the second try's (4, the primal; the model's later runs, its cut rounds hot-started from the basis, go
#: back to SIMPLEX_STRATEGY).  Bench seed 11994 (lp): windows of 1,256-2,243 rows x 40-88 columns end
#: unknown in the dual simplex in 0.004-0.13 s (Devex: "possibly dual unbounded" at every iteration, each a
#: rebuild), and the dual retry stalled the same way until its time limit (0.6-0.9 s of CPU, 8 retries); the
#: primal simplex ends 5 of them in a few ms (3 still run to the limit).  11.0 -> 5.7 s of CPU, the same motion
#: (session 51).
SIMPLEX_STRATEGY_RETRY = 4
#: Stage 2 followed, where it holds control points at their floor, by one LP step on the travel time
#: (``WindowLP._time_stage``; with ``LimitSet.time_stage``: method lp).
TIME_STAGE = True
#: Column scaling (``WindowLP._col_scale``): basis values below this do not bound a column's scale,
#: and no column is scaled below this share of the window's Q.
COL_SCALE_MIN_BASIS = 0.1
COL_SCALE_FLOOR = 1e-12
#: Each free control point's upper bound is COL_HI_FACTOR x the one its velocity rows imply, from the points where its
#: basis function is at least COL_HI_MIN_BASIS (``WindowLP._implied_col_hi``).  2 until session 34 (a margin, not
#: needed: the rows imply the bound itself, and the floors stay below it, ``_col_scale`` taking its minimum over a
#: superset of the points); at 1 the dual simplex starts nearer the optimum, flower v+a 391 -> 365 iterations, with
#: jerk 460 -> 438, the same motion.
COL_HI_FACTOR = 1.0
COL_HI_MIN_BASIS = 0.25
#: ... but none that is over this in the solver's scaled variables (``_col_scale``): a column next to a cusp's rest
#: end, its scale ~1e-12 of Q, got a bound of 6e12 there, and HiGHS stopped with kSolveError.
COL_HI_MAX_SCALED = 1e6
#: A free control point whose velocity bound is the same at every row point of its support (to FLAT_CAP_RTOL:
#: a feed cap, a line's axis vmax) is held at that bound itself (``flat_reach``): no feed over the cap between
#: the points, and no control points alternating about it.
FLAT_CAP_COLUMNS = True
FLAT_CAP_RTOL = 1e-12
#: An axis whose path-derivative coefficients are all below this is not moving.
AXIS_EPS = 1e-12
#: Two axes' rows at a point are parallel where |v_x x v_y| <= this x |v_x| |v_y| (``implied_rows``): the smaller is
#: implied by the larger and left out.  A row left out for a near-parallel pair can be exceeded by at most this
#: share of its coefficients' size; the verification grid checks every axis anyway.
PARALLEL_ROW_TOL = 1e-12
#: Stage 2 (the jerk rows) first goes on in stage 1's HiGHS model from its optimal basis (``WindowLP.solve``).
STAGE2_WARM = True
#: Stage-1 rows that the other rows at their point hold are left out (``held_rows``, ``held_jerk_rows``); off: every
#: row.  The flower's v+a LP has 1,894 rows instead of 2,660 (HiGHS 17.8 -> 13.9 ms), the same motion.  Off from
#: session 30's a42273f to session 31: bench seed 664 lp took over 120 s of CPU with it (7.6 s without).  Its piece
#: 1, refined to 128, 256 and 512 knot intervals, had windows that their floors made infeasible, and HiGHS's dual
#: simplex ran seconds on each to status unknown; the column bounds (``WindowLP._implied_col_hi``) end those runs in
#: 0.03-1 s, and the case takes ~4 s either way.  Bench seeds 0-699 but 388 and 615, both methods, with the bounds
#: and the held rows: 1,396 runs, 0 failures.
POINT_HELD_ROWS = True
#: ... where they hold with this relative margin.
HELD_ROW_MARGIN = 1e-9
#: Knot intervals next to a rest end whose acceleration and jerk rows are the drive's control signal and
#: servo error (lp+nlp, ``LimitSet.rest_drive``): the rest interval.  Since session 14 the NLP solves it
#: too (``solvers.nlp.REST_ENDS``): this LP feed is where its rest windows start from, and what a failed
#: one keeps (a chain then starts from the LP's state at the interval's far knot).
#: Flower (one loop, phased knots 2.33 mm): the LP's x acceleration was capped by
#: the router's amax 500 mm/s^2 there while the servo error admits ~936; motion 3.0652 s with none,
#: 3.0426 s with the rest interval alone (its second control point then meets interval 1's amax rows),
#: 3.0144 s with two, 3.0136 s with three.  One: with two, bench seeds 0-59 (lp+nlp) had 23 NLP fallbacks
#: instead of 3 ('Infeasible_Problem_Detected', also with REST_DRIVE_SHARE 0.9: the LP's state at knot 1,
#: inside its limits, is one the NLP's f spline, f'' constant per interval, cannot continue from after a
#: steep ramp; docs/benchmark-history.md "The rest zones", branch restshift) and seed 54 took 1.74 x the
#: motion time; with one, seeds 10, 13, 15, 51, 54 have no fallback and are as fast or faster than without the rows.
REST_DRIVE_INTERVALS = 1
#: Share of emax the LP's rows next to a rest end give the servo error (lp+nlp, ``WindowLP._rest_drive_rows``).
REST_DRIVE_SHARE = 0.99
#: Next to a rest end (lp+nlp) the feed is capped where b |x_s| F or Kv |x_s| F would take more than this
#: share of umax or of the servo error's share (``WindowLP._rest_feed_cap``): the rows at that feed stay feasible.
REST_FEED_BUDGET = 0.5
#: |x_s| under which the sign of an axis's velocity counts as unknown (both signs of the friction term):
#: the LP's rows next to a rest end and the NLP's rows (``solvers.nlp``) share it, so the LP's state there
#: is taken with the same friction signs by the NLP window that starts from it.
SIGN_EPS = 0.02

GeometryFn = Callable[[FloatArray], PathSamples]


@dataclass(frozen=True)
class WindowSpec:
    """One LP window over knot intervals [k0, k1) of a piece.

    Attributes:
        index: window number (for diagnostics).
        k0, k1: knot interval range; control points k0 .. k1+1 are variables.
        d: knot spacing, mm.  n_int: knot intervals in the piece.
        start_fixed: (c_k0, c_k0+1) inherited from the previous window, or None
            for a rest start (piece start).
        end_rest: True if k1 is the piece end (true rest), False for an
            artificial window end (q = q' = 0 there).
        prev_c: (k0_prev, c_prev), the previous window's solution.  Rows on the
            inherited intervals are widened (by at most VERIFY_TOL) to admit it,
            so the window is feasible by construction.
        prev_qstar: (k0_prev, c*_prev), the previous window's stage-1 control
            points.  On the first ``INHERITED_INTERVALS`` knot intervals the
            jerk rows use the previous window's q* (the inherited state was
            made feasible against it), so stage 2 stays feasible.
        a_rest_start, a_rest_end: per-axis rest acceleration (3,) at a rest start / end
            instead of ``LimitSet.a_rest`` (a corner shares the step with the next piece), or None.
        end_fixed: (c_k1, c_k1+1) of the solution that goes on after k1 (a seam window joining two
            chains of windows, ``pipeline._solve_windows``), or None (end_rest / an artificial end).
        next_c, next_qstar: (k0_next, control points) of that solution and its stage-1 q*: on the
            last ``inherited`` knot intervals the rows are widened to admit it and the jerk rows use
            its q*, as prev_c and prev_qstar do at the start.
    """

    index: int
    k0: int
    k1: int
    d: float
    n_int: int
    start_fixed: tuple[float, float] | None
    end_rest: bool
    prev_qstar: tuple[int, FloatArray] | None = None
    prev_c: tuple[int, FloatArray] | None = None
    a_rest_start: FloatArray | None = None
    a_rest_end: FloatArray | None = None
    #: keep the control point next to a rest end above a floor too (q' > 0 there); the pipeline
    #: asks for it only once refining the knots has not made the feed leave rest
    rest_floor: bool = False
    end_fixed: tuple[float, float] | None = None
    next_c: tuple[int, FloatArray] | None = None
    next_qstar: tuple[int, FloatArray] | None = None
    #: the rest intervals (the piece's first knot interval at a rest start, its last at a rest end) get the
    #: shapes ``bspline.rest_shapes`` (a bump and rises) added to q, their amplitudes variables of the LP
    #: (method lp with jerk, ``pipeline._solve_windows``; see ``WindowLP``)
    rest_shapes: bool = False
    #: with the rest shapes: the acceleration step at rest is at least REST_STEP_FLOOR_SHARE of its bound
    rest_step_floor: bool = False

    @property
    def ncols(self) -> int:
        return self.k1 - self.k0 + 2


@dataclass(frozen=True)
class WindowResult:
    c: FloatArray  # (ncols,) control points, mm^2/s^2
    c_star: FloatArray  # stage-1 solution
    iterations: int
    cut_rounds: int
    added_points: int
    #: verification points still over a limit (by > VERIFY_TOL) after the last cut round
    unverified: int = 0
    #: control points held at their q floor (the knots are too coarse for the path there)
    floored: int = 0
    #: amplitudes (``bspline.REST_SHAPES``,) of the rest shapes at the piece's start and end
    #: (``WindowSpec.rest_shapes``), mm^2/s^2, or None where the window has none
    shapes: tuple[FloatArray | None, FloatArray | None] = (None, None)


#: lp+nlp with the kinematic limits kept in the NLP (``Options.nlp_kinematic``, which promises the true jerk): the
#: acceleration at rest and its steps at curvature jumps are held by the jerk as method lp holds them (jmax Ts / 2,
#: STEP_SHARE jmax Ts) besides the drive's servo error.  Without it test seeds 0-59 read 1.01-3.96 x jmax in 29 of
#: 60 runs (most at t = 0 or a corner: the drive's rest step, 2-4 x jmax Ts / 2); with it (and the NLP's sampled
#: jerk, ``nlp.SAMPLED_KINEMATIC``) 0 of 60, bench 0-39 1 of 40 (session 67).
KINEMATIC_REST_FROM_JERK = True
#: ... and its acceleration and jerk rows next to a tangent break passed at speed are coupled to the feed there
#: (``LimitSet.v_step_period``, ``WindowLP._vstep_coupling``) as method lp's are: where an NLP window fails the LP's
#: feed is the output, and it must hold the true jerk too (cam+opts seed 183 lp+nlp: 47 NLP windows infeasible,
#: the LP's feed kept, 1.26 x jmax after the repair rounds where two lines meet at 0.05 degrees; session 68).
KINEMATIC_VSTEP_COUPLING = True
#: ... and so are its jerk rows next to a curvature jump (``LimitSet.step_jerk_period``, ``WindowLP._step_jerk``): held
#: as the samples' third differences see them with the acceleration step beside them, as method lp's are.  Bench+opts
#: seed 840 lp+nlp (session 72; `nlp_kinematic`, `nlp_overlap` 3): its NLP windows failed on most of a 24.5 mm piece,
#: the LP's feed was kept, and at a C1 knot inside a NURBS (x_ss 0.134 -> 0.046 /mm) passed at 15 mm/s the samples
#: read jerk_y 1.117 x (the profile's own jerk <= 0.994 x there, the acceleration step within its STEP_SHARE): a 422
#: after the repair rounds (1.018 x), whose verified points left the LP as it was.
KINEMATIC_STEP_JERK = True


@dataclass(frozen=True)
class LimitSet:
    vmax: FloatArray  # (3,)
    amax: FloatArray
    jmax: FloatArray
    a_rest: FloatArray
    feed_max: float | None
    jerk: bool
    #: largest step of axis acceleration allowed at a curvature jump (G1 junction, C1 knot), (3,) or None
    a_step: FloatArray | None = None
    #: output sample period Ts (s) when the jerk is held as the samples' third differences see it
    #: next to a curvature jump (method lp with jerk, ``WindowLP._step_jerk``), else None
    step_jerk_period: float | None = None
    #: largest step of axis velocity allowed at a tangent break passed at speed, (3,) mm/s
    #: (``v_step_limit``), or None (no such rows)
    v_step: FloatArray | None = None
    #: output sample period Ts (s) when the acceleration and jerk rows next to a tangent break are
    #: coupled to the feed there (method lp, ``WindowLP._vstep_coupling``), else None (the cap only)
    v_step_period: float | None = None
    #: the drive model (``Machine.drive_arrays``) whose control signal and servo error replace the
    #: acceleration and jerk rows in the knot intervals next to a rest end (lp+nlp without the NLP's
    #: kinematic rows: those intervals keep the LP's feed, ``WindowLP._rest_drive_rows``), or None
    rest_drive: dict[str, FloatArray] | None = None
    #: check the cut rounds' limits at points added where the path turns sharply between the verification
    #: grid's points (``WindowLP._check_geometry``): method lp, whose feed is the output.  Not lp+nlp: its NLP
    #: windows refine their own grid at turns (``nlp._refine_turns``), and the LP seeing a turn its knots are
    #: too coarse for slowed it far around the turn (bench seed 594 lp+nlp, a 0.42 mm radius in a 5.4 m path on
    #: 85 mm knots: 0.565 -> 6.24 s of motion)
    check_turns: bool = False
    #: cap stage 2's q* next to rest ends at what a feed from rest can reach (``QSTAR_REST_REACH``): method lp; off
    #: in a piece's last repair round for its samples (``pipeline._repair_limits``), and under lp+nlp, whose NLP
    #: makes the feed (with it: lp+nlp bench seeds 0-99 none shorter, 3 longer by up to 3.2 %)
    rest_reach: bool = True
    #: with ``rest_reach``: within 3 Ts of travel of a path end too, not only of a corner, q* may be over the reach
    #: by the room its acceleration step needs in the samples' third differences (``WindowLP._step_reach_factor``
    #: with END_STEP_KERNEL): a piece's first repair round for its samples (``pipeline._repair_limits``)
    rest_reach_ends: bool = False
    #: method lp with jerk: the rest shapes in a piece's rest intervals (``WindowSpec.rest_shapes``,
    #: ``pipeline._solve_windows``).  Off in the round a piece gets past its repair rounds for its samples where
    #: samples still over the promise lie in a rest interval (``pipeline._repair_limits``): there the rises' steep
    #: bends can hold off the cut rounds
    #: (bench seed 14855: a rest interval of 6 mm, a_x 1.0105 x amax at r = 0.007 of it through both repair rounds,
    #: 27 verification points still over after each window's 6 cut rounds).
    rest_shapes: bool = True
    #: stage 2's floored windows take one LP step on the travel time (``WindowLP._time_stage``, with TIME_STAGE):
    #: method lp, whose feed is the output.  Not lp+nlp, whose NLP makes the feed: bench seeds 0-79 3 shorter (down
    #: to 0.973x), at up to 3.3x the CPU of a case (seed 10 0.31 -> 1.02 s)
    time_stage: bool = False

    @classmethod
    def from_machine(
        cls, m: Machine, sample_period: float, jerk: bool, rest_from_drive: bool = False, kinematic: bool = False
    ) -> LimitSet:
        """``rest_from_drive``: lp+nlp (rest and step limits from the drive model's e and u);
        ``kinematic``: with it, the velocity step is held within the kinematic limits too (the NLP keeps them)."""
        vmax, amax, jmax = m.limit_arrays()
        if rest_from_drive:
            dr = m.drive_arrays()
            a_rest = np.minimum(amax, REST_SHARE * dr["emax"] / (dr["Ka"] + dr["Kj"] / (2.0 * sample_period)))
            a_step = REST_SHARE * dr["emax"] / (dr["Ka"] + dr["Kj"] / (2.0 * sample_period))
            if kinematic and jerk and KINEMATIC_REST_FROM_JERK:
                a_rest = np.minimum(a_rest, jmax * sample_period / 2.0)
                a_step = np.minimum(a_step, STEP_SHARE * jmax * sample_period)
        else:
            a_rest = np.minimum(amax, jmax * sample_period / 2.0) if jerk else amax
            a_step = STEP_SHARE * jmax * sample_period
        return cls(vmax, amax, jmax, a_rest, m.feed_max, jerk, a_step if jerk else None,
                   sample_period if jerk and (not rest_from_drive or (kinematic and KINEMATIC_STEP_JERK)) else None,
                   v_step_limit(m, sample_period, jerk, rest_from_drive, kinematic,
                                V_STEP_SHARE_DRIVE if rest_from_drive else V_STEP_SHARE),
                   sample_period if not rest_from_drive or (kinematic and jerk and KINEMATIC_VSTEP_COUPLING) else None,
                   m.drive_arrays() if rest_from_drive and not kinematic and m.has_drives else None,
                   not rest_from_drive, time_stage=not rest_from_drive)


def v_step_limit(
    m: Machine, Ts: float, jerk: bool, from_drive: bool, kinematic: bool, share: float
) -> FloatArray:
    """Largest axis velocity step Delta v_x (3,) mm/s allowed at a tangent break passed at speed.

    Sampled at Ts, a step Delta v adds an impulse to the differences of the positions (``V_KERNEL_*``):
    lp holds V_KERNEL_A Delta v / Ts <= share amax and, with jerk, V_KERNEL_J Delta v / Ts^2 <=
    share jmax; lp+nlp (``from_drive``) holds the drive model's e and u,
    ``vstep_servo_error`` Delta v <= share emax and
    M V_KERNEL_A Delta v / Ts <= share (umax - |c| - |d|), and with ``kinematic`` both."""
    _, amax, jmax = m.limit_arrays()
    dv = amax * Ts / V_KERNEL_A
    if jerk or kinematic:
        dv = np.minimum(dv, jmax * Ts**2 / V_KERNEL_J)
    if from_drive:
        dr = m.drive_arrays()
        with np.errstate(divide="ignore"):
            by_e = dr["emax"] / vstep_servo_error(dr["Ka"], dr["Kj"], Ts)
            room = np.maximum(dr["umax"] - np.abs(dr["c"]) - np.abs(dr["d"]), 0.0)
            by_u = np.where(dr["M"] > 0.0, room * Ts / (V_KERNEL_A * np.where(dr["M"] > 0.0, dr["M"], 1.0)), np.inf)
        drive = np.minimum(by_e, by_u)
        dv = np.minimum(dv, drive) if kinematic else drive
    return np.asarray(share * dv, dtype=np.float64)


def vstep_servo_error(Ka: FloatArray, Kj: FloatArray, Ts: float) -> FloatArray:
    r"""Peak servo error a velocity step of 1 mm/s adds to the samples at period Ts, per axis (s^-1 x the drive's
    mm / (mm/s) gains: mm per mm/s).

    Sampled at Ts, a step dv at t_b is an impulse dv delta(t - t_b) in a: the hat mean of a (the second difference
    centred at t) gains dv H(t - t_b), H(x) = max(0, Ts - |x|) / Ts^2, and the drive model's central jerk (the mean
    of two third differences over 2 Ts) dv (H(t + Ts - t_b) - H(t - Ts - t_b)) / (2 Ts).  Both are piecewise linear
    in t with kinks at t_b + k Ts, k = -2 .. 2, where Ka x the first plus Kj x the second is Ka V_KERNEL_A / Ts
    (k = 0, the jerk 0), +-Kj V_KERNEL_JC / Ts^2 (k = -+1, the hat 0) or 0 (k = +-2): the larger of the two is the
    peak (``V_STEP_E_PEAK``; else their sum, a looser bound).  Ka, Kj (3,) s^2 and s^3; returns (3,)."""
    ka = np.asarray(Ka, dtype=np.float64) * V_KERNEL_A / Ts
    kj = np.asarray(Kj, dtype=np.float64) * V_KERNEL_JC / Ts**2
    return np.maximum(ka, kj) if V_STEP_E_PEAK else ka + kj


def _admit(
    A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, near: NDArray[np.bool_], x: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Rows lo <= A y <= hi widened at the ``near`` rows to admit the point x."""
    val = (A @ x)[near]  # (the rows' products as A[near] @ x forms them, without scipy's copy of the rows)
    lo, hi = lo.copy(), hi.copy()
    lo[near] = np.minimum(lo[near], val)
    hi[near] = np.maximum(hi[near], val)
    return lo, hi


def _index_type(nnz: int, ncols: int) -> type[np.signedinteger[Any]]:
    """The CSR index type scipy would choose: 32-bit where nnz and the columns fit, else 64-bit."""
    return np.int32 if nnz < 2**31 and ncols < 2**31 else np.int64


def new_highs() -> highspy.Highs:
    """A HiGHS instance set up as the LP windows run it: quiet, PRESOLVE, DUAL_EDGE_WEIGHT, SIMPLEX_SCALE,
    SIMPLEX_STRATEGY."""
    h = highspy.Highs()  # type: ignore[no-untyped-call]
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", PRESOLVE)
    h.setOptionValue("simplex_dual_edge_weight_strategy", DUAL_EDGE_WEIGHT)
    h.setOptionValue("simplex_scale_strategy", SIMPLEX_SCALE)
    h.setOptionValue("simplex_strategy", SIMPLEX_STRATEGY)
    return h


def select_rows(A: sp.csr_matrix, which: NDArray[np.bool_]) -> sp.csr_matrix:
    """A[which] (rows where ``which``, in order): the same matrix as scipy's indexing, which took ~180 us for a
    900-row window's rows (~40 us here)."""
    idx = np.flatnonzero(which)
    counts = np.diff(A.indptr)[idx]
    indptr = np.zeros(idx.size + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    # each kept row's entries: its start, plus 0 .. count - 1
    take = np.repeat(A.indptr[:-1][idx] - indptr[:-1], counts) + np.arange(int(indptr[-1]))
    itype = _index_type(int(indptr[-1]), A.shape[1])
    return csr.make(A.data[take], A.indices[take].astype(itype), indptr.astype(itype), (idx.size, A.shape[1]))


def stack_rows(blocks: list[sp.csr_matrix]) -> sp.csr_matrix:
    """sp.vstack(blocks, format="csr") for CSR blocks of the same column count (their entries one after the other;
    ~250 -> ~50 us for a window's six blocks)."""
    ncols = blocks[0].shape[1]
    nnz = [b.indptr[-1] for b in blocks]
    offs = np.cumsum([0, *nnz[:-1]])
    itype = _index_type(int(sum(nnz)), ncols)
    shifted = [(b.indptr[1:] + o).astype(itype) for b, o in zip(blocks, offs, strict=True)]
    indptr = np.concatenate([np.zeros(1, dtype=itype), *shifted])
    data = np.concatenate([b.data[: b.indptr[-1]] for b in blocks])
    indices = np.concatenate([b.indices[: b.indptr[-1]].astype(itype) for b in blocks])
    return csr.make(data, indices, indptr, (int(indptr.size - 1), ncols))


def flat_reach(k: IntArray, W0: FloatArray, cap: FloatArray, ncols: int) -> FloatArray:
    """For each control point c_j (ncols,): cap, where cap is finite and the same (to FLAT_CAP_RTOL) at every
    point s with b_j(s) > 0; inf elsewhere.  Where it is, c_j <= cap keeps q <= cap between the
    points too (q is a convex combination of c >= 0: the B-spline's convex hull), and on a cruise at the cap it
    leaves one optimum where integral q had many: c_j + c_j+1 = 2 cap at the knots holds the rows with the
    control points alternating about the cap (a line at an 8 mm/s cap: 1.0116, 0.9884, 1.0007, 0.9993 of it
    squared, the feed 0.05 % over the cap between the points and 0.4 % under it).

    k, W0, cap as ``column_reach``'s."""
    on = np.where(W0 > 0.0, 1.0, 0.0)
    return flat_bound(column_reach(k, on, cap, ncols, 0.5), -column_reach(k, on, -cap, ncols, 0.5))


def flat_bound(lo: FloatArray, hi: FloatArray) -> FloatArray:
    """lo where a bound's smallest and largest values over a support, lo and hi (same shapes), are finite and the
    same to FLAT_CAP_RTOL; inf elsewhere (``flat_reach``, ``solvers.nlp.flat_feed_columns``)."""
    spread = np.full(lo.shape, np.inf)
    fin = np.isfinite(lo) & np.isfinite(hi)
    spread[fin] = hi[fin] - lo[fin]
    return np.where(spread <= FLAT_CAP_RTOL * lo, lo, np.inf)


def column_reach(
    k: IntArray, W0: FloatArray, cap: FloatArray, ncols: int, min_basis: float, ok: NDArray[np.bool_] | None = None
) -> FloatArray:
    """For each control point c_j (ncols,), the smallest cap(s) / b_j(s) over the points s where its basis function
    b_j(s) >= min_basis (and ``ok``), inf where there is none: with every c >= 0, q(s) >= c_j b_j(s), so
    q(s) <= cap(s) keeps c_j at most that.

    k (K,): each point's first nonzero control point (``bspline.basis``, counted from the window's first); W0 (K, 3):
    the basis weights b_k, b_k+1, b_k+2 there; cap (K,).  Points in order of s (each column's points together:
    per-column minima by ``np.minimum.reduceat``; otherwise ``np.minimum.at``, the same minima, ~10x slower).
    Compiled where it can be (``solvers.native``: the same minima, in any order)."""
    lib = native.library()
    if lib is not None:
        fast = native.column_reach(lib, k, W0, cap, ncols, min_basis, ok)
        if fast is not None:
            return fast
    out = np.full(ncols, np.inf)
    for i in range(3):
        sel = W0[:, i] >= min_basis
        if ok is not None:
            sel &= ok
        col = k[sel] + i
        if col.size == 0:
            continue
        val = cap[sel] / W0[sel, i]
        if np.all(col[1:] >= col[:-1]):
            first = np.flatnonzero(np.concatenate([[True], col[1:] != col[:-1]]))
            out[col[first]] = np.minimum(out[col[first]], np.minimum.reduceat(val, first))
        else:
            np.minimum.at(out, col, val)
    return out


class _Rows:
    """Accumulates sparse rows lo <= A chat <= hi."""

    def __init__(self, ncols: int) -> None:
        self.ncols = ncols
        self.blocks: list[sp.csr_matrix] = []
        self.lo: list[FloatArray] = []
        self.hi: list[FloatArray] = []
        #: HiGHS model holding the first ``passed`` blocks (cut rounds add only new rows)
        self.highs: highspy.Highs | None = None
        self.passed = 0
        #: column scale sigma (ncols,): the solver's variables are y = chat / sigma (``WindowLP._col_scale``)
        self.col_scale = np.ones(ncols)
        #: each model row's scale r (``build``: the rows passed to the solver are multiplied by it), in model order
        self.row_scale = np.zeros(0)
        #: (model rows, lo, hi) changed since the last solve, for the solver's model (``change_bounds``)
        self.bound_changes: list[tuple[NDArray[np.intp], FloatArray, FloatArray]] = []
        #: stage 1's velocity rows at its row points: their block, and which of the points (not in a rest interval
        #: with the drive's rows) have one (``WindowLP._stage1_rows``; stage 2 going on in the same model changes
        #: their bounds to q*)
        self.velocity_rows: tuple[int, NDArray[np.bool_]] | None = None

    def add(self, A: sp.csr_matrix, lo: FloatArray, hi: FloatArray) -> None:
        if A.shape[0]:
            # (a CSR matrix as it is: wrapping it again shares its arrays all the same, at scipy's checking cost)
            self.blocks.append(A if type(A) is sp.csr_matrix else sp.csr_matrix(A))
            self.lo.append(np.asarray(lo, dtype=np.float64))
            self.hi.append(np.asarray(hi, dtype=np.float64))

    def change_bounds(self, block: int, lo: FloatArray, hi: FloatArray) -> None:
        """New bounds of a block's rows (in place; for the solver's model too if the block was passed to it)."""
        self.lo[block], self.hi[block] = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        if block < self.passed:
            start = sum(b.shape[0] for b in self.blocks[:block])
            self.bound_changes.append((np.arange(start, start + self.blocks[block].shape[0]), self.lo[block],
                                       self.hi[block]))

    def copy(self) -> _Rows:
        """A new row set starting with these rows (no solver state)."""
        out = _Rows(self.ncols)
        out.blocks, out.lo, out.hi = list(self.blocks), list(self.lo), list(self.hi)
        out.col_scale = self.col_scale
        return out

    def build(self, first: int = 0) -> tuple[sp.csr_matrix, FloatArray, FloatArray, FloatArray]:
        """Rows of blocks[first:] in the solver's variables y (columns times ``col_scale``) as one
        cleaned CSR matrix with bounds, and the scale each row was multiplied by (r: the rows passed
        are diag(r) A).  Coefficients below TINY_COEF (in units of Q) are dropped first; then each
        row is divided by the larger of its largest coefficient and its largest
        finite bound, so a row whose columns and bound are all ~1e-8 (q capped near a tight turn)
        is O(1), and a row whose coefficients are all tiny against its bound stays as it was (an
        axis barely moving: normalising it by its coefficients gave bounds of ~5e13 and Clarabel
        stopped with InsufficientProgress).  A row whose bound of at least ROW_BOUND_FLOOR that leaves below
        it is scaled up to it, its largest coefficient to at most ROW_COEF_CAP: the solvers' tolerances are
        absolute."""
        if len(self.blocks) <= first:
            return sp.csr_matrix((0, self.ncols)), np.zeros(0), np.zeros(0), np.zeros(0)
        A = stack_rows(self.blocks[first:])
        if any(np.may_share_memory(A.data, b.data) for b in self.blocks[first:]):  # (scaled in place below)
            A = A.copy()
        A.data[np.abs(A.data) < TINY_COEF] = 0.0
        A.eliminate_zeros()
        # the column and row scalings multiply each entry once (the products A diag(sigma) and diag(r) A
        # would give, entry for entry), in place: the stacked copy, never a block (they are built again)
        A.data *= self.col_scale[A.indices]
        lo, hi = np.concatenate(self.lo[first:]), np.concatenate(self.hi[first:])
        coef = np.zeros(A.shape[0])
        full = np.diff(A.indptr) > 0
        if full.any():
            coef[full] = np.maximum.reduceat(np.abs(A.data), A.indptr[:-1][full])
        bound = np.maximum(np.where(np.isfinite(lo), np.abs(lo), 0.0), np.where(np.isfinite(hi), np.abs(hi), 0.0))
        big = np.maximum(coef, bound)
        r = 1.0 / np.where(big > 0.0, big, 1.0)
        # a bound not below ROW_BOUND_FLOOR (HiGHS's absolute tolerance against it), coefficients not above
        # ROW_COEF_CAP: r = min(floor / bound, cap / coef), where that is more than 1 / max(coef, bound); only
        # for bounds of at least the floor as given (a limit is 1 in the rows' units, q is in units of Q): a
        # smaller one is ~0 (q <= q* next to a rest end, q* ~1e-12 Q), held to the tolerance in Q's units as before
        small = (bound >= ROW_BOUND_FLOOR) & (bound < ROW_BOUND_FLOOR * coef)
        if small.any():
            r[small] = np.maximum(r[small], np.minimum(ROW_BOUND_FLOOR / bound[small], ROW_COEF_CAP / coef[small]))
        A.data *= np.repeat(r, np.diff(A.indptr))
        return A, lo * r, hi * r, r


def axis_kinematics(
    g: PathSamples, q: FloatArray, q1: FloatArray, q2: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Feed f (K,) and axis v, a, j (K, 3) from q, q', q'' (``solvers.kinematics``)."""
    fd = kinematics.from_q(q, q1, q2)
    return (fd[0], *kinematics.axis_kinematics(g, *fd))


def step_cap(limit: FloatArray, jump: FloatArray) -> FloatArray:
    """min over axes of limit_x / |jump_x| at each break (nb,) from jump (nb, 3); inf where no axis jumps."""
    with np.errstate(divide="ignore"):
        return np.asarray(np.min(np.where(jump > AXIS_EPS, limit[None, :] / np.where(jump > AXIS_EPS, jump, 1.0),
                                          np.inf), axis=1), dtype=np.float64)


def tangent_jump(right: PathSamples, left: PathSamples, eps: float) -> FloatArray:
    """|jump of x_s| per axis (K, 3) at breaks from the geometry eps mm either side: the difference
    of x_s less its smooth part, eps (x_ss(+) + x_ss(-)), so a smooth knot of a tight curve (x_s
    turning by 2 eps kappa over the 2 eps) does not count as a tangent break."""
    return np.asarray(np.abs(right.d1 - left.d1 - eps * (right.d2 + left.d2)), dtype=np.float64)


def curvature_jump(right: PathSamples, left: PathSamples, eps: float) -> FloatArray:
    """|jump of x_ss| per axis (K, 3) at breaks from the geometry eps mm either side, less its smooth part
    eps (x_sss(+) + x_sss(-)), as ``tangent_jump``: a G2 junction inside a corner blend's clothoids (x_sss up to
    ~1e7 /mm^2 on a blend of 1 um) read 5-20 /mm at eps = 1 nm, whose step caps and coupled rows held the LP's
    feed at its floor across the knot interval around it (random program cam 20: a 412 s crawl over 0.3 mm)."""
    return np.asarray(np.abs(right.d2 - left.d2 - eps * (right.d3 + left.d3)), dtype=np.float64)


Coupling = tuple[NDArray[np.bool_], sp.csr_matrix, FloatArray]
#: ``WindowLP._reach_ends``' record of one rest end.
_ReachEnd = tuple[float, float, float, FloatArray, FloatArray, FloatArray, float, float]


def _union(K: int, parts: list[Coupling | None]) -> Coupling | None:
    """Coupled row terms of several sources over K points summed: (near, C, const) on the union of near."""
    have = [p for p in parts if p is not None]
    if not have:
        return None
    if len(have) == 1:
        return have[0]
    near = np.zeros(K, dtype=bool)
    for p in have:
        near |= p[0]
    pos = np.cumsum(near) - 1
    n = int(near.sum())
    ncols = have[0][1].shape[1]
    C = sp.csr_matrix((n, ncols))
    const = np.zeros(n)
    for nr, Ci, ci in have:
        at = pos[nr]
        P = sp.csr_matrix((np.ones(at.size), (at, np.arange(at.size))), shape=(n, at.size))
        C = C + P @ Ci
        const[at] += ci
    return near, sp.csr_matrix(C), const


def implied_rows(vecs: dict[int, FloatArray]) -> dict[int, NDArray[np.bool_]]:
    r"""Per axis, the points where its row is implied by another axis's row at the same point.

    Each axis x has at each point one two-sided row |v_x . z| <= 1 in the point's terms z (q, q' and q'', as
    B-spline rows), v_x (K, m) its coefficients over the axis's limit.  Where v_x = lambda v_y with |lambda| <= 1,
    |v_x . z| = |lambda| |v_y . z| <= 1 holds whenever y's row does, and it still does on rows widened to admit a
    point (``_admit``: lambda times y's widened bounds lies within x's).  Parallel: |v_x x v_y| <= PARALLEL_ROW_TOL
    |v_x| |v_y|; of equal norms the first axis keeps its row.  On a straight line x_ss = x_sss = 0 and every
    axis's acceleration (jerk) row is a multiple of one: a 0.5 mm line in the plane had 1,339 and 2,213 rows in
    its two stages for 76 columns, of which the second axis's ~440 and ~880 decided nothing.

    Args:
        vecs: axis -> (K, m) coefficients, m = 2 or 3; only the moving axes.
    Returns:
        axis -> (K,) bool, True where that axis's row is implied.
    """
    axes = list(vecs)
    norm = {ax: np.sqrt(np.einsum("ij,ij->i", v, v)) for ax, v in vecs.items()}
    out = {ax: np.zeros(v.shape[0], dtype=bool) for ax, v in vecs.items()}
    for i, a in enumerate(axes):
        for b in axes[i + 1 :]:
            u, v = vecs[a], vecs[b]
            if u.shape[1] == 2:
                cross = np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
            else:
                cross = np.linalg.norm(np.cross(u, v), axis=1)
            parallel = cross <= PARALLEL_ROW_TOL * norm[a] * norm[b]
            out[b] |= parallel & (norm[b] <= norm[a])
            out[a] |= parallel & (norm[a] < norm[b])
    return out


def held_rows(
    alpha: dict[int, FloatArray], beta: dict[int, FloatArray], ub: FloatArray, plain: NDArray[np.bool_],
    implied: dict[int, NDArray[np.bool_]],
) -> tuple[NDArray[np.bool_], dict[int, NDArray[np.bool_]]]:
    r"""Stage-1 rows that the other rows at the same point hold, in the point's (q, p = q').

    At a point the rows are the velocity row 0 <= q <= U (U = ub) and per moving axis x the slab
    |alpha_x q + beta_x p| <= 1 (the acceleration x_ss q + x_s q' / 2 over amax).  Only at ``plain`` points, where
    q >= 0 also follows from the column bounds and no row is widened (``WindowLP._plain_points``), and where U is
    finite; axes whose row is ``implied`` (a parallel one, ``implied_rows``) are not counted on.

    - The velocity row is held where two slabs bound q below U: their parallelogram's largest q is
      (|beta_x| + |beta_y|) / |alpha_x beta_y - alpha_y beta_x| (a determinant of 0: no parallelogram); a slab with
      beta_x = 0 alone bounds q by 1 / |alpha_x|.
    - Where it stays, slab y is held by slab x if x's interval of p lies inside y's for every q in [0, U]: centres
      -alpha q / beta, half-widths 1 / |beta|; the gap of the centres grows linearly from 0 at q = 0, so at q = U,
      |alpha_x / beta_x - alpha_y / beta_y| U + 1 / |beta_x| <= 1 / |beta_y| (which includes q = 0's
      |beta_y| <= |beta_x|).
      A slab with beta_y = 0 (|alpha_y| q <= 1) is held by the velocity row where |alpha_y| U <= 1.

    At a point either the velocity row or slabs are left out, never both (each case leans on the other's rows);
    every test has the relative margin HELD_ROW_MARGIN.  Flower loop, v + a: ~25 % of the rows.

    Returns:
        (velocity row held (K,), axis -> its slab held (K,)).
    """
    K = ub.size
    axes = list(alpha)
    m = HELD_ROW_MARGIN
    v_held = np.zeros(K, dtype=bool)
    a_held = {ax: np.zeros(K, dtype=bool) for ax in axes}
    ok = plain & np.isfinite(ub)
    if not ok.any() or _one_row_each(implied, {ax: beta[ax] == 0.0 for ax in axes}, ok):
        return v_held, a_held
    U = np.where(ok, ub, 0.0)
    on = {ax: ~implied[ax] for ax in axes}
    aa = {ax: np.abs(alpha[ax]) for ax in axes}
    bb = {ax: np.abs(beta[ax]) for ax in axes}
    for i, x in enumerate(axes):
        v_held |= on[x] & (bb[x] == 0.0) & (aa[x] * U * (1.0 - m) >= 1.0)
        for y in axes[i + 1 :]:
            det = np.abs(alpha[x] * beta[y] - alpha[y] * beta[x])
            v_held |= on[x] & on[y] & (det > 0.0) & (bb[x] + bb[y] <= U * (1.0 - m) * det)
    v_held &= ok
    free = ok & ~v_held
    with np.errstate(divide="ignore", invalid="ignore"):
        for y in axes:
            held = (bb[y] == 0.0) & (aa[y] * U <= 1.0 - m)
            for x in axes:
                if x == y:
                    continue
                live = on[x] & ~a_held[x] & (bb[x] > 0.0) & (bb[y] > 0.0)
                gap = np.abs(alpha[x] / beta[x] - alpha[y] / beta[y])
                held |= live & (gap * U + 1.0 / bb[x] <= (1.0 - m) / bb[y])
            a_held[y] = free & on[y] & held
    return v_held, a_held


def _one_row_each(
    implied: dict[int, NDArray[np.bool_]], flat: dict[int, NDArray[np.bool_]], ok: NDArray[np.bool_]
) -> bool:
    """Whether ``held_rows`` / ``held_jerk_rows`` can hold nothing: at every ``ok`` point at most one axis's row is
    not ``implied`` (their other rules hold one axis's row by another's), and no such row is ``flat`` (no term in
    the highest derivative, p or r: the rules of one row alone).  A straight line's points, where the parallel rows
    leave one axis's: a 0.5 mm G01 move ran them ~6 times, ~1.3 ms of its ~55 ms, to find nothing."""
    count = np.zeros(ok.size, dtype=np.int64)
    for ax, imp in implied.items():
        live = ok & ~imp
        if np.any(live & flat[ax]):
            return False
        count += live
    return bool(np.all(count <= 1))


def held_jerk_rows(
    acc: dict[int, tuple[FloatArray, FloatArray]], jerk: dict[int, tuple[FloatArray, FloatArray, FloatArray]],
    ub: FloatArray, plain: NDArray[np.bool_], implied: dict[int, NDArray[np.bool_]],
) -> dict[int, NDArray[np.bool_]]:
    r"""Stage-2 jerk rows that another axis's jerk row holds at their point, in the point's (q, p = q', r = q'').

    Axis x's pseudo-jerk row is |gamma_x q + delta_x p + eps_x r| <= 1 (``jerk[x]`` = (gamma, delta, eps): x_sss,
    1.5 x_ss and 0.5 x_s times sqrt(q*) / jmax).  The stage-1 rows at the same point (``held_rows``: those left
    out are held by the others) keep (q, p) in the box [0, U] x [p_lo, p_hi], U = ``ub`` (min of the velocity bound
    and q*), p_lo and p_hi from the acceleration slabs |alpha q + beta p| <= 1 (``acc[x]`` = (alpha, beta)): each
    slab's p-interval is linear in q, so over 0 <= q <= U it lies between its values at q = 0 and q = U; the box
    intersects them over the axes.  Row y is held by row x where x's interval of r lies inside y's for every
    (q, p) of the box: centres -(gamma q + delta p) / eps, half-widths 1 / |eps|, and the gap of the centres is
    |linear| (convex), so at the box's four corners, max |c_x - c_y| + 1 / |eps_x| <= 1 / |eps_y|.  A row with
    eps_y = 0 is held where max over the corners of |gamma_y q + delta_y p| <= 1.  Only at ``plain`` points
    (``WindowLP._plain_points``) with U finite; rows ``implied`` (``implied_rows``) neither count nor are counted
    on; margin HELD_ROW_MARGIN.  Flower loop with jerk: ~1/3 of the jerk rows.

    Returns:
        axis -> (K,) True where its jerk row is held.
    """
    K = ub.size
    axes = list(jerk)
    m = HELD_ROW_MARGIN
    held = {ax: np.zeros(K, dtype=bool) for ax in axes}
    ok = plain & np.isfinite(ub)
    if not ok.any() or _one_row_each(implied, {ax: jerk[ax][2] == 0.0 for ax in axes}, ok):
        return held
    U = np.where(ok, ub, 0.0)
    p_lo, p_hi = np.full(K, -np.inf), np.full(K, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for a, b in acc.values():
            ends = [(sgn - a * q) / b for sgn in (-1.0, 1.0) for q in (0.0, U)]
            on = b != 0.0
            p_lo = np.where(on, np.maximum(p_lo, np.minimum.reduce(ends)), p_lo)
            p_hi = np.where(on, np.minimum(p_hi, np.maximum.reduce(ends)), p_hi)
        ok &= np.isfinite(p_lo) & np.isfinite(p_hi)
        p_lo, p_hi = np.where(ok, p_lo, 0.0), np.where(ok, p_hi, 0.0)
        corners = [(q, p) for q in (0.0, U) for p in (p_lo, p_hi)]
        for y in axes:
            gy, dy, ey = jerk[y]
            h = (ey == 0.0) & (np.maximum.reduce([np.abs(gy * q + dy * p) for q, p in corners]) <= 1.0 - m)
            for x in axes:
                if x == y:
                    continue
                gx, dx, ex = jerk[x]
                live = ~implied[x] & ~held[x] & (ex != 0.0) & (ey != 0.0)
                gap = np.maximum.reduce([np.abs((gy * q + dy * p) / ey - (gx * q + dx * p) / ex) for q, p in corners])
                h |= live & (gap + 1.0 / np.abs(ex) <= (1.0 - m) / np.abs(ey))
            held[y] = ok & ~implied[y] & h
    return held


def axis_moves(g: PathSamples, ax: int) -> bool:
    """Whether axis ``ax`` moves along these points (else its rows are all zero)."""
    return bool(np.max(np.abs(g.d1[:, ax])) + np.max(np.abs(g.d2[:, ax])) > AXIS_EPS)


def _min_ratio(X: FloatArray, num: FloatArray, square: bool) -> FloatArray:
    """min over the axes of num / x where x > AXIS_EPS (inf elsewhere), x = X^2 (``square``) or |X| (K,)."""
    lib = native.library()
    if lib is not None:  # the same numbers, compiled (``solvers.native``)
        return native.min_ratio(lib, X, num, AXIS_EPS, square)
    x = X**2 if square else np.abs(X)
    with np.errstate(divide="ignore"):
        return np.asarray(np.min(np.where(x > AXIS_EPS, num[None, :] / x, np.inf), axis=1), dtype=np.float64)


def tangential_bound(X: FloatArray, limit: FloatArray) -> FloatArray:
    """min over the moving axes of limit_x / |X_x| (K,; inf where no axis moves): with X = x_s the bound on the
    tangential feed, acceleration or jerk that a per-axis limit sets where the path's curvature terms are left out."""
    return _min_ratio(X, limit, False)


#: Newton steps for the time t of a distance sigma from rest in ``reach_q`` (from above, within 26 % of t: 6 reach
#: the last place).
REACH_NEWTON_STEPS = 8


def _ramp(t: Any, a0: Any, J: Any) -> tuple[Any, Any]:
    """Distance (mm) and feed (mm/s) at time t of the fastest ramp from rest while under A: the step a0, then the
    jerk J: a0 t^2 / 2 + J t^3 / 6 and a0 t + J t^2 / 2 (floats or arrays)."""
    return t * t * (a0 / 2.0 + J * t / 6.0), t * (a0 + J * t / 2.0)


def reach_q(sig: FloatArray, a0: float, J: FloatArray, A: FloatArray) -> FloatArray:
    """``WindowLP._rest_reach``'s q (K,) at distances sig >= 0 from rest (K,), mm, with the step a0 (mm/s^2) and the
    bounds J (K,, mm/s^3) and A (K,, mm/s^2)."""
    a0v = np.minimum(a0, A)
    s1, v1 = _ramp((A - a0v) / J, a0v, J)  # (where the ramp meets A)
    q = v1 * v1 + 2.0 * A * (sig - s1)
    ramp = sig < s1
    if ramp.any():
        s, a, j = sig[ramp], a0v[ramp], J[ramp]
        with np.errstate(divide="ignore", invalid="ignore"):  # (a = 0: the jerk's term alone; s = 0: t = 0)
            t = np.minimum(np.cbrt(6.0 * s / j), np.where(a > 0.0, np.sqrt(2.0 * s / a), np.inf))
        for _ in range(REACH_NEWTON_STEPS):  # (sigma(t) convex and increasing for t >= 0: from above, monotone)
            sig_t, v = _ramp(t, a, j)
            t = np.where(v > 0.0, t - (sig_t - s) / np.where(v > 0.0, v, 1.0), t)
        q[ramp] = _ramp(t, a, j)[1] ** 2
    return np.asarray(q, dtype=np.float64)


def reach_distance(V: float, a0: float, J: float, A: float) -> float:
    """How far (mm) ``reach_q``'s ramp from rest (the step a0, the jerk J up to the acceleration A, then A) takes
    to reach the feed V (mm/s): no feed under those bounds reaches V sooner."""
    a0 = min(a0, A)
    s1, v1 = _ramp((A - a0) / J, a0, J)
    if V <= v1:
        t = (math.sqrt(a0 * a0 + 2.0 * J * V) - a0) / J
        return float(_ramp(t, a0, J)[0])
    return float(s1 + (V * V - v1 * v1) / (2.0 * A))


def s_curve(V: FloatArray, a0: float, J: FloatArray, A: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Time (s) and distance (mm) of the fastest ramp from rest to the feed V (K,, mm/s) that never passes V: the
    step a0 (mm/s^2), the jerk J (K,, mm/s^3) up to the acceleration a1 <= A (K,, mm/s^2), A held, then -J down to
    0 at V (the time-optimal jerk-limited ramp, the S-curve).  ``reach_q``'s ramp leaves out its last phase.

        a1 = min(A, sqrt((2 J V + a0^2) / 2))           (the peak acceleration)
        t1 = (a1 - a0) / J,  v1 = a0 t1 + J t1^2 / 2,  s1 = a0 t1^2 / 2 + J t1^3 / 6
        t2 = (V - a1^2 / (2 J) - v1) / a1,  v2 = v1 + a1 t2,  s2 = v1 t2 + a1 t2^2 / 2
        t3 = a1 / J,  s3 = v2 t3 + a1 t3^2 / 2 - J t3^3 / 6

    NaN where no such ramp is: the step alone overshoots (a0^2 / (2 J) > V), or a bound is not finite and > 0."""
    V, J, A = (np.asarray(x, dtype=np.float64) for x in (V, J, A))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        a0v = np.minimum(a0, A)
        a1 = np.minimum(A, np.sqrt((2.0 * J * V + a0v * a0v) / 2.0))
        t1 = (a1 - a0v) / J
        s1, v1 = _ramp(t1, a0v, J)
        v2 = V - a1 * a1 / (2.0 * J)
        t2 = np.maximum(0.0, (v2 - v1) / a1)
        s2 = t2 * (v1 + v2) / 2.0
        t3 = a1 / J
        s3 = t3 * (v2 + a1 * t3 / 2.0 - J * t3 * t3 / 6.0)
        ok = (np.isfinite(J) & np.isfinite(A) & np.isfinite(V) & (J > 0.0) & (A > 0.0) & (V > 0.0)
              & (a0v * a0v <= 2.0 * J * V))
    T = np.where(ok, t1 + t2 + t3, np.nan)
    D = np.where(ok, s1 + s2 + s3, np.nan)
    return np.asarray(T, dtype=np.float64), np.asarray(D, dtype=np.float64)


def _reach_travel(T: float, a0: float, J: float, A: float, V: float) -> float:
    """How far (mm) a feed from rest can get in T seconds under the step a0, the jerk J and the acceleration A
    (``reach_q``'s ramp, then A) and the feed V (at most V T)."""
    a0 = min(a0, A)
    t1 = min(T, (A - a0) / J) if J > 0.0 else 0.0
    s1, v1 = _ramp(t1, a0, J)
    dt = T - t1
    return float(min(s1 + dt * (v1 + A * dt / 2.0), V * T))


def velocity_bound(g: PathSamples, lim: LimitSet) -> FloatArray:
    """Upper bound on q at points g (K,): min(Fmax^2, programmed feed^2, min_x vmax_x^2 / x_s^2)."""
    ub = _min_ratio(g.d1, lim.vmax**2, True)
    if lim.feed_max is not None:
        ub = np.minimum(ub, lim.feed_max**2)
    if g.feed_limit is not None:
        ub = np.minimum(ub, g.feed_limit**2)
    return np.asarray(ub, dtype=np.float64)


def acceleration_bound(g: PathSamples, amax: FloatArray) -> FloatArray:
    """Upper bound on q at points g (K,) from the acceleration limits alone: the largest q for which some
    sddot holds every axis' |a_x| = |x_ss q + x_s sddot| <= amax_x (the maximum velocity curve of the
    acceleration rows; inf where nothing bounds it).

    An axis with x_s = 0 (|x_s| <= AXIS_EPS; x_ss too is read as 0 where under it) bounds q by amax / |x_ss|.
    An axis with x_s != 0 holds sddot in [-r q - w, -r q + w] (r = x_ss / x_s, w = amax / |x_s|), and two such
    intervals meet, for every pair (by Helly's theorem in one dimension, for all the axes), where
    |r_1 - r_2| q <= w_1 + w_2."""
    beta = g.d1
    alpha = np.where(np.abs(g.d2) <= AXIS_EPS, 0.0, g.d2)  # (rounding residues of a straight line's 0)
    still = np.abs(beta) <= AXIS_EPS
    safe = np.where(still, 1.0, beta)
    r = np.where(still, 0.0, alpha / safe)
    w = np.where(still, np.inf, amax[None, :] / np.abs(safe))
    with np.errstate(divide="ignore", invalid="ignore"):
        ub = np.min(np.where(still, amax[None, :] / np.abs(alpha), np.inf), axis=1)
        n_ax = beta.shape[1]
        for i in range(n_ax):
            for k in range(i + 1, n_ax):
                both = ~still[:, i] & ~still[:, k]
                pair = (w[:, i] + w[:, k]) / np.abs(r[:, i] - r[:, k])
                ub = np.minimum(ub, np.where(both, pair, np.inf))
    return np.asarray(np.where(np.isnan(ub), np.inf, ub), dtype=np.float64)


@dataclass(frozen=True)
class _ShapeRows:
    """The rest shapes (``bspline.rest_shapes``) at those of a basis' points that lie in a rest interval."""

    rows: IntArray  # (Kr,) the points' indices
    cols: IntArray  # (Kr,) the column of their rest end's first amplitude
    S: tuple[FloatArray, FloatArray, FloatArray]  # (Kr, REST_SHAPES) each: q, q', q'' per unit amplitude


#: The breaks whose velocity steps count (``WindowLP._vstep_live``): s (nl,), w_b (nl,), reach (nl,), q0 (nl,).
_LiveSteps = tuple[FloatArray, FloatArray, FloatArray, FloatArray]
#: ``bspline.basis`` at points (k, W0, W1, W2) and the rest shapes there (None: the window has none).
Basis = tuple[IntArray, FloatArray, FloatArray, FloatArray, _ShapeRows | None]


class WindowLP:
    r"""Builds and solves the two-stage LP of one window, with cutting planes.

    Columns: the window's control points c_k0 .. c_k1+1 (``WindowSpec.ncols``), then, with
    ``WindowSpec.rest_shapes``, the amplitudes (g, h_k) of each rest interval's shapes (the head's, then the
    tail's; ``bspline.REST_SHAPES`` each): there q = sum_j c_j B_j + g b + sum_k h_k e_k
    (``bspline.rest_shapes``: b = r (1 - r)^2, e_k = r^2 (1 - r)^k, r the unit distance from rest).  All are 0
    at rest and at the inner knot, where their slopes are 0 too, so q keeps its value and slope at both ends of
    the interval; the bump adds g / d to |q'| at rest.  On a quadratic alone the acceleration leaving rest
    rises linearly over the whole first interval, where the jerk-limited optimum reaches amax within
    micrometres (a 100 mm line on 64 intervals: 1.241 s against that optimum's closed-form 0.975 s); with the
    shapes (q a polynomial of degree 7 there) it rises within a fraction of the interval (1.052 s; 256
    intervals without them 1.106 s).
    """

    def __init__(
        self, spec: WindowSpec, lim: LimitSet, geometry: GeometryFn, solver: str, breaks: FloatArray | None = None,
        verify: FloatArray | None = None,
    ) -> None:
        """``breaks``: piece-local s where the geometry's third derivative may jump
        (NURBS knots); both sides of each are verified.  ``verify``: more piece-local s
        to verify (sampled points the pipeline found over a limit, ``solvers.verify``)."""
        self.breaks = np.zeros(0) if breaks is None else np.asarray(breaks, dtype=np.float64)
        self.verify = np.zeros(0) if verify is None else np.asarray(verify, dtype=np.float64)
        self.spec = spec
        self.lim = lim
        self.geometry = geometry
        self.solver = solver
        self.iterations = 0
        #: whether a lower floor is left to try if this model is infeasible (``solve``, ``_highs_run``)
        self.fallback_left = False
        self.Q = 1.0
        self._fine_g: tuple[FloatArray, PathSamples] | None = None
        self._check_g: tuple[FloatArray, PathSamples] | None = None
        self._step_cache: tuple[FloatArray, FloatArray, FloatArray] | None = None
        self._vstep_cache: FloatArray | None = None
        self._reach_cache: list[_ReachEnd] | None = None
        #: ``_break_qmax`` for the Q it was computed at, and ``_vstep_live`` per (axis, limit, kernel, power, Q):
        #: both read only the window's breaks, not the points asked about (a flower loop with jerk asked for
        #: them ~60 and ~40 times a schedule)
        self._qmax_cache: tuple[float, FloatArray] | None = None
        self._vstep_live_cache: dict[tuple[int, float, float, int, float], _LiveSteps | None] = {}
        #: ``_cap`` of the last geometry asked about, as (geometry, cap): the floor and the column scales both
        #: read the verification grid's
        self._cap_cache: tuple[PathSamples, FloatArray] | None = None
        #: ``velocity_bound`` of the last two geometries asked about (the checkpoints' and the verification
        #: grid's, asked for in turn), as (geometry, bound)
        self._ub_cache: list[tuple[PathSamples, FloatArray]] = []
        #: knot intervals after k0 on which the previous window's solution and q* are inherited
        self.inherited = INHERITED_INTERVALS
        #: the rest intervals with shapes: (head, knot interval, column of the first amplitude)
        self.shape_ends: list[tuple[bool, int, int]] = []
        if spec.rest_shapes and spec.start_fixed is None and spec.k0 == 0:  # (not a second chain's start at rest)
            self.shape_ends.append((True, spec.k0, spec.ncols))
        if spec.rest_shapes and spec.end_rest:
            self.shape_ends.append((False, spec.k1 - 1, spec.ncols + bspline.REST_SHAPES * len(self.shape_ends)))
        #: columns: the control points, then the shapes' amplitudes
        self.nvar = spec.ncols + bspline.REST_SHAPES * len(self.shape_ends)

    # ----- row blocks ---------------------------------------------------------
    def _basis(self, s: FloatArray) -> Basis:
        """``bspline.basis`` at s in this window, k (K,), W0, W1, W2 (K, 3), and the rest shapes at those of
        the points in a rest interval with shapes (``shape_ends``; ``bspline.on_rest_interval``, as where
        ``timing.PieceProfile._bumped`` adds them)."""
        sp_ = self.spec
        k, W0, W1, W2 = bspline.basis(s, sp_.d, sp_.n_int, sp_.k0, sp_.k1 - 1)
        if not self.shape_ends:
            return k, W0, W1, W2, None
        rows, cols, S = [], [], []
        for head, kr, col in self.shape_ends:
            at = np.flatnonzero(bspline.on_rest_interval(s, sp_.d, kr, head))
            rows.append(at)
            cols.append(np.full(at.size, col, dtype=np.int64))
            S.append(bspline.rest_shapes(s[at], sp_.d, kr, head))
        shapes = _ShapeRows(np.concatenate(rows), np.concatenate(cols),
                            (np.concatenate([x[0] for x in S]), np.concatenate([x[1] for x in S]),
                             np.concatenate([x[2] for x in S])))
        return k, W0, W1, W2, shapes

    def _mats(self, s: FloatArray) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
        """The designs B0, B1, B2 of q, q', q'' at s."""
        basis = self._basis(s)
        one, zero = np.ones(s.size), np.zeros(s.size)
        return self._combo(basis, one), self._combo(basis, zero, one), self._combo(basis, zero, zero, one)

    def _combo(self, basis: Basis, *coef: FloatArray) -> sp.csr_matrix:
        """sum_i diag(coef_i) B_i (B_0, B_1, B_2 the designs of q, q', q'' at the basis' points), as CSR
        (nvar columns: the rest shapes' amplitudes after the control points)."""
        k, W0, W1, W2, shapes = basis
        spec = self.spec
        terms = list(zip(coef, (W0, W1, W2), strict=False))
        if shapes is None or shapes.rows.size == 0:  # (the amplitudes' columns, if any, empty)
            return bspline.combination(k, terms, spec.k0, self.nvar)
        K = k.size
        data3 = bspline.combination_data(terms).ravel()
        cols3 = bspline.design_columns(k, spec.k0)
        data = sum(a[shapes.rows, None] * S for a, S in zip(coef, shapes.S, strict=False))
        nr = bspline.REST_SHAPES
        # One CSR from the B-spline's three entries a row and the shapes' amplitudes (columns after every
        # control point), each row's columns ascending: what hstack([combination, E]) gave, without scipy's
        # per-matrix overhead (three matrices built and checked a call; _combo was ~20 % of a flower loop's LP
        # with jerk)
        r = np.concatenate([np.repeat(np.arange(K), 3), np.repeat(shapes.rows, nr)])
        c = np.concatenate([cols3, (shapes.cols[:, None] + np.arange(nr)[None, :]).ravel()])
        order = np.lexsort((c, r))
        indptr = np.concatenate([[0], np.cumsum(np.bincount(r, minlength=K))])
        v = np.concatenate([data3, np.asarray(data, dtype=np.float64).ravel()])
        itype = _index_type(v.size, self.nvar)
        return csr.make(v[order], c[order].astype(itype), indptr.astype(itype), (K, self.nvar))

    def _add_needed(self, rows: _Rows, A: sp.csr_matrix, s: FloatArray, need: NDArray[np.bool_]) -> None:
        """Rows -1 <= A chat <= 1 at the points s where ``need`` (the others are implied, ``implied_rows``)."""
        if need.all():
            self._add(rows, A, -np.ones(s.size), np.ones(s.size), s)
        elif need.any():
            k = int(need.sum())
            self._add(rows, select_rows(A, need), -np.ones(k), np.ones(k), s[need])

    def _add(self, rows: _Rows, A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, s: FloatArray) -> None:
        """Add rows at points s; on inherited intervals widen them to admit the previous solution (and on
        the last ones before a seam window's fixed end, the next one)."""
        rows.add(A, *self._widened(A, lo, hi, s))

    def _widened(
        self, A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, s: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """``_add``'s bounds of rows A at points s."""
        spec = self.spec
        if spec.prev_c is not None:
            near = s < self._inherited_end(spec.prev_c) * spec.d
            if near.any():
                k_prev, c_prev = spec.prev_c
                x = np.zeros(self.nvar)  # (no rest shapes where a previous solution is inherited)
                m = min(spec.ncols, c_prev.size - (spec.k0 - k_prev))
                x[:m] = c_prev[spec.k0 - k_prev : spec.k0 - k_prev + m] / self.Q
                lo, hi = _admit(A, lo, hi, near, x)
        if spec.next_c is not None:
            near = s > self._next_start(spec.next_c) * spec.d
            if near.any():
                k_next, c_next = spec.next_c
                x = np.zeros(self.nvar)
                a = max(0, k_next - spec.k0)  # (the next solution's columns from the window's, or later)
                x[a : spec.ncols] = c_next[spec.k0 + a - k_next : spec.k0 + spec.ncols - k_next] / self.Q
                lo, hi = _admit(A, lo, hi, near, x)
        return lo, hi

    def _stage1_rows(
        self, rows: _Rows, g: PathSamples, Q: float, qstar: FloatArray | None, velocity_only: bool = False,
        record: bool = False,
    ) -> None:
        """Velocity (q <= ub: the velocity bound, and q* with ``qstar``) and acceleration rows at points g.

        ``record``: the velocity rows' block is kept in ``rows.velocity_rows`` (stage 1 at its row points).  With
        ``velocity_only`` (stage 2 going on in stage 1's model at the same points) the acceleration rows, there
        already and not depending on q*, are not added again, and the recorded velocity rows get the bound
        q <= min(ub, q*) in place; only points without one (held in stage 1, not under q*) get new rows."""
        ub = self._velocity_bound(g)
        if qstar is not None:
            ub = np.minimum(ub, np.maximum(qstar, 0.0))
        rest = self._rest_mask(g.s)
        if rest.any():
            gr = g.subset(rest)
            ub_r = np.minimum(ub[rest], self._rest_feed_cap(gr) ** 2)
            self._add(rows, self._mats(gr.s)[0], np.zeros(ub_r.size), ub_r / Q, gr.s)
            self._rest_drive_rows(rows, gr, Q, np.sqrt(ub_r), None)
            g, ub = g.subset(~rest), ub[~rest]
            if g.s.size == 0:
                return
        basis = self._basis(g.s)
        moving = [ax for ax in range(3) if axis_moves(g, ax)]
        # a = x_ss q + x_s q' / 2 per axis: |alpha q + beta q'| <= 1, alpha = x_ss / amax, beta = x_s / (2 amax)
        alpha = {ax: g.d2[:, ax] / self.lim.amax[ax] for ax in moving}
        beta = {ax: 0.5 * g.d1[:, ax] / self.lim.amax[ax] for ax in moving}
        implied = implied_rows({ax: np.column_stack([alpha[ax], beta[ax]]) for ax in moving})
        v_held, a_held = held_rows(alpha, beta, ub, self._plain_points(g.s), implied) if POINT_HELD_ROWS else (
            np.zeros(ub.size, dtype=bool), {ax: np.zeros(ub.size, dtype=bool) for ax in moving})
        V = self._combo(basis, np.ones(ub.size))
        rec = rows.velocity_rows if velocity_only else None
        if rec is not None and rec[1].size == ub.size:
            block, had = rec
            lo_h, hi_h = self._widened(select_rows(V, had), np.zeros(int(had.sum())), ub[had] / Q, g.s[had])
            rows.change_bounds(block, lo_h, hi_h)
            v_held = v_held | had  # (those points have their row)
        if v_held.any():
            V, ub_v, s_v = select_rows(V, ~v_held), ub[~v_held], g.s[~v_held]
        else:
            ub_v, s_v = ub, g.s
        n_blocks = len(rows.blocks)
        self._add(rows, V, np.zeros(ub_v.size), ub_v / Q, s_v)
        if record:
            rows.velocity_rows = (n_blocks, ~v_held) if len(rows.blocks) > n_blocks else None
        for ax in [] if velocity_only else moving:
            A = self._combo(basis, g.d2[:, ax], 0.5 * g.d1[:, ax])
            A.data *= Q / self.lim.amax[ax]  # (a fresh matrix: A * scale's entries, without its copy)
            self._add_needed(rows, A, g.s, ~(implied[ax] | a_held[ax]))
            self._add_coupled(rows, A, g.s, self._vstep_coupling(g.s, ax, self.lim.amax[ax], V_KERNEL_A, 1))

    def _plain_points(self, s: FloatArray) -> NDArray[np.bool_]:
        """Points s (K,) where q >= 0 follows from the column bounds (outside a rest end's knot interval, whose
        outer control point and rest shapes are free) and whose rows ``_add`` keeps as they are (outside the
        intervals where they are widened to admit an inherited solution): where ``held_rows`` may leave rows out."""
        spec = self.spec
        out = np.ones(s.size, dtype=bool)
        if spec.start_fixed is None:
            out &= s >= (spec.k0 + 1) * spec.d
        if spec.end_rest:
            out &= s <= (spec.k1 - 1) * spec.d
        if spec.prev_c is not None:
            out &= s >= self._inherited_end(spec.prev_c) * spec.d
        if spec.next_c is not None:
            out &= s <= self._next_start(spec.next_c) * spec.d
        return out

    def _rest_mask(self, s: FloatArray) -> NDArray[np.bool_]:
        """Points s (K,) in the REST_DRIVE_INTERVALS knot intervals next to a rest end of the piece, where the
        drive's rows replace the acceleration and jerk rows (``LimitSet.rest_drive``)."""
        spec = self.spec
        out = np.zeros(s.size, dtype=bool)
        if self.lim.rest_drive is None:
            return out
        k = REST_DRIVE_INTERVALS
        if spec.start_fixed is None:
            out |= s < (spec.k0 + k) * spec.d
        if spec.end_rest:
            out |= s > (spec.k1 - k) * spec.d
        return out

    def _rest_feed_cap(self, g: PathSamples) -> FloatArray:
        """Largest feed F (K,) at points g next to a rest end for which, on every axis, b |x_s| F <=
        REST_FEED_BUDGET umax and Kv |x_s| F <= REST_FEED_BUDGET REST_DRIVE_SHARE emax."""
        dr = self.lim.rest_drive
        assert dr is not None  # (only called where _rest_mask found points)
        xs = np.abs(g.d1)
        with np.errstate(divide="ignore"):
            fu = np.where(xs * dr["b"] > 0, REST_FEED_BUDGET * dr["umax"] / (xs * dr["b"]), np.inf)
            fe = np.where(xs * dr["Kv"] > 0, REST_FEED_BUDGET * REST_DRIVE_SHARE * dr["emax"] / (xs * dr["Kv"]), np.inf)
        return np.minimum(kinematics.row_min(fu), kinematics.row_min(fe))

    def _rest_drive_rows(self, rows: _Rows, g: PathSamples, Q: float, R: FloatArray, qstar: FloatArray | None) -> None:
        r"""Control signal and servo error rows at points g next to a rest end (lp+nlp: those knot intervals
        keep the LP's feed, so they hold the NLP's limits, not the LP's v, a, j caps).

        With a = x_ss q + x_s q' / 2 and X = x_sss q + 1.5 x_ss q' + 0.5 x_s q'' (both linear in c), the
        true v = x_s r and j = r X with r = sqrt(q) in [0, R] (q <= R^2 is a row), so

            u(r) = M a + b x_s r + c + d sigma,   e(r) = Ka a + r (Kv x_s + Kj X)

        are linear in r: |u| <= umax and |e| <= E = REST_DRIVE_SHARE emax hold for every r in [0, R] if
        they hold at r = 0 and r = R, four linear rows per axis (sigma = sign(x_s), both signs where
        |x_s| < SIGN_EPS).  Without qstar (stage 1) X is left out of e(R) (stage 1 is v + a), with
        it (stage 2: ``_jerk_rows``) R = sqrt(q*) >= r.  (Stage 2 re-adds stage 1's rows, so its e(R) row
        without X stays too: a little conservative, not needed for the bound.)"""
        dr = self.lim.rest_drive
        assert dr is not None
        basis = self._basis(g.s)
        for ax in range(3):
            if not axis_moves(g, ax):
                continue
            xs = g.d1[:, ax]
            A = self._combo(basis, g.d2[:, ax], 0.5 * xs) * Q
            unsure = np.abs(xs) < SIGN_EPS
            sg_hi = np.where(unsure, 1.0, np.sign(xs))
            sg_lo = np.where(unsure, -1.0, np.sign(xs))
            um, E = dr["umax"][ax], REST_DRIVE_SHARE * dr["emax"][ax]
            cf = dr["c"][ax]
            if qstar is None:
                one = np.ones(g.s.size)
                self._add(rows, A * (dr["Ka"][ax] / E), -one, one, g.s)
                self._add(rows, A * (dr["M"][ax] / um), (-um - cf - dr["d"][ax] * sg_lo) / um,
                          (um - cf - dr["d"][ax] * sg_hi) / um, g.s)
                vr = dr["b"][ax] * xs * R
                self._add(rows, A * (dr["M"][ax] / um), (-um - cf - dr["d"][ax] * sg_lo - vr) / um,
                          (um - cf - dr["d"][ax] * sg_hi - vr) / um, g.s)
                er = dr["Kv"][ax] * xs * R
                self._add(rows, A * (dr["Ka"][ax] / E), (-E - er) / E, (E - er) / E, g.s)
            else:
                X = self._combo(basis, g.d3[:, ax], 1.5 * g.d2[:, ax], 0.5 * xs) * Q
                er = dr["Kv"][ax] * xs * R
                self._add(rows, (A * dr["Ka"][ax] + sp.diags(R * dr["Kj"][ax]) @ X) / E, (-E - er) / E,
                          (E - er) / E, g.s)

    def _jerk_rows(self, rows: _Rows, g: PathSamples, Q: float, qstar: FloatArray) -> None:
        ub = self._velocity_bound(g)  # (the stage-1 rows' at the same points: kept, not computed again)
        rest = self._rest_mask(g.s)
        if rest.any():
            gr = g.subset(rest)
            R = np.sqrt(np.minimum(np.maximum(qstar[rest], 0.0), self._rest_feed_cap(gr) ** 2))
            self._rest_drive_rows(rows, gr, Q, R, qstar[rest])
            g, qstar, ub = g.subset(~rest), qstar[~rest], ub[~rest]
            if g.s.size == 0:
                return
        keep = np.sqrt(np.maximum(qstar, 0.0)) > TINY_SQRT_QSTAR * np.sqrt(Q)
        if not keep.any():
            return
        g, ub = g.subset(keep), ub[keep]
        rq = np.sqrt(qstar[keep])
        basis = self._basis(g.s)
        moving = [ax for ax in range(3) if axis_moves(g, ax)]
        # pseudo-jerk sqrt(q*) (x_sss q + 1.5 x_ss q' + 0.5 x_s q''): the row of (x_sss, 1.5 x_ss, 0.5 x_s) / jmax
        implied = implied_rows({ax: np.column_stack([g.d3[:, ax], 1.5 * g.d2[:, ax], 0.5 * g.d1[:, ax]])
                                / self.lim.jmax[ax] for ax in moving})
        if POINT_HELD_ROWS:
            jmax = self.lim.jmax
            held = held_jerk_rows(
                {ax: (g.d2[:, ax] / self.lim.amax[ax], 0.5 * g.d1[:, ax] / self.lim.amax[ax]) for ax in moving},
                {ax: (g.d3[:, ax] * rq / jmax[ax], 1.5 * g.d2[:, ax] * rq / jmax[ax], 0.5 * g.d1[:, ax] * rq / jmax[ax])
                 for ax in moving},
                np.minimum(ub, qstar[keep]), self._plain_points(g.s), implied)
            implied = {ax: implied[ax] | held[ax] for ax in moving}
        for ax in moving:
            J = self._combo(basis, g.d3[:, ax], 1.5 * g.d2[:, ax], 0.5 * g.d1[:, ax])
            A = csr.make(J.data * np.repeat(rq * Q / self.lim.jmax[ax], np.diff(J.indptr)), J.indices, J.indptr,
                         J.shape)
            # next to a curvature jump, |j| + the step's share <= jmax (``_step_jerk``); next to a
            # tangent break, + the velocity step's impulse (``_vstep_coupling``): one row holds both
            parts = [self._vstep_coupling(g.s, ax, self.lim.jmax[ax], V_KERNEL_J, 2)]
            step = self._step_jerk(g.s, ax)
            if step is not None:
                # each break charged its share at its cap, a constant (``_step_crowd_factor``: at most
                # STEP_CONST_TOTAL at any point)
                near, M = step
                const = np.asarray(M @ self._break_qmax(), dtype=np.float64)
                parts.append((near, sp.csr_matrix((int(near.sum()), self.nvar)), const))
            coup = _union(g.s.size, parts)
            if coup is not None and coup[1].nnz == 0:  # constants only: one row |A chat| <= 1 - const at those points
                near, _, const = coup
                self._add_needed(rows, A, g.s, ~implied[ax] & ~near)
                self._add(rows, A[near], const - 1.0, 1.0 - const, g.s[near])
            else:
                self._add_needed(rows, A, g.s, ~implied[ax])
                self._add_coupled(rows, A, g.s, coup)

    def _rest_rows(self, rows: _Rows, s_rest: float, sign: float, Q: float, a_rest: FloatArray | None) -> float:
        """q(s_rest) = 0 and sign * q'(s_rest) * max_x(|x_s|/(2 a_rest_x)) <= 1 (a_rest: default lim.a_rest).
        Returns the largest control point next to the rest end these allow (q' = 2 c / d there), mm^2/s^2."""
        g = self._known_geometry(np.array([s_rest]))
        B0, B1, _ = self._mats(g.s)
        rows.add(B0, np.zeros(1), np.zeros(1))
        r = float(np.max(np.abs(g.d1[0]) / (2.0 * (self.lim.a_rest if a_rest is None else a_rest))))
        # (the feed leaves rest: q' >= 0 there, which c >= 0 gives without the rest shapes, whose bump moves it)
        # (with ``WindowSpec.rest_step_floor``, at least REST_STEP_FLOOR_SHARE of its step)
        lo = (REST_STEP_FLOOR_SHARE if self.spec.rest_step_floor else 0.0) if self.shape_ends else -np.inf
        rows.add(B1 * (sign * Q * r), np.array([lo]), np.ones(1))
        return self.spec.d / (2.0 * r) if r > 0.0 else np.inf

    def _row_points(self, s_check: FloatArray) -> FloatArray:
        """The points where the LP's rows are (sorted): the checkpoints, and in each rest interval with shapes
        REST_SHAPE_POINTS more across it and REST_SHAPE_ZOOM at d 2^-k from rest, k = 1 .. REST_SHAPE_ZOOM.

        The shapes make q a polynomial of degree 7 there (the quadratic's checkpoints alone let it swing
        between them: stage 1, v + a, set the acceleration to 25 x amax at 1e-4 of the interval from rest,
        with amplitudes ~1e3 Q that the rows at its verification points, their rises' coefficients ~r^2
        dropped as TINY_COEF, did not hold back), and the feed leaves rest within micrometres."""
        if not self.shape_ends:
            return s_check
        spec = self.spec
        r = np.concatenate([np.arange(1, REST_SHAPE_POINTS + 1) / (REST_SHAPE_POINTS + 1.0),
                            2.0 ** -np.arange(1, REST_SHAPE_ZOOM + 1), REST_ROW_R])
        more = [spec.d * r if head else (kr + 1 - r) * spec.d for head, kr, _ in self.shape_ends]
        return np.unique(np.concatenate([s_check, *more]))

    def _eval(self, c: FloatArray, s: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """q, q', q'' at piece-local s of a window's solution c (nvar,: control points, then the rest shapes'
        amplitudes)."""
        spec = self.spec
        q3 = bspline.evaluate(c[: spec.ncols], s, spec.d, k_lo=spec.k0, k_hi=spec.k1 - 1, col0=spec.k0)
        for head, kr, col in self.shape_ends:
            amp = c[col : col + bspline.REST_SHAPES]
            bspline.add_rest_bump(q3, s, spec.d, kr, head, float(amp[0]), tuple(float(x) for x in amp[1:]))
        return q3

    def _shapes(self, c: FloatArray) -> tuple[FloatArray | None, FloatArray | None]:
        """The rest shapes' amplitudes (head, tail) in a window's solution c (nvar,), None where there are none."""
        out: list[FloatArray | None] = [None, None]
        for head, _, col in self.shape_ends:
            out[0 if head else 1] = np.array(c[col : col + bspline.REST_SHAPES], dtype=np.float64)
        return out[0], out[1]

    def _next_start(self, nxt: tuple[int, FloatArray]) -> int:
        """The knot from which a seam window's next solution ``nxt`` = (k0_next, control points) is
        inherited: ``self.inherited`` intervals before k1, within that solution."""
        return max(self.spec.k1 - self.inherited, nxt[0])

    def _inherited_end(self, prev: tuple[int, FloatArray]) -> int:
        """The knot up to which the previous window's ``prev`` = (k0_prev, control points) is inherited:
        ``self.inherited`` intervals after k0, within the previous window."""
        k_prev, c_prev = prev
        return min(self.spec.k0 + self.inherited, k_prev + c_prev.size - 2)

    def _qstar(self, c_star: FloatArray, s: FloatArray) -> FloatArray:
        """q*(s) of this window, or of the previous window on the inherited intervals."""
        spec = self.spec
        q = self._eval(c_star, s)[0]
        if spec.prev_qstar is not None:
            k_prev, c_prev = spec.prev_qstar
            near = s < self._inherited_end(spec.prev_qstar) * spec.d
            if near.any():
                q[near] = bspline.evaluate(
                    c_prev, s[near], spec.d, k_lo=spec.k0, k_hi=spec.k1 - 1, col0=k_prev
                )[0]
        if spec.next_qstar is not None:
            k_next, c_next = spec.next_qstar
            near = s > self._next_start(spec.next_qstar) * spec.d
            if near.any():
                q[near] = bspline.evaluate(
                    c_next, s[near], spec.d, k_lo=spec.k0, k_hi=spec.k1 - 1, col0=k_next
                )[0]
        return q

    def _capped_qstar(self, c_star: FloatArray, g: PathSamples) -> FloatArray:
        """Stage 2's q* at the points g (K,): ``_qstar``, but at most QSTAR_JERK_CAP x the q at which the jerk's
        curvature term alone reaches jmax, min over the axes of (jmax / |x_sss|)^(2/3).

        The pseudo-jerk row sqrt(q*) (x_sss q + 1.5 x_ss q' + 0.5 x_s q'') <= jmax holds the true jerk
        sqrt(q) (...) for any q* >= q (stage 2 has q <= q*), and is the more conservative the further q* is above
        the q it ends with.  Stage 1 (v and a only) can leave q* many times above what the jerk allows: bench
        seed 1864 (lp), q* ~4e9 mm^2/s^2 (65 m/s) over a knot span with |x_sss| = 0.08 /mm^2, where the row read
        q <= 6.5e6 (2.5 m/s, the true bound 7.5 m/s), and on 3.6 mm knots the feed dipped from 14.7 m/s to
        1.0 m/s around it (0.07 m/s with the turn check, ``_check_geometry``) with no limit above 0.2 of its
        value there."""
        q = self._qstar(c_star, g.s)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            cap = QSTAR_JERK_CAP * _min_ratio(g.d3, self.lim.jmax, False) ** (2.0 / 3.0)
        q = np.minimum(q, cap)
        if QSTAR_REST_REACH > 0.0 and self.lim.rest_reach:
            q = np.minimum(q, QSTAR_REST_REACH * self._rest_reach(g.s, self._reach_ends(g)))
        return np.asarray(q, dtype=np.float64)

    def _rest_reach(self, s: FloatArray, ends: list[_ReachEnd]) -> FloatArray:
        r"""The largest q (K,) a feed leaving (or reaching) the window's rest ends can have at the points s (K,), inf
        where the window has no rest end, mm^2/s^2 (times ``_step_reach_factor`` near a corner, and near a path end
        with ``LimitSet.rest_reach_ends``).

        At a distance sigma from rest, with the tangential bounds a_0 on the acceleration step at rest (the rest
        row's: min_x a_rest_x / |x_s,x| at the rest point), A on the acceleration and J on the jerk (min_x amax_x
        / |x_s,x|, jmax_x / |x_s,x|, their largest from the rest end to the point), the fastest feed is the one
        that steps to a_0 and ramps at J to A, then holds A:

            sigma = a_0 t^2 / 2 + J t^3 / 6,  v = a_0 t + J t^2 / 2          for t <= t_1 = (A - a_0) / J,
            q = v(t_1)^2 + 2 A (sigma - sigma(t_1))                             beyond,

        and q = v^2 (t from sigma by Newton's method from above).  No feed under those bounds is faster at any
        sigma (a brute-force search over piecewise-constant jerks: at most 0.99986 of it); curvature terms of the
        axes' jerk are left out (an estimate near rest, where the feed is small).  The bounds come from the first
        points the window is asked about (its row points, ``_reach_ends``: ``ends``) and are read at the first of
        those at or beyond each point."""
        out = np.full(s.size, np.inf)
        for s_rest, sign, a0, sig_grid, J_run, A_run, factor, near in ends:
            sig = sign * (s - s_rest)
            at = np.minimum(np.searchsorted(sig_grid, sig, side="left"), sig_grid.size - 1)
            reach = reach_q(np.maximum(sig, 0.0), a0, J_run[at], A_run[at])
            if factor != 1.0:  # (within 3 Ts of travel of a corner, or of any rest end: ``_step_reach_factor``)
                reach = np.where(sig <= near, factor * reach, reach)
            out = np.minimum(out, np.where(sig < 0.0, np.inf, reach))
        return out

    def _step_reach_factor(self, kernel: float) -> float:
        """How many times the reach (``_rest_reach``) q* may be within 3 Ts of travel of a rest end whose
        acceleration step adds up to ``kernel`` step / Ts to the samples' third differences: 1 / (1 - share)^2,
        share the largest over the axes of kernel a_rest_x / (Ts jmax_x) (1 without sampled jerk rows).  At a
        corner kernel = STEP_KERNEL (share at most 3/8, factor 2.56); at a path end END_STEP_KERNEL (at most
        0.105, factor 1.25), only with ``LimitSet.rest_reach_ends``: a piece's first repair round.

        A third difference of the samples whose span (3 Ts) holds a corner's rest instant sees the jerk on both
        sides plus up to STEP_KERNEL |step| / Ts, the axis acceleration stepping by up to a_rest_x across the
        corner, both sides together (``pipeline._corner_rest``; ``_step_jerk``'s kernel).  With q* the reach the
        feed left and reached corners at the jerk bound, and the samples read up to 1.14 x jmax there (bench seeds
        0-149, lp); a repair round solves only the piece after the corner (seed 30: 1.019 x after both).  With q*
        at most this factor over the reach there the jerk rows over-read the jerk by at least 1 / (1 - share) while
        q is at most the reach (always), which leaves the step its share, as stage 1's q* did (~3x at the step's
        end).  Travel from rest within 3 Ts is bounded by the fastest ramp (``_reach_travel``).  The factor
        everywhere cost the square corner 0.7 % (1.0621 -> 1.0700 s); rows holding the share within 3 Ts of travel
        cost fast machines' short paths up to 30 % (bench seeds 10, 59: a coarser knot plan won)."""
        Ts = self.lim.step_jerk_period
        if Ts is None:
            return 1.0
        share = float(np.max(kernel * self.lim.a_rest / (Ts * self.lim.jmax)))
        return 1.0 / (1.0 - min(share, 0.5)) ** 2

    def _reach_ends(self, g: PathSamples) -> list[_ReachEnd]:
        """Per rest end of the window (kept from the first call, on the row points): (its s, +1 at a start, -1
        at an end, a_0, the points' distances from it ascending (K,), the running largest J and A there (K,), the
        factor on the reach (``_step_reach_factor``: at a corner; at a path end with ``LimitSet.rest_reach_ends``,
        else 1) and the distance from rest it applies within: 3 Ts of travel, ``_reach_travel`` with the window's
        largest J and A and feed sqrt(Q))."""
        if self._reach_cache is not None:
            return self._reach_cache
        spec, lim = self.spec, self.lim
        ends: list[tuple[float, float, FloatArray | None]] = []
        if spec.start_fixed is None:
            ends.append((spec.k0 * spec.d, 1.0, spec.a_rest_start))
        if spec.end_rest:
            ends.append((spec.k1 * spec.d, -1.0, spec.a_rest_end))
        out = []
        for s_rest, sign, a_rest in ends:
            sig = sign * (g.s - s_rest)
            order = np.argsort(sig, kind="stable")
            x_s = g.d1[order]
            J = np.maximum.accumulate(_min_ratio(x_s, lim.jmax, False))
            A = np.maximum.accumulate(_min_ratio(x_s, lim.amax, False))
            g_rest = self._known_geometry(np.array([s_rest]))
            a0 = float(_min_ratio(g_rest.d1, lim.a_rest if a_rest is None else a_rest, False)[0])
            if a_rest is not None:
                factor = self._step_reach_factor(STEP_KERNEL)  # (a corner)
            else:
                factor = self._step_reach_factor(END_STEP_KERNEL) if lim.rest_reach_ends else 1.0  # (a path end)
            Ts = lim.step_jerk_period
            near = (0.0 if factor == 1.0 or Ts is None
                    else _reach_travel(3.0 * Ts, a0, float(J[-1]), float(A[-1]), math.sqrt(self.Q)))
            out.append((s_rest, sign, a0, sig[order], J, A, factor, near))
        self._reach_cache = out
        return out

    # ----- solve -------------------------------------------------------------
    def solve(self, s_check: FloatArray) -> WindowResult:
        spec = self.spec
        self._fine_geometry(s_check)  # first: the rows' points, the breaks and the window's ends are on its grid
        g = self._known_geometry(self._row_points(s_check))
        # scale of q: the largest velocity bound, but no more than the q reachable from rest over
        # the whole piece (q' = 2 sddot <= 2 |amax|, and the jerk's bound): with limits far above what a short piece can
        # use (v^2 / a >> L) the velocity bound alone left acceleration rows with coefficients
        # ~1e9 and HiGHS returned no status
        L = spec.n_int * spec.d
        # (|sddot| = |x_s . a| <= the norm of the moving axes' amax: an axis the window does not move has a = 0;
        # with all three a machine whose x is 1e6 x slower than y and z scaled an x line's q to ~5e-7 of Q, under
        # HiGHS's tolerances: its acceleration rows gave way (2.11 x amax) through every cut round, session 59)
        moving = np.array([axis_moves(g, ax) or not Q_REACH_MOVING_AXES for ax in range(3)])
        moving = moving if moving.any() else np.ones(3, dtype=bool)
        Q_reach = 2.0 * float(np.linalg.norm(self.lim.amax[moving])) * L
        if self.lim.jerk:  # from rest under jerk j: s = j t^3 / 6, v = j t^2 / 2
            j = float(np.linalg.norm(self.lim.jmax))
            Q_reach = min(Q_reach, 4.0 * (0.5 * j) ** (2.0 / 3.0) * (6.0 * L) ** (4.0 / 3.0))
        Q = float(min(np.max(np.minimum(self._velocity_bound(g), 1e300)), Q_reach))
        self.Q = Q
        if not np.isfinite(Q) or Q <= 0:
            raise InfeasibleError("window has no positive velocity bound", window=spec.index)
        n = spec.ncols
        # objective: maximise integral q = sum w_j c_j; only its direction matters, so it is
        # normalised (with Q ~ 1e8 the raw weights made HiGHS's dual simplex fail, status NotSet)
        w_raw = bspline.integral_weights(spec.k0, spec.k1, spec.d, spec.k0, n)
        # q >= 0 everywhere, not only at checkpoints: the B-spline basis is non-negative, so
        # c >= 0 suffices (the rows keep q >= 0 only at checkpoints, and q dipping below 0
        # between them stalls the feed inside the path).  The control point outside a rest end
        # is -c of its neighbour (q = 0 there with q' != 0), so it stays free.
        col_lo = np.zeros(n)
        col_hi = np.full(n, np.inf)
        floor_cols = np.ones(n, dtype=bool)
        if spec.start_fixed is not None:
            col_lo[:2] = col_hi[:2] = np.asarray(spec.start_fixed) / Q
            floor_cols[:2] = False
        else:
            col_lo[0] = -np.inf
            floor_cols[:2] = False
        if spec.end_rest:
            col_lo[-1] = -np.inf
        elif spec.end_fixed is not None:
            col_lo[-2:] = col_hi[-2:] = np.asarray(spec.end_fixed) / Q
        else:
            col_lo[-2:] = col_hi[-2:] = 0.0
        floor_cols[-2:] = False
        if self.shape_ends:  # the rest shapes' amplitudes: free, no floor, their integrals in the objective
            n_ext = self.nvar - n
            col_lo = np.concatenate([col_lo, np.full(n_ext, -np.inf)])
            col_hi = np.concatenate([col_hi, np.full(n_ext, np.inf)])
            floor_cols = np.concatenate([floor_cols, np.zeros(n_ext, dtype=bool)])
            w_raw = np.concatenate([w_raw, np.tile(bspline.rest_shape_integrals(spec.d), len(self.shape_ends))])
        w = w_raw / float(np.max(np.abs(w_raw)))

        base = _Rows(self.nvar)
        g_fine = self._fine_geometry(s_check)
        base.col_scale = self._col_scale(g_fine, Q)
        rest_c: list[tuple[int, float]] = []  # (column next to a rest end, its largest value)
        if spec.start_fixed is None:
            rest_c.append((1, self._rest_rows(base, spec.k0 * spec.d, 1.0, Q, spec.a_rest_start)))
        if spec.end_rest:
            rest_c.append((n - 2, self._rest_rows(base, spec.k1 * spec.d, -1.0, Q, spec.a_rest_end)))

        step_cap = self._step_rows(base, Q)
        # Away from the rest ends q is kept above a small floor (a constant feed that meets every
        # limit at every checkpoint): with knots coarser than a sharp turn, the optimum of
        # integral q otherwise lets q touch 0 at a knot (two zero control points), where the
        # time 1 / sqrt(q) diverges and the feed stalls.  Next to a rest end the slope q' there
        # (c_1 = d q' / 2) gets the same floor, or FLOOR_SHARE of what a_rest allows if smaller:
        # a turn inside the first knot interval made integral q larger with c_1 = 0 and c_2 at
        # the turn's cap (q = c_2 tau^2 / 2), and a feed leaving rest with q' = 0 never leaves
        # (bench seed 14; only with ``spec.rest_floor``).  If the floor makes the window
        # infeasible (an inherited start below it), it is dropped.
        col_hi = self._implied_col_hi(g, Q, col_lo, col_hi, base.col_scale)
        floor = min(self._floor(g_fine), FLOOR_SHARE * step_cap)
        floor_lo = col_lo.copy()
        floor_lo[floor_cols] = floor / Q
        if not spec.rest_floor:
            rest_c = []
        for j, c_max in rest_c:
            floor_lo[j] = max(col_lo[j], min(floor, FLOOR_SHARE * c_max) / Q)
        # First each control point's own floor, FLOOR_SHARE of its reach (``_col_scale``): the one
        # window-wide floor is set by the tightest point of the window, and a turn of 0.05 um radius
        # put it at ~1e-9 of Q, where the LP parked control points far from the turn (a 3.4 mm path
        # took 1,124 s, bench seed 224).  Then the window-wide floor, then none.
        local_lo = floor_lo.copy()
        local_lo[floor_cols] = np.maximum(floor_lo[floor_cols], LOCAL_FLOOR_SHARE * base.col_scale[floor_cols])
        for j, c_max in rest_c:
            local_lo[j] = max(floor_lo[j], LOCAL_FLOOR_SHARE * min(base.col_scale[j], c_max / Q))
        # Neither floor above RAMP_FLOOR_SHARE of what a feed from a rest end can reach at the column: on a short
        # piece the ramp from rest spans many knot intervals, and the floors there made both floored models
        # infeasible (a 2.8 mm line: two infeasible solves before the one without a floor)
        ramp = self._ramp_reach(g, n) / Q
        for lo_k in (local_lo, floor_lo):
            cap = floor_cols[:n] & (lo_k[:n] > RAMP_FLOOR_SHARE * ramp)
            lo_k[:n][cap] = np.maximum(col_lo[:n][cap], RAMP_FLOOR_SHARE * ramp[cap])
        floors = [local_lo, floor_lo, col_lo]
        for i, lo_i in enumerate(floors):
            self.fallback_left = i < len(floors) - 1
            try:
                chat1, c_star, pts1, r1 = self._stage1(base, g, w, lo_i, col_hi, Q, s_check)
            except (InfeasibleError, SolverFailure):
                if i == len(floors) - 1:
                    raise
                continue
            floors = floors[i:]
            break
        # control points the LP holds at a floor (not next to an artificial window end, where the
        # feed comes to rest and the next window takes over)
        at_floor = floor_cols.copy()
        if not spec.end_rest:
            at_floor[n - 4 : n] = False

        def floored(chat: FloatArray, lo: FloatArray) -> int:
            return int(np.sum(at_floor & (lo > 0.0) & (chat <= lo * (1.0 + FLOORED_TOL))))

        if not self.lim.jerk:
            return WindowResult(chat1[:n] * Q, c_star[:n], self.iterations, pts1[0], pts1[1], pts1[2],
                                floored(chat1, floors[0]), self._shapes(chat1 * Q))

        # stage 2: + q <= q*, pseudo-jerk
        qstar = self._capped_qstar(c_star, g)

        last_rows: list[_Rows] = []  # (the model of the last stage-2 solve: ``_time_stage`` goes on in it)

        def stage2(lo: FloatArray, warm: _Rows | None = None) -> tuple[FloatArray, tuple[int, int, int]]:
            # a fresh model each time (the solver keeps its column bounds), or stage 1's own (``warm``, on its
            # floor: the rows added to it, the dual simplex going on from its optimal basis)
            r2 = base.copy() if warm is None else warm
            last_rows[:] = [r2]
            self._stage1_rows(r2, g, Q, qstar, velocity_only=warm is not None)
            self._jerk_rows(r2, g, Q, qstar)
            return self._cuts(self._run(r2, w, lo, col_hi), r2, w, lo, col_hi, Q, s_check, c_star)

        # Stage 2 first goes on in stage 1's model (STAGE2_WARM, HiGHS): stage 1's optimum meets every row but
        # the jerk rows (q = q* where q <= q* is imposed), so its basis is dual feasible and only the jerk rows'
        # violations are left to the dual simplex.  Stage 1's velocity rows at its row points get q <= q* in
        # place (``_Rows.change_bounds``), points without one new rows, and the jerk rows are added: its
        # acceleration rows are there already, and its cut rows (limits at verification points, which stage 2's
        # own rounds would add where they bind) stay.  Flower with jerk: stage 2's 290 iterations from scratch
        # -> 56.  If it fails, stage 2 runs from scratch as below.
        warm = r1 if STAGE2_WARM and self.solver == "highs" and r1.highs is not None else None

        # A floor (or a cut round under it) infeasible: the next one.  All infeasible with an inherited
        # start: again with the previous window's solution and q* inherited over twice the intervals, up
        # to the whole overlap.  Bench seed 565: the previous window's stage 2 met a break's cap
        # (q <= 24, the feed from 72 to 4.9 mm/s) 9.5 intervals after this window's start with the jerk
        # binding all the way; this window's own q* differed by 0.2 % 1-2 intervals in, and its
        # linearised jerk rows no longer reached the cap from the inherited state.
        while True:
            try:
                for i, lo_i in enumerate(floors):
                    self.fallback_left = i < len(floors) - 1
                    try:
                        if warm is not None:
                            r_warm, warm = warm, None
                            try:
                                chat2, pts2 = stage2(lo_i, r_warm)
                                break
                            except (InfeasibleError, SolverFailure):
                                pass
                        chat2, pts2 = stage2(lo_i)
                    except (InfeasibleError, SolverFailure):
                        if i == len(floors) - 1:
                            raise
                        continue
                    break
                break
            except (InfeasibleError, SolverFailure):
                prev = spec.prev_qstar
                if prev is None or self._inherited_end(prev) >= prev[0] + prev[1].size - 2:
                    raise
                self.inherited *= 2
        n_floored = floored(chat2, lo_i)  # (stage 2's count: what the knot refinements go by)
        if TIME_STAGE and self.lim.time_stage and n_floored and self.solver == "highs" and last_rows:
            # (the smallest floor: a floored control point is one at a floor > 0 among the first n)
            q_min = float(np.min(lo_i[:n][lo_i[:n] > 0.0])) * Q
            chat2 = self._time_stage(chat2, last_rows[0], lo_i, col_hi, Q, s_check, c_star, g_fine.s, q_min)
        return WindowResult(chat2[:n] * Q, c_star[:n], self.iterations, pts1[0] + pts2[0], pts1[1] + pts2[1],
                            pts2[2], n_floored, self._shapes(chat2 * Q))

    def _q_at_least(self, chat: FloatArray, s: FloatArray, Q: float, q_min: float) -> FloatArray:
        """q (K,) of a solution chat (in units of Q) at the points s (K,), at least q_min (mm^2/s^2)."""
        return np.maximum(self._eval(chat * Q, s)[0], q_min)

    @staticmethod
    def _travel(q: FloatArray, s: FloatArray) -> float:
        """T = integral ds / sqrt(q) over the points s (K,) (trapezoids) for q (K,) there: a travel time, s."""
        f = 1.0 / np.sqrt(q)
        return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(s)))

    def _time_stage(self, chat: FloatArray, rows: _Rows, lo: FloatArray, col_hi: FloatArray, Q: float,
                    s_check: FloatArray, c_star: FloatArray, s: FloatArray, q_min: float) -> FloatArray:
        r"""Stage 2's solution chat, or one more LP on its rows (``rows``, its HiGHS model: the dual simplex goes on
        from its basis) with the travel time's gradient as the objective, if that is faster.

        Stage 2 maximises integral q ds, which hardly sees a narrow dip: where its solution holds control points
        at their floor (a crawl), the travel time T(c) = integral q^(-1/2) ds is what matters, and

            dT/dc_j = -1/2 integral B_j(s) q(s)^(-3/2) ds,

        so the LP here maximises sum_j w_j c_j with w_j = integral B_j(s) max(q, q_min)^(-3/2) ds (stage 2's q on
        the verification grid s (K,), trapezoids; q_min the window's smallest floor, so that the rest ends, where q
        goes to 0, do not take all the weight), then its cut rounds.  The rows are the same, so the result keeps
        every limit stage 2 keeps; it is kept only if its T (``_travel``) is lower.  (With HiGHS only: Clarabel
        would solve the window from scratch once more.)  One such step (a second gained
        little more at 2.5x the added CPU: lp bench 0-299, 48 shorter against 47).  Session 51: lp bench 0-299,
        47 runs shorter (276 0.558x, 46 0.945x, 255 0.949x), none longer; cam 0-59 12 shorter (35 0.962x), none
        longer; wall time of lp bench 0-149, side by side, 1.04x in all (a case up to ~1.7x: seed 13 1.07 -> 1.84 s).
        Stage 2's floored count is what the window reports: counted after this step, a crawl lifted just off its
        floor stopped the knot refinements that found the fast profile (bench seed 251 1.36x)."""
        q = self._q_at_least(chat, s, Q, q_min)
        ds = np.zeros(s.size)
        ds[1:] += 0.5 * np.diff(s)
        ds[:-1] += 0.5 * np.diff(s)
        wt = np.asarray(self._mats(s)[0].T @ (ds * (q / Q) ** -1.5), dtype=np.float64)
        wt = wt / float(np.max(np.abs(wt)))
        try:
            c3, _ = self._cuts(self._run(rows, wt, lo, col_hi), rows, wt, lo, col_hi, Q, s_check, c_star)
        except (InfeasibleError, SolverFailure):
            return chat
        return c3 if self._travel(self._q_at_least(c3, s, Q, q_min), s) < self._travel(q, s) else chat

    def _stage1(
        self, base: _Rows, g: PathSamples, w: FloatArray, col_lo: FloatArray, col_hi: FloatArray, Q: float,
        s_check: FloatArray,
    ) -> tuple[FloatArray, FloatArray, tuple[int, int, int], _Rows]:
        """Stage 1 (velocity + acceleration) with cutting planes: (chat, c*, (rounds, added, unverified), its rows
        and model)."""
        r1 = base.copy()
        self._stage1_rows(r1, g, Q, None, record=True)
        chat1 = self._run(r1, w, col_lo, col_hi)
        chat1, pts1 = self._cuts(chat1, r1, w, col_lo, col_hi, Q, s_check, None)
        return chat1, chat1 * Q, pts1, r1

    def _step_rows(self, rows: _Rows, Q: float) -> float:
        """q <= min_x a_step_x / |jump of x_ss| at every geometry break inside the window (the
        acceleration step there, x_ss jump x q, stays within a_step), and q <= min_x (v_step_x /
        |jump of x_s|)^2 (the velocity step at a tangent break passed at speed, f |jump of x_s|,
        stays within v_step), both lowered where breaks crowd (``_break_qmax``); returns the smallest cap."""
        if self.breaks.size == 0:
            return np.inf
        br = self._steps()[0]
        if br.size == 0:
            return np.inf
        cap = self._break_qmax()
        keep = cap < Q  # q never exceeds Q (the largest velocity bound): larger caps are no rows
        if not keep.any():
            return np.inf
        B0 = self._mats(br[keep])[0]
        rows.add(B0, np.full(int(keep.sum()), -np.inf), cap[keep] / Q)
        return float(np.min(cap[keep]))

    def _break_qmax(self) -> FloatArray:
        """The largest q each break may have (nb,): its velocity step's cap, its acceleration step's and Q, times
        ``_step_crowd_factor`` (rows of every model, ``_step_rows``)."""
        if self._qmax_cache is None or self._qmax_cache[0] != self.Q:
            qmax = np.minimum(np.minimum(self._vstep_caps(), self._step_caps()), self.Q)
            self._qmax_cache = (self.Q, qmax * self._step_crowd_factor(qmax))
        return self._qmax_cache[1]

    def _step_reach(self, qmax: FloatArray) -> FloatArray:
        """How far (nb,) mm from each break a point's sampled third differences can span it (``_step_jerk``):
        3 Ts of travel at most at the window's largest feed sqrt(Q), and at most 3 Ts sqrt(qmax) + |amax| (3 Ts)^2 / 2,
        the break's own largest feed sqrt(qmax) and the tangential acceleration (at most |amax|: x_s . a) over the
        3 Ts either side (until session 50 3 Ts (sqrt(qmax) + 3 Ts |amax|), twice the acceleration's share)."""
        Ts = self.lim.step_jerk_period
        assert Ts is not None
        return self._travel_3ts(Ts, qmax)

    def _travel_3ts(self, Ts: float, qmax: FloatArray) -> FloatArray:
        """The travel (nb,) mm over 3 Ts either side of a break whose q is at most qmax (nb,): at most
        min(3 Ts sqrt(Q), 3 Ts sqrt(qmax) + |amax| (3 Ts)^2 / 2) (``_step_reach``, ``_live_steps``)."""
        span = 3.0 * Ts
        return np.asarray(np.minimum(span * np.sqrt(self.Q), span * np.sqrt(qmax) + 0.5 * span * span
                                     * float(np.linalg.norm(self.lim.amax))), dtype=np.float64)

    def _step_crowd_factor(self, qmax: FloatArray) -> FloatArray:
        r"""Factor (nb,) <= 1 on each break's cap qmax (nb,) so that at every point s the step terms of the curvature
        jumps within reach (``_step_jerk``) add up to at most STEP_CONST_TOTAL of jmax_x at their caps:

            T_x(s) = sum_{b: |s - s_b| <= R_b} w_bx qmax_b,   w_bx = STEP_KERNEL |jump_bx| / (Ts jmax_x),
            factor_b = min_x min(1, STEP_CONST_TOTAL / max_{|s - s_b| <= R_b} T_x(s))

        (R_b = ``_step_reach``; lowering the caps only shrinks the reaches, so the sums stay within the share).  The
        jerk rows then charge each break its term at its cap as a constant (``_jerk_rows``).  Until session 50 the
        breaks whose constants summed to over STEP_CONST_TOTAL were coupled to the rows through q(s_b), and the LP,
        whose objective integral q hardly sees a narrow dip, traded q(s_b) against the points around: it held
        those breaks at their q floor, a crawl (bench seed 71 lp: ~1.5 mm/s for 0.08 s at two curvature jumps
        4.9 mm apart, where the caps allow hundreds of mm/s; 0.194 -> 0.133 s; on 1 mm knots 1.97 -> 0.17 s).

        T_x is piecewise constant and rises only where a reach starts, so its largest value over [s_b - R_b,
        s_b + R_b] is at one of those starts inside: O(nb log nb) by sorting and one ``maximum.reduceat``."""
        out = np.ones(qmax.size)
        if self.lim.step_jerk_period is None or qmax.size == 0:
            return out
        Ts = self.lim.step_jerk_period
        br, jump, _ = self._steps()
        reach = self._step_reach(qmax)
        lo, hi = br - reach, br + reach
        o_lo, o_hi = np.argsort(lo, kind="stable"), np.argsort(hi, kind="stable")
        x = lo[o_lo]  # where a reach starts (sorted)
        n_in = np.searchsorted(x, x, side="right")  # reaches started at or before each start
        n_out = np.searchsorted(hi[o_hi], x, side="left")  # ... and ended before it
        at = np.column_stack([np.searchsorted(x, lo, side="left"), np.searchsorted(x, hi, side="right")]).ravel()
        for ax in range(3):
            share = STEP_KERNEL * jump[:, ax] / (Ts * self.lim.jmax[ax]) * qmax
            share = np.where(share > STEP_JERK_MIN, share, 0.0)  # (``_step_jerk``'s live breaks)
            total = (np.concatenate([[0.0], np.cumsum(share[o_lo])])[n_in]
                     - np.concatenate([[0.0], np.cumsum(share[o_hi])])[n_out])
            worst = np.maximum.reduceat(np.append(total, 0.0), at)[::2]
            out = np.minimum(out, np.where(worst > STEP_CONST_TOTAL, STEP_CONST_TOTAL / np.maximum(worst, 1e-300), 1.0))
        return out

    def _step_caps(self) -> FloatArray:
        """Cap on q at each break from the acceleration step, min_x a_step_x / |jump of x_ss|, (nb,)."""
        br, jump, _ = self._steps()
        return np.full(br.size, np.inf) if self.lim.a_step is None else step_cap(self.lim.a_step, jump)

    def _vstep_caps(self) -> FloatArray:
        """Cap on q at each break from the velocity step, min_x (v_step_x / |jump of x_s|)^2, (nb,) (computed
        once per window: every row and check near a break reads it)."""
        if self._vstep_cache is None:
            br, _, jump1 = self._steps()
            self._vstep_cache = (np.full(br.size, np.inf) if self.lim.v_step is None
                                 else step_cap(self.lim.v_step, jump1) ** 2)
        return self._vstep_cache

    def _vstep_terms(
        self, s: FloatArray, ax: int, limit: float, kernel: float, power: int
    ) -> tuple[NDArray[np.bool_], sp.csr_matrix, FloatArray, FloatArray] | None:
        """The impulse of the velocity steps at tangent breaks passed at speed, as the sampled
        acceleration (``power`` 1, ``kernel`` V_KERNEL_A) or jerk (2, V_KERNEL_J) of axis ``ax`` sees it
        at points s: kernel |jump_bx| f_b / Ts^power per unit ``limit``, for points whose differences can
        span break b: within 3 Ts of travel of it, at the largest feed its cap allows plus what the
        acceleration limits add over 3 Ts, and at most at the window's largest feed (``_travel_3ts``, as
        for a curvature jump; a polyline of 0.5 mm legs is dense: at the window's largest feed three
        breaks were within reach of one point and their rows infeasible).

        Returns (near (K,) bool, W (near.sum(), nl) sparse, the weight w_b of f_b at each near point
        (none where b is not close), the live breaks' s (nl,), q0 (nl,) the q at which f_b is linearised: the
        largest q the break's cap allows, min(cap, Q), divided by the square of the number of live
        breaks within twice the reach (so the constant shares of breaks close to one point add up to
        at most half the limit)), or None where no break's impulse reaches V_STEP_MIN of the limit."""
        live = self._vstep_live(ax, limit, kernel, power)
        if live is None:
            return None
        br, w, reach, q0 = live
        # points within each break's reach, by bisection on the sorted points (a dense polyline has
        # ~1,000 breaks and ~10,000 verification points per window)
        order = np.argsort(s, kind="stable")
        ss = s[order]
        lo = np.searchsorted(ss, br - reach, side="left")
        hi = np.searchsorted(ss, br + reach, side="right")
        cnt = hi - lo
        if not cnt.any():
            return None
        pt = order[np.repeat(hi - cnt.cumsum(), cnt) + np.arange(int(cnt.sum()))]  # points of each break
        col = np.repeat(np.arange(br.size), cnt)
        near = np.zeros(s.size, dtype=bool)
        near[pt] = True
        row = (np.cumsum(near) - 1)[pt]
        W = sp.csr_matrix((w[col], (row, col)), shape=(int(near.sum()), br.size))
        return near, W, br, q0

    def _vstep_live(self, ax: int, limit: float, kernel: float, power: int) -> _LiveSteps | None:
        """The breaks whose velocity step's impulse counts for axis ``ax`` (``_vstep_terms``): their s, weight
        w_b, reach and linearisation point q0 (crowding applied), or None; computed once per window and Q."""
        key = (ax, limit, kernel, power, self.Q)
        if key not in self._vstep_live_cache:
            self._vstep_live_cache[key] = self._live_steps(ax, limit, kernel, power)
        return self._vstep_live_cache[key]

    def _live_steps(self, ax: int, limit: float, kernel: float, power: int) -> _LiveSteps | None:
        """``_vstep_live`` computed."""
        Ts = self.lim.v_step_period
        if Ts is None or self.lim.v_step is None or self.breaks.size == 0:
            return None
        br, _, jump1 = self._steps()
        q0 = np.minimum(self._vstep_caps(), self.Q)
        # the break's largest feed (its acceleration step's cap too: ``_break_qmax``) decides whether its
        # impulse counts and how far it reaches; the tangent stays at q0 (a point nearer the break's feed
        # steepens the coupling, and the LP held such breaks at their floor: bench seed 894)
        qmax = self._break_qmax()
        w = kernel * jump1[:, ax] / (Ts**power * limit)
        live = w * np.sqrt(qmax) > V_STEP_MIN
        if not live.any():
            return None
        br, q0, qmax, w = br[live], q0[live], qmax[live], w[live]
        # (until session 51 3 Ts (sqrt(qmax) + 3 Ts |amax|): twice the acceleration's share, and not bounded by sqrt(Q))
        reach = self._travel_3ts(Ts, qmax) + BREAK_EPS_MM
        # breaks within twice the reach of each (counted against the largest reach: at most more)
        crowd = (np.searchsorted(br, br + reach + reach.max(), side="right")
                 - np.searchsorted(br, br - reach - reach.max(), side="left"))
        return br, w, reach, np.asarray(q0 / crowd.astype(np.float64) ** 2, dtype=np.float64)

    def _vstep_coupling(
        self, s: FloatArray, ax: int, limit: float, kernel: float, power: int
    ) -> tuple[NDArray[np.bool_], sp.csr_matrix, FloatArray] | None:
        """Rows |a_x(s)| (or |j_x(s)|) + sum_b w_b f_b <= limit at points s near tangent breaks
        (``_vstep_terms``), linear in q: f_b = sqrt(q_b) <= (sqrt(q0_b) + q_b / sqrt(q0_b)) / 2, the
        tangent of the concave sqrt at q0_b (``_vstep_terms``: the largest q_b the break's cap allows,
        lowered where breaks crowd; exact there, and at q_b = 0 it keeps half the share at q0_b free).
        Returns (near, C (near.sum(), ncols) the coefficients of chat, const (near.sum(),)), per unit
        limit: rows A[near] +- C <= 1 - const."""
        t = self._vstep_terms(s, ax, limit, kernel, power)
        if t is None:
            return None
        near, W, br, q0 = t
        rq0 = np.sqrt(q0)
        C = sp.csr_matrix(W @ sp.diags(self.Q / (2.0 * rq0)) @ self._mats(br)[0])
        return near, C, np.asarray(W @ (0.5 * rq0), dtype=np.float64)

    def _vstep_seen(self, c: FloatArray, s: FloatArray, ax: int, limit: float, kernel: float,
                    power: int) -> FloatArray:
        """sum_b w_b f_b per unit limit at points s (K,) for control points c (``_vstep_terms``)."""
        out = np.zeros(s.size)
        t = self._vstep_terms(s, ax, limit, kernel, power)
        if t is not None:
            near, W, br, _ = t
            out[near] = W @ np.sqrt(np.maximum(self._eval(c, br)[0], 0.0))
        return out

    def _add_coupled(
        self, rows: _Rows, A: sp.csr_matrix, s: FloatArray,
        coup: tuple[NDArray[np.bool_], sp.csr_matrix, FloatArray] | None,
    ) -> None:
        """Rows A[near] + C <= 1 - const and C - A[near] <= 1 - const (|A chat| + C chat + const <= 1)."""
        if coup is None:
            return
        near, C, const = coup
        free = np.full(int(near.sum()), -np.inf)
        self._add(rows, A[near] + C, free, 1.0 - const, s[near])
        self._add(rows, C - A[near], free, 1.0 - const, s[near])

    def _steps(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Geometry breaks strictly inside the window, |jump of x_ss| and |jump of x_s| there per axis,
        ((nb,), (nb, 3), (nb, 3))."""
        if self._step_cache is None:
            spec = self.spec
            lo, hi = spec.k0 * spec.d, spec.k1 * spec.d
            br = self.breaks[(self.breaks > lo + BREAK_EPS_MM) & (self.breaks < hi - BREAK_EPS_MM)]
            if br.size:
                right, left = self._known_geometry(br + BREAK_EPS_MM), self._known_geometry(br - BREAK_EPS_MM)
                jump, jump1 = curvature_jump(right, left, BREAK_EPS_MM), tangent_jump(right, left, BREAK_EPS_MM)
            else:
                jump = jump1 = np.zeros((0, 3))
            self._step_cache = (br, np.asarray(jump, dtype=np.float64), np.asarray(jump1, dtype=np.float64))
        return self._step_cache

    def _step_jerk(self, s: FloatArray, ax: int) -> tuple[NDArray[np.bool_], sp.csr_matrix] | None:
        """The sampled jerk next to a curvature jump (bench seed 47): the axis acceleration steps by
        |jump_x| q(s_b) at the break s_b, and a third difference of the samples whose span (3 Ts)
        holds the break sees the jerk around it plus up to STEP_KERNEL |step| / Ts.  So at points
        within 3 Ts of travel of a break the jerk rows become
        |j(s)| + sum_b STEP_KERNEL |jump_bx| q(s_b) / Ts <= jmax_x, q(s_b) taken at its cap there (a constant:
        ``_step_crowd_factor``) and as it is in the checks (``_violations``).

        The travel is bounded by the break's own largest feed (``_break_qmax``: its caps hold q(s_b) in
        every model) plus what the acceleration limits add over 3 Ts, and by the window's largest feed
        sqrt(Q).  Bounded by sqrt(Q) alone, a break capped at 0.08 mm/s next to a 2.7 um turn (bench seed
        894 lp) coupled its q to the jerk rows of checkpoints 1.3 mm either side, and the LP held it at
        its floor to give them its share: a 36 s crawl over 36 um.

        Returns (near (K,) bool: the points s that need it, M (near.sum(), nb): per unit jmax, the
        weight of q(s_b) in the sum), or None."""
        Ts = self.lim.step_jerk_period
        if Ts is None or self.breaks.size == 0:
            return None
        br, jump, _ = self._steps()
        jmax = self.lim.jmax[ax]
        wgt = STEP_KERNEL * jump[:, ax] / (Ts * jmax)
        qmax = self._break_qmax()
        live = wgt * qmax > STEP_JERK_MIN
        if not live.any():
            return None
        # within 3 Ts of travel of the break: at most the window's largest feed, sqrt(Q), and at most its own
        # largest feed (``_break_qmax``) plus what the acceleration limits add over 3 Ts
        reach = self._step_reach(qmax)
        close = (np.abs(s[:, None] - br[None, :]) <= reach[None, :]) & live[None, :]
        near = close.any(axis=1)
        if not near.any():
            return None
        return near, sp.csr_matrix(np.where(close[near], wgt[None, :], 0.0))

    def _fine(self, s_check: FloatArray) -> FloatArray:
        """The verification grid: VERIFY_SUBDIV points per checkpoint gap, both sides of geometry
        knots, both sides of every knot of q (q'' and so the jerk jump there; a checkpoint on a
        knot lands on either side by rounding: 935 d from linspace floors to interval 934), and
        points at h 2^-k, k = 4 .. REST_ZOOM_LEVELS, from each rest end (h the checkpoint gap there).

        Next to a rest end q ~ |q'(L)| (L - s), so f ~ sqrt(L - s): the last micrometres pass in a
        fraction of a sample, and a hook there goes by unseen by an even grid.  Bench seed 5772: a
        segment turning 47 degrees over its last 50 um (radius 1.5 mm down to 0.98 um at its end)
        before a corner had an analytic jerk of 65 x jmax at 0.1 um from the end (1.85 x in the 1 ms
        samples); with these points the rest's q' shrinks until it holds (0.11 x)."""
        frac = np.arange(1, VERIFY_SUBDIV) / VERIFY_SUBDIV
        s_fine = (s_check[:-1, None] + np.diff(s_check)[:, None] * frac[None, :]).ravel()
        lo, hi = s_check[0], s_check[-1]
        spec = self.spec
        kd = np.arange(spec.k0 + 1, spec.k1) * spec.d
        q_knots = np.concatenate([kd - BREAK_EPS_MM, kd + BREAK_EPS_MM])
        br = self.breaks[(self.breaks > lo + BREAK_EPS_MM) & (self.breaks < hi - BREAK_EPS_MM)]
        extra = self.verify[(self.verify > lo) & (self.verify < hi)]
        zoom = 2.0 ** -np.arange(4, REST_ZOOM_LEVELS + 1)
        rest = [np.zeros(0)]
        if spec.start_fixed is None:
            rest.append(lo + (s_check[1] - lo) * zoom)
        if spec.end_rest:
            rest.append(hi - (hi - s_check[-2]) * zoom)
        return np.sort(np.concatenate([s_check, s_fine, br - BREAK_EPS_MM, br + BREAK_EPS_MM, q_knots, extra, *rest]))

    def _fine_geometry(self, s_check: FloatArray) -> PathSamples:
        """Geometry on the verification grid of ``s_check``, evaluated once per window."""
        if self._fine_g is None or self._fine_g[0] is not s_check:
            self._fine_g = (s_check, self.geometry(self._fine(s_check)))
        return self._fine_g[1]

    def _check_geometry(self, s_check: FloatArray) -> PathSamples:
        """The points the cut rounds check (``_cuts``): the verification grid (``_fine_geometry``) with
        VERIFY_SUBDIV - 1 more points in every gap across which the unit tangent turns by more than VERIFY_TURN_RAD
        (t_i . t_i+1 < cos VERIFY_TURN_RAD), again in the new gaps, VERIFY_TURN_LEVELS times at most (with
        ``LimitSet.check_turns``; else the grid itself)."""
        g = self._fine_geometry(s_check)
        if not self.lim.check_turns:
            return g
        if self._check_g is not None and self._check_g[0] is s_check:
            return self._check_g[1]
        frac = np.arange(1, VERIFY_SUBDIV) / VERIFY_SUBDIV
        cos_min = math.cos(VERIFY_TURN_RAD)
        for _ in range(VERIFY_TURN_LEVELS):
            gap = np.flatnonzero(np.einsum("ij,ij->i", g.d1[:-1], g.d1[1:]) < cos_min)  # (x_s: unit tangents)
            if gap.size == 0:
                break
            s_new = (g.s[gap, None] + (g.s[gap + 1] - g.s[gap])[:, None] * frac[None, :]).ravel()
            g_new = self.geometry(s_new)
            g = g.concat(g_new).subset(np.argsort(np.concatenate([g.s, g_new.s]), kind="stable"))
        self._check_g = (s_check, g)
        return g

    def _known_geometry(self, s: FloatArray) -> PathSamples:
        """Geometry at s (K,), the points on the verification grid taken from its geometry (``_fine_geometry``;
        the same numbers: each point is evaluated on its own), the others evaluated.  The grid holds the
        checkpoints, both sides of every break and the window's ends: a flower loop's rows, breaks and rest ends
        evaluated them again (~5 ms of a ~50 ms v + a schedule)."""
        if self._fine_g is None or s.size == 0:
            return self.geometry(s)
        grid = self._fine_g[1]
        i = np.minimum(np.searchsorted(grid.s, s), grid.s.size - 1)
        on = grid.s[i] == s
        if on.all():
            return grid.subset(i)
        if not on.any():
            return self.geometry(s)
        new = self.geometry(s[~on])

        def merged(known: FloatArray, fresh: FloatArray) -> FloatArray:
            out = np.empty((s.size, *known.shape[1:]))
            out[on] = known[i[on]]
            out[~on] = fresh
            return out

        fl = None if grid.feed_limit is None or new.feed_limit is None else merged(grid.feed_limit, new.feed_limit)
        return PathSamples(s, merged(grid.position, new.position), merged(grid.d1, new.d1), merged(grid.d2, new.d2),
                           merged(grid.d3, new.d3), fl)

    def _cap(self, g: PathSamples) -> FloatArray:
        """The largest constant q that meets every limit at each point of g (K,), inf where none binds:
        q <= ub (velocity, feed), |x_ss| q <= amax, |x_sss| q sqrt(ub) <= jmax (pseudo-jerk, q* <= ub).
        (Shared with later calls on the same g: not to be changed in place.)"""
        if self._cap_cache is not None and self._cap_cache[0] is g:
            return self._cap_cache[1]
        ub = self._velocity_bound(g)
        lim = self.lim
        with np.errstate(divide="ignore", invalid="ignore"):
            qa = _min_ratio(g.d2, lim.amax, False)
            cap = np.minimum(ub, qa)
            if lim.jerk:
                qj = _min_ratio(g.d3, lim.jmax, False) / np.sqrt(ub)
                cap = np.minimum(cap, qj)
        out = np.asarray(cap, dtype=np.float64)
        self._cap_cache = (g, out)
        return out

    def _ramp_reach(self, g: PathSamples, n: int) -> FloatArray:
        """q a feed leaving (or reaching) this window's rest ends can have at each control point's peak (n,), from
        its distance r to the nearer rest end: 2 a_t r, and with jerk rows 0.25 j_t^(2/3) (6 r)^(4/3) if less
        (v = j t^2 / 2 at s = j t^3 / 6), a_t and j_t the smallest tangential acceleration and jerk the axes allow at
        the points g (min over points and axes of amax / |x_s|, jmax / |x_s|; curvature and the drive's rows
        ignored: an estimate, not a bound); inf without a rest end in the window."""
        spec = self.spec
        if spec.start_fixed is not None and not spec.end_rest:
            return np.full(n, np.inf)

        def tangential(lim: FloatArray) -> float:
            return float(np.min(_min_ratio(g.d1, lim, False)))

        peak = (np.arange(n) - 0.5) * spec.d  # column j's basis function peaks half an interval before k0 + j
        r = np.full(n, np.inf)
        if spec.start_fixed is None:
            r = np.maximum(peak, 0.0)
        if spec.end_rest:
            r = np.minimum(r, np.maximum((spec.k1 - spec.k0) * spec.d - peak, 0.0))
        out = 2.0 * tangential(self.lim.amax) * r
        if self.lim.jerk:
            out = np.minimum(out, 0.25 * tangential(self.lim.jmax) ** (2.0 / 3.0) * (6.0 * r) ** (4.0 / 3.0))
        return np.asarray(out, dtype=np.float64)

    def _velocity_bound(self, g: PathSamples) -> FloatArray:
        """``velocity_bound`` of g, kept for the next calls on the same g (not to be changed in place)."""
        for seen, ub in self._ub_cache:
            if seen is g:
                return ub
        ub = velocity_bound(g, self.lim)
        self._ub_cache = [self._ub_cache[-1], (g, ub)] if self._ub_cache else [(g, ub)]
        return ub

    def _floor(self, g: PathSamples) -> float:
        """FLOOR_SHARE x the largest constant q that meets every limit at the points g (verification grid)."""
        cap = self._cap(g)
        finite = cap[np.isfinite(cap)]
        return FLOOR_SHARE * float(np.min(finite)) if finite.size else 0.0

    def _col_scale(self, g: PathSamples, Q: float) -> FloatArray:
        """Column scale sigma (ncols,) in units of Q: for each control point c_j, the smallest
        cap(s) / b_j(s) over the verification points where its basis function b_j >= COL_SCALE_MIN_BASIS
        (``_cap``; c >= 0 and q >= c_j b_j, so this is c_j's reach), clipped to [COL_SCALE_FLOOR, 1].

        With one scale Q for the whole window, q near a turn of ~1 um radius is ~1e-8 of Q: the
        floor and q >= 0 there were below HiGHS's feasibility tolerance (1e-7), so it returned
        c = -1.6e-9 Q and the feed stalled.  Scaled per column, every column is O(1) where it binds."""
        spec = self.spec
        k, W0, _, _ = bspline.basis(g.s, spec.d, spec.n_int, spec.k0, spec.k1 - 1)
        cap = np.minimum(self._cap(g), Q)
        sig = np.minimum(column_reach(k - spec.k0, W0, cap, spec.ncols, COL_SCALE_MIN_BASIS), Q)
        sig = np.clip(sig / Q, COL_SCALE_FLOOR, 1.0)
        if spec.start_fixed is None:  # c_k0 = -c_k0+1 at a rest start
            sig[0] = sig[1]
        if spec.end_rest:
            sig[-1] = sig[-2]
        # the rest shapes' amplitudes: the reach of the rest interval's inner control point (the shapes are
        # what q is made of there besides it), over each shape's peak (the steepest rise peaks at 1.3e-4 of its
        # amplitude)
        peaks = bspline.rest_shape_peaks()
        ext = [sig[2 if head else spec.ncols - 3] / peaks for head, _, _ in self.shape_ends]
        return np.asarray(np.concatenate([sig, *ext]), dtype=np.float64)

    def _implied_col_hi(
        self, g: PathSamples, Q: float, col_lo: FloatArray, col_hi: FloatArray, sig: FloatArray
    ) -> FloatArray:
        """col_hi (nvar,) with each free control point's upper bound that the velocity rows at the row points g
        imply, times COL_HI_FACTOR (in units of Q, as col_lo and col_hi).

        At a point s where q >= 0 follows from the column bounds (``_plain_points``; c_i >= 0 for the three
        control points i whose basis functions b_i are nonzero there) and q(s) <= ub(s) (the point's velocity row,
        or its other rows, ``held_rows``): c_j b_j(s) <= q(s) <= ub(s), so c_j <= ub(s) / b_j(s).  The bound is
        the smallest over the points where b_j >= COL_HI_MIN_BASIS (inf where there is none).

        The rows imply the bound, so it leaves the LP's optimum where it is; it keeps the dual simplex off
        unbounded directions.  Bench seed 664 (lp), piece 1 on 128 knot intervals with its floors: a model
        that the floors make infeasible (5,791 rows, 130 columns) ran 0.3-4.6 s of dual simplex to status
        unknown (10 ms an iteration, the objective at 1e13), and 2 s more with presolve to prove it infeasible;
        with the bounds, 0.03 s to infeasible.

        With FLAT_CAP_COLUMNS a column whose bound is flat over its support is held at it (``flat_reach``): that
        bound cuts into the rows' feasible set on purpose (the feed between the checkpoints)."""
        spec = self.spec
        n = spec.ncols
        k, W0, _, _ = bspline.basis(g.s, spec.d, spec.n_int, spec.k0, spec.k1 - 1)
        cols = k[:, None] - spec.k0 + np.arange(3)[None, :]  # (K, 3): the control points nonzero at each point
        ok = self._plain_points(g.s) & kinematics.row_all(col_lo[cols] >= 0.0)
        ub = self._velocity_bound(g) / Q
        bound = column_reach(k - spec.k0, W0, ub, n, COL_HI_MIN_BASIS, ok)
        if FLAT_CAP_COLUMNS:
            bound = np.minimum(bound, flat_reach(k - spec.k0, W0, ub, n))
        out = col_hi.copy()
        free = (col_lo[:n] < col_hi[:n]) & (COL_HI_FACTOR * bound <= COL_HI_MAX_SCALED * sig[:n])
        out[:n][free] = np.minimum(col_hi[:n][free], COL_HI_FACTOR * bound[free])
        return out

    def _cuts(
        self,
        chat: FloatArray,
        rows: _Rows,
        w: FloatArray,
        col_lo: FloatArray,
        col_hi: FloatArray,
        Q: float,
        s_check: FloatArray,
        c_star: FloatArray | None,
    ) -> tuple[FloatArray, tuple[int, int, int]]:
        """Verify on a finer grid (``_check_geometry``); add violated points as rows and re-solve."""
        g = self._check_geometry(s_check)
        rounds = added = 0
        for i in range(MAX_CUT_ROUNDS + 1):
            viol = self._violations(chat * Q, g, c_star)
            if not viol.any() or i == MAX_CUT_ROUNDS:
                break
            gv = g.subset(viol)
            if c_star is None:
                self._stage1_rows(rows, gv, Q, None)
            else:
                qstar = self._capped_qstar(c_star, gv)
                self._stage1_rows(rows, gv, Q, qstar)
                self._jerk_rows(rows, gv, Q, qstar)
            chat = self._run(rows, w, col_lo, col_hi)
            rounds += 1
            added += int(viol.sum())
        return chat, (rounds, added, int(viol.sum()))

    def _violations(self, c: FloatArray, g: PathSamples, c_star: FloatArray | None) -> NDArray[np.bool_]:
        q3 = self._eval(c, g.s)
        f, v, a, j = axis_kinematics(g, *q3)
        tol = 1.0 + VERIFY_TOL
        bad = f * f > self._velocity_bound(g) * tol**2
        if self.shape_ends:  # q >= 0 (the rest shapes' amplitudes are free columns: ``solve``)
            bad |= q3[0] < -REST_SHAPE_Q_TOL * self.Q
        lim = self.lim
        rest = self._rest_mask(g.s)
        if rest.any():  # next to a rest end: the drive's u and e (``_rest_drive_rows``), not a and j
            dr = lim.rest_drive
            assert dr is not None
            gr = g.subset(rest)
            unsure = np.abs(gr.d1) < SIGN_EPS
            uu = dr["M"] * a[rest] + dr["b"] * v[rest] + dr["c"]
            u_worst = np.where(unsure, np.abs(uu) + dr["d"], np.abs(uu + dr["d"] * np.sign(gr.d1)))
            e = dr["Kv"] * v[rest] + dr["Ka"] * a[rest] + (dr["Kj"] * j[rest] if c_star is not None else 0.0)
            bad[rest] |= (kinematics.row_any(u_worst > dr["umax"] * tol)
                          | kinematics.row_any(np.abs(e) > dr["emax"] * tol))
            bad[rest] |= f[rest] > self._rest_feed_cap(gr) * tol
            a = np.where(rest[:, None], 0.0, a)
            j = np.where(rest[:, None], 0.0, j)
        aa = np.abs(a)
        for ax in range(3):  # + the impulse of velocity steps nearby
            aa[:, ax] += lim.amax[ax] * self._vstep_seen(c, g.s, ax, lim.amax[ax], V_KERNEL_A, 1)
        bad |= kinematics.row_any(aa > lim.amax[None, :] * tol)
        if c_star is not None:
            aj = np.abs(j)
            for ax in range(3):
                step = self._step_jerk(g.s, ax)
                if step is not None:
                    near, M = step
                    aj[near, ax] += lim.jmax[ax] * (M @ self._eval(c, self._steps()[0])[0])
                aj[:, ax] += lim.jmax[ax] * self._vstep_seen(c, g.s, ax, lim.jmax[ax], V_KERNEL_J, 2)
            bad |= kinematics.row_any(aj > lim.jmax[None, :] * tol)
        return np.asarray(bad)

    def _run(self, rows: _Rows, w: FloatArray, col_lo: FloatArray, col_hi: FloatArray) -> FloatArray:
        """Solve in the scaled variables y = chat / sigma (``_col_scale``); returns chat."""
        sig = rows.col_scale
        wy = w * sig
        wy = wy / float(np.max(np.abs(wy)))
        lo_y, hi_y = col_lo / sig, col_hi / sig
        if self.solver == "highs":
            return self._highs(rows, wy, lo_y, hi_y) * sig
        A, lo, hi, _ = rows.build()
        return self._clarabel(A, lo, hi, wy, lo_y, hi_y) * sig

    def _highs(self, rows: _Rows, w: FloatArray, col_lo: FloatArray, col_hi: FloatArray) -> FloatArray:
        """Solve with HiGHS; after the first call only the new (cut) rows are added and
        the dual simplex restarts from the previous basis."""
        inf = highspy.kHighsInf
        if rows.highs is not None:
            h = rows.highs
            # (the objective as given: ``_time_stage`` re-solves a model with another)
            h.changeColsCost(w.size, np.arange(w.size, dtype=np.int32), np.ascontiguousarray(-w, dtype=np.float64))
            for idx, lo_c, hi_c in rows.bound_changes:  # (in the rows' scales as passed)
                r = rows.row_scale[idx]
                h.changeRowsBounds(  # type: ignore[attr-defined]  # (in highspy, not in its stubs)
                    idx.size, idx.astype(np.int32), np.where(np.isfinite(lo_c), lo_c * r, -inf),
                    np.where(np.isfinite(hi_c), hi_c * r, inf))
            rows.bound_changes.clear()
            A, lo, hi, r_new = rows.build(rows.passed)
            rows.passed = len(rows.blocks)
            rows.row_scale = np.concatenate([rows.row_scale, r_new])
            if A.shape[0]:
                h.addRows(
                    A.shape[0],
                    np.where(np.isfinite(lo), lo, -inf),
                    np.where(np.isfinite(hi), hi, inf),
                    A.nnz,
                    A.indptr[:-1].astype(np.int32),
                    A.indices.astype(np.int32),
                    A.data,
                )
            return self._highs_run(h)
        A, lo, hi, rows.row_scale = rows.build()
        rows.passed = len(rows.blocks)
        rows.bound_changes.clear()
        h = new_highs()
        rows.highs = h
        # columns, then the rows as they are (CSR), each passed as one numpy buffer: filling a ``HighsLp``'s
        # fields copied every array element by element (~1.5 ms a model of ~2,700 rows)
        n = A.shape[1]
        passed = (
            h.addVars(n, np.where(np.isfinite(col_lo), col_lo, -inf), np.where(np.isfinite(col_hi), col_hi, inf)),
            h.changeColsCost(n, np.arange(n, dtype=np.int32), np.ascontiguousarray(-w, dtype=np.float64)),
            h.addRows(A.shape[0], np.where(np.isfinite(lo), lo, -inf), np.where(np.isfinite(hi), hi, inf), A.nnz,
                      A.indptr[:-1].astype(np.int32), A.indices.astype(np.int32), A.data),
        )
        if highspy.HighsStatus.kError in passed:
            raise SolverFailure("HiGHS did not take the LP", window=self.spec.index, status=str(passed))
        return self._highs_run(h)

    def _highs_run(self, h: highspy.Highs) -> FloatArray:
        self._timed_run(h)
        status = h.getModelStatus()
        # Not optimal: once more with the other presolve setting, SIMPLEX_SCALE_RETRY and the primal simplex
        # (SIMPLEX_STRATEGY_RETRY), cold; but an infeasible model with a lower floor still to try goes to it
        # (``solve``): a short piece's floors are infeasible next to its rest ends, and proving it twice took 4 of
        # a 2.8 mm line's 5 solves
        infeasible = status == highspy.HighsModelStatus.kInfeasible
        if status != highspy.HighsModelStatus.kOptimal and not (infeasible and self.fallback_left):
            h.setOptionValue("presolve", "on" if PRESOLVE == "off" else "off")
            h.setOptionValue("simplex_scale_strategy", SIMPLEX_SCALE_RETRY)
            h.setOptionValue("simplex_strategy", SIMPLEX_STRATEGY_RETRY)
            h.clearSolver()
            self._timed_run(h)
            h.setOptionValue("simplex_strategy", SIMPLEX_STRATEGY)  # (the dual again for the cut rounds' hot starts)
            status = h.getModelStatus()
        self.iterations += int(h.getInfo().simplex_iteration_count)
        if status == highspy.HighsModelStatus.kInfeasible:
            raise InfeasibleError("LP window is infeasible", window=self.spec.index, status=str(status))
        if status != highspy.HighsModelStatus.kOptimal:
            sp = self.spec  # (the window's knots; the machine's limits are what the LP's scale comes from)
            raise SolverFailure(
                f"HiGHS did not reach optimality on LP window {sp.index} (knot intervals {sp.k0}..{sp.k1} of "
                f"{sp.d:.6g} mm, cold and with the other presolve and scaling): limits many orders of magnitude "
                "apart (e.g. jmax 1e-3 with amax 1e8) or a knot spacing far from the path's scale leave its "
                "rows ill-conditioned", field="machine", value=str(status), window=sp.index, status=str(status))
        return np.asarray(h.getSolution().col_value, dtype=np.float64)

    @staticmethod
    def _timed_run(h: highspy.Highs) -> None:
        """h.run() stopped after HIGHS_TIME_LIMIT_S + HIGHS_TIME_PER_ROW_S a row of wall time (HiGHS's
        time limit counts every run of the object: it is set from the run time so far)."""
        h.setOptionValue("time_limit", h.getRunTime() + HIGHS_TIME_LIMIT_S + HIGHS_TIME_PER_ROW_S * h.getNumRow())
        h.run()

    def _clarabel(
        self, A: sp.csr_matrix, lo: FloatArray, hi: FloatArray, w: FloatArray, col_lo: FloatArray, col_hi: FloatArray
    ) -> FloatArray:
        n = A.shape[1]
        fixed = np.flatnonzero(np.isfinite(col_lo) & (col_lo == col_hi))
        E = sp.csr_matrix((np.ones(fixed.size), (np.arange(fixed.size), fixed)), shape=(fixed.size, n))
        eq = np.isfinite(lo) & np.isfinite(hi) & (lo == hi)
        up = np.isfinite(hi) & ~eq
        dn = np.isfinite(lo) & ~eq
        Aall = sp.vstack([E, A[eq], A[up], -A[dn]], format="csc")
        b = np.concatenate([col_lo[fixed], lo[eq], hi[up], -lo[dn]])
        cones = [clarabel.ZeroConeT(fixed.size + int(eq.sum())), clarabel.NonnegativeConeT(int(up.sum() + dn.sum()))]
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        P = sp.csc_matrix((n, n))
        solver = clarabel.DefaultSolver(P, -w, Aall, b, cones, settings)
        sol = solver.solve()
        self.iterations += int(sol.iterations)
        status = str(sol.status)
        if status in ("PrimalInfeasible", "AlmostPrimalInfeasible"):
            raise InfeasibleError("LP window is infeasible", window=self.spec.index, status=status)
        if status not in ("Solved", "AlmostSolved"):
            raise SolverFailure("Clarabel did not converge", window=self.spec.index, status=status)
        return np.asarray(sol.x, dtype=np.float64)
