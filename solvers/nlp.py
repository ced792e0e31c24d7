r"""NLP refinement of the feed under drive limits (spec §5), in windows (spec §6).

Variable: control points p of the uniform quadratic B-spline f(s) = sdot
(mm/s) on the LP's knot grid (spacing d), scaled as p = Fs phat.  At
checkpoint s_k (N per knot interval) and for every moving axis x, with
geometry x_s, x_ss, x_sss (``PathSamples.d1, d2, d3``):

    v = x_s f
    a = x_ss f^2 + x_s f f'
    j = x_sss f^3 + 3 x_ss f^2 f' + x_s (f f'^2 + f^2 f'')
    control signal  u = M a + b v + c + d sign(v),   |u| <= umax
    servo error     e = Kv v + Ka a + Kj j,          |e| <= emax
    optional        |v| <= vmax,  f <= Fmax,  |a| <= amax,  |j| <= jmax (true jerk)
    f >= 0

Since f >= 0, sign(v) = sign(x_s): the friction term is a constant per
checkpoint and moves into the bounds,

    -umax - c - d sigma <= M a + b v <= umax - c - d sigma,   sigma = sign(x_s);

at checkpoints next to a reversal of x_s (or with |x_s| < SIGN_EPS) both
signs are taken (conservative: upper with +d, lower with -d).

Objective: travel time over the window's committed intervals,
sum_k w_k / (f_k + delta), plus TAIL_TIME_WEIGHT times the travel time over
the overlap (which the next window solves again), minus a small reward
LAMBDA_TAIL sum f_k over the overlap.  The travel-time integral
is singular at rest (spec §10); rest intervals never enter an NLP window.

Window: knot intervals [a, b) -> control points p_a .. p_{b+1}.  p_a, p_{a+1}
are fixed (the inherited state: f and f' at knot a); p_b, p_{b+1} are fixed
too, either to 0 (artificial rest at the window's far end) or to the LP's
state at knot b (a join).  One solver is built per window shape (knot
intervals, moving axes, optional rows), with the geometry, drive coefficients
and weights as parameters and the fixed control points and row bounds given
per call, then re-called window after window: the dense interior point of
``solvers.ipm`` (``DENSE_IPM``), and CasADi ``nlpsol``s with Ipopt, built on
first use, for the solves it does not finish.

Between checkpoints the limits are verified on a VERIFY_SUBDIV-times finer
grid (and both sides of geometry knots), bisected where the tangent turns
fast (REFINE_TURN) or a utilisation changes fast (REFINE_UTIL) between its
points, so features narrower than the grid (sharp turns, curvature peaks) are
seen.  Then, per round (at most MAX_CUT_ROUNDS, re-solved warm): the worst
point of a stretch over a limit by more than SLOT_OVERSHOOT, or any stretch
once the window uses slots, gets a *cut slot*: a checkpoint placed there, one
per knot interval, with the path's exact derivatives (the window switches to
its shape with slot rows); a stretch next to a used slot tightens that slot's
bounds; the other stretches tighten the bounds of the checkpoints around them
by the overshoot.  (Tightening alone cannot hold a feature the checkpoints do
not see: a 0.2 mm turn between checkpoints 0.55 mm apart reached 1.7 x emax.)
With the output's sample period Ts known (``NlpLimits.sample_period``), two
more checks: at curvature jumps the acceleration step's servo error as one
sample sees it (|e| either side + Kj |step| / (2 Ts)), and u and e as the
finite differences of the sampled positions see them, at every sample phase
(``NlpRefiner._sampled``: exact kernel means of v and a over +-2 Ts).

Dual windows (spec §6): the LP walks the piece in large windows; within each
LP window's committed span [K_m, K_{m+1}] the NLP windows walk a *chain* that
starts from the LP's state at K_m and ends joined to the LP's state at
K_{m+1}, so every LP window starts from a state the LP produced.  If any NLP
window of a chain fails (Ipopt status, or limits still violated after the cut
rounds), the whole chain keeps the LP feed, which is feasible, and the
diagnostics say which window and why.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np
import osqp
import scipy.sparse as sp
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d

from geometry.toolpath import PathSamples
from solvers import bspline, ccompile, kinematics
from solvers.ipm import STATUS_INFEASIBLE, DenseIpm, IpmResult
from solvers.lp import (
    AXIS_EPS,
    SIGN_EPS,
    V_KERNEL_A,
    axis_moves,
    flat_bound,
    step_cap,
    tangent_jump,
    vstep_servo_error,
)
from solvers.machine import Machine
from solvers.timing import PieceProfile

FloatArray = NDArray[np.float64]
GeometryFn = Callable[[FloatArray], PathSamples]
#: A rest end's rise factors, one per ``bspline.REST_RISE_POWERS`` (mm/s), or none (no rise there).
Rise = tuple[float, ...]
#: An NLP span of a chain: (a, b, p_a .. p_{b+1}, rise factors of the piece's first and last rest interval,
#: none unless the span solved it: ``NlpRefiner._chain``).
Span = tuple[int, int, FloatArray, tuple[Rise, Rise]]
#: The chain's feed committed before a window: (A, p_A .. p_{a+1}, the rise factors of the piece's first
#: rest interval if A = 0).
_Left = tuple[int, FloatArray, Rise]

#: Share of the sampled e and u budgets the impulse of a velocity step (a tangent break passed at speed)
#: may take (``solvers.lp.v_step_limit``): the impulse is verified on top of the motion's e and u by the sampled
#: check (``NlpRefiner._sampled_and_steps``) and a violation tightens the rows there, so the NLP takes more than
#: the LP's V_STEP_SHARE, whose rows keep a fixed share free instead.
V_STEP_SHARE = 0.9
#: Relative overshoot at a verification point that triggers a tightening round.
VERIFY_TOL = 2e-3
VERIFY_SUBDIV = 4
MAX_CUT_ROUNDS = 4
#: A window whose best round is over a limit by at most this (fine grid) is accepted when
#: tightening stalls (Ipopt fails on tightened bounds, or the rounds run out); the sampled re-check, within
#: 1 % (``solvers.verify``), still judges what it gives.  5e-3 until session 34: bench seed 1881 lp+nlp (a
#: 1.31 mm piece on 20 um knots, a G1 junction whose curvature jumps by 5.3 /mm) ended its rounds at 1.0058,
#: and the chain fell back to the LP's feed, which the samples read at 1.044 x emax at the junction (the LP
#: of lp+nlp leaves e next to a step to the NLP): a 422 after 2 repair rounds, since session 9's 64-interval
#: plans (818095d).  With 8e-3 the NLP's feed is kept and passes (0.60 s of motion).
ACCEPT_TOL = 8e-3
#: A window's limits are verified this many knot intervals past its commit (the next window
#: inherits the first of them whole and the second's start state; the rest are its first free intervals).
#: With 2, the 18.35 m path at 4.63 mm knots in 496-interval LP windows had two NLP fallbacks: a window
#: committed a deceleration 0.6 of an interval short of a curvature jump it had not verified, whose sampled
#: step the next window, from those inherited control points, could not bring under emax (1.21 x, then
#: infeasible once tightened).  With 4: none, and bench seeds 10900-10999 and cam seeds 500-539 lp+nlp the
#: same motion (session 46).
VERIFY_PAST_COMMIT = 4
#: Retries with half the tightening when a tightened window is infeasible.
MAX_SOFTER_RETRIES = 2
#: Row bounds start at this fraction of each limit (fewer tightening rounds).
BOUND_FACTOR = 0.995
#: Tightened bounds never go below this fraction of the limit.
MIN_BOUND_FACTOR = 0.5
#: Extra margin applied with each tightening (beyond the measured overshoot).
TIGHTEN_MARGIN = 1e-3
#: A violated point's checkpoint bounds are scaled by overshoot^-TIGHTEN_POWER ...
TIGHTEN_POWER = 2.0
#: ... at these checkpoints relative to the one before the point.
TIGHTEN_SPREAD = np.arange(-1, 3)
#: Sub-points per checkpoint cell used for the x_sss envelope.
ENVELOPE_SUBDIV = 2
#: Reward on sum f over a window's overlap, relative to the time weights.
LAMBDA_TAIL = 1e-2
#: Weight of the overlap's travel time against the committed intervals'.  With none (only LAMBDA_TAIL's
#: reward on f there), a window whose commit fell just before a petal's valley kept its feed high up to the
#: commit and braked past it into the valley at 6.7 mm/s (the LP's: 37 mm/s), and the next window inherited
#: that braking: the 18.35 m path at 4.63 mm knots in 496-interval LP windows took 3.61 s for one of its
#: identical loops against a median 3.18 s.  Measured on that path (200-interval windows / 496 / default knots):
#: 0 -> 143.666 / 144.140 / 135.461 s of motion, 0.1 -> 143.619 / 143.306 / 135.331, 0.3 -> 143.615 / 143.110 /
#: 135.315, 1.0 -> 143.617 / 143.100 / 135.316, and 5-10 % fewer NLP iterations (session 46).
TAIL_TIME_WEIGHT = 0.3
#: Offset added to f in 1/f of the time objective (scaled units).
DELTA_F = 1e-3
#: Offset (mm) used to evaluate either side of a geometry knot (at the knot's own s the path may be
#: evaluated on either side: bench seed 6 gave the left side at s and the right side at s + 1e-12).
BREAK_EPS_MM = 1e-6
#: Adaptive verification: a fine-grid cell is bisected (at most REFINE_LEVELS times) where the
#: tangent turns by more than REFINE_TURN (rad) or a utilisation changes by more than REFINE_UTIL
#: across it (features narrower than the uniform grid: sharp turns, curvature peaks).
REFINE_LEVELS = 6
REFINE_TURN = 0.05
REFINE_UTIL = 0.05
REFINE_MAX_POINTS = 20_000
#: Sampled check (``NlpRefiner._sampled``): time steps per sample period of its uniform grid, and the
#: largest grid (a window slower than that per sample is not checked: its e changes little per sample).  Even: the
#: plain third difference (``util["sampled_jerk"]``) reads the second differences Ts / 2 either side of its centre.
SAMPLED_SUBDIV = 8
SAMPLED_MAX_POINTS = 400_000
#: The sampled check also reads the motion just outside the window (``_Context``): this many sample
#: periods of it on each side (the centres up to 2 Ts outside, whose differences reach 2 Ts further),
#: found on a grid of at most CONTEXT_POINTS points.  Without it the centres within 2 Ts of a window
#: end went unchecked: at 7 m/s a 31 mm piece is five samples, and bench seed 537 showed sampled
#: e 1.023 x emax 1.3 Ts before a window's end, where the window's own check read 0.937.
CONTEXT_SAMPLES = 4.5
CONTEXT_POINTS = 2_000
#: ... and evaluated every this many sample periods (the check's grid is Ts / SAMPLED_SUBDIV).
CONTEXT_STEP = 1.0 / 16.0
#: A window starts using cut slots when a violated stretch's worst point is over a limit by more than
#: this factor (a feature the checkpoints do not see); smaller overshoots tighten the checkpoints
#: around them.  Once it uses slots, every violated stretch gets one while its interval's is free.
SLOT_OVERSHOOT = 1.05
#: Scale-down steps of the LP hand-over until it meets the NLP's limits.
HANDOVER_SHRINK = 0.97
#: OSQP's ADMM step for the hand-over fit (its default), set up with and restored after every fit that adapted it.
HANDOVER_RHO = 0.1
HANDOVER_MAX_STEPS = 30
#: A chain whose LP feed is already what the NLP would give, at its feed bound (Fmax, the path's feed
#: limit, vmax / |x_s|) to this share on the chain's fine grid, is not solved: the NLP cannot move
#: faster there.  Only without a curvature jump or tangent break with a step cap in the chain, and
#: with every other utilisation of the LP's feed (the NLP's model and the sampled check) at most
#: LP_KEPT_UTIL (bench seed 3714: the LP at Fmax on 99.9 % of a 3.2 m path at 0.052 mm knots, u and e
#: at most 0.17 and 0.015 of their limits; 1,376 NLP windows took 178 s of CPU to return Fmax).
LP_KEPT_FEED_GAP = 1e-4
LP_KEPT_UTIL = 0.9
#: ... and a break with a step cap stops it only where the LP's feed there is over this share of the cap (until
#: session 53 every such break did, whatever the feed: a 3-D wave at a 5 mm/s cap, its C1 knots every ~12 of the
#: knot floor's intervals, kept 6 of 5,423 intervals, and 218 NLP windows took 6.9 s to gain 1.3 ms in 54.23 s;
#: now 10 windows, 0.7 s of CPU).  The step's servo error (``_step_servo_error``) is among the utilisations above.
LP_KEPT_STEP_CAP_SHARE = 0.9
#: Inside a chain that is not kept whole, a stretch of knot intervals where the LP's feed is kept by the same
#: rules keeps it unsolved too (``kept_parts``): the chain is solved as the parts either side of it, each from
#: and to the LP's state at the stretch's ends.  Without it the NLP's work grew with the LP's windows, whose
#: joins cut the chains: cam-bench seed 132 with LP windows of 200 / 400 / 800 intervals took 1,873 / 3,585 /
#: 6,674 NLP windows (cam seed 4: 76 / 24 / 6 chains kept whole, 173 / 251 / 337 windows).
#: A solved part takes this share of the NLP overlap (at least one interval) from the stretch next to it: the
#: NLP's feed may leave (reach) the bound earlier (later) than the LP's, within its stopping distance ...
LP_KEPT_MARGIN_PER_OVERLAP = 1.0
#: ... and a stretch is kept only if what is left of it is at least this many NLP overlaps long.
LP_KEPT_MIN_RUN_PER_OVERLAP = 1.0


#: CPU seconds one Ipopt solve may take (its own clock, all threads).  Normal solves take 0.02-0.5 s; on a
#: few windows whose solve fails anyway MUMPS's numerical pivoting (delayed pivots: dense fronts) made each
#: iteration ~0.3 s: bench seed 25 (lp+nlp) spent 91 s in one re-solve that ran its 300 iterations to
#: Maximum_Iterations_Exceeded, 97 of the case's 99 s; the safe retry then took 0.8 s.
MAX_SOLVE_CPU_S = 5.0
#: The NLP shapes the rest intervals too: a chain that starts (ends) at a rest end of the piece solves its
#: first (last) window with the rest interval's q as the quadratic from rest to the f spline's state at the
#: inner knot (``_Shape._rest_rows``), so that state is the NLP's to choose instead of the LP's (whose rest
#: interval holds the drive's rows only conservatively, and whose state the f spline may not be able to
#: continue: docs/benchmark-history.md "The rest zones").  If such a window fails, the chain is solved again
#: from (to) the LP's state at the inner knot, as without.
REST_ENDS = True
#: ... and gives a rest interval's q one more degree of freedom: q = the quadratic from rest + g b, with
#: b = tau (1 - tau)^2 (``bspline.rest_bump``: 0 at both ends, slope 0 at the inner knot) and g = p_rest f_in,
#: p_rest the otherwise unused control point p_0 (p_n+1) and f_in the feed at the inner knot.  The quadratic
#: alone ties the acceleration at rest to the state at the inner knot, and its acceleration can only fall
#: along the interval; the 4x finer NLP's rises after the step at rest (flower: 1711 -> 3010 mm/s^2 in the
#: first 0.5 mm) and reaches 72 mm/s at 1 mm against the quadratic's 55.
REST_BUMP = True
#: ... and, with REST_BUMP, a third: h e, e = tau^2 (1 - tau)^2 (``bspline.rest_bump``: 0 at both ends, slope
#: 0 at both), h = r f_in with r a variable of its own per rest end (x past p_n+1).  Where the step at rest is
#: at its bound (the LP's) the bump is spent on the step (flower: g < 0, the quadratic's own slope was over
#: it), and the acceleration could not rise after the step; e moves neither the step nor the inner state.
#: A window from (to) rest that fails with it is solved again without it before the LP's state is taken
#: (``NlpRefiner.rise``): the rest interval's N + 1 checkpoints hold the sharper shape less well
#: (``square_corner``: 1.12 x between them after 4 rounds).  Flower 3.0033 -> 2.9996 s.  Since session 17
#: one rise per power in ``bspline.REST_RISE_POWERS`` (2, 3, 4, 5: q a polynomial of degree 7 in tau that
#: vanishes at rest), each its own variable, with the rest points' rows (``REST_SUBDIV``) to hold them:
#: flower 2.9996 -> 2.9810 s, its rest intervals 2.3 and 0.2 ms behind the 4x finer NLP's (were 7.0, 8.8).
REST_RISE = True
#: A rest interval has rows at tau = j / (N REST_SUBDIV), j = 0 .. N REST_SUBDIV: its N + 1 checkpoints and,
#: between them, the rest points (``rest_point_taus``: the path's exact derivatives there, like a cut slot's,
#: and bounds of their own, tightened by the violations next to them).  Over 1 / N of a knot interval the
#: shapes q + g b + sum h_k e_k swing between the checkpoints: flower at N = 4 with two rises and no rest
#: points the rest intervals gained 1-1.5 ms and the tightening of their few rows took 3-4 ms from the
#: intervals next to them (3.0053 s against one rise's 2.9996); with rows as dense as the 4x finer NLP's
#: the rises pay (``REST_RISE``, ``bspline.REST_RISE_POWERS``).
REST_SUBDIV = 4
#: A rest end whose LP feed at the rest interval's inner knot is at least this share of the NLP's feed bound
#: there (``_feed_bound``: the feed cap, the axes' vmax) is solved without its rises (``NlpRefiner.rise``; None:
#: never): the LP's ramp reaches the bound within the interval, and the degree-7 rest polynomial cannot rise
#: to it and stay flat: it wobbled under the cap (a line at 1 mm/s left rest at 0.91, 0.85, 0.84, 0.97, 0.96,
#: 0.79 of it in its first 13 ms; session 59: dips of 18.0, 7.6, 5.5, 4.2 % of the cap at 1, 2, 3, 5 mm/s, none
#: with the rises off, for +3.0 to +4.7 ms a rest end).  0.99 left 5 and 6 mm/s's (LP at 0.948 of the cap
#: there).  Cam 0-59 lp+nlp: 22 of 60 programs changed, -8.9 ms net over their 4,325 s; rest ramps dipping
#: over 1 % 44 -> 30 of 120 (those left: the path's own (the LP's dip too) or the bound well above the LP's
#: feed there).  The router without a feed cap has no bound at a rest end (inf): the benchmarks are unchanged.
#: 0.8 since session 61: at 0.9 the same line at 7-12 mm/s (the LP at 0.83-0.90 of the cap there) dipped by 3.9,
#: 1.1, 1.9, 0.3, 0.4 % at 7, 9, 10, 11, 12 mm/s; at 0.8 by under 1e-5, for +2.1-2.5 ms a rest end; cam 0-59
#: lp+nlp: 7 programs changed, +5.0 ms net (+0.08 to +3.3 ms), two rest ramps' 0.5 and 0.9 % dips gone.
REST_RISE_CAP_SHARE: float | None = 0.8
#: A free feed control point whose bound is the same (to ``lp.FLAT_CAP_RTOL``) at every checkpoint of its
#: support is held at that bound (``flat_feed_columns``).
FLAT_FEED_COLUMNS = True
#: ... but for the first (last) REST_FLAT_SKIP control points at a rest end: p_0 carries the rest interval's bump
#: and p_1 its feed's inner end, the rest interval's feed being its own polynomial, not the f spline.  3 at
#: first (p_2 too, whose support reaches into the rest interval): the circle of 100 mm at 50 mm/s then passed
#: the cap by 0.06 % in the interval after the rest interval (p_2 over it between the checkpoints) and dipped
#: 1.7 % under it after; with 2, 2.7e-7 and never over it, 0.01 ms faster.
REST_FLAT_SKIP = 2
#: A window from or to rest is solved with its slot rows from round 0 (``_Shape`` ``slotted``; unused slots
#: are unbounded): one shape to build instead of two.
REST_SLOTTED = True
#: Pieces on fewer knot intervals keep the LP's rest intervals.
REST_ENDS_MIN_INTERVALS = 4
#: Gauss-Legendre nodes and weights on [0, 1] for a rest interval's travel time (``_Shape._rest_rows``).
_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(16)
REST_GL: tuple[FloatArray, FloatArray] = (0.5 * _GL_WEIGHTS, 0.5 * (_GL_NODES + 1.0))
#: Floor of the scaled q under a square root in a rest interval (q is 0 at rest itself).
REST_Q_FLOOR = 1e-20
#: A rest interval's control point next to rest may fall to this share of the LP's (its acceleration at
#: rest; keeps the travel time's integrand finite) and not rise above the LP's (the LP sized the step at
#: rest for the sampled servo error: ``solvers.lp``'s rest rows).
REST_C_FLOOR = 1e-3
#: ... and its upper bound is this share of the LP's: Ipopt meets a row's bound to its tolerance (a
#: random corner read 1.9e-6 over a bound of the LP's value), so the step at rest stays within the LP's.
REST_C_CEIL = 1.0 - 1e-5
IPOPT_OPTIONS: dict[str, Any] = {
    "ipopt.print_level": 0,
    "ipopt.sb": "yes",
    "print_time": False,
    "ipopt.max_iter": 300,
    # a solve that runs past this much CPU stops (status Maximum_CpuTime_Exceeded) and is handled as any
    # failed solve (MAX_SOLVE_CPU_S)
    "ipopt.max_cpu_time": MAX_SOLVE_CPU_S,
    # (1e-7 before: 1e-6 saves 10 % of the iterations on the 18.35 m path at 4.63 mm knots, motion -0.06 %;
    # the limits are verified on the fine grid whatever Ipopt reports; 1e-5 cost 0.2 % motion on the flower)
    "ipopt.tol": 1e-6,
    "ipopt.acceptable_tol": 1e-5,
    # fewer iterations than the monotone default on this problem class (249 vs 337 on two flower loops)
    "ipopt.mu_strategy": "adaptive",
    "ipopt.linear_solver": "mumps",
    # spec §10: MUMPS scaling off cut NLP time ~2.5x on this problem class
    "ipopt.mumps_permuting_scaling": 0,
    "ipopt.mumps_scaling": 0,
    # approximate minimum degree ordering instead of MUMPS's automatic choice: a window that solves a rest
    # interval (its rest points' rows, ``REST_SUBDIV``) took 2-3x as long per iteration in the linear
    # solves with the automatic choice (bench seed 0: 0.76 -> 0.33 s, seed 35: 1.83 -> 0.99 s); other
    # windows about the same (18.35 m path at 4.63 mm knots: 16.5 -> 15.8 s of NLP, same iterates)
    "ipopt.mumps_pivot_order": 0,
    # no forced iterative-refinement step after each KKT solve (Ipopt still refines when the residual
    # is large): the same iterates to ~1e-14 and ~10 % less Ipopt time (flower x10 at 4.63 mm, replayed
    # windows, best of 5: 0.82 -> 0.74 s)
    "ipopt.min_refinement_steps": 0,
    "error_on_fail": False,
    # no multipliers of the ~1,400 parameters after each solve (unused): ~1 ms a call
    "calc_lam_p": False,
}
#: Re-solves of a window (tightening rounds) start from the previous round's primal and dual point:
#: the rows are the same (a cut slot adds rows whose multipliers start at 0), only bounds moved.
#: Flower x10 at 4.63 mm knots: re-solve iterations 415 -> ~220 (cold Ipopt walks back to the
#: central path from mu_init).  A window inheriting from the previous one starts from that window's
#: last dual point shifted by the advance (rows past its end at 0): 18.35 m path at 4.63 mm knots,
#: 4280 -> 4042 iterations.  Other solves start from zero multipliers: one nlpsol per shape serves
#: both (a second, cold one doubled the set-up: ~0.2 s a 39-interval shape, seconds for a
#: full-horizon one), and zero multipliers cost about what Ipopt's own start does (63 flower
#: windows replayed: 993 vs 994 iterations).
IPOPT_WARM_OPTIONS: dict[str, Any] = {**IPOPT_OPTIONS, "ipopt.warm_start_init_point": "yes"}
#: Start solves from the previous round's / window's dual point (tests compare with False).
WARM_START = True
#: A solve that fails is retried once with Ipopt's own cold start and the tighter, slower settings
#: (forced refinement step, tol 1e-7): on random bench cases the fast settings declared a few more
#: windows locally infeasible in round 0 (80 bench-profile seeds: 13 fallbacks vs 6 before them).
IPOPT_SAFE_OPTIONS: dict[str, Any] = {**IPOPT_OPTIONS, "ipopt.tol": 1e-7, "ipopt.min_refinement_steps": 1}


#: Windows are solved first by ``solvers.ipm.DenseIpm`` (a condensed, dense interior point for few
#: variables and many rows); a solve it does not finish goes to Ipopt with IPOPT_SAFE_OPTIONS, cold.
#: Replayed windows (flower x10 and bench seeds 0-11, 156 solves at Ipopt's start points): all converged,
#: objective within 1.1e-6 of Ipopt's or below it, 1.13 vs 2.90 s and 2.70 vs 9.41 s of CPU.
DENSE_IPM = True
#: A window the dense method does not finish from the hand-over (warm, then cold) is tried once more with the
#: rows violated at the start elastic (``solvers.ipm``, ``solve(elastic=True)``) before Ipopt: such starts read
#: up to 600 x a limit, and the plain method's steps shrink to 1e-4..1e-9 there.
DENSE_ELASTIC = True
#: The dense method's status for rows its elastic attempt found locally infeasible (``ipm.ELASTIC_RHO_GROWTH``).
#: In a tightening round (or its softer retries) the solve is then not handed to Ipopt but fails as Ipopt's
#: infeasible ones do: the best verified feed so far, else a softer retry.  A window's first solve still goes to
#: Ipopt: the verdict is a local one (on random non-convex rows it was once wrong where Ipopt solved, test_ipm),
#: and there a wrong one would cost the window its NLP feed, where in a round it costs a softer tightening.
DENSE_INFEASIBLE = STATUS_INFEASIBLE


def _dense_solve(ipm: DenseIpm | None, x: FloatArray, p: FloatArray, lbx: FloatArray, ubx: FloatArray,
                 lbg: FloatArray, ubg: FloatArray, lam_g: FloatArray) -> IpmResult | None:
    """``ipm.solve`` from the given multipliers, and if that does not finish, from unit ones (``ipm.WARM_MU0``),
    and if that does not either, from unit ones with the rows violated at x elastic (``ipm.ELASTIC_RHO``); None
    without a dense solver.  An arithmetic error in it is a failed solve (Ipopt then solves the window from the
    same start).  The result's iterations are all the solves'."""
    if ipm is None:
        return None

    def one(lam: FloatArray | None, elastic: bool = False) -> IpmResult:
        try:
            return ipm.solve(x, p, lbx, ubx, lbg, ubg, lam, elastic=elastic)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            return IpmResult(x, np.zeros(lbg.size), np.zeros(x.size), 0, f"{type(exc).__name__}: {exc}")

    res = one(lam_g if np.any(lam_g) else None)
    if res.success:
        return res
    used = res.iterations
    if np.any(lam_g):
        res = one(None)
        used += res.iterations
    if not res.success and DENSE_ELASTIC:
        res = one(None, elastic=True)
        used += res.iterations
    return dataclasses.replace(res, iterations=used)


#: With the kinematic limits (``NlpLimits.amax``, ``jmax``: ``Options.nlp_kinematic``) the sampled check
#: (``NlpRefiner._sampled``) also reads the samples' acceleration and jerk (``util["sampled_acceleration"]``,
#: ``util["sampled_jerk"]``): at curvature jumps the model's points did not see bench seed 23's 1.16 x jmax.
SAMPLED_KINEMATIC = True
#: ... and reads the jerk as the plain third difference the promise is checked by (``tests/fdcheck``), with each
#: velocity step's impulse at its exact peak (``_impulse_probes``), not the drive model's central difference, which
#: reads an impulse at half: cam+opts seeds 183 and 235 lp+nlp, 1.05-1.26 x jmax where lines meet at 0.05 degrees
#: (session 68).
SAMPLED_PLAIN_JERK = True
#: The sampled check's servo error and control signal at each velocity step's exact kinks too (``_impulse_probes``):
#: on its grid of Ts / SAMPLED_SUBDIV they read ~0.95 x of the samples' own next to a tangent break (session 68).
SAMPLED_IMPULSE_PROBES = True
#: ``NlpRefiner._step_servo_error`` bounds a velocity step's impulse too (e and u either side plus the impulse's
#: bound, at the break's two points) everywhere.  False (session 69): only where the sampled check cannot read the
#: impulse (``_sampled_and_steps``); it reads it exactly (``_impulse_probes``), the bound ~1.3-1.8 x that.  On dense
#: unblended G01 spirals (0.1-1 mm chords turning by 0.14-0.45 degrees, lp+nlp) the bound's tightening did not
#: converge: 1-4 NLP windows fell back to the LP's feed; without it 0-1, motion -0.3 to -18 % (1.0 mm chords at
#: R 150-300 mm: 5.88 -> 4.81 s), NLP CPU down, the samples' e and u as before (``tests/solvers/test_tangent_breaks``).
#: cam 3750-3809 lp+nlp: 60/60 both, none longer, 5 shorter by up to 0.06 %.
STEP_BOUND_VSTEP = False
#: From a window's second tightening round on, a sampled servo error or control signal over its limit within reach
#: of a velocity step (a tangent break passed at speed) tightens the e and u rows of the checkpoints around it as an
#: overshoot of this power (``_vstep_boost``), and to at most the rows' own utilisation at that point x its
#: overshoot^-TIGHTEN_POWER (``NlpRefiner._vstep_ceiling``).  The step's impulse f |jump of x_s| is in the sampled
#: differences, not in the rows (x_ss = 0 along a polyline's chords): the sum came down too little a round, or not at
#: all while the rows were under their tightened bounds (the 0.5 mm spiral below: e 0.53 in the rows where the samples
#: read 1.03, the same solution in rounds 2-4).  1: off.  Session 70, dense unblended G01 spirals under lp+nlp whose
#: windows stayed over after 4 rounds and fell back to the LP's feed: 0.2 / 0.3 / 0.5 mm chords 2.193 / 2.787 / 4.077
#: -> 1.700 / 1.946 / 2.719 s, no fallback (``tests/solvers/test_tangent_breaks``); the power alone 1.705 / 2.031 s
#: and the 0.5 mm spiral still fell back; from the first round (tried) 5 of cam 3870-3929 ran up to 0.13 % longer
#: (windows that pass anyway tightened harder than they needed); a power of 1.5 left the 0.3 mm spiral falling back;
#: capping the feed rows instead (the round's feed x overshoot^-2 around the point) dipped the feed and made it worse
#: (worst 1.35, fallbacks 1 -> 2 / 1 -> 1 / 0 -> 3 on the 0.2 / 0.3 / 1.0 mm spirals).  Under ``Options.nlp_kinematic``
#: the sampled jerk (|dv| / Ts^2 an impulse) holds the jerk rows the same way (their own cap, ``cap_j``): a 0.05 mm
#: spiral 4.906 -> 4.164 s, fallbacks 4 -> 1; 0.1 mm 5.404 -> 5.016 s.
VSTEP_TIGHTEN_BOOST = 2.0
#: ... the first round (``rnd``) whose tightening that applies to
VSTEP_BOOST_ROUND = 2


class NlpFailure(Exception):
    """An NLP window did not produce a verified feasible feed (handled by falling back to the LP)."""

    def __init__(self, reason: str, window: int, status: str = "") -> None:
        super().__init__(reason)
        self.reason = reason
        self.window = window
        self.status = status


@dataclass(frozen=True)
class NlpLimits:
    """Per-axis drive coefficients and the optional kinematic limits, each (3,)."""

    M: FloatArray
    b: FloatArray
    c: FloatArray
    d: FloatArray
    Kv: FloatArray
    Ka: FloatArray
    Kj: FloatArray
    umax: FloatArray
    emax: FloatArray
    vmax: FloatArray | None
    amax: FloatArray | None
    jmax: FloatArray | None
    feed_max: float | None
    #: largest step of axis acceleration allowed at a curvature jump (3,), or None (see solvers.lp.LimitSet)
    a_step: FloatArray | None = None
    #: output sample period Ts, s: the servo error of an acceleration step at a curvature jump is
    #: verified as seen over one sample (Kj |step| / (2 Ts) on top of e on either side), or None
    sample_period: float | None = None
    #: largest step of axis velocity allowed at a tangent break passed at speed (3,) mm/s, or None
    #: (``solvers.lp.v_step_limit``; its impulse in the sampled e and u is verified with the
    #: acceleration step's, ``NlpRefiner._step_servo_error``)
    v_step: FloatArray | None = None

    @classmethod
    def from_machine(
        cls, m: Machine, axis_velocity: bool, kinematic: bool, a_step: FloatArray | None = None,
        sample_period: float | None = None, v_step: FloatArray | None = None,
    ) -> NlpLimits:
        dr = m.drive_arrays()
        vmax, amax, jmax = m.limit_arrays()
        # axis speed: the drive's own limit (inf where none), and the LP's vmax only if asked
        v_cap = dr["vmax"] if not (axis_velocity or kinematic) else np.minimum(dr["vmax"], vmax)
        return cls(
            dr["M"], dr["b"], dr["c"], dr["d"], dr["Kv"], dr["Ka"], dr["Kj"], dr["umax"], dr["emax"],
            v_cap if np.isfinite(v_cap).any() else None,
            amax if kinematic else None,
            jmax if kinematic else None,
            m.feed_max,
            a_step,
            sample_period,
            v_step,
        )

    def utilisation(self, g: PathSamples, fd: kinematics.FeedDerivs) -> dict[str, FloatArray]:
        """|u|/umax, |e|/emax (and v, a, j, feed when limited) at points g, each (K, 3) or (K,).

        Friction uses sign(x_s), the sign of v for f > 0.
        """
        v, a, j = kinematics.axis_kinematics(g, *fd)
        u = self.M * a + self.b * v + self.c + self.d * np.sign(g.d1)
        e = self.Kv * v + self.Ka * a + self.Kj * j
        out = {"control_signal": np.abs(u) / self.umax, "servo_error": np.abs(e) / self.emax}
        if self.vmax is not None:
            out["velocity"] = np.abs(v) / self.vmax
        if self.amax is not None and self.jmax is not None:
            out["acceleration"] = np.abs(a) / self.amax
            out["jerk"] = np.abs(j) / self.jmax
        cap = np.full(g.s.size, np.inf if self.feed_max is None else self.feed_max)
        if g.feed_limit is not None:
            cap = np.minimum(cap, g.feed_limit)
        if np.isfinite(cap).any():
            out["feed"] = fd[0] / cap
        return out


# ----- one window shape ----------------------------------------------------------
def flat_feed_columns(feed_ub: FloatArray, n: int, N: int, head: bool, tail: bool) -> FloatArray:
    """Each feed control point's own bound (n + 2,), mm/s: the feed bound where it is the same (``lp.flat_bound``)
    at every checkpoint of the control point's three knot intervals, inf elsewhere and for the REST_FLAT_SKIP
    control points at a rest end (the rest interval's feed is not the f spline's).  With p >= 0, p_j <= F keeps
    f <= F between the checkpoints too (the B-spline's convex hull) and leaves no room for control points
    alternating about the bound on a cruise at a feed cap (``solvers.lp.flat_reach``, the LP's).

    feed_ub: (n (N + 1),) the bound at the checkpoints (``checkpoint_layout``), mm/s."""
    per = feed_ub.reshape(n, N + 1)
    lo = np.concatenate([[np.inf, np.inf], per.min(axis=1), [np.inf, np.inf]])
    hi = np.concatenate([[-np.inf, -np.inf], per.max(axis=1), [-np.inf, -np.inf]])
    lo3 = np.minimum(np.minimum(lo[:-2], lo[1:-1]), lo[2:])  # (n + 2,): intervals j - 2 .. j
    hi3 = np.maximum(np.maximum(hi[:-2], hi[1:-1]), hi[2:])
    out = flat_bound(lo3, hi3)
    if head:
        out[:REST_FLAT_SKIP] = np.inf
    if tail:
        out[-REST_FLAT_SKIP:] = np.inf
    return np.asarray(out, dtype=np.float64)


def checkpoint_layout(n: int, N: int) -> tuple[NDArray[np.int64], FloatArray]:
    """Knot interval k (window-local) and tau in [0, 1] of each NLP checkpoint, each (n (N+1),).

    Every interval is checked at tau = 0, 1/N, .., 1, so a knot is checked
    from both sides (f'' and the geometry's third derivative jump there).
    """
    k = np.repeat(np.arange(n, dtype=np.int64), N + 1)
    tau = np.tile(np.linspace(0.0, 1.0, N + 1), n)
    return k, tau


def rest_point_taus(N: int) -> FloatArray:
    """Unit tau of a rest interval's rest points (``REST_SUBDIV``): j / (N REST_SUBDIV) for j between the
    checkpoints' (each (M,), M = N (REST_SUBDIV - 1))."""
    j = np.arange(1, N * REST_SUBDIV)
    return np.asarray(j[j % REST_SUBDIV != 0] / (N * REST_SUBDIV), dtype=np.float64)


def knot_twins(n: int, N: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Checkpoints (window-local indices) of the rows that depend on f and f' only (u, a, f): ``kept``,
    and each interior knot's checkpoint seen from the left, ``dup`` (tau = 1 of interval k < n - 1),
    with its ``twin`` seen from the right (tau = 0 of interval k + 1).  f and f' are continuous at a knot
    and the geometry is evaluated at the same s, so those rows are the same function twice: ``_Shape``
    keeps the twin's, bounded by both checkpoints' bounds (``NlpRefiner._row_bounds``)."""
    K = n * (N + 1)
    dup = np.arange(n - 1, dtype=np.int64) * (N + 1) + N
    kept = np.setdiff1d(np.arange(K, dtype=np.int64), dup)
    return kept, dup, dup + 1


def _interval_basis(k: NDArray[np.int64], tau: FloatArray, ncols: int) -> tuple[sp.csr_matrix, ...]:
    """B0, B1, B2 (K, ncols) for unit knot spacing at explicit (interval, tau) points."""
    W0 = np.column_stack([(1 - tau) ** 2 / 2, (-2 * tau * tau + 2 * tau + 1) / 2, tau * tau / 2])
    W1 = np.column_stack([-(1 - tau), 1 - 2 * tau, tau])
    W2 = np.broadcast_to(np.array([1.0, -2.0, 1.0]), W0.shape)
    return tuple(bspline.design(k, W, 0, ncols) for W in (W0, W1, W2))


def eval_f(p: FloatArray, k: NDArray[np.int64], tau: FloatArray, d: float) -> kinematics.FeedDerivs:
    """f, f', f'' of window control points p at explicit (interval, tau) points."""
    c0, c1, c2 = p[k], p[k + 1], p[k + 2]
    a2 = c0 - 2.0 * c1 + c2
    a1 = c1 - c0
    return 0.5 * (c0 + c1) + tau * (a1 + 0.5 * a2 * tau), (a1 + a2 * tau) / d, a2 / (d * d)


@functools.cache
def _checkpoint_function(na: int, with_aj: bool, values_only: bool = False) -> Any:
    """The rows of one NLP checkpoint (``_Shape._mapped_problem``), as a CasADi function of
    (y_k (3), its parameters (4 na + 2), the window's (2 + 8 na)[, lam_k (R)]).

    Out (one column): the R rows (``_Shape._axis_rows`` at the point, then the scaled feed f^), then with
    ``values_only`` the term w_time / (f^ + DELTA_F) - w_feed f^; else their Jacobian in y_k (R x 3, column
    by column), the term, its gradient (3) and the Hessian of term + lam_k^T rows in y_k (3 x 3, column by
    column), by automatic differentiation of this one point (a derivation written out by hand measured
    320 instructions against 337 with 2 axes: not worth its code)."""
    y3 = ca.SX.sym("y", 3)
    pk = ca.SX.sym("pk", 4 * na + 2)
    gl = ca.SX.sym("gl", 2 + 8 * na)
    Fs, inv_d = gl[0], gl[1]
    fh = y3[0]
    f, f1, f2 = Fs * fh, Fs * inv_d * y3[1], Fs * inv_d * inv_d * y3[2]
    axes = range(na)
    rows = _Shape._axis_rows(f, f1, f2, [pk[i] for i in axes], [pk[na + i] for i in axes],
                             [pk[2 * na + i] for i in axes], [pk[3 * na + i] for i in axes],
                             [gl[2 + 8 * i : 10 + 8 * i] for i in axes], with_aj)
    r = ca.vertcat(*rows, fh)
    term = pk[4 * na] / (fh + DELTA_F) - pk[4 * na + 1] * fh
    if values_only:
        return ca.Function("nlp_checkpoint", [y3, pk, gl], [ca.vertcat(r, term)])
    lk = ca.SX.sym("lam", r.size1())
    h, _ = ca.hessian(term + ca.dot(lk, r), y3)
    return ca.Function("nlp_checkpoint_d", [y3, pk, gl, lk],
                       [ca.vertcat(r, ca.vec(ca.densify(ca.jacobian(r, y3))), term, ca.gradient(term, y3),
                                   ca.vec(ca.densify(h)))])


def _interval_function(na: int, with_aj: bool, N: int, values_only: bool = False) -> Any:
    """``_interval_functions`` (cached by its arguments given in full, however they are given here)."""
    return _interval_functions(int(na), bool(with_aj), int(N), bool(values_only))


@functools.cache
def _interval_functions(na: int, with_aj: bool, N: int, values_only: bool) -> Any:
    """``interval_sx`` compiled to C (``solvers.ccompile``: the same values, ~12 x faster with 2 axes)."""
    return ccompile.compiled(interval_sx(na, with_aj, N, values_only))


def interval_sx(na: int, with_aj: bool, N: int, values_only: bool) -> Any:
    """``_checkpoint_function`` over the N + 1 checkpoints of one knot interval (each argument and the
    result with one column per checkpoint; the window's parameters once), as one SX function: mapped over
    the window's intervals it is called n times instead of n (N + 1), and reads the window's parameters
    once per interval."""
    base = _checkpoint_function(na, with_aj, values_only)
    ins = [ca.SX.sym(f"i{i}", int(base.size1_in(i)), 1 if i == 2 else N + 1) for i in range(base.n_in())]
    name = f"nlp_interval{'' if values_only else '_d'}_{na}{'aj' if with_aj else ''}_{N}"
    return ca.Function(name, ins, [base.map(N + 1)(*ins)])


def _slot_function(na: int, with_aj: bool, values_only: bool = False) -> Any:
    """``_slot_functions`` (cached by its arguments given in full, however they are given here)."""
    return _slot_functions(int(na), bool(with_aj), bool(values_only))


@functools.cache
def _slot_functions(na: int, with_aj: bool, values_only: bool) -> Any:
    """``slot_sx`` compiled to C (``solvers.ccompile``)."""
    return ccompile.compiled(slot_sx(na, with_aj, values_only))


def slot_sx(na: int, with_aj: bool, values_only: bool) -> Any:
    r"""The rows of one cut slot (``_Shape`` ``slotted``) as a function of its knot interval's control points
    c = (c_0, c_1, c_2), its parameters (tau, then x_s, x_ss, x_sss per moving axis), the window's (2 + 8 na)
    [and the rows' multipliers lam (R)]: ``_checkpoint_function``'s R rows at y = B(tau) c, the point's
    (f^, f^', f^'') (q's quadratic on the interval), with x_sss as both envelope bounds.

    Out (one column): the R rows; unless ``values_only`` then their Jacobian in c (R x 3, column by column)
    and the Hessian of lam^T rows in c (3 x 3, column by column): J_y B and B^T H_y B, by automatic
    differentiation of this one slot (``_Shape._mapped_problem`` maps it over the window's n slots)."""
    c3 = ca.SX.sym("c", 3)
    ps = ca.SX.sym("ps", 1 + 3 * na)
    gl = ca.SX.sym("gl", 2 + 8 * na)
    t = ps[0]
    c0, c1, c2 = c3[0], c3[1], c3[2]
    y3 = ca.vertcat(0.5 * (c0 + c1) + t * ((c1 - c0) + 0.5 * (c0 - 2 * c1 + c2) * t),
                    (c1 - c0) + (c0 - 2 * c1 + c2) * t, c0 - 2 * c1 + c2)
    xsss = ps[1 + 2 * na : 1 + 3 * na]
    pk = ca.vertcat(ps[1 : 1 + 2 * na], xsss, xsss, ca.SX.zeros(2))
    base = _checkpoint_function(na, with_aj, values_only=True)
    r = base(y3, pk, gl)[: base.size1_out(0) - 1]  # (without the checkpoint's travel-time term)
    name = f"nlp_slot{'' if values_only else '_d'}_{na}{'aj' if with_aj else ''}"
    if values_only:
        return ca.Function(name, [c3, ps, gl], [r])
    lam = ca.SX.sym("lam", r.size1())
    h, _ = ca.hessian(ca.dot(lam, r), c3)
    return ca.Function(name, [c3, ps, gl, lam],
                       [ca.vertcat(r, ca.vec(ca.densify(ca.jacobian(r, c3))), ca.vec(ca.densify(h)))])


def _rest_end(p_rest: Any, p_in: Any, p_out: Any, rise: Sequence[Any], Fs: Any, inv_d: Any, ck: list[list[Any]],
              coef: list[Any], with_aj: bool, head: bool, N: int, pts: list[list[Any]] | None,
              scale: Any) -> tuple[Any, list[Any], Any, Any, list[Any]]:
    r"""The rows of one rest end of a window (``_Shape._rest_rows``, whose docstring has the formulas), in
    CasADi SX.

    From the f spline's control points at the end: p_rest (p_0 or p_n+1: the bump's amplitude, ``_rest_g``),
    p_in and p_out (either side of the inner knot: ``rest_cps``) and the end's ``rise`` variables; at the rest
    interval's N + 1 checkpoints ``ck`` = [x_s, x_ss, x_sss_hi, x_sss_lo][axis] (columns of N + 1) and its rest
    points ``pts`` = [x_s, x_ss, x_sss][axis] (columns of M; None: none), with the window's Fs, 1/d and the
    axes' coefficients ``coef``.

    Returns (the row next to rest c_rest + g / 2, the checkpoints' rows per block (``_Shape._axis_rows_t``:
    per axis u, e_hi, e_lo, [a, j_hi, j_lo]; columns of N + 1), the scaled feed sqrt(q) there (N + 1), the
    travel time ``scale`` (2 / n) times the Gauss-Legendre sum, the rest points' rows per block
    (``_exact_rows``)).  ``_Shape._rest_rows`` calls it with the window's symbols (the whole-window problem:
    Ipopt's, and the tests' oracle), ``_rest_end_exprs`` with the end's own (its rows' linearity, and
    ``rest_end_sx``: the reference of ``_rest_end_mx``, which the dense method evaluates)."""
    wq, xq = REST_GL
    c0, c1, c2 = _rest_cp_values(p_in, p_out, head)
    c_rest, c_in = (c1, c2) if head else (c1, c0)   # next to rest, and the inner one
    # the bump's amplitude (REST_BUMP; p_rest, unused otherwise, is fixed at 0 without it) and the rises'
    # (REST_RISE; their variables fixed at 0 where the bump is)
    g = _rest_g(p_rest, p_in, p_out) if REST_BUMP else None
    h = [_rest_g(r, p_in, p_out) for r in rise]
    extra = c_rest if g is None else c_rest + 0.5 * g
    travel = scale * sum(
        float(wi) / ca.sqrt(ca.fmax(
            2.0 * c_rest + 0.5 * (c_in - 3.0 * c_rest) * float(xi) ** 2
            + (0.0 if g is None else bspline.rest_bump_quotient(float(xi) ** 2, g, h)), REST_Q_FLOOR))
        for wi, xi in zip(wq, xq, strict=True)
    )
    r, sd, sdd, sddd = _rest_point(np.linspace(0.0, 1.0, N + 1), (c0, c1, c2), g, h, head, Fs, inv_d)
    vals = _Shape._axis_rows_t(sd, sdd, sddd, ck[0], ck[1], ck[2], ck[3], coef, with_aj)
    point_vals: list[Any] = []
    if pts is not None:
        # (x_sss exact: e_hi = e_lo and j_hi = j_lo, one row each with both bounds: ``_exact_rows``)
        _, sd, sdd, sddd = _rest_point(rest_point_taus(N), (c0, c1, c2), g, h, head, Fs, inv_d)
        point_vals = _exact_rows(_Shape._axis_rows_t(sd, sdd, sddd, pts[0], pts[1], pts[2], pts[2], coef, with_aj),
                                 with_aj)
    return extra, vals, r, travel, point_vals


def _rest_settings() -> tuple[Any, ...]:
    """The module settings a rest end's rows are built with (tests switch them): part of the key of
    ``_rest_end_function``'s cache, as of ``_cached_shape``'s."""
    return (REST_BUMP, REST_RISE, REST_SUBDIV, REST_Q_FLOOR, DELTA_F, bspline.REST_BUMP_POWER,
            bspline.REST_RISE_POWERS, REST_GL[0].tobytes(), REST_GL[1].tobytes())


@dataclass(frozen=True)
class RestEnd:
    """One rest end's rows as functions of its own variables (``_rest_end_mx``), and their layout.

    Inputs: z = (p_rest, p_in, p_out, rise_1 .. rise_nr) (3 + nr,), the rest interval's checkpoint parameters
    PK (4 na + 2, N + 1: x_s, x_ss, x_sss_hi, x_sss_lo per moving axis, w_time, w_feed: ``_Shape``'s order),
    its rest points' RP (3 na, M: x_s, x_ss, x_sss of axis 0, then of axis 1, ...), the window's (2 + 8 na),
    the travel time's factor 2 / n (1,)[, the rows' multipliers lam (R (N + 1) + 1 + B M)].
    Rows, ``rows`` in all: the checkpoints' (template row r of checkpoint c at r (N + 1) + c: ``_Shape``'s R
    rows, the scaled feed last), the row next to rest, the rest points' (block b of point j at
    R (N + 1) + 1 + b M + j).
    ``values``: (rows, term) with the term the travel time plus the checkpoints' w_time / (f^ + DELTA_F) -
    w_feed f^; ``derivatives``: the same, the rows' Jacobian in z (sparse, ``jac``'s pattern), the term's
    gradient (dense) and the Hessian of term + lam^T rows in z (sparse, ``hess``' pattern)."""

    values: Any
    derivatives: Any
    rows: int
    #: rows (rows,) whose second derivatives in z vanish
    linear: NDArray[np.bool_]
    #: (row, column) of the Jacobian's entries in its nonzero order
    jac: tuple[NDArray[np.int64], NDArray[np.int64]]
    #: (row, column) of the Hessian's entries in its nonzero order
    hess: tuple[NDArray[np.int64], NDArray[np.int64]]


def _rest_end_exprs(na: int, with_aj: bool, N: int, head: bool, nr: int, M: int) -> tuple[list[Any], Any, Any]:
    """``RestEnd``'s inputs (without lam), rows and term: ``_rest_end`` at symbols of the end's own (SX)."""
    z = ca.SX.sym("z", 3 + nr)
    npk = 4 * na + 2
    pk = ca.SX.sym("pk", npk, N + 1)
    rp = ca.SX.sym("rp", 3 * na, M)
    gl = ca.SX.sym("gl", 2 + 8 * na)
    scale = ca.SX.sym("scale")
    col = [pk[i, :].T for i in range(npk)]
    ck = [col[b * na : (b + 1) * na] for b in range(4)]
    pts = [[rp[3 * i + j, :].T for i in range(na)] for j in range(3)] if M else None
    coef = [gl[2 + 8 * i : 10 + 8 * i] for i in range(na)]
    extra, vals, r, travel, point_vals = _rest_end(z[0], z[1], z[2], [z[3 + i] for i in range(nr)], gl[0], gl[1],
                                                   ck, coef, with_aj, head, N, pts, scale)
    rows = ca.vertcat(*vals, r, extra, *point_vals)
    term = travel + ca.sum1(col[npk - 2] / (r + DELTA_F)) - ca.sum1(col[npk - 1] * r)
    return [z, pk, rp, gl, scale], rows, term


def rest_end_sx(na: int, with_aj: bool, N: int, head: bool, nr: int, M: int, values_only: bool) -> Any:
    """``RestEnd``'s function (its values, or with ``values_only`` False its derivatives too) as one SX
    function of the end's own variables, differentiated by CasADi: the tests' reference for ``_rest_end_mx``
    (evaluated in its stead it took 258 us against 25 us, 2 axes: ~34,000 instructions; gcc -O1 compiled them
    in 3-8 s to an evaluation of 111 us)."""
    ins, rows, term = _rest_end_exprs(na, with_aj, N, head, nr, M)
    name = (f"nlp_rest{'' if values_only else '_d'}_{na}{'aj' if with_aj else ''}_{N}_{'head' if head else 'tail'}"
            f"_{nr}_{M}")
    if values_only:
        return ca.Function(name, ins, [ca.vertcat(rows, term)])
    z = ins[0]
    lam = ca.SX.sym("lam", rows.size1())
    h, _ = ca.hessian(term + ca.dot(lam, rows), z)
    return ca.Function(name, [*ins, lam],
                       [ca.vertcat(rows, term), ca.jacobian(rows, z), ca.densify(ca.gradient(term, z)), h])


def _rest_point_sx(na: int, with_aj: bool, values_only: bool) -> Any:
    r"""One point of a rest interval (``RestEnd``) as a function of u = (q^, q^', q^'') there (q scaled by Fs^2,
    in unit tau), its parameters pk (4 na + 2: x_s, x_ss, x_sss_hi, x_sss_lo per moving axis, w_time, w_feed),
    the window's gl (2 + 8 na)[, the rows' multipliers lam (R)].

    sdot = Fs sqrt(q^), sddot = Fs^2 / d q^' / 2, sdddot = sdot Fs^2 / d^2 q^'' / 2 (``_rest_point``).  Out
    (one column): the R rows (``_Shape._axis_rows_t``, then sqrt(q^)) and the term w_time / (sqrt(q^) +
    DELTA_F) - w_feed sqrt(q^); unless ``values_only`` then the rows' Jacobian in u (R x 3, column by column),
    the term's gradient in u (3), that of term + lam^T rows (3) and its Hessian (3 x 3, column by column)."""
    u = ca.SX.sym("u", 3)
    pk = ca.SX.sym("pk", 4 * na + 2)
    gl = ca.SX.sym("gl", 2 + 8 * na)
    Fs, inv_d = gl[0], gl[1]
    r = ca.sqrt(ca.fmax(u[0], REST_Q_FLOOR))
    sd = Fs * r
    axes = range(na)
    rows = _Shape._axis_rows_t(sd, 0.5 * Fs * Fs * inv_d * u[1], 0.5 * sd * Fs * Fs * inv_d * inv_d * u[2],
                               [pk[i] for i in axes], [pk[na + i] for i in axes], [pk[2 * na + i] for i in axes],
                               [pk[3 * na + i] for i in axes], [gl[2 + 8 * i : 10 + 8 * i] for i in axes], with_aj)
    rr = ca.vertcat(*rows, r)
    term = pk[4 * na] / (r + DELTA_F) - pk[4 * na + 1] * r
    name = f"nlp_rest_point{'' if values_only else '_d'}_{na}{'aj' if with_aj else ''}"
    if values_only:
        return ca.Function(name, [u, pk, gl], [ca.vertcat(rr, term)])
    lam = ca.SX.sym("lam", rr.size1())
    lag = term + ca.dot(lam, rr)
    h, _ = ca.hessian(lag, u)
    return ca.Function(name, [u, pk, gl, lam],
                       [ca.vertcat(rr, ca.vec(ca.densify(ca.jacobian(rr, u))), term, ca.densify(ca.gradient(term, u)),
                                   ca.densify(ca.gradient(lag, u)), ca.vec(ca.densify(h)))])


@functools.cache
def _rest_point_functions(na: int, with_aj: bool, values_only: bool, settings: tuple[Any, ...]) -> Any:
    """``_rest_point_sx`` compiled to C (``solvers.ccompile``)."""
    del settings  # (the key of the cache only)
    return ccompile.compiled(_rest_point_sx(na, with_aj, values_only))


def _rest_node_function() -> Any:
    """A rest interval's travel-time integrand at one Gauss-Legendre node: tau(s) = w / sqrt(max(s, REST_Q_FLOOR))
    and its first two derivatives in s (``_rest_end``; one column of 3 per (s, w))."""
    s, wi = ca.SX.sym("s"), ca.SX.sym("w")
    tau = wi / ca.sqrt(ca.fmax(s, REST_Q_FLOOR))
    d1 = ca.gradient(tau, s)
    return ca.Function("nlp_rest_node", [s, wi], [ca.vertcat(tau, d1, ca.gradient(d1, s))])


def _rest_end_matrices(N: int, head: bool, nr: int, M: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """A rest end's constant maps from w = (c_0, c_1, c_2[, g, h_1 .. h_nr]) (``rest_cps``, ``_rest_g``, with
    REST_BUMP): A (3 P, nw), (q^, q^', q^'') at each of the P = N + 1 + M points (the checkpoints, then the rest
    points: ``_rest_point``'s quadratic plus g b + sum h_k e_k); An (REST_GL nodes, nw), the travel time's
    integrand under the root at each node (``_rest_end``); e (nw,), the row next to rest c_1 + g / 2."""
    ts = np.concatenate([np.linspace(0.0, 1.0, N + 1), rest_point_taus(N)[:M]])
    cols = [np.stack([0.5 * (1.0 - ts) ** 2, 0.5 * (1.0 + 2.0 * ts - 2.0 * ts * ts), 0.5 * ts * ts]),
            np.stack([ts - 1.0, 1.0 - 2.0 * ts, ts]),
            np.stack([np.ones_like(ts), -2.0 * np.ones_like(ts), np.ones_like(ts)])]  # [derivative](3, P)
    _, xq = REST_GL
    r = xq**2
    rest_n = 2.0 - 1.5 * r  # c_rest = c_1; c_in = c_2 at the head, c_0 at the tail
    an = [0.5 * r if not head else np.zeros_like(r), rest_n, 0.5 * r if head else np.zeros_like(r)]
    e = [0.0, 1.0, 0.0]
    if REST_BUMP:
        shapes = [bspline.rest_bump(ts, 1.0, 0, head, 1.0)]
        shapes += [bspline.rest_bump(ts, 1.0, 0, head, 0.0, tuple(float(i == k) for i in range(nr))) for k in range(nr)]
        cols = [np.vstack([c, *[s[j] for s in shapes]]) for j, c in enumerate(cols)]
        an.append(np.asarray(bspline.rest_bump_quotient(r, 1.0), dtype=np.float64))
        an += [np.asarray(bspline.rest_bump_quotient(r, 0.0, [float(i == k) for i in range(nr)]), dtype=np.float64)
               for k in range(nr)]
        e += [0.5] + [0.0] * nr
    A = np.stack(cols, axis=1)  # (nw, 3, P)
    nw = A.shape[0]
    return A.transpose(2, 1, 0).reshape(3 * ts.size, nw), np.stack(an, axis=1), np.asarray(e)


def _rest_w_function(head: bool, nr: int) -> Any:
    """w(z) = (c_0, c_1, c_2[, g, h_1 .. h_nr]) of a rest end's z = (p_rest, p_in, p_out, rise_1 .. rise_nr)
    (``_rest_cp_values``, ``_rest_g``; g and h with REST_BUMP), its Jacobian W (nw x nz) and, for given mu (nw),
    sum_k mu_k d2 w_k / dz2 (nz x nz)."""
    z = ca.SX.sym("z", 3 + nr)
    c0, c1, c2 = _rest_cp_values(z[1], z[2], head)
    w = [c0, c1, c2]
    if REST_BUMP:
        w += [_rest_g(z[0], z[1], z[2])] + [_rest_g(z[3 + i], z[1], z[2]) for i in range(nr)]
    wv = ca.vertcat(*w)
    mu = ca.SX.sym("mu", wv.size1())
    h, _ = ca.hessian(ca.dot(mu, wv), z)
    return ca.Function("nlp_rest_w", [z, mu], [wv, ca.densify(ca.jacobian(wv, z)), ca.densify(h)])


def _rest_end_mx(na: int, with_aj: bool, N: int, head: bool, nr: int, M: int, values_only: bool) -> Any:
    r"""``RestEnd``'s function by the chain rule through w (``_rest_w_function``) and the points' u = A w
    (``_rest_end_matrices``): each point's rows and derivatives in its own u (``_rest_point_sx``, mapped), the
    nodes' in their s = An w (``_rest_node_function``), then (MX)

        J_z = J_u A W,   grad_z = W^T (A^T g_u + An^T (k tau')),
        H_z = W^T (A^T blockdiag(H_u) A + An^T diag(k tau'') An) W + sum_k G_k d2 w_k / dz2,
        G = A^T gL_u + An^T (k tau') + lam_rest e

    (k = 2 / n, gL_u the gradient of term + lam^T rows in u): what CasADi's automatic derivatives of the same
    rows in z gave (``_rest_end``; session 45: 34,000 SX instructions for 2 axes, 258 us an evaluation)."""
    npk = 4 * na + 2
    z = ca.MX.sym("z", 3 + nr)
    PK = ca.MX.sym("pk", npk, N + 1)
    RP = ca.MX.sym("rp", 3 * na, M)
    GL = ca.MX.sym("gl", 2 + 8 * na)
    scale = ca.MX.sym("scale")
    settings = _rest_settings()
    A, An, e = _rest_end_matrices(N, head, nr, M)
    P = N + 1 + M
    wf = _rest_w_function(head, nr)
    w, W, _ = wf(z, ca.DM.zeros(A.shape[1]))
    Ad = ca.DM(A)
    U = ca.reshape(ca.mtimes(Ad, w), 3, P)
    if M:
        xsss = [3 * i + 2 for i in range(na)]
        PKr = ca.vertcat(RP[[3 * i for i in range(na)], :], RP[[3 * i + 1 for i in range(na)], :], RP[xsss, :],
                         RP[xsss, :], ca.MX.zeros(2, M))
        PKall = ca.horzcat(PK, PKr)
    else:
        PKall = PK
    per_axis, keep = _exact_layout(with_aj)
    R = per_axis * na + 1
    # local rows: checkpoint c's template row r at r (N + 1) + c; the row next to rest; the rest points' (block b
    # of point j at R (N + 1) + 1 + b M + j, block b = axis i's keep[q] at b = i len(keep) + q)
    ck_r, ck_p = np.repeat(np.arange(R), N + 1), np.tile(np.arange(N + 1), R)  # (template, point) of each
    ck_row = ck_r * (N + 1) + ck_p                                             # checkpoint row, in order
    nb = na * len(keep)
    pt_b, pt_j = np.repeat(np.arange(nb), M), np.tile(np.arange(M), nb)
    pt_p = N + 1 + pt_j
    pt_r = (pt_b // len(keep)) * per_axis + np.asarray(keep)[pt_b % len(keep)]
    n_rows = R * (N + 1) + 1 + nb * M
    pt_row = R * (N + 1) + 1 + pt_b * M + pt_j
    rest_row = R * (N + 1)
    node = _rest_node_function().map(An.shape[0])
    s = ca.mtimes(ca.DM(An), w)
    nd = node(s.T, ca.DM(REST_GL[0]).T)  # (3, nodes)
    name = f"nlp_rest_mx{'' if values_only else '_d'}_{na}{'aj' if with_aj else ''}_{N}_{'head' if head else 'tail'}"

    def values(out: Any, nout: int, o_term: int) -> Any:
        """(rows, term) from the points' outputs (nout a point, the term at o_term)."""
        vals = ca.vertcat(out[(ck_p * nout + ck_r).tolist()], ca.dot(ca.DM(e), w), out[(pt_p * nout + pt_r).tolist()])
        term = ca.sum1(out[(np.arange(N + 1) * nout + o_term).tolist()]) + scale * ca.sum2(nd[0, :])
        return ca.vertcat(vals, term)

    if values_only:
        pf = _rest_point_functions(na, with_aj, True, settings)
        return ca.Function(name, [z, PK, RP, GL, scale], [values(ca.vec(pf.map(P)(U, PKall, GL)), R + 1, R)])
    lam = ca.MX.sym("lam", n_rows)
    # each point's multipliers per template row (0: a row the end does not have: a rest point's e_lo, j_lo, feed)
    lidx = np.full((P, R), n_rows, dtype=np.int64)
    lidx[ck_p, ck_r] = ck_row
    lidx[pt_p, pt_r] = pt_row
    LP = ca.reshape(ca.vertcat(lam, ca.MX(1, 1))[lidx.ravel().tolist()], R, P)
    pf = _rest_point_functions(na, with_aj, False, settings)
    out = ca.vec(pf.map(P)(U, PKall, GL, LP))
    nout = 4 * R + 16
    o_j, o_t, o_gt, o_gl, o_h = R, 4 * R, 4 * R + 1, 4 * R + 4, 4 * R + 7
    # J_z = S B: S (rows x 3 P) holds each row's J_u at its point's u; B = A W; the row next to rest e^T W
    B = ca.mtimes(Ad, W)
    rp_, rr_ = np.concatenate([ck_p, pt_p]), np.concatenate([ck_r, pt_r])
    rows_l = np.concatenate([ck_row, pt_row])
    S = _gathered(n_rows, 3 * P, np.repeat(rows_l, 3), (3 * rp_[:, None] + np.arange(3)[None, :]).ravel(),
                  (rp_[:, None] * nout + o_j + np.arange(3)[None, :] * R + rr_[:, None]).ravel(), out)
    E = np.zeros((n_rows, e.size))
    E[rest_row] = e
    jac = ca.mtimes(S, B) + ca.mtimes(ca.DM(E), W)
    pidx = (np.arange(P)[:, None] * nout + np.arange(3)[None, :]).ravel()
    k_d1 = scale * nd[1, :].T
    Ant = ca.DM(An.T)
    grad = ca.mtimes(W.T, ca.mtimes(Ad.T, out[(pidx + o_gt).tolist()]) + ca.mtimes(Ant, k_d1))
    G = ca.mtimes(Ad.T, out[(pidx + o_gl).tolist()]) + ca.mtimes(Ant, k_d1) + lam[rest_row] * ca.DM(e)
    a3, b3 = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    BD = _gathered(3 * P, 3 * P, (3 * np.arange(P)[:, None] + a3.ravel()[None, :]).ravel(),
                   (3 * np.arange(P)[:, None] + b3.ravel()[None, :]).ravel(),
                   (np.arange(P)[:, None] * nout + o_h + (a3 + 3 * b3).ravel()[None, :]).ravel(), out)
    Bn = ca.mtimes(ca.DM(An), W)
    _, _, Cw = wf(z, G)
    hess = (ca.mtimes(B.T, ca.mtimes(BD, B)) + ca.mtimes(Bn.T, Bn * ca.repmat(scale * nd[2, :].T, 1, 3 + nr)) + Cw)
    return ca.Function(name, [z, PK, RP, GL, scale, lam], [values(out, nout, o_t), jac, grad, hess])


def _rest_end_function(na: int, with_aj: bool, N: int, head: bool, nr: int, M: int) -> RestEnd:
    """``_rest_end_functions`` (cached by its arguments given in full and by the module's rest settings)."""
    return _rest_end_functions(int(na), bool(with_aj), int(N), bool(head), int(nr), int(M), _rest_settings())


@functools.cache
def _rest_end_functions(na: int, with_aj: bool, N: int, head: bool, nr: int, M: int,
                        settings: tuple[Any, ...]) -> RestEnd:
    """``RestEnd`` of ``_rest_end_mx`` (its rows' linearity from ``_rest_end``'s SX)."""
    del settings  # (the key of the cache only)
    ins, rows, _ = _rest_end_exprs(na, with_aj, N, head, nr, M)
    linear = ~np.asarray(ca.which_depends(rows, ins[0], 2, True), dtype=bool)
    d = _rest_end_mx(na, with_aj, N, head, nr, M, values_only=False)
    jr, jc = (np.asarray(a, dtype=np.int64) for a in d.sparsity_out(1).get_triplet())
    hr, hc = (np.asarray(a, dtype=np.int64) for a in d.sparsity_out(3).get_triplet())
    return RestEnd(values=_rest_end_mx(na, with_aj, N, head, nr, M, values_only=True), derivatives=d,
                   rows=int(rows.size1()), linear=linear, jac=(jr, jc), hess=(hr, hc))


def warm_interval_functions(N: int = 4, axes: Sequence[int] = (1, 2, 3)) -> None:
    """Build (and compile: ``solvers.ccompile``) the interval functions of windows moving ``axes`` axes at N
    checkpoints an interval and the cut slots' (``slot_sx``), and build the rest ends' (``RestEnd``: ~0.1 s
    each, two per axis count), without the kinematic rows (the defaults), so that processes forked afterwards
    start with them: the service's forkserver, whose every job would otherwise generate their C again (~50 ms
    for 2 axes) and build its rest ends' functions (session 45, fresh processes with them warm: flower lp+nlp
    0.47 -> 0.36 s, square corner 0.35 -> 0.19 s, with the rest ends' functions and their chain rule)."""
    nr = len(bspline.REST_RISE_POWERS) if REST_BUMP and REST_RISE else 0
    M = rest_point_taus(N).size if REST_ENDS else 0
    for na in axes:
        for values_only in (False, True):
            _interval_function(na, False, N, values_only)
            _slot_function(na, False, values_only)
        for head in (True, False):
            _rest_end_function(na, False, N, head, nr, M)


def _splice(col: Any, rep: dict[int, Any]) -> Any:
    """The SX column ``col`` with the entries from each of rep's keys on replaced by rep's value there (a
    column: as many entries as it has), the runs between them as slices."""
    parts: list[Any] = []
    i0 = 0
    for i in sorted(rep):
        if i > i0:
            parts.append(col[i0:i])
        parts.append(rep[i])
        i0 = i + int(ca.SX(rep[i]).size1())
    if i0 < col.size1():
        parts.append(col[i0:])
    return ca.vertcat(*parts)


def _gathered(nr: int, nc: int, rows: NDArray[np.int64], cols: NDArray[np.int64], src: NDArray[np.int64],
              values: Any) -> Any:
    """An nr x nc sparse MX whose entry (rows[i], cols[i]) is values[src[i]] (no position twice)."""
    spy, mapping = ca.Sparsity.triplet(nr, nc, rows.tolist(), cols.tolist(), True)
    mp = np.asarray(mapping, dtype=np.int64)
    if spy.nnz() != mp.size:
        raise ValueError("a position given twice")
    order = np.empty_like(mp)
    order[mp] = np.arange(mp.size)
    return ca.MX(spy, values[src[order].tolist()])


class _Shape:
    """The NLP of one window shape: n knot intervals, N + 1 checkpoints each, given moving axes.

    Parameter vector (per call):
        [Fs, 1/d, x_s (na K), x_ss (na K), x_sss_hi (na K), x_sss_lo (na K), w_time (K), w_feed (K),
         per moving axis: M/umax, b/umax, Kv/emax, Ka/emax, Kj/emax, 1/vmax, 1/amax, 1/jmax]
    x_sss_hi/lo: the largest/smallest x_sss around each checkpoint.  e and j
    are increasing in x_sss (its factor Kj f^3 >= 0), so the upper row with
    x_sss_hi and the lower row with x_sss_lo bound them wherever the geometry's
    third derivative jumps near a checkpoint (NURBS knots).
    Rows, per moving axis: u, e_hi (upper bound only), e_lo (lower only), [a, j_hi, j_lo]; then f,
    whose upper bound min(Fmax, min_x vmax_x / |x_s|) carries the feed and axis velocity limits.
    With ``slotted``: n cut slots (``_Slots``), parameters tau (n), then x_s, x_ss, x_sss (n each)
    per moving axis; rows as above (x_sss exact, so e_hi = e_lo) and f, per slot.
    With ``head`` / ``tail`` (a rest interval: ``_rest_rows``): the rise variables after p_n+1, the rest
    points' parameters last (x_s, x_ss, x_sss over all of them, per moving axis in turn) and their rows
    after every other (one per rest end for its step, then u, e, [a, j] per axis at the rest points).
    A shape is built with the dense method's problem (``_mapped_problem``: functions built once per kind of
    window, mapped and gathered); the whole window as one SX problem (``_lifted``) is built only when Ipopt's
    problem or a test asks for it (since session 45: ~2/3 of a rest window's build was its SX).
    """

    def __init__(self, n: int, N: int, axes: tuple[int, ...], with_aj: bool, slotted: bool = False,
                 head: bool = False, tail: bool = False) -> None:
        self.n, self.N, self.axes, self.with_aj, self.slotted = n, N, axes, with_aj, slotted
        self.head, self.tail = head, tail
        k, tau = checkpoint_layout(n, N)
        K = k.size
        self.K = K
        ncols = n + 2
        self.B0, B1, B2 = _interval_basis(k, tau, ncols)
        na = len(axes)
        #: variables past p_n+1: the rise factors of each rest end (``REST_RISE``, one per
        #: ``bspline.REST_RISE_POWERS``: first the head's, then the tail's)
        self.n_rise = (int(head) + int(tail)) * len(bspline.REST_RISE_POWERS) if REST_BUMP and REST_RISE else 0
        #: the rest points (``rest_point_taus``) of each rest end: first the head's, then the tail's
        self.n_rest_points = (int(head) + int(tail)) * rest_point_taus(N).size if REST_ENDS else 0
        #: parameters before the rest points' (``_lifted``'s order)
        self._n_base = 2 + 4 * na * K + 2 * K + 8 * na + (n * (1 + 3 * na) if slotted else 0)
        # the rows read x through (B0 x, B1 x, B2 x) at the checkpoints: lifted variables y = L x of their own
        # (``_lifted``, ``_mapped_problem``)
        self._L = sp.hstack([sp.vstack([self.B0, B1, B2]), sp.csr_matrix((3 * K, self.n_rise))], format="csr")
        kept, _, _ = knot_twins(n, N)
        # row_index[block, checkpoint]: the row of that block at that checkpoint (-1: none)
        reduced = ([True, False, False] + ([True, False, False] if with_aj else [])) * na + [True]
        self.row_index = np.full((len(reduced), K), -1, dtype=np.int64)
        nxt = 0
        for blk, red in enumerate(reduced):
            cols = kept if red else np.arange(K)
            self.row_index[blk, cols] = nxt + np.arange(cols.size)
            nxt += cols.size
        self.base_rows = nxt
        #: rows after the slots (``_rest_rows``): one per rest end, then the rest points' (per moving axis u,
        #: e, [a, j], each over the rest points: ``_exact_rows``, ``_exact_bounds``)
        self.n_rest = (int(head) + int(tail)) + (4 if with_aj else 2) * na * self.n_rest_points
        self.rows = nxt + (n * len(reduced) if slotted else 0) + self.n_rest
        self._lifted_sx: dict[str, Any] | None = None
        #: the first solver of every solve (``DENSE_IPM``); Ipopt's are built on first use
        self.ipm: DenseIpm | None = None
        if DENSE_IPM:
            self.ipm = DenseIpm(self._mapped_problem(na))
        self._problem_x: dict[str, Any] | None = None
        self._solver: Any = None
        self._safe_solver: Any = None
        # hand-over least squares: min |B0 p - y|^2 s.t. B0 p >= 0, fixed ends (OSQP, built once)
        Pm = sp.triu(self.B0.T @ self.B0, format="csc")
        A = sp.vstack([sp.eye(ncols), self.B0], format="csc")
        self.fit = osqp.OSQP()
        self.fit.setup(
            Pm, np.zeros(ncols), A, np.full(ncols + K, -np.inf), np.full(ncols + K, np.inf),
            verbose=False, eps_abs=1e-6, eps_rel=1e-6, polishing=True, rho=HANDOVER_RHO,
            # no warm start from the previous fit: shapes are reused across schedules (_cached_shape)
            # and a result must not depend on what this thread solved before (nor may rho: ``handover``)
            warm_starting=False,
        )

    @property
    def _lifted(self) -> dict[str, Any]:
        """The window's NLP as one SX problem in x and the lifted y = L x (x, y, L, p, f, g): Ipopt's
        (``_problem``) and the tests' oracle of ``_mapped_problem``; built on first use (``_build_lifted``)."""
        if self._lifted_sx is None:
            self._lifted_sx = self._build_lifted()
        return self._lifted_sx

    def _build_lifted(self) -> dict[str, Any]:
        """``_lifted``: the parameters in their order (``take``), the rows in theirs (``row_index``, the slots',
        the rest ends')."""
        n, N, K, axes, with_aj, slotted = self.n, self.N, self.K, self.axes, self.with_aj, self.slotted
        na = len(axes)
        ncols = n + 2
        xx = ca.SX.sym("p", ncols + self.n_rise)
        x = xx[:ncols]
        n_base = self._n_base
        P = ca.SX.sym("P", n_base + 3 * na * self.n_rest_points)
        Fs, inv_d = P[0], P[1]
        off = 2

        def take(m: int) -> Any:
            nonlocal off
            out = P[off : off + m]
            off += m
            return out

        xs = [take(K) for _ in axes]
        xss = [take(K) for _ in axes]
        xsss_hi = [take(K) for _ in axes]
        xsss_lo = [take(K) for _ in axes]
        wt = take(K)
        wf = take(K)
        coef = [take(8) for _ in axes]
        # the dense method takes derivatives per checkpoint (``DenseIpm``'s lifted variables, y = L x); Ipopt's
        # problem has L x substituted (``_problem``)
        y = ca.SX.sym("y", 3 * K)
        fh = y[:K]
        f = Fs * fh
        f1 = Fs * inv_d * y[K : 2 * K]
        f2 = Fs * inv_d * inv_d * y[2 * K :]
        kept, _, _ = knot_twins(n, N)
        sel = [int(i) for i in kept]
        rest_time: Any = 0.0
        rest_rows: list[Any] = []
        if self.head or self.tail:
            # the rest intervals in q (``rest_cps``): their checkpoints' rows, feed and travel time from the
            # q the state at the inner knot gives; interval 0's f (p_0) and interval n-1's (p_n+1) are unused;
            # the rest points' x_s, x_ss, x_sss per moving axis are the last parameters
            m = self.n_rest_points
            rp = [[P[n_base + (3 * i + j) * m : n_base + (3 * i + j + 1) * m] for i in range(na)] for j in range(3)]
            fh, rows, rest_time, rest_rows = self._rest_rows(x, xx[ncols:], Fs, inv_d, fh, f, f1, f2, xs, xss,
                                                             xsss_hi, xsss_lo, coef, with_aj, sel, rp)
        else:
            rows = self._axis_rows(f, f1, f2, xs, xss, xsss_hi, xsss_lo, coef, with_aj, sel)
        rows.append(fh[sel])
        if slotted:
            # cut slots, one per knot interval at a tau given per call, with the path's exact derivatives
            # there (no envelope); unused slots have unbounded rows
            ts = take(n)
            sxs = [take(n) for _ in axes]
            sxss = [take(n) for _ in axes]
            sxsss = [take(n) for _ in axes]
            c0, c1, c2 = x[0:n], x[1 : n + 1], x[2 : n + 2]
            sfh = 0.5 * (c0 + c1) + ts * ((c1 - c0) + 0.5 * (c0 - 2 * c1 + c2) * ts)
            sf = Fs * sfh
            sf1 = Fs * inv_d * ((c1 - c0) + (c0 - 2 * c1 + c2) * ts)
            sf2 = Fs * inv_d * inv_d * (c0 - 2 * c1 + c2)
            rows += self._axis_rows(sf, sf1, sf2, sxs, sxss, sxsss, sxsss, coef, with_aj)
            rows.append(sfh)
        # the rest intervals' control points next to rest (their acceleration at rest) and their rest points'
        # rows, after every other row
        rows += rest_rows
        g = ca.vertcat(*rows)
        if int(g.size1()) != self.rows or off != n_base:
            raise ValueError(f"the window's problem has {int(g.size1())} rows and {off} parameters before the rest "
                             f"points', its layout {self.rows} and {n_base}")
        obj = ca.sum1(wt / (fh + DELTA_F)) - ca.sum1(wf * fh) + rest_time
        return {"x": xx, "y": y, "L": self._L, "p": P, "f": obj, "g": g}

    def _mapped_problem(self, na: int) -> dict[str, Any]:
        r"""The window's NLP for ``DenseIpm`` with its derivatives given (MX): the rows of the checkpoints by one
        function of a knot interval's checkpoints, mapped over the window's n intervals, the cut slots' and the
        rest ends' alike; no automatic differentiation over the window.

        At checkpoint k the rows (``_axis_rows``: per moving axis u, e_hi, e_lo, [a, j_hi, j_lo]; then the
        scaled feed) and the travel-time term w_time / (f^ + DELTA_F) - w_feed f^ read the lifted variables
        y_k = (f^, f^', f^''), the checkpoint's parameters (x_s, x_ss, x_sss_hi, x_sss_lo per moving axis,
        w_time, w_feed) and the window's (Fs, 1/d, the axes' coefficients).  ``_checkpoint_function`` gives at
        one checkpoint the R rows, their Jacobian in y_k (R x 3), the term, its gradient and the Hessian in
        y_k of term + lam_k^T rows (lam_k: the rows' multipliers, 0 for a row the window leaves out: the knot
        twins' u, a and feed rows); ``_interval_function`` over an interval's N + 1 checkpoints, mapped over
        the n intervals, is built once per (axes, rows, N) for every window length.  Automatic
        differentiation over the whole window (SX) took ~2/3 of a shape's 0.2-0.45 s build.

        The cut slots' rows are mapped alike (``slot_sx``: a slot reads its interval's 3 control points, and
        neighbouring slots' Hessian blocks overlap, so they are gathered every third slot at a time; session
        44: slotted shapes 0.072 -> 0.034 s at 69 intervals).  A rest end's rows (its interval's checkpoints',
        the row next to rest, its rest points') and its interval's term are one function of the end's z =
        (p_rest, p_in, p_out, its rises) (``RestEnd``, built once per (axes, rows, N, end); session 45, 2
        axes: a window from rest to rest with slots 0.118 -> 0.022 s at 64 intervals, from rest 0.083 -> 0.024 s
        at 70).  All are gathered into g (m0), grad f, J_v (m0 x n_v) and H_v (n_v x n_v) in v = (y, x);
        ``DenseIpm`` carries them to x with L."""
        K, n, N = self.K, self.n, self.N
        nx = n + 2 + self.n_rise
        ny = 3 * K
        nv = ny + nx
        m0 = self.rows
        tmpl = _interval_function(na, self.with_aj, N)
        R = int(tmpl.size1_in(3))
        nout = int(tmpl.size1_out(0))
        npk = 4 * na + 2
        if self.row_index.shape[0] != R:
            raise ValueError(f"checkpoint rows {self.row_index.shape[0]} != the map's {R}")
        # the rest ends (head: interval 0, tail: n - 1): their checkpoints' rows and feed are the rest ends'
        ends = [(hd, k) for hd, k, on in ((True, 0, self.head), (False, n - 1, self.tail)) if on]
        own = np.zeros(K, dtype=bool)
        for _, k in ends:
            own[k * (N + 1) : (k + 1) * (N + 1)] = True
        # g row -> (template row, checkpoint) where the map gives it
        blk, cp = np.nonzero(self.row_index >= 0)
        at = self.row_index[blk, cp]
        keep = ~own[cp]
        row_t = np.full(m0, -1, dtype=np.int64)
        row_k = np.full(m0, -1, dtype=np.int64)
        row_t[at[keep]], row_k[at[keep]] = blk[keep], cp[keep]
        mr = np.flatnonzero(row_t >= 0)
        # the cut slots' rows (``slot_sx``, mapped over the n slots): g row base_rows + r n + i is template row r
        # of slot i
        s_idx = (self.base_rows + np.arange(R)[:, None] * n + np.arange(n)[None, :] if self.slotted
                 else np.zeros((R, 0), dtype=np.int64))
        y = ca.MX.sym("y", ny)
        x = ca.MX.sym("x", nx)
        P = ca.MX.sym("P", self._n_base + 3 * na * self.n_rest_points)
        lam = ca.MX.sym("lam", m0)
        Y = ca.reshape(y, K, 3).T
        PK = ca.reshape(P[2 : 2 + npk * K], K, npk).T
        GL = ca.vertcat(P[0:2], P[2 + npk * K : 2 + npk * K + 8 * na])
        # the multipliers per (template row, checkpoint), 0 where the map's row is not in g
        lidx = np.full((K, R), m0, dtype=np.int64)
        lidx[row_k[mr], row_t[mr]] = mr
        lam0 = ca.vertcat(lam, ca.MX(1, 1))
        LK = ca.reshape(lam0[lidx.ravel().tolist()], R, K)
        # entry o of checkpoint k at k nout + o (the map over intervals keeps the checkpoints' columns)
        out = ca.vec(tmpl.map(n)(Y, PK, GL, LK))
        out_fg = ca.vec(_interval_function(na, self.with_aj, N, values_only=True).map(n)(Y, PK, GL))
        # slot i reads c_i .. c_i+2 and its parameters (tau, x_s, x_ss, x_sss per axis: one block of n each)
        s_r, s_i = (a.ravel() for a in np.meshgrid(np.arange(R), np.arange(s_idx.shape[1]), indexing="ij"))
        s_rows = s_idx.ravel()
        nout_s = 4 * R + 9
        s_out: Any = ca.MX(0, 1)
        s_fg: Any = ca.MX(0, 1)
        if self.slotted:
            X3 = ca.reshape(x[(np.arange(n)[None, :] + np.arange(3)[:, None]).ravel(order="F").tolist()], 3, n)
            ps0 = 2 + npk * K + 8 * na
            PS = ca.reshape(P[ps0 : ps0 + n * (1 + 3 * na)], n, 1 + 3 * na).T
            LS = ca.reshape(lam[s_idx.ravel(order="F").tolist()], R, n)
            s_out = ca.vec(_slot_function(na, self.with_aj).map(n)(X3, PS, GL, LS))
            s_fg = ca.vec(_slot_function(na, self.with_aj, values_only=True).map(n)(X3, PS, GL))
        kk = np.flatnonzero(~own)
        # each rest end: its z in x, its rows in g (-1: a row the window leaves out, a knot twin's), its
        # function's outputs (values; values, J, grad, H)
        M = self.n_rest_points // len(ends) if ends else 0
        nr = len(bspline.REST_RISE_POWERS) if self.n_rise else 0
        nb = (4 if self.with_aj else 2) * na
        rest0 = m0 - self.n_rest
        e_spec: list[tuple[RestEnd, NDArray[np.int64], NDArray[np.int64]]] = []
        e_fg: list[Any] = []
        e_d: list[list[Any]] = []
        for e, (hd, k) in enumerate(ends):
            fun = _rest_end_function(na, self.with_aj, N, hd, nr, M)
            zx = np.array(([0, 1, 2] if hd else [n + 1, n - 1, n]) + [n + 2 + e * nr + i for i in range(nr)],
                          dtype=np.int64)
            i0 = k * (N + 1)
            pts = rest0 + len(ends) + np.arange(nb)[:, None] * (len(ends) * M) + e * M + np.arange(M)[None, :]
            g_rows = np.concatenate([self.row_index[:, i0 : i0 + N + 1].ravel(), [rest0 + e], pts.ravel()])
            if g_rows.size != fun.rows:
                raise ValueError(f"a rest end's rows {g_rows.size} != its function's {fun.rows}")
            p_rp = self._n_base + np.arange(3 * na)[:, None] * self.n_rest_points + e * M + np.arange(M)[None, :]
            args = [x[zx.tolist()], PK[:, i0 : i0 + N + 1], ca.reshape(P[p_rp.ravel(order="F").tolist()], 3 * na, M),
                    GL, ca.MX(2.0 / n)]
            e_spec.append((fun, zx, g_rows))
            e_fg.append(fun.values(*args))
            e_d.append(list(fun.derivatives(*args, lam0[np.where(g_rows >= 0, g_rows, m0).tolist()])))

        def values(outv: Any, per_k: int, o_term: int, sv: Any, per_s: int, ev: list[Any]) -> tuple[Any, Any]:
            """(f, g) from the map's values (per_k a checkpoint, the term at o_term), the slots' (per_s a slot)
            and the rest ends' (their rows, then their term)."""
            src = np.full(m0, -1, dtype=np.int64)
            src[mr] = row_k[mr] * per_k + row_t[mr]
            src[s_rows] = int(outv.size1()) + s_i * per_s + s_r
            terms = (kk * per_k + o_term).tolist()
            base = int(outv.size1()) + int(sv.size1())
            for (_, _, g_rows), ve in zip(e_spec, ev, strict=True):
                inside = np.flatnonzero(g_rows >= 0)
                src[g_rows[inside]] = base + inside
                terms.append(base + g_rows.size)
                base += int(ve.size1())
            if (src < 0).any():
                raise ValueError(f"{int((src < 0).sum())} of the window's rows have no value")
            vals = ca.vertcat(outv, sv, *ev)
            return ca.sum1(vals[terms]), vals[src.tolist()]

        f_fg, g_fg = values(out_fg, R + 1, R, s_fg, R, e_fg)
        f_d, g_d = values(out, nout, 4 * R, s_out, nout_s, [d[0] for d in e_d])
        o_grad, o_hess = 4 * R + 1, 4 * R + 4
        # grad f in v: the map's in y, plus the rest ends' in their z
        gy = np.full(ny, int(out.size1()), dtype=np.int64)
        for c in range(3):
            gy[c * K + kk] = kk * nout + o_grad + c
        grad = ca.vertcat(ca.vertcat(out, ca.MX(1, 1))[gy.tolist()], ca.MX.zeros(nx, 1))
        # J_v: a map's row reads y at its checkpoint (entry (r, c) of its R x 3 block at R + c R + r)
        ji = [mr, mr, mr]
        jc = [c * K + row_k[mr] for c in range(3)]
        js = [row_k[mr] * nout + R + c * R + row_t[mr] for c in range(3)]
        # a slot's row (r of slot i) reads c_i .. c_i+2 (entry (r, c) of its R x 3 block at R + c R + r)
        n_o, n_s = int(out.size1()), int(s_out.size1())
        ji += [s_rows] * 3
        jc += [ny + s_i + c for c in range(3)]
        js += [n_o + s_i * nout_s + R + c * R + s_r for c in range(3)]
        # a rest end's rows read its z (its Jacobian's entries in their order, where the row is in g)
        base = n_o + n_s
        for fun, zx, g_rows in e_spec:
            jr, jcz = fun.jac
            inside = np.flatnonzero(g_rows[jr] >= 0)
            ji.append(g_rows[jr[inside]])
            jc.append(ny + zx[jcz[inside]])
            js.append(base + inside)
            base += jr.size
        jac = _gathered(m0, nv, np.concatenate(ji), np.concatenate(jc), np.concatenate(js),
                        ca.vertcat(out, s_out, *[d[1].nz[:] for d in e_d]))
        # H_v: the map's 3 x 3 blocks in y (entry (a, b) at o_hess + a + 3 b)
        a3, b3 = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        hess = _gathered(nv, nv, (a3.ravel()[:, None] * K + kk[None, :]).ravel(),
                         (b3.ravel()[:, None] * K + kk[None, :]).ravel(),
                         (kk[None, :] * nout + o_hess + (a3 + 3 * b3).ravel()[:, None]).ravel(), out)
        if self.slotted:
            # the slots' 3 x 3 blocks at c_i .. c_i+2 (entry (a, b) at 4 R + a + 3 b): neighbouring slots share
            # control points, so every third slot's blocks at a time (no position twice in one gather)
            for m in range(3):
                si = np.arange(m, n, 3)
                hess = hess + _gathered(
                    nv, nv, (ny + si[None, :] + a3.ravel()[:, None]).ravel(),
                    (ny + si[None, :] + b3.ravel()[:, None]).ravel(),
                    (si[None, :] * nout_s + 4 * R + (a3 + 3 * b3).ravel()[:, None]).ravel(), s_out)
        # the rest ends' gradient and Hessian in their z, one end at a time (two ends of a short window may
        # share a control point)
        for (fun, zx, _), d in zip(e_spec, e_d, strict=True):
            grad = grad + _gathered(nv, 1, ny + zx, np.zeros(zx.size, dtype=np.int64), np.arange(zx.size), d[2])
            hr, hc = fun.hess
            hess = hess + _gathered(nv, nv, ny + zx[hr], ny + zx[hc], np.arange(hr.size), d[3].nz[:])
        lin = np.zeros(m0, dtype=bool)
        lin[mr] = row_t[mr] == R - 1   # the scaled feed rows
        lin[s_rows] = s_r == R - 1   # the slots' feed rows
        for fun, _, g_rows in e_spec:
            in_g = g_rows >= 0
            lin[g_rows[in_g]] = fun.linear[in_g]
        return {"x": x, "y": y, "L": self._L, "p": P, "f": f_fg, "g": g_fg,
                "derivatives": {"f": f_d, "g": g_d, "lam": lam, "grad": grad, "jac": jac, "hess": hess,
                                "linear": lin}}

    @property
    def _problem(self) -> dict[str, Any]:
        """The NLP in x alone (Ipopt's): y = L x substituted (on first use)."""
        if self._problem_x is None:
            lf = self._lifted
            xs = ca.mtimes(ca.DM(sp.csc_matrix(self._L)), lf["x"])
            f, g = ca.substitute([lf["f"], lf["g"]], [lf["y"]], [xs])
            self._problem_x = {"x": lf["x"], "p": lf["p"], "f": f, "g": g}
        return self._problem_x

    @property
    def solver(self) -> Any:
        """The NLP with IPOPT_WARM_OPTIONS (built on first use: with ``DENSE_IPM`` only after a solve the
        dense method did not finish)."""
        if self._solver is None:
            self._solver = ca.nlpsol("feed_nlp", "ipopt", self._problem, IPOPT_WARM_OPTIONS)
        return self._solver

    @property
    def safe_solver(self) -> Any:
        """The same NLP with IPOPT_SAFE_OPTIONS (built on first use: only after a failed solve)."""
        if self._safe_solver is None:
            self._safe_solver = ca.nlpsol("feed_nlp_safe", "ipopt", self._problem, IPOPT_SAFE_OPTIONS)
        return self._safe_solver

    def _rest_rows(self, x: Any, rise: Any, Fs: Any, inv_d: Any, fh: Any, f: Any, f1: Any, f2: Any,
                   xs: list[Any], xss: list[Any], xsss_hi: list[Any], xsss_lo: list[Any], coef: list[Any],
                   with_aj: bool, sel: list[int], rp: list[list[Any]]) -> tuple[Any, list[Any], Any, list[Any]]:
        r"""Rows, scaled feed and travel time of a window whose first (``head``) or last (``tail``) knot interval
        is a rest interval of the piece, its feed sqrt(q) from the quadratic q that starts (ends) at rest and
        meets the f spline's value and slope at the inner knot (``rest_cps``).

        With q's control points c_0, c_1, c_2 on the interval (c_0 = -c_1 at the start), in unit tau:
        q = (c_0 (1 - tau)^2 + c_1 (1 + 2 tau - 2 tau^2) + c_2 tau^2) / 2, and in time
        sdot = sqrt(q), sddot = q' / 2, sdddot = sqrt(q) q'' / 2 (finite at rest, where 1/f is not).
        Travel time: with tau = w^2, q = w^2 (2 c_1 + (c_2 - 3 c_1) w^2 / 2) and the integral of d / sqrt(q)
        over the interval is 2 d times that of 1 / sqrt(2 c_1 + (c_2 - 3 c_1) w^2 / 2) over w in [0, 1]
        (REST_GL Gauss-Legendre nodes; mirrored for the tail); in the objective's units (times / L, f scaled
        by Fs) that is 2 / n times the node sum.  With REST_BUMP, q has g b added (``bspline.rest_bump``,
        g = ``_rest_g`` of p_0 or p_n+1): under the root g (1 - w^2)^m, and in the rows g b, g b', g b''; with
        REST_RISE also sum_k h_k e_k (h_k = ``_rest_g`` of the end's variables in ``rise``: the head's first),
        alike.
        Extra rows (one per rest end): c_1 + g / 2 (the control point next to rest, plus half the bump's
        amplitude: q' = (2 c_1 + g) / d there), whose bounds hold the acceleration at rest; then the rows at
        the rest points (``rest_point_taus``: between the checkpoints, with the path's exact derivatives
        there, ``rp`` = [x_s, x_ss, x_sss][axis] over the rest points), per moving axis u, e, [a, j] each
        over all of them (``_exact_rows``).

        Returns (scaled feed at every checkpoint, the base rows with the rest intervals' checkpoints
        replaced, the travel time term, the extra rows)."""
        n, N = self.n, self.N
        full = self._axis_rows(f, f1, f2, xs, xss, xsss_hi, xsss_lo, coef, with_aj)
        # the rest intervals' checkpoints replaced (index -> expression), the others kept as slices: no SX
        # element by element over the window (~2,800 element reads at 70 intervals)
        fh_rep: dict[int, Any] = {}
        full_rep: list[dict[int, Any]] = [{} for _ in full]
        rest_time: Any = 0.0
        extra: list[Any] = []
        M = rest_point_taus(N).size if self.n_rest_points else 0
        nr = len(bspline.REST_RISE_POWERS) if self.n_rise else 0
        point_rows: list[list[Any]] = []  # [row block][rest end]
        n_end = 0
        for is_rest, k, inner in ((self.head, 0, 1), (self.tail, n - 1, n - 1)):
            if not is_rest:
                continue
            # the interval's checkpoints k (N + 1) .. k (N + 1) + N, and the end's rest points
            i0, i1 = k * (N + 1), (k + 1) * (N + 1)
            p0, p1 = n_end * M, (n_end + 1) * M
            ck = [[v[i0:i1] for v in blk] for blk in (xs, xss, xsss_hi, xsss_lo)]
            pts = [[v[p0:p1] for v in rp_j] for rp_j in rp] if M else None
            row, vals, r, travel, point_vals = _rest_end(
                x[0] if k == 0 else x[n + 1], x[inner], x[inner + 1], [rise[n_end * nr + i] for i in range(nr)],
                Fs, inv_d, ck, coef, with_aj, k == 0, N, pts, 2.0 / n)
            n_end += 1
            extra.append(row)
            rest_time = rest_time + travel
            for rep, val in zip(full_rep, vals, strict=True):
                rep[i0] = val
            fh_rep[i0] = r
            if not point_rows:
                point_rows = [[] for _ in point_vals]
            for blk, val in zip(point_rows, point_vals, strict=True):
                blk.append(val)
        reduced = ([True, False, False] + ([True, False, False] if with_aj else [])) * len(xs)
        spliced = [_splice(col, rep) for col, rep in zip(full, full_rep, strict=True)]
        rows = [blk[sel] if red else blk for blk, red in zip(spliced, reduced, strict=True)]
        extra += [ca.vertcat(*blk) for blk in point_rows]
        return _splice(fh, fh_rep), rows, rest_time, extra

    @staticmethod
    def _axis_rows_t(sd: Any, sdd: Any, sddd: Any, xs: list[Any], xss: list[Any], xsss_hi: list[Any],
                     xsss_lo: list[Any], coef: list[Any], with_aj: bool) -> list[Any]:
        """``_axis_rows`` at one point from the feed's time derivatives (sdot, sddot, sdddot)."""
        rows = []
        for i in range(len(xs)):
            v = xs[i] * sd
            a = xss[i] * sd * sd + xs[i] * sdd
            j_rest = 3.0 * xss[i] * sd * sdd + xs[i] * sddd
            j_hi = xsss_hi[i] * sd * sd * sd + j_rest
            j_lo = xsss_lo[i] * sd * sd * sd + j_rest
            cf = coef[i]
            rows.append(cf[0] * a + cf[1] * v)
            e_va = cf[2] * v + cf[3] * a
            rows.append(e_va + cf[4] * j_hi)
            rows.append(e_va + cf[4] * j_lo)
            if with_aj:
                rows.append(cf[6] * a)
                rows.append(cf[7] * j_hi)
                rows.append(cf[7] * j_lo)
        return rows

    @staticmethod
    def _axis_rows(f: Any, f1: Any, f2: Any, xs: list[Any], xss: list[Any], xsss_hi: list[Any], xsss_lo: list[Any],
                   coef: list[Any], with_aj: bool, sel: list[int] | None = None) -> list[Any]:
        """Per moving axis: u, e_hi, e_lo, [a, j_hi, j_lo] at points with feed f, f', f''; the u and a rows
        (f and f' only) at the points ``sel`` if given."""
        f_sq = f * f
        f_cu = f_sq * f
        rows = []
        for i in range(len(xs)):
            v = xs[i] * f
            a = xss[i] * f_sq + xs[i] * f * f1
            j_rest = 3.0 * xss[i] * f_sq * f1 + xs[i] * (f * f1 * f1 + f_sq * f2)
            j_hi = xsss_hi[i] * f_cu + j_rest
            j_lo = xsss_lo[i] * f_cu + j_rest
            cf = coef[i]
            u = cf[0] * a + cf[1] * v
            rows.append(u if sel is None else u[sel])
            e_va = cf[2] * v + cf[3] * a
            rows.append(e_va + cf[4] * j_hi)
            rows.append(e_va + cf[4] * j_lo)
            if with_aj:
                rows.append(cf[6] * a if sel is None else (cf[6] * a)[sel])
                rows.append(cf[7] * j_hi)
                rows.append(cf[7] * j_lo)
        return rows

    def handover(self, y: FloatArray, fixed: dict[int, float]) -> FloatArray:
        """Control points (scaled) fitting y (K,) at the checkpoints with f >= 0 and fixed points held."""
        ncols = self.n + 2
        lo = np.full(ncols + self.K, -np.inf)
        hi = np.full(ncols + self.K, np.inf)
        lo[ncols:] = 0.0
        for i, val in fixed.items():
            lo[i] = hi[i] = val
        self.fit.update(q=-(self.B0.T @ y), l=lo, u=hi)
        res = self.fit.solve(raise_error=False)
        if res.info.rho_updates:
            # OSQP keeps the step it adapted to for the next solve: restored, so that the next fit does not depend
            # on this one (cam seed 97 lp+nlp: the NLP's feed differed by 1e-10 on 1 and 2 workers, whose shapes
            # had fitted other chains before)
            self.fit.update_settings(rho=HANDOVER_RHO)
        x = np.asarray(res.x, dtype=np.float64)
        if x.size != ncols or not np.all(np.isfinite(x)):
            x = np.interp(np.arange(ncols) - 0.5, np.linspace(0, self.n, self.K), y)
        for i, val in fixed.items():
            x[i] = val
        return x


@dataclass
class NlpStats:
    """Counters accumulated over all NLP windows of a schedule."""

    windows: int = 0
    iterations: int = 0
    cut_rounds: int = 0
    failures: list[dict[str, Any]] = field(default_factory=list)
    window_times: list[float] = field(default_factory=list)
    handover_scaled: int = 0
    #: hand-overs still over a limit after HANDOVER_MAX_STEPS scale-downs (started from unscaled)
    handover_unscaled: int = 0
    softer_retries: int = 0
    #: re-solves (tightening rounds) warm-started from the previous round's primal-dual point
    warm_resolves: int = 0
    #: iterations of the re-solves (tightening rounds, softer retries), warm-started or not
    resolve_iterations: int = 0
    #: first solves of a window started from the previous window's dual point
    warm_first: int = 0
    #: failed solves retried with Ipopt's cold start and IPOPT_SAFE_OPTIONS
    safe_retries: int = 0
    #: chains not solved: the LP's feed sits at the feed bound, well inside the other limits (LP_KEPT_*)
    lp_kept_chains: int = 0
    #: stretches inside solved chains that kept the LP's feed by the same rules (LP_KEPT_MIN_RUN_PER_OVERLAP),
    #: and their knot intervals
    lp_kept_spans: int = 0
    lp_kept_intervals: int = 0
    #: worst fine-grid utilisation of any accepted window (<= 1 + ACCEPT_TOL)
    worst_verified: float = 0.0
    #: refined spans slower than the LP's feed that kept the NLP's feed: the LP's is over an NLP limit there
    #: (``NlpRefiner.lp_worst``; ``solvers.pipeline._refine_piece``)
    slower_kept: int = 0
    #: windows that solved a rest interval (``REST_ENDS``) and failed, solved again from (to) the LP's state
    rest_retries: int = 0
    #: rest ends solved without their rises because the LP's feed reaches its bound there (REST_RISE_CAP_SHARE)
    rest_rises_capped: int = 0
    #: iterations of ``solvers.ipm.DenseIpm`` (also in ``iterations``), and its solves handed to Ipopt
    ipm_iterations: int = 0
    ipm_handed: int = 0
    #: ... and its solves found locally infeasible (``DENSE_INFEASIBLE``: not handed to Ipopt)
    ipm_infeasible: int = 0


#: NLP shapes kept per thread across schedules (each ~0.15-0.3 s of CasADi set-up, Ipopt's more; a shape
#: depends only on its key, every limit and geometry value is a parameter of the call)
SHAPE_CACHE_SIZE = 16
#: ... and at most this much memory of them (MB, as ``shape_mb`` estimates it), the newest shape always kept.  A
#: shape's size grows with its window, and refined pieces use windows of up to 512 intervals (session 51, cam-bench
#: seed 100 lp+nlp streamed, 10.4 M samples: 16 shapes alone, up to 580 MB of them, peaked at +512 MB of resident
#: memory over the 107 MB before; with this bound +365 MB, 185 shapes built instead of 155, CPU 74.0 -> 75.5 s,
#: the samples bit-identical).  Where the windows are short (the flower's 12-24 intervals) 16 shapes take ~30 MB.
SHAPE_CACHE_MB = 256.0
#: A shape's memory per knot interval and moving axis at N = 4 (MB: the resident growth while one is built, 51.8 MB
#: at 512 intervals and 3 axes, 61.9 MB with cut slots; session 51), and the factor with cut slots.  A rest window's
#: shape has ~3-4 MB more whatever its size, not counted: the estimate is there to bound the large ones.
SHAPE_MB_PER_AXIS_INTERVAL = 0.035
SHAPE_SLOTTED_FACTOR = 1.2
_SHAPE_CACHE = threading.local()
#: Shapes this process has built (``_cached_shape``): a ``ChainPool`` forked before the last build forks again.
_SHAPE_BUILDS = 0


def shape_mb(key: tuple[Any, ...]) -> float:
    """The memory (MB) a cached shape of this key holds, estimated from its intervals n, checkpoints per interval N,
    moving axes and cut slots: SHAPE_MB_PER_AXIS_INTERVAL n |axes| N / 4 (x SHAPE_SLOTTED_FACTOR with slots)."""
    n, N, axes, _, slotted = key[:5]
    return float(SHAPE_MB_PER_AXIS_INTERVAL * n * len(axes) * N / 4.0 * (SHAPE_SLOTTED_FACTOR if slotted else 1.0))


def _cached_shape(n: int, N: int, axes: tuple[int, ...], with_aj: bool, slotted: bool, head: bool = False,
                  tail: bool = False) -> _Shape:
    """The shape for this key from this thread's LRU cache, built on a miss (at most SHAPE_CACHE_SIZE shapes and
    SHAPE_CACHE_MB of them).  Per thread: a CasADi Function's call and the OSQP hand-over fit hold state, so two
    threads never share one."""
    cache: OrderedDict[tuple[Any, ...], _Shape] | None = getattr(_SHAPE_CACHE, "shapes", None)
    if cache is None:
        cache = _SHAPE_CACHE.shapes = OrderedDict()
    # (with the module's rest settings a rest window's shape is built with: tests switch them)
    rest = (REST_ENDS, *_rest_settings()) if head or tail else None
    key = (n, N, axes, with_aj, slotted, head, tail, rest)
    shape = cache.get(key)
    if shape is None:
        global _SHAPE_BUILDS
        shape = cache[key] = _Shape(n, N, axes, with_aj, slotted, head, tail)
        _SHAPE_BUILDS += 1
        while len(cache) > SHAPE_CACHE_SIZE or (len(cache) > 1 and sum(map(shape_mb, cache)) > SHAPE_CACHE_MB):
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return shape


class NlpRefiner:
    """Builds NLP shapes on demand (cached) and refines LP feed profiles piece by piece.

    The shapes themselves live only in the thread's bounded cache (``_cached_shape``): a refiner keeps the
    keys it used (``shape_keys``), never the shapes.  Refiners are made per window plan, and a path whose
    pieces have many plans (cam-bench seed 100, lp+nlp: 162 pieces, 46 refiners) held every shape any of
    them had used, up to 512 knot intervals each: 43 shapes and ~1.2 GB of resident memory by piece 60,
    3.4 GB at the end, growing with the path."""

    def __init__(
        self,
        lim: NlpLimits,
        N: int,
        window: int,
        overlap: int,
        fault: Callable[[int], None] | None = None,
        stats: NlpStats | None = None,
        long_window: int | None = None,
    ) -> None:
        """``fault``: test hook called with the NLP window index before each solve (may raise);
        ``long_window``: the window of a chain that holds at least one of it (``chain_window``)."""
        self.lim = lim
        self.N = N
        self.window = window
        self.overlap = overlap
        self.long_window = long_window
        self.fault = fault
        #: (n, axes, slotted, head, tail) of every shape this refiner has used, in first-use order
        self.shape_keys: dict[tuple[int, tuple[int, ...], bool, bool, bool], None] = {}
        self.stats = stats if stats is not None else NlpStats()
        #: piece-local s verified besides the fine grid (set per piece by ``refine``)
        self.verify: FloatArray = np.zeros(0)
        #: whether the current piece's first / last rest interval may have its bump (REST_BUMP): only where
        #: the machine stands before (after) the piece, at the path's start (end), not at a corner (set per
        #: piece by ``refine``)
        self.bump: tuple[bool, bool] = (True, True)
        #: the motion before the current piece when it starts at a corner, (t < 0, v, a) (``Motion``; None: the
        #: machine stands there), for the sampled check of its first window (set per piece by ``refine``)
        self.lead_in: Motion | None = None
        #: the feed of the piece as the round before solved it (a sample repair round's: ``refine``'s ``outer``),
        #: read by the sampled check beyond the ends of the current chain part (``_spans``) instead of the LP's
        #: where it joins this round's LP state there (``_Outer``); None: the LP's (set per piece by ``refine``)
        self.outer: _Outer | None = None
        #: ``outer`` as the context beyond the ends of the chain part ``_spans`` solves (``_outer_sides``, set per part)
        self._part_outer: _OuterSides | None = None
        #: whether the current chain's first / last rest interval may have its rise (REST_RISE): off for the
        #: retry of a window from (to) rest that failed with it, and where the LP's feed reaches its bound at
        #: the interval's inner knot (REST_RISE_CAP_SHARE) (set per chain by ``_spans``)
        self.rise: list[bool] = [True, True]
        #: how many leading LP control points are final while a chain is solved (``ChainPipeline``; None: all)
        self.c_final: int | None = None
        #: the last solve's window start, size, moving axes, lam_g (rows without cut slots), lam_x and its
        #: shape's row_index: the next window of the chain (``prev`` given) starts from them
        self._duals: tuple[int, int, tuple[int, ...], FloatArray, FloatArray, NDArray[np.int64]] | None = None

    def _outer_sides(self, c: FloatArray, d: float, A: int, B: int) -> _OuterSides | None:
        """``self.outer`` as the context beyond the ends of the chain part over knots [A, B) (``_Context.around``):
        at each end inside the piece where it joins this round's LP state (f and f' within OUTER_JOIN_TOL of the
        LP's: the LP was not changed there), else None at that end (the LP's feed is read there)."""
        outer = self.outer
        if outer is None:
            return None
        n_int = c.size - 2
        ends = np.array([A * d, B * d])
        lp = kinematics.from_q(*bspline.evaluate(c, ends, d))
        out = outer.feed(ends)
        scale = np.maximum(np.abs(lp[0]), 1e-300)
        inside = np.array([A > 0, B < n_int])  # (a rest end has no neighbour)
        ok = (inside & (np.abs(out[0] - lp[0]) <= OUTER_JOIN_TOL * scale)
              & (np.abs(out[1] - lp[1]) * d <= OUTER_JOIN_TOL * scale))
        if not ok.any():
            return None
        p = outer.p[np.isfinite(outer.p)] if outer.p is not None else np.zeros(0)
        f_hi = max(math.sqrt(max(float(np.max(outer.c)), 0.0)), float(np.max(p, initial=0.0)))
        return _OuterSides(outer.feed, ends[0] if ok[0] else -math.inf, ends[1] if ok[1] else math.inf, f_hi)

    def _shape(self, n: int, axes: tuple[int, ...], slotted: bool = False, head: bool = False,
               tail: bool = False) -> _Shape:
        self.shape_keys[(n, axes, slotted, head, tail)] = None
        return _cached_shape(n, self.N, axes, self.lim.amax is not None, slotted, head, tail)

    def chain_window(self, A: int, B: int, n_int: int) -> int:
        """The window (knot intervals) of the chain over knots [A, B) of a piece of n_int intervals:
        ``long_window`` if its grid between the rest intervals (knots 1 .. n_int - 1) holds one, else
        ``window``.  A chain shorter than the long window keeps the short one: its windows then share one
        shape, where one window over the whole chain would need a shape of its own length (bench seeds
        0-59 with every window 6 x the overlap: +26 % lp+nlp CPU, shapes of 81-106 intervals built once each)."""
        span = min(B, n_int - 1) - max(A, 1)
        if self.long_window is not None and span >= self.long_window:
            return self.long_window
        return self.window

    def prebuild(self, geometry: GeometryFn, d: float, A: int, B: int, n_int: int) -> None:
        """Build the shapes of a whole window (``chain_window`` knot intervals, without and with cut slots) for
        the axes moving over knots [A, B), before workers fork: each forked worker would otherwise build both
        itself (18.35 m path, 2 workers: 4 builds of 0.2-0.3 s for 2).  No-op for a chain of at most
        its window + 2 intervals (its windows are the rest ends' or shorter ones)."""
        W = self.chain_window(A, B, n_int)
        if B - A <= W + 2:
            return
        k_loc, tau = checkpoint_layout(B - A, self.N)
        moving = _moving_axes(geometry((A + k_loc + tau) * d))
        for slotted in (False, True):
            self._shape(W, moving, slotted)

    # ----- a piece -------------------------------------------------------------------
    def refine(
        self,
        geometry: GeometryFn,
        c: FloatArray,
        d: float,
        joins: list[int],
        breaks: FloatArray,
        on_chain: Callable[[float], None] | None = None,
        pool: tuple[ChainPool, Any] | None = None,
        verify: FloatArray | None = None,
        bump: tuple[bool, bool] = (True, True),
        lead_in: Motion | None = None,
        outer: _Outer | None = None,
    ) -> tuple[FloatArray, NDArray[np.bool_], tuple[Rise, Rise]]:
        """f control points (n_int + 2,), the mask of knot intervals that use them, and the rise factors of
        the first and last rest interval (REST_RISE, mm/s; 0 where the LP's stays).  The mask is True on
        a rest interval (the first or last) the NLP solved: its q is then ``rest_cps`` of the f control
        points at its inner knot plus the bump of p_0 (p_n_int+1) and the rise (``rest_profile`` makes the
        piece's profile of it).

        ``c``: the LP's q control points over the piece; ``joins``: knots where LP
        windows meet (chains end and start there); ``breaks``: piece-local s of
        geometry knots; ``on_chain(s)`` is called after each chain with the piece-local
        arc length (mm) done (it may raise to cancel).  Chains are independent given the
        LP: with ``pool`` (the schedule's workers and the piece's key there) they are solved in its forked
        processes.
        ``verify``: more piece-local s to verify (sampled points found over a limit); ``bump``: whether the
        first / last rest interval may have its bump (``self.bump``); ``lead_in``: the motion before the piece
        (``self.lead_in``); ``outer``: the piece's feed as the round before solved it (``self.outer``; a sample
        repair round's, on the same knots).
        """
        self.verify = np.zeros(0) if verify is None else np.asarray(verify, dtype=np.float64)
        self.bump = bump
        self.lead_in = lead_in
        self.outer = outer if outer is not None and outer.d == d and outer.n_int == c.size - 2 else None
        n_int = c.size - 2
        p = np.zeros(n_int + 2)
        mask = np.zeros(n_int, dtype=bool)
        # the chains' parts: those whose LP feed is already the NLP's answer keep it (mask False, no spans)
        parts = [part for A, B in chain_spans(n_int, joins) for part in self._chain_parts(geometry, c, d, A, B, breaks)]
        solve = [(A, B) for A, B, k in parts if not k]
        results: Iterator[list[Span]]
        if pool is not None and len(solve) > 1:
            results = pool[0].spans(pool[1], self, geometry, c, d, breaks, solve)
        else:
            results = (self._spans(geometry, c, d, A, B, breaks) for A, B in solve)
        rise: list[Rise] = [(), ()]
        for _, B, k in parts:
            spans = [] if k else next(results)
            _place(spans, p, mask, rise)
            if on_chain is not None:
                on_chain(B * d)
        return p, mask, (rise[0], rise[1])

    def _chain_parts(
        self, geometry: GeometryFn, c: FloatArray, d: float, A: int, B: int, breaks: FloatArray
    ) -> list[tuple[int, int, bool]]:
        """The chain over knots [A, B) as consecutive parts (a, b, kept): kept parts keep the LP's feed, the
        others are solved as chains of their own, from and to the LP's state at their ends.  The whole chain
        is one kept part if the LP's feed is kept on all of it (``_kept_intervals``) and it holds neither rest
        interval, else ``kept_parts`` of its kept intervals (a rest interval is never kept: the NLP's ramp from and
        to rest is its own, cam seed 31 lp+nlp 0.26 % faster than the LP's; until session 53 a chain kept whole
        kept the LP's ramps in it)."""
        ok = self._kept_intervals(geometry, c, d, A, B, breaks)
        n_int = c.size - 2
        if ok.size and ok.all() and A > 0 and B < n_int:
            self.stats.lp_kept_chains += 1
            return [(A, B, True)]
        flags = np.zeros(B - A, dtype=bool)
        A1 = max(A, 1)
        flags[A1 - A : A1 - A + ok.size] = ok
        parts = kept_parts(flags, A, n_int, max(1, math.ceil(LP_KEPT_MARGIN_PER_OVERLAP * self.overlap)),
                           self._kept_min_run(), self.window)
        for a, b, k in parts:
            if k:
                self.stats.lp_kept_spans += 1
                self.stats.lp_kept_intervals += b - a
        return parts

    def _kept_min_run(self) -> int:
        """Knot intervals a kept stretch needs at least (LP_KEPT_MIN_RUN_PER_OVERLAP)."""
        return math.ceil(LP_KEPT_MIN_RUN_PER_OVERLAP * self.overlap)

    def _kept_intervals(
        self, geometry: GeometryFn, c: FloatArray, d: float, A: int, B: int, breaks: FloatArray
    ) -> NDArray[np.bool_]:
        """Whether the LP's feed is kept as it is (``LP_KEPT_FEED_GAP``, ``LP_KEPT_UTIL``) on each knot interval
        of [max(A, 1), min(B, n_int - 1)) (the rest intervals: the LP's feed is not at a bound there): on the
        chain's fine grid (and the verified points in it) it is within LP_KEPT_FEED_GAP of the NLP's feed
        bound, over it (or the axis speeds over theirs) by at most VERIFY_TOL, every other limit of the NLP
        (model and sampled) is used at most LP_KEPT_UTIL, and no break whose step cap the LP's feed is over
        LP_KEPT_STEP_CAP_SHARE of is in the interval or next to it.  A fine point on a knot (to 1e-9 of an
        interval) counts for both intervals there."""
        A, B = max(A, 1), min(B, c.size - 3)
        if B <= A:
            return np.zeros(0, dtype=bool)
        s0, s1 = A * d, B * d
        fine = self._fine_points(s0, s1, d, breaks)
        g = geometry(fine)
        ub = self._feed_bound(g)
        fd = kinematics.from_q(*bspline.evaluate(c, fine, d))
        with np.errstate(invalid="ignore"):
            good = np.isfinite(ub) & (fd[0] >= (1.0 - LP_KEPT_FEED_GAP) * ub)
        x = (fine - s0) / d
        n = B - A
        lo = np.clip(np.floor(x - 1e-9).astype(np.int64), 0, n - 1)
        hi = np.clip(np.floor(x + 1e-9).astype(np.int64), 0, n - 1)

        def intervals(point_ok: NDArray[np.bool_]) -> NDArray[np.bool_]:
            bad = ~point_ok
            out: NDArray[np.bool_] = (np.bincount(lo[bad], minlength=n) + np.bincount(hi[bad], minlength=n)) == 0
            return out

        ok = intervals(good)
        min_run = min(ok.size, self._kept_min_run())
        if all(j - i < min_run for i, j in _true_runs(ok)):  # (no stretch to keep, whatever the other limits)
            return ok
        br, f_cap = self._step_caps(geometry, s0, s1, breaks)
        # (with the feed's share of each step cap and the servo error of the step across it, as a window's)
        util = self._fine_utilisation(fine, g, fd, br, f_cap)
        self._sampled_and_steps(fine, g, fd, util, br)
        # (the feed and axis-speed rows are the feed bound itself)
        for k, u in util.items():
            cap = 1.0 + VERIFY_TOL if k in ("feed", "velocity") else LP_KEPT_UTIL
            good &= (u.max(axis=1) if u.ndim == 2 else u) <= cap
        ok = intervals(good)
        if br.size:  # (a cap the LP's feed is well under binds nothing; its step's e is in ``util`` above)
            f_br = np.sqrt(np.maximum(bspline.evaluate(c, br, d)[0], 0.0))
            br = br[f_br > LP_KEPT_STEP_CAP_SHARE * f_cap]
        for k in np.floor((br - s0) / d).astype(np.int64):
            ok[max(k - 1, 0) : k + 2] = False
        return ok

    def _rise_free(self, tail: bool) -> bool:
        """Whether the piece's first (last, ``tail``) rest interval's rise is free in the current chain: with
        REST_BUMP and REST_RISE, where its bump is (``bump``) and no retry took it off (``rise``)."""
        return REST_BUMP and REST_RISE and self.bump[int(tail)] and self.rise[int(tail)]

    def lp_worst(self, geometry: GeometryFn, c: FloatArray, d: float, A: int, B: int, breaks: FloatArray) -> float:
        """The LP feed's worst utilisation of the NLP's limits over knots [A, B): verified as a window's feed
        is (fine grid refined at turns and fast changes, the steps at curvature jumps, the sampled u and e;
        ``self.verify`` as set for the piece).  lp+nlp's LP holds the drive limits through its own proxies
        and leaves part of them to the NLP (at a curvature jump its step alone may take V_STEP_SHARE of
        emax, the e either side is the NLP's to hold: bench seed 4629, 1.11 x in the model), so its feed is
        not admissible everywhere."""
        s0, s1 = A * d, B * d
        fine = self._fine_points(s0, s1, d, breaks)
        fine, g = _refine_turns(geometry, fine, geometry(fine))
        br, f_cap = self._step_caps(geometry, s0, s1, breaks)

        def verify() -> tuple[kinematics.FeedDerivs, dict[str, FloatArray]]:
            fd = kinematics.from_q(*bspline.evaluate(c, fine, d))
            return fd, self._fine_utilisation(fine, g, fd, br, f_cap)

        fd, util = verify()
        for _ in range(REFINE_LEVELS):
            mids = _fast_cells(fine, util)
            if mids.size == 0 or fine.size + mids.size > REFINE_MAX_POINTS:
                break
            fine, g = _merge(fine, g, mids, geometry(mids))
            fd, util = verify()
        self._sampled_and_steps(fine, g, fd, util, br)
        return max(float(np.max(u)) for u in util.values())

    def _fine_utilisation(
        self, fine: FloatArray, g: PathSamples, fd: kinematics.FeedDerivs, br: FloatArray, f_cap: FloatArray
    ) -> dict[str, FloatArray]:
        """Utilisation of every NLP limit on the fine grid at feed ``fd``, with the feed's share of its cap
        just past each curvature jump at ``br`` ("step") and the servo error of the step across it."""
        util = self.lim.utilisation(g, fd)
        if br.size:
            at = _find(fine, br + BREAK_EPS_MM)
            ok_at = at >= 0
            step = np.zeros(fine.size)
            step[at[ok_at]] = fd[0][at[ok_at]] / f_cap[ok_at]
            util["step"] = step
            if self.lim.sample_period is not None:
                self._step_servo_error(g, fd, _find(fine, br - BREAK_EPS_MM), at, util, STEP_BOUND_VSTEP)
        return util

    def _sampled_and_steps(
        self, fine: FloatArray, g: PathSamples, fd: kinematics.FeedDerivs, util: dict[str, FloatArray],
        br: FloatArray, ctx: _ContextMotion | None = None, rest_span: tuple[float, float] = (-math.inf, math.inf),
    ) -> None:
        """``_sampled``, then, without STEP_BOUND_VSTEP, the velocity-step bound of ``_step_servo_error`` at the
        breaks ``br`` whose impulse the sampled check did not read exactly (it did not run, or the break is within
        2 Ts of the ends of the centres it checks)."""
        covered = self._sampled(fine, g, fd, util, ctx, rest_span)
        if STEP_BOUND_VSTEP or not br.size or self.lim.sample_period is None:
            return
        out = np.ones(br.size, dtype=bool) if covered is None else (br < covered[0]) | (br > covered[1])
        if out.any():
            self._step_servo_error(g, fd, _find(fine, br[out] - BREAK_EPS_MM), _find(fine, br[out] + BREAK_EPS_MM),
                                   util, True)

    def _record(self, a: int, b: int, d: float, window: int, reason: str, status: str, fallback: str) -> None:
        self.stats.failures.append({
            "nlp_window": window, "s_range": [a * d, b * d], "reason": reason, "status": status,
            "fallback": fallback,
        })

    def _spans(
        self, geometry: GeometryFn, c: FloatArray, d: float, A: int, B: int, breaks: FloatArray
    ) -> list[Span]:
        """NLP spans (a, b, p_a .. p_{b+1}, rise) covering [A, B) from and back to LP states (rise: ``_chain``'s).

        Normally one span, the whole chain.  If a window fails, the span so far
        is closed by re-solving the previous window with its far end joined to
        the LP's state (a *bridge*) and a new span starts there from the LP's
        state; if a span's first window fails, the LP feed is kept over one
        window advance and a new span starts after it.  Failures are recorded.
        """
        out: list[Span] = []
        a0 = A
        self.rise = [True, True]
        self._part_outer = self._outer_sides(c, d, A, B)
        n_int = c.size - 2
        if REST_RISE_CAP_SHARE is not None:  # (the rise of a rest end whose LP feed reaches its bound: off)
            ends = ([(False, 1)] if A == 0 else []) + ([(True, n_int - 1)] if B == n_int else [])
            for tail, k in ends:
                if not self._rise_free(tail):  # (a corner's rest end has no rise to take off)
                    continue
                ub = float(self._feed_bound(geometry(np.array([k * d])))[0])
                if math.sqrt(max(0.0, 0.5 * (c[k] + c[k + 1]))) >= REST_RISE_CAP_SHARE * ub:
                    self.rise[int(tail)] = False
                    self.stats.rest_rises_capped += 1
        while B - a0 >= 2:
            try:
                b0, vals, rise = self._chain(geometry, c, d, a0, B, breaks)
            except LpNotFinal:
                raise
            except Exception as exc:
                if a0 == 0:  # the chain from the rest end (``_window``) failed: without the rise, then from the
                    # LP's state at knot 1
                    self.stats.rest_retries += 1
                    if self._rise_free(False):
                        self.rise[0] = False
                    else:
                        a0 = 1
                    continue
                skip = min(B, a0 + max(2, self.window - self.overlap))
                if isinstance(exc, NlpFailure):
                    self._record(a0, skip, d, exc.window, exc.reason, exc.status, "lp feed kept on this span")
                else:
                    self._record(a0, skip, d, self.stats.windows - 1, f"{type(exc).__name__}: {exc}", "exception",
                                 "lp feed kept on this span")
                a0 = skip
                continue
            out.append((a0, b0, vals, rise))
            a0 = b0
        return out

    def _chain(
        self, geometry: GeometryFn, c: FloatArray, d: float, A: int, B: int, breaks: FloatArray
    ) -> tuple[int, FloatArray, tuple[Rise, Rise]]:
        """NLP windows from the LP state at knot A towards B; returns (b, p_A .. p_{b+1}, rise) with b = B,
        or an earlier knot b where a bridge joined the LP state after a failed window; rise: the rise factors
        (REST_RISE, mm/s) of the piece's first and last rest interval where the chain solved them, else none.

        A window inheriting from the previous NLP window fixes three control
        points (so its first knot interval is the one the previous window
        verified) and takes the previous solution as its initial guess.
        Raises NlpFailure if the first window fails.
        """
        out = np.zeros(B - A + 2)
        a = A
        n_int = c.size - 2
        # (from / to a rest end the window solves the rest interval: ``_window``)
        start: tuple[float, ...] = () if A == 0 else _lp_state(c, d, A)
        end = (0.0, 0.0) if B == n_int else _lp_state(c, d, B)
        prev: FloatArray | None = None
        last: tuple[int, int, tuple[float, ...], FloatArray | None, _Left | None] | None = None
        rise: list[Rise] = [(), ()]
        W, P = self.chain_window(A, B, n_int), self.overlap
        while True:
            # windows and commits on the grid of the chain between the rest intervals (knots 1 .. n_int - 1),
            # a rest interval added to the first (last) window: solving the rest intervals changes the motion
            # next to them, not where every later window of the chain starts (bench: a shifted grid moved a
            # join of the 18.35 m path's first chain onto a petal valley, +118 ms)
            ga, gb = max(a, 1), min(B, n_int - 1)
            b = gb if gb - ga <= W else ga + W
            if b == gb:
                b = commit = B
            else:
                commit = ga + W - P
                if gb - commit < W:
                    commit = max(gb - W, ga + 1)
            left = (A, out[: a - A + 2].copy(), rise[0]) if a > A else None
            try:
                try:
                    sol = self._window(geometry, c, d, a, b, commit, start, end if b == B else (0.0, 0.0), breaks,
                                       prev, left)
                except LpNotFinal:
                    raise
                except Exception:
                    if not (b == B == n_int and B - 1 - a >= 2):
                        raise
                    # the window that solved the rest interval at the piece's end failed: without the rise,
                    # then to the LP's state at its inner knot instead
                    self.stats.rest_retries += 1
                    again: FloatArray | None = None
                    if self._rise_free(True):
                        self.rise[1] = False
                        try:
                            again = self._window(geometry, c, d, a, b, commit, start, end, breaks, prev, left)
                        except LpNotFinal:
                            raise
                        except Exception:
                            self.stats.rest_retries += 1
                    if again is not None:
                        sol = again
                    else:
                        B = b = commit = n_int - 1
                        end = _lp_state(c, d, B)
                        out = out[: B - A + 2]
                        sol = self._window(geometry, c, d, a, b, commit, start, end, breaks, prev, left)
                sol, (rise_h, rise_t) = _split_rise(sol, a, b, n_int)
            except Exception as exc:
                if last is None or isinstance(exc, LpNotFinal):
                    raise
                # bridge: the previous window again, its far end joined to the LP state
                la, lb, lstart, lprev, lleft = last
                reason = exc.reason if isinstance(exc, NlpFailure) else f"{type(exc).__name__}: {exc}"
                status = exc.status if isinstance(exc, NlpFailure) else "exception"
                window = exc.window if isinstance(exc, NlpFailure) else self.stats.windows - 1
                try:
                    bridge = self._window(geometry, c, d, la, lb, lb, lstart, _lp_state(c, d, lb), breaks, lprev,
                                          lleft)
                except LpNotFinal:
                    raise
                except Exception:
                    raise NlpFailure(f"{reason}; the bridge to the LP feed failed too", window, status) from exc
                self._record(a, lb, d, window, reason, status, "previous window re-solved to join the lp feed")
                bridge, (rise_h, _) = _split_rise(bridge, la, lb, n_int)
                if la == 0:
                    rise[0] = rise_h
                out[la - A : lb - A + 2] = bridge
                return lb, out[: lb - A + 2], (rise[0], ())
            if a == 0:
                rise[0] = rise_h
            if b == B:
                out[a - A :] = sol
                return B, out, (rise[0], rise_t if b == n_int else ())
            out[a - A : commit - A + 3] = sol[: commit - a + 3]
            last = (a, b, start, prev, left)
            start = tuple(float(x) for x in sol[commit - a : commit - a + 3])
            prev = sol[commit - a :]
            a = commit

    def _window(
        self,
        geometry: GeometryFn,
        c: FloatArray,
        d: float,
        a: int,
        b: int,
        commit: int,
        start: tuple[float, ...],
        end: tuple[float, float],
        breaks: FloatArray,
        prev: FloatArray | None,
        left: _Left | None = None,
    ) -> FloatArray:
        """Solve one NLP window over knot intervals [a, b); returns p_a .. p_{b+1} (mm/s), then the rise factors
        of the rest ends it solves (REST_RISE, ``_Shape.n_rise``: ``_split_rise``).

        ``start``: the first 2 (from the LP) or 3 (from the previous window)
        control points, fixed; ``end``: p_b, p_{b+1}, fixed; ``prev``: the
        previous window's solution from p_a on (initial guess), or None;
        ``left``: (A, p_A .. p_{a+1}, rise), the chain's feed already committed before a
        (None: the LP's feed is the motion before a).
        Limits are verified over [a, commit + 1] (one interval past the
        commit, which the next window inherits whole).
        A window from the piece's start (a = 0: ``start`` is empty) or to its end (b = n_int: ``end`` is
        ignored) solves that rest interval too, in q (``_Shape._rest_rows``); p_0 (p_b+1) is then the factor
        of its bump (REST_BUMP, ``_rest_g``), or unused, 0.
        """
        t0 = time.perf_counter()
        index = self.stats.windows
        self.stats.windows += 1
        lim, N = self.lim, self.N
        n = b - a
        n_int = c.size - 2
        head, tail = a == 0, b == n_int
        k_loc, tau = checkpoint_layout(n, N)
        s_chk = (a + k_loc + tau) * d
        fine = self._fine_points(a * d, min(b, commit + VERIFY_PAST_COMMIT) * d, d, breaks)
        if head or tail:
            fine = _rest_fine(fine, a * d if head else None, b * d if tail else None, d, N * VERIFY_SUBDIV)
        # the motion around the window for the sampled check: before a (the chain so far, or the LP), and
        # after b when the chain ends there (inside a chain the next window checks what follows)
        joins_lp = not tail and (end[0] != 0.0 or end[1] != 0.0)
        ctx = _Context.around(c, d, a * d, fine[-1] if joins_lp else None, left, lim.sample_period, self.c_final,
                              self._part_outer)
        # the rest intervals' rest points (``REST_SUBDIV``): the head's, then the tail's
        s_rest = np.concatenate([(k0 + rest_point_taus(N)) * d for k0, on in ((a, head), (b - 1, tail)) if on]
                                + [np.zeros(0)])
        # every point the set-up evaluates, in one call (a call costs ~0.6 ms on top of ~2 us a point)
        br_near = breaks[(breaks > (a - 1) * d) & (breaks < (b + 1) * d)]
        geometry = _Prefetched(geometry, np.concatenate([
            s_chk, _envelope_points(k_loc, tau, a, d, N).ravel(), br_near - BREAK_EPS_MM,
            br_near + BREAK_EPS_MM, fine, ctx.points(), s_rest,
        ]))
        ctx_motion = ctx.motion(geometry)
        if (head or tail) and lim.sample_period is not None:
            ctx_motion = _standing(ctx_motion, head, tail, lim.sample_period, self.lead_in if head else None)
        g = geometry(s_chk)
        xsss_hi, xsss_lo = _third_derivative_envelope(geometry, g, k_loc, tau, a, d, N, breaks)
        moving = _moving_axes(g)
        # a window from or to rest starts with its slot rows (unbounded until a slot is placed): nearly
        # every one places slots in a cut round, and its second shape cost another 0.25-0.45 s to build
        # (REST_SLOTTED)
        shape = self._shape(n, moving, slotted=REST_SLOTTED and (head or tail), head=head, tail=tail)
        g_rest = geometry(s_rest)
        rest_params = np.concatenate([x[:, ax] for ax in moving for x in (g_rest.d1, g_rest.d2, g_rest.d3)]
                                     + [np.zeros(0)])
        #: the rest points' bound factor (u, e; a and j relative to BOUND_FACTOR, like a slot's)
        rest_fac = np.full(s_rest.size, BOUND_FACTOR)
        K = shape.K
        q_lp = bspline.evaluate(c, s_chk, d)[0]
        f_lp = np.sqrt(np.maximum(q_lp, 0.0))
        Fs = max(float(np.max(f_lp)), *(abs(x) for x in start), 1e-6) * 1.5
        fixed = {i: x / Fs for i, x in enumerate(start)}
        fit: dict[int, float] = {}  # the hand-over starts the rest intervals from the LP's state at their inner knot
        rest_lo: list[float] = []
        rest_hi: list[float] = []
        if head:
            fixed[0] = 0.0
            fit = {i + 1: x / Fs for i, x in enumerate(_lp_state(c, d, 1))}
        if tail:
            fixed[n + 1] = 0.0
            fit.update({n - 1 + i: x / Fs for i, x in enumerate(_lp_state(c, d, n_int - 1))})
        else:
            fixed.update({n: end[0] / Fs, n + 1: end[1] / Fs})
        for on, c_lp in ((head, c[1]), (tail, c[n_int])):
            if on:
                if not c_lp > 0.0:
                    self.stats.window_times.append(time.perf_counter() - t0)
                    raise NlpFailure("the LP feed does not leave or reach the rest end", index, "rest")
                rest_lo.append(REST_C_FLOOR * c_lp / Fs**2)
                rest_hi.append(REST_C_CEIL * c_lp / Fs**2)
        # (the rise factors, past p_n+1, start at 0: ``_Shape.n_rise``)
        x0 = np.concatenate([shape.handover(f_lp / Fs, {**fixed, **fit}), np.zeros(shape.n_rise)])
        if prev is not None:
            m = min(prev.size, n + 2) - self.overlap // 2
            x0[:m] = prev[:m] / Fs
        if head or tail:
            x0 = self._shrink_to_feasible(x0, fixed, g, lambda pw: _window_feed(pw, s_chk, a, b, d, head, tail), Fs)
        else:
            x0 = self._shrink_to_feasible(x0, fixed, g, lambda pw: kinematics.from_f(*eval_f(pw, k_loc, tau, d)), Fs)
        # parameters
        ds = np.where((tau == 0.0) | (tau == 1.0), d / (2 * N), d / N)
        in_commit = k_loc < commit - a
        # (a rest interval's travel time is its own term of the objective: ``_Shape._rest_rows``)
        rest_chk = (head & (k_loc == 0)) | (tail & (k_loc == n - 1))
        L = n * d
        wt = np.where(rest_chk, 0.0, np.where(in_commit, ds / L, TAIL_TIME_WEIGHT * ds / L))
        wf = np.where(in_commit, 0.0, LAMBDA_TAIL * ds / L)
        coefs = []
        for ax in moving:
            coefs.append([
                lim.M[ax] / lim.umax[ax], lim.b[ax] / lim.umax[ax],
                lim.Kv[ax] / lim.emax[ax], lim.Ka[ax] / lim.emax[ax], lim.Kj[ax] / lim.emax[ax],
                1.0 / lim.vmax[ax] if lim.vmax is not None else 0.0,
                1.0 / lim.amax[ax] if lim.amax is not None else 0.0,
                1.0 / lim.jmax[ax] if lim.jmax is not None else 0.0,
            ])
        pvec = np.concatenate([
            [Fs, 1.0 / d],
            *(g.d1[:, ax] for ax in moving), *(g.d2[:, ax] for ax in moving),
            *(xsss_hi[:, ax] for ax in moving), *(xsss_lo[:, ax] for ax in moving),
            wt, wf, np.ravel(coefs),
        ])
        nx = n + 2 + shape.n_rise
        lbx = np.full(nx, -np.inf)
        ubx = np.full(nx, np.inf)
        for i, val in fixed.items():
            lbx[i] = ubx[i] = val
        # the rise factors (REST_RISE): fixed at 0 unless that end's bump is free
        lbx[n + 2 :] = ubx[n + 2 :] = 0.0
        if REST_BUMP:  # p_0 (p_n+1) carries the rest interval's bump: free, from 0 (``_Shape._rest_rows``)
            # (at a corner the bump stays 0: the sampled check below sees the machine standing before/after
            # the piece, not the other piece's acceleration, whose step the corner shares: bench seed 55, a
            # bump's rise after the step took the sampled servo error to 1.06 x next to a corner)
            nr = len(bspline.REST_RISE_POWERS)
            for i, j in [(0, n + 2)] * (head and self.bump[0]) + [(n + 1, nx - nr)] * (tail and self.bump[1]):
                lbx[i], ubx[i] = -np.inf, np.inf
                if shape.n_rise and self._rise_free(i > 0):  # (a cached shape has them when REST_RISE is off)
                    lbx[j : j + nr], ubx[j : j + nr] = -np.inf, np.inf
        fac_u = np.full((K, len(moving)), BOUND_FACTOR)
        fac_e = np.full((K, len(moving)), BOUND_FACTOR)
        fac_k = np.ones(K)  # velocity/feed rows are linear in f: no margin needed
        # the jerk rows' own ceiling under ``Options.nlp_kinematic`` (``_vstep_ceiling``; inf: fac_k alone)
        cap_j = np.full((K, len(moving)), np.inf)
        # checkpoints fully determined by fixed control points carry no rows; where only f and f'
        # are fixed (the knots of the fixed states) the rows without f'' (u, a, f) are constant
        free_rows = np.ones(K, dtype=bool)
        state_fixed = ((k_loc == 0) & (tau == 0.0)) | ((k_loc == n - 1) & (tau == 1.0))
        if len(start) == 3:
            free_rows[k_loc == 0] = False
            state_fixed |= (k_loc == 1) & (tau == 0.0)
        keep = free_rows & ~state_fixed
        sig_hi, sig_lo = _friction_signs(g.d1)
        feed_ub = self._feed_bound(g)
        # next to a state taken from the LP (chain start, join end) the LP's own feed is admissible
        # (the LP met the velocity bound to its verification tolerance)
        near_lp = np.zeros(K, dtype=bool)
        if len(start) == 2:
            near_lp |= k_loc == 0
        if end[0] != 0.0 or end[1] != 0.0:
            near_lp |= k_loc == n - 1
        feed_lp = np.where(near_lp, f_lp * (1.0 + 1e-9), 0.0)
        feed_ub = np.maximum(feed_ub, feed_lp)
        # the feed rows' floor (``_row_bounds``): none until a tightening under feed_lp makes the window infeasible
        feed_floor = np.zeros(K)
        # curvature jumps (knots, smooth junctions): f <= f_cap there, held at the two checkpoints around each.
        # At a checkpoint next to a state taken from the LP the cap is deferred (``_LpSideCaps``): added, as
        # max(f_cap, the LP's feed), once the verification finds the step at that break over its limit
        br, f_cap = self._step_caps(geometry, a * d, b * d, breaks)
        lp_side = _LpSideCaps.empty()
        if br.size:
            x = (br - a * d) / d
            kint = np.clip(np.floor(x), 0, n - 1).astype(np.int64)
            kc = kint * (N + 1) + np.clip(np.floor((x - kint) * N), 0, N - 1).astype(np.int64)
            for off in (0, 1):
                np.minimum.at(feed_ub, kc + off, np.where(near_lp[kc + off], np.inf, f_cap))
            lp_side = _LpSideCaps.at(br, f_cap, kc, near_lp, f_lp)
        # the velocity steps among them, whose impulses the e and u rows do not hold (``_vstep_boost``)
        vbr = self._velocity_breaks(geometry, br) if VSTEP_TIGHTEN_BOOST != 1.0 else br[:0]
        if FLAT_FEED_COLUMNS:  # (a control point under a flat feed bound is held at it: ``flat_feed_columns``)
            col_ub = flat_feed_columns(feed_ub, n, N, head, tail) / Fs
            held = (lbx[: n + 2] < ubx[: n + 2]) & np.isfinite(col_ub)
            ubx[: n + 2][held] = np.minimum(ubx[: n + 2][held], col_ub[held])
            x0[: n + 2] = np.minimum(x0[: n + 2], ubx[: n + 2])
        floor_u, floor_e = self._inherited_floor(prev, g, xsss_hi, xsss_lo, k_loc, tau, d, moving)
        fine, g_fine = _refine_turns(geometry, fine, geometry(fine))
        # cut slots may sit where a free control point acts, off the fixed states at the window ends (and
        # off the rest intervals, whose feed is not the f spline's)
        slot_lo = (a + (1 if len(start) == 3 or head else 0)) * d
        slot_hi = (b - (1 if tail else 0)) * d
        slots = _Slots(n, a, d, moving, slot_lo + BREAK_EPS_MM, slot_hi - BREAK_EPS_MM, 0.5 * d / N)
        rest_span = (d if head else -math.inf, (b - 1) * d if tail else math.inf)

        def verify(pw: FloatArray) -> tuple[kinematics.FeedDerivs, dict[str, FloatArray]]:
            fd = _window_feed(pw, fine, a, b, d, head, tail)
            return fd, self._fine_utilisation(fine, g_fine, fd, br, f_cap)

        x = x0
        # with lam_x: the dual point the solve starts from (the previous round's, or the previous window's)
        lam_g: FloatArray | None = None
        lam_x: FloatArray | None = None
        if prev is not None:
            lam_g, lam_x = self._shifted_duals(a, n, moving, shape)
        worst = math.inf
        best: tuple[float, FloatArray] | None = None
        prev_fac: tuple[FloatArray, ...] | None = None
        retries = 0
        rnd = 0
        while rnd <= MAX_CUT_ROUNDS:
            lbg, ubg = self._row_bounds(moving, fac_u, fac_e, fac_k, sig_hi, sig_lo, feed_ub, feed_floor, Fs,
                                        free_rows, keep, cap_j)
            if shape.slotted:
                s_lo, s_hi = slots.bounds(self, prev)
                lbg, ubg = np.concatenate([lbg, s_lo]), np.concatenate([ubg, s_hi])
            if shape.n_rest:
                fr = np.repeat(rest_fac[:, None], len(moving), axis=1)
                pts = _point_bounds(lim, moving, g_rest.d1, fr, fr, np.minimum(1.0, rest_fac / BOUND_FACTOR))
                pts_lo, pts_hi = _exact_bounds(*pts, lim.amax is not None)
                lbg = np.concatenate([lbg, rest_lo, pts_lo.ravel()])
                ubg = np.concatenate([ubg, rest_hi, pts_hi.ravel()])
            if self.fault is not None:
                self.fault(index)
            p_all = np.concatenate([pvec, slots.params(), rest_params] if shape.slotted else [pvec, rest_params])
            args: dict[str, Any] = {"x0": x, "p": p_all, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
            warm = WARM_START and lam_g is not None and lam_x is not None
            args["lam_g0"] = lam_g if warm else np.zeros(shape.rows)
            args["lam_x0"] = lam_x if warm else np.zeros(nx)
            dense = _dense_solve(shape.ipm, x, p_all, lbx, ubx, lbg, ubg, args["lam_g0"])
            res: dict[str, Any]
            st: dict[str, Any]
            # the dense method's own verdict on a round's rows (never Ipopt's: that one gets the safe retry)
            dense_infeasible = dense is not None and dense.status == DENSE_INFEASIBLE and rnd > 0
            if dense is not None and dense.success:
                res = {"x": dense.x, "lam_g": dense.lam_g, "lam_x": dense.lam_x}
                st = {"success": True, "return_status": dense.status, "iter_count": dense.iterations}
                self.stats.ipm_iterations += dense.iterations
            elif dense is not None:
                # not finished by the dense method (from the given multipliers, then from unit ones): it was the
                # fast attempt, Ipopt's safe settings below are the retry (the fast Ipopt settings first cost
                # 2 Ipopt solves per window that is infeasible after a tightening: 18.35 m path, 7 of 7 handed),
                # unless its elastic attempt found the rows of a tightening round locally infeasible
                # (``DENSE_INFEASIBLE``)
                self.stats.ipm_iterations += dense.iterations
                if dense_infeasible:
                    self.stats.ipm_infeasible += 1
                else:
                    self.stats.ipm_handed += 1
                res = {}
                st = {"success": False, "return_status": dense.status, "iter_count": dense.iterations}
            else:
                solver = shape.solver
                res = solver(**args)
                st = solver.stats()
            self.stats.iterations += int(st.get("iter_count", 0))
            if rnd > 0 or retries > 0:
                self.stats.resolve_iterations += int(st.get("iter_count", 0))
            if warm:
                if rnd == 0 and retries == 0:
                    self.stats.warm_first += 1
                else:
                    self.stats.warm_resolves += 1
            status = str(st.get("return_status", "unknown"))
            if not st.get("success", False) and status != "Solved_To_Acceptable_Level" and not dense_infeasible:
                # once per solve: Ipopt's own cold start with the safe settings
                safe = shape.safe_solver
                res = safe(**{k: v for k, v in args.items() if k not in ("lam_g0", "lam_x0")})
                st = safe.stats()
                self.stats.iterations += int(st.get("iter_count", 0))
                self.stats.safe_retries += 1
                status = str(st.get("return_status", "unknown"))
            if not st.get("success", False) and status != "Solved_To_Acceptable_Level":
                if best is not None and best[0] <= 1.0 + ACCEPT_TOL:
                    return self._accept(best, t0)
                if rnd > 0 and not feed_floor.any() and np.any(keep & (feed_ub / Fs * fac_k < feed_lp / Fs)):
                    # the tightening took feed rows next to the LP's state under the LP's feed, which the
                    # fixed state may not reach: the round again with those rows at it (``_row_bounds``)
                    feed_floor = feed_lp
                    x = best[1] / Fs if best is not None else x0
                    lam_g = None
                    continue
                if rnd > 0 and prev_fac is not None and retries < MAX_SOFTER_RETRIES:
                    # tightening made the window infeasible: retry with half of it (geometric mean)
                    retries += 1
                    self.stats.softer_retries += 1
                    for cur, old in zip((fac_u, fac_e, fac_k, slots.fac, rest_fac, cap_j), prev_fac, strict=True):
                        cur[...] = np.sqrt(cur * old)
                    x = best[1] / Fs if best is not None else x0
                    lam_g = None
                    continue
                self.stats.window_times.append(time.perf_counter() - t0)
                raise NlpFailure(f"Ipopt did not converge (round {rnd})", index, status)
            x = np.asarray(res["x"], dtype=np.float64).ravel()
            lam_g = np.asarray(res["lam_g"], dtype=np.float64).ravel()
            lam_x = np.asarray(res["lam_x"], dtype=np.float64).ravel()
            self._duals = (a, n, moving, lam_g[: shape.base_rows].copy(), lam_x.copy(), shape.row_index)
            if not np.all(np.isfinite(x)):
                self.stats.window_times.append(time.perf_counter() - t0)
                raise NlpFailure("Ipopt returned a non-finite point", index, status)
            # verify on the fine grid, refined where a utilisation changes fast between its points
            pw = x * Fs
            fd, util = verify(pw)
            for _ in range(REFINE_LEVELS):
                mids = _fast_cells(fine, util)
                if mids.size == 0 or fine.size + mids.size > REFINE_MAX_POINTS:
                    break
                fine, g_fine = _merge(fine, g_fine, mids, geometry(mids))
                fd, util = verify(pw)
            # (after the refinement: its utilisations are spread)
            self._sampled_and_steps(fine, g_fine, fd, util, br, ctx_motion, rest_span)
            inside = np.ones(fine.size, dtype=bool)  # (the feed is 0 at a rest end itself)
            if head:
                inside &= fine > 0.0
            if tail:
                inside &= fine < b * d
            if np.any(fd[0][inside] <= 0.0):
                self.stats.window_times.append(time.perf_counter() - t0)
                raise NlpFailure("feed reaches zero inside the window", index, "nonpositive feed")
            worst = max(float(np.max(u)) for u in util.values())
            if best is None or worst < best[0]:
                best = (worst, pw)
            if worst <= 1.0 + VERIFY_TOL:
                return self._accept(best, t0)
            if rnd == MAX_CUT_ROUNDS:
                break
            rnd += 1
            self.stats.cut_rounds += 1
            # the worst point of each violated stretch gets a cut slot while slots last; the rest
            # tighten the bounds of the checkpoints around them
            prev_fac = (fac_u.copy(), fac_e.copy(), fac_k.copy(), slots.fac.copy(), rest_fac.copy(), cap_j.copy())
            # a deferred cap whose step is over its limit is added from the next round on (bench seed 2053)
            added = lp_side.add_violated(fine, util, feed_ub)
            util = slots.place(fine, g_fine, util)
            if slots.any and not shape.slotted:  # the window's shape with slot rows: the same rows, then the slots'
                shape = self._shape(n, moving, slotted=True, head=head, tail=tail)
                cut = lam_g.size - shape.n_rest
                lam_g = np.concatenate([lam_g[:cut], np.zeros(shape.rows - lam_g.size), lam_g[cut:]])
            reach = _vstep_reach(fine, fd[0], vbr, lim.sample_period) if rnd >= VSTEP_BOOST_ROUND else None
            self._tighten(_vstep_boost(util, reach), fine, a * d, d, moving, fac_u, fac_e, fac_k)
            if reach is not None:
                self._vstep_ceiling(util, reach, fine, a * d, d, moving, fac_u, fac_e, cap_j)
            _tighten_points(util, fine, s_rest, d / (N * REST_SUBDIV), rest_fac)
            fac_k[added] = prev_fac[2][added]  # (a cap just added is not tightened: its overshoot was without it)
            # bounds of constant rows stay as they are (tightening them could only make the window infeasible)
            fac_u[~keep] = BOUND_FACTOR
            fac_e[~free_rows] = BOUND_FACTOR
            np.maximum(fac_u, floor_u, out=fac_u)
            np.maximum(fac_e, floor_e, out=fac_e)
            fac_k[~keep] = 1.0
        if best is not None and best[0] <= 1.0 + ACCEPT_TOL:
            return self._accept(best, t0)
        self.stats.window_times.append(time.perf_counter() - t0)
        raise NlpFailure(
            f"limits exceeded between checkpoints after {MAX_CUT_ROUNDS} rounds (worst {worst:.4f})",
            index, "unverified",
        )

    def _shifted_duals(
        self, a: int, n: int, moving: tuple[int, ...], shape: _Shape
    ) -> tuple[FloatArray | None, FloatArray | None]:
        """The previous window's last dual point (rows without cut slots) moved to this window's checkpoints,
        or (None, None) if that window moved other axes (another row layout) or does not overlap this one.
        Rows and variables past its end start at 0, and so do a rest end's rows.  The windows may differ in
        size (a chain's last window, one that solves a rest interval: ``_chain``)."""
        dd = self._duals
        if dd is None or dd[2] != moving or not 0 < a - dd[0] < dd[1]:
            return None, None
        adv = a - dd[0]
        sh = adv * (self.N + 1)
        src_index = dd[5]
        m = min(shape.K, src_index.shape[1] - sh)
        dst, src = shape.row_index[:, :m], src_index[:, sh : sh + m]
        ok = (dst >= 0) & (src >= 0)
        lam_g = np.zeros(shape.rows)
        lam_g[dst[ok]] = dd[3][src[ok]]
        lam_x = np.zeros(n + 2 + shape.n_rise)  # (a rest end's rise factor: 0)
        kx = min(n + 2, dd[1] + 2 - adv)
        lam_x[:kx] = dd[4][adv : adv + kx]
        return lam_g, lam_x

    def _inherited_floor(
        self,
        prev: FloatArray | None,
        g: PathSamples,
        xsss_hi: FloatArray,
        xsss_lo: FloatArray,
        k_loc: NDArray[np.int64],
        tau: FloatArray,
        d: float,
        moving: tuple[int, ...],
    ) -> tuple[FloatArray, FloatArray]:
        """Lowest bound factors (K, na) for u and e rows: on the first VERIFY_PAST_COMMIT intervals of
        an inherited window, the previous window's solution (verified there on the fine grid) stays
        admissible, so tightening can never make the window infeasible there."""
        K = k_loc.size
        fu = np.zeros((K, len(moving)))
        fe = np.zeros((K, len(moving)))
        if prev is None:
            return fu, fe
        # the verified intervals and the knot that closes them (u depends on f and f' only, which are
        # continuous there, so that knot seen from the next interval must admit the same value)
        sel = (k_loc < VERIFY_PAST_COMMIT) | ((k_loc == VERIFY_PAST_COMMIT) & (tau == 0.0))
        sel &= k_loc + 2 < prev.size
        if not sel.any():
            return fu, fe
        f, f1, f2 = eval_f(prev, k_loc[sel], tau[sel], d)
        lim = self.lim
        for m, ax in enumerate(moving):
            xs, xss = g.d1[sel, ax], g.d2[sel, ax]
            v = xs * f
            acc = xss * f * f + xs * f * f1
            j_rest = 3.0 * xss * f * f * f1 + xs * (f * f1 * f1 + f * f * f2)
            sig = np.sign(xs)
            u_hi = lim.M[ax] * acc + lim.b[ax] * v + lim.c[ax] + lim.d[ax] * np.where(np.abs(xs) < SIGN_EPS, 1, sig)
            u_lo = lim.M[ax] * acc + lim.b[ax] * v + lim.c[ax] + lim.d[ax] * np.where(np.abs(xs) < SIGN_EPS, -1, sig)
            e_va = lim.Kv[ax] * v + lim.Ka[ax] * acc
            e_hi = e_va + lim.Kj[ax] * (xsss_hi[sel, ax] * f**3 + j_rest)
            e_lo = e_va + lim.Kj[ax] * (xsss_lo[sel, ax] * f**3 + j_rest)
            fu[sel, m] = np.maximum(np.abs(u_hi), np.abs(u_lo)) / lim.umax[ax] * (1 + 1e-9)
            fe[sel, m] = np.maximum(e_hi, -e_lo) / lim.emax[ax] * (1 + 1e-9)
        return fu, fe

    def _accept(self, best: tuple[float, FloatArray], t0: float) -> FloatArray:
        self.stats.window_times.append(time.perf_counter() - t0)
        self.stats.worst_verified = max(self.stats.worst_verified, best[0])
        return best[1]

    def _tighten(
        self,
        util: dict[str, FloatArray],
        fine: FloatArray,
        s0: float,
        d: float,
        moving: tuple[int, ...],
        fac_u: FloatArray,
        fac_e: FloatArray,
        fac_k: FloatArray,
    ) -> None:
        """Scale the bounds of the checkpoints around each violated fine point by overshoot^-TIGHTEN_POWER.

        Per round each checkpoint is scaled once, by the largest overshoot near
        it (violations next to each other do not compound)."""
        K = fac_k.size
        near = _tightened_checkpoints(fine, s0, d, K, self.N)

        def scale_for(ratio: FloatArray) -> FloatArray:
            """(K,) factor: min over nearby violated points of ratio^-p - margin (1 where none)."""
            out = np.ones(K)
            bad = ratio > 1.0 + VERIFY_TOL
            if bad.any():
                sc = _tighten_scale(ratio[bad])
                np.minimum.at(out, near[bad].ravel(), np.repeat(sc, near.shape[1]))
            return out

        for name, arr in util.items():
            if name in ("control_signal", "servo_error", "sampled_control_signal", "sampled_servo_error"):
                fac = fac_u if name.endswith("control_signal") else fac_e
                for m, ax in enumerate(moving):
                    fac[:, m] = np.maximum(MIN_BOUND_FACTOR, fac[:, m] * scale_for(arr[:, ax]))
            else:
                ratio = arr if arr.ndim == 1 else kinematics.row_max(arr)
                fac_k[:] = np.maximum(MIN_BOUND_FACTOR, fac_k * scale_for(ratio))

    def _velocity_breaks(self, geometry: GeometryFn, br: FloatArray) -> FloatArray:
        """The breaks of ``br`` (mm) where x_s jumps (``solvers.lp.tangent_jump``): velocity steps at speed."""
        if not br.size or self.lim.sample_period is None:
            return br[:0]
        jump = tangent_jump(geometry(br + BREAK_EPS_MM), geometry(br - BREAK_EPS_MM), BREAK_EPS_MM)
        moves: NDArray[np.bool_] = np.max(jump, axis=1) > AXIS_EPS
        return br[moves]

    def _vstep_ceiling(
        self, util: dict[str, FloatArray], reach: NDArray[np.bool_], fine: FloatArray, s0: float, d: float,
        moving: tuple[int, ...], fac_u: FloatArray, fac_e: FloatArray, cap_j: FloatArray,
    ) -> None:
        """Hold the e (u) rows of the checkpoints around each fine point in ``reach`` whose sampled servo error
        (control signal) is over its limit at most at the rows' own utilisation there (``util["servo_error"]``,
        ``util["control_signal"]``) x overshoot^-TIGHTEN_POWER - TIGHTEN_MARGIN, per axis (VSTEP_TIGHTEN_BOOST);
        under ``Options.nlp_kinematic`` the jerk rows likewise for the sampled jerk, by their own cap ``cap_j``
        (K, moving axes; inf: none), since their bound factor fac_k is the acceleration's and the feed's too.

        Where a velocity step's impulse carries the overshoot the rows can be far under their bound (the feed held
        by other rows): scaling the bound alone leaves the solution as it was until the bound comes down to them."""
        K = fac_e.shape[0]
        near = _tightened_checkpoints(fine, s0, d, K, self.N)
        for name, model, fac in (("sampled_servo_error", "servo_error", fac_e),
                                 ("sampled_control_signal", "control_signal", fac_u),
                                 ("sampled_jerk", "jerk", cap_j)):
            if name not in util or model not in util:
                continue
            for m, ax in enumerate(moving):
                r = util[name][:, ax]
                bad = np.flatnonzero(reach & (r > 1.0 + VERIFY_TOL))
                if not bad.size:
                    continue
                ceil = np.full(K, np.inf)
                np.minimum.at(ceil, near[bad].ravel(),
                              np.repeat(util[model][bad, ax] * _tighten_scale(r[bad]), near.shape[1]))
                fac[:, m] = np.maximum(MIN_BOUND_FACTOR, np.minimum(fac[:, m], ceil))

    def _row_bounds(
        self,
        moving: tuple[int, ...],
        fac_u: FloatArray,
        fac_e: FloatArray,
        fac_k: FloatArray,
        sig_hi: FloatArray,
        sig_lo: FloatArray,
        feed_ub: FloatArray,
        feed_floor: FloatArray,
        Fs: float,
        free_rows: NDArray[np.bool_],
        keep: NDArray[np.bool_],
        cap_j: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Row bounds in the order of ``_Shape``'s rows (scaled units).

        Rows at checkpoints not in ``free_rows`` are unbounded; so are the u, a
        and f rows at checkpoints not in ``keep`` (constant there).

        The jerk rows' bound is min(fac_k, ``cap_j``) (``_vstep_ceiling``; None: fac_k).
        The feed rows hold f <= max(fac_k feed_ub, feed_floor).  ``feed_floor`` (K,) is 0 until a
        tightening that took feed rows next to a state taken from the LP under the LP's feed made the
        window infeasible; from then on (the same round solved again) it is the LP's feed (times
        1 + 1e-9) at the checkpoints next to such a state, 0 elsewhere.  There the fixed state leaves f
        little freedom: in the first interval f(tau) = (1 - tau)^2 / 2 p_a + (1 + 2 tau - 2 tau^2) / 2
        p_a+1 + tau^2 / 2 p_a+2 with only p_a+2 free, and f >= 0 at the next knot, (p_a+1 + p_a+2) / 2
        >= 0, bounds p_a+2 from below.  Bench seed 4629: the step cap at a curvature jump 0.3 of the way
        into a chain's first interval (``_LpSideCaps``, 0.324 mm/s; the step's servo error, not the
        cap, was over) tightened to MIN_BOUND_FACTOR x, 0.162 mm/s, at checkpoints where the LP's feed
        is 0.247 and 0.220 and the fixed state (p_a, p_a+1) = (0.470, 0.157) allows no less than 0.235
        and 0.157: Ipopt 'Infeasible_Problem_Detected', the softer retries (geometric means) tightened
        back to it a round later, and the piece fell back to the LP's feed.  With the floor the round
        passes, its feed at the jump 0.229 mm/s, 4 % under the LP's (the other rows still reach under it).
        Not from the start: where a tightening under the LP's feed stays feasible it is what holds a
        limit the LP's feed misses next to its state (bench seeds 14 and 185: with the floor in every
        round a window stayed 1.020 and 1.0095 x over and fell back, 185's motion 5.5 % longer)."""
        lim = self.lim
        K = free_rows.size
        lo: list[FloatArray] = []
        hi: list[FloatArray] = []
        inf = np.full(K, np.inf)
        const = ~keep
        for m, ax in enumerate(moving):
            um, c, dd = lim.umax[ax], lim.c[ax], lim.d[ax]
            hi.append(np.where(const, np.inf, (um * fac_u[:, m] - c - dd * sig_hi[:, ax]) / um))
            lo.append(np.where(const, -np.inf, (-um * fac_u[:, m] - c - dd * sig_lo[:, ax]) / um))
            hi.extend([fac_e[:, m].copy(), inf.copy()])
            lo.extend([-inf, -fac_e[:, m]])
            if lim.amax is not None:
                fj = fac_k if cap_j is None else np.minimum(fac_k, cap_j[:, m])
                hi.extend([np.where(const, np.inf, fac_k), fj.copy(), inf.copy()])
                lo.extend([np.where(const, -np.inf, -fac_k), -inf, -fj])
        lo.append(np.where(const, -np.inf, 0.0))
        hi.append(np.where(const, np.inf, np.maximum(feed_ub / Fs * fac_k, feed_floor / Fs)))
        off = ~free_rows
        for lo_i, hi_i in zip(lo, hi, strict=True):
            lo_i[off] = -np.inf
            hi_i[off] = np.inf
        # u, a and f rows: one row per interior knot, bounded by both of its checkpoints' bounds
        kept, dup, twin = knot_twins(K // (self.N + 1), self.N)
        per_axis = 6 if lim.amax is not None else 3
        reduced = [i for i in range(len(lo)) if i == len(lo) - 1 or i % per_axis in (0, 3)]
        for i in reduced:
            lo[i][twin] = np.maximum(lo[i][twin], lo[i][dup])
            hi[i][twin] = np.minimum(hi[i][twin], hi[i][dup])
            lo[i], hi[i] = lo[i][kept], hi[i][kept]
        return np.concatenate(lo), np.concatenate(hi)

    def _step_caps(
        self, geometry: GeometryFn, s0: float, s1: float, breaks: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Breaks inside (s0, s1) where x_ss or x_s jumps, and the feed cap there: f^2 |jump of x_ss| <= a_step
        per axis (the sampled acceleration step, seen as jerk and servo error over one period), and
        f |jump of x_s| <= v_step (a tangent break passed at speed: the velocity step, seen as an impulse)."""
        lim = self.lim
        if lim.a_step is None and lim.v_step is None:
            return np.zeros(0), np.zeros(0)
        br = breaks[(breaks > s0 + BREAK_EPS_MM) & (breaks < s1 - BREAK_EPS_MM)]
        if br.size == 0:
            return br, np.zeros(0)
        right, left = geometry(br + BREAK_EPS_MM), geometry(br - BREAK_EPS_MM)
        cap_f = np.full(br.size, np.inf)
        if lim.a_step is not None:
            # the plain difference, smooth part included (not ``lp.curvature_jump``): with the smooth part taken
            # out, the caps at the 45-loop flower's C2 knots went (2 nm x x_sss read as a jump before) and one
            # window handed to Ipopt took 5.4 s instead of 0.47 s (the 18.35 m path at the default knots,
            # lp+nlp compute 4.9 -> 9.4 s; session 38).  Caps that are too low only make the NLP more careful.
            cap_f = np.sqrt(step_cap(lim.a_step, np.abs(right.d2 - left.d2)))
        if lim.v_step is not None:
            cap_f = np.minimum(cap_f, step_cap(lim.v_step, tangent_jump(right, left, BREAK_EPS_MM)))
        keep = np.isfinite(cap_f)
        return br[keep], cap_f[keep]

    def _step_servo_error(
        self, g: PathSamples, fd: kinematics.FeedDerivs, left: NDArray[np.int64], right: NDArray[np.int64],
        util: dict[str, FloatArray], impulse: bool,
    ) -> None:
        """Servo error of the sampled acceleration step at curvature jumps (fine-grid indices of the left
        and right side of each, -1 if absent).  A step of the axis acceleration between two samples
        (x_ss jump x f^2) is seen in the central third difference as at most |step| / (2 Ts) of jerk on
        top of the e either side, so each side's servo-error utilisation is raised to
        (|e_side| + Kj |step| / (2 Ts)) / emax, and ``util["step"]`` to the larger of the two: a violation
        tightens the e rows next to the jump (or gets a cut slot there) and the feed cap at it.

        ``impulse``: with a velocity step's impulse too (a tangent break passed at speed), bounded by e either side
        plus ``solvers.lp.vstep_servo_error`` |dv| (and u by M V_KERNEL_A |dv| / Ts), the triangle inequality over
        instants up to Ts apart: loose where the sampled check reads the impulse exactly (``STEP_BOUND_VSTEP``)."""
        lim = self.lim
        Ts = lim.sample_period
        ok = (left >= 0) & (right >= 0)
        if Ts is None or not ok.any():
            return
        lt, rt = left[ok], right[ok]
        both = np.concatenate([lt, rt])
        v, acc, j = kinematics.axis_kinematics(g.subset(both), *(x[both] for x in fd))
        e = np.abs(lim.Kv * v + lim.Ka * acc + lim.Kj * j).reshape(2, lt.size, 3)
        seen = lim.Kj * np.abs(acc[lt.size :] - acc[: lt.size]) / (2.0 * Ts)
        u = np.abs(lim.M * acc + lim.b * v + lim.c + lim.d * np.sign(v)).reshape(2, lt.size, 3)
        if impulse:
            # a velocity step (tangent break passed at speed) is an impulse in the differences
            dv = np.abs(v[lt.size :] - v[: lt.size])
            seen = seen + vstep_servo_error(lim.Ka, lim.Kj, Ts) * dv
            u = u + lim.M * V_KERNEL_A * dv / Ts
        for side, idx in enumerate((lt, rt)):
            np.maximum.at(util["servo_error"], idx, (e[side] + seen) / lim.emax)
            np.maximum.at(util["control_signal"], idx, u[side] / lim.umax)
        np.maximum.at(util["step"], rt, np.max((np.maximum(e[0], e[1]) + seen) / lim.emax, axis=1))

    def _sampled(
        self, fine: FloatArray, g: PathSamples, fd: kinematics.FeedDerivs, util: dict[str, FloatArray],
        ctx: _ContextMotion | None = None, rest_span: tuple[float, float] = (-math.inf, math.inf),
    ) -> tuple[float, float] | None:
        """u and e as the finite differences of the positions sampled at Ts see them, at every sample phase.

        The differences are exact kernel averages of the motion: with T = Ts,
        (x(t+T) - x(t-T)) / 2T is the mean of v over [t-T, t+T]; the second difference is the mean of a
        under the hat (T - |tau|) / T^2; the central third difference (a(t+T) - a(t-T)) / 2T of those
        means.  So e_sampled = Kv v_mean + Ka a_mean + Kj j_mean and u_sampled likewise (friction with the
        sign of v_mean), computed on a uniform time grid (t(s) = integral ds / f over the fine grid, a and
        v interpolated) for every centre whose differences lie inside the window.  Where the model's e
        changes within a sample (feed x Ts over a knot interval) these exceed the model's by a few percent
        (random cases 8, 133: 1.02 x emax with e <= 0.995 at every point).  Each centre's utilisation
        is spread over the points its differences use (+-2 Ts), so a violation tightens the checkpoints
        there: ``util["sampled_control_signal"]``, ``util["sampled_servo_error"]`` (F, 3).

        ``ctx``: the motion just outside the window (``_Context``), read by the differences of the centres
        near the window's ends (without it those within 2 Ts of an end are not checked).  Outside
        ``rest_span`` (the rest intervals of a window that solves them) the time of a step of the grid is
        2 ds / (f_0 + f_1), exact for a constant sddot as at rest, where the trapezoid of 1 / f is not.

        Returns the span of s (mm) whose velocity steps' impulses it read exactly (``_impulse_probes`` with
        SAMPLED_IMPULSE_PROBES; the centres within 2 Ts of each step checked), or None if it read none."""
        lim = self.lim
        Ts = lim.sample_period
        if Ts is None or fine.size < 3:
            return None
        f = fd[0]
        dsf = np.diff(fine)
        with np.errstate(divide="ignore"):
            dt = dsf * 0.5 * (1.0 / f[:-1] + 1.0 / f[1:])
            if rest_span[0] > fine[0] or rest_span[1] < fine[-1]:
                mean_v = (fine[1:] <= rest_span[0]) | (fine[:-1] >= rest_span[1])
                dt = np.where(mean_v, 2.0 * dsf / (f[:-1] + f[1:]), dt)
        if not np.all(np.isfinite(dt)):
            # a feed of 0 inside the window (an iterate that stalls; test seed 14 with nlp_overlap 2 raised an
            # OverflowError below and lost the window): no time grid, the sampled check is left to the pipeline
            return None
        t = np.concatenate([[0.0], np.cumsum(dt)])
        v, acc, _ = kinematics.axis_kinematics(g, *fd)
        t_fine = t
        if ctx is not None:
            t, v, acc = ctx.joined(t, v, acc)
            t_fine = t[ctx.left_size : ctx.left_size + fine.size]
        own = slice(0, fine.size) if ctx is None else slice(ctx.left_size, ctx.left_size + fine.size)
        steps = _velocity_steps(fine, t_fine, v[own], acc[own])
        M = SAMPLED_SUBDIV
        h = Ts / M
        n_u = int((t[-1] - t[0]) / h) + 1
        if n_u < 4 * M + 1 or n_u > SAMPLED_MAX_POINTS:
            return None
        tu = t[0] + np.arange(n_u) * h
        k = np.arange(-M, M + 1)
        box = np.where(np.abs(k) == M, 0.5, 1.0) / (2 * M)
        hat = (M - np.abs(k)) / M**2
        valid = slice(2 * M, n_u - 2 * M)
        half = M // 2  # (SAMPLED_SUBDIV is even: the plain third difference's second differences at +-Ts / 2)
        # each velocity step's impulse dv delta(t - t_b) under the hat: dv (Ts - |t - t_b|) / Ts^2 on its +-Ts
        impulses: list[tuple[int, int, FloatArray, FloatArray]] = []
        for t_b, dv in steps:
            lo, hi = np.searchsorted(tu, (t_b - Ts, t_b + Ts))
            impulses.append((lo, hi, (Ts - np.abs(tu[lo:hi] - t_b)) / Ts**2, dv))
        e_s = np.zeros((n_u, 3))
        u_s = np.zeros((n_u, 3))
        # with the kinematic limits (``Options.nlp_kinematic``) the samples' acceleration and jerk too: bench seed 23
        # read 1.16 x jmax at a curvature jump, which the model's points did not see
        a_s = np.zeros((n_u, 3)) if lim.amax is not None and SAMPLED_KINEMATIC else None
        j_s = np.zeros((n_u, 3)) if lim.jmax is not None and SAMPLED_KINEMATIC else None
        for i in range(3):
            if not (v[:, i].any() or acc[:, i].any()):
                # a standing axis: the means below are exact zeros, so e = 0 and u = c (the same values)
                u_s[valid, i] = abs(lim.c[i]) / lim.umax[i]
                continue
            vm = np.convolve(np.interp(tu, t, v[:, i]), box, mode="same")
            am_motion = np.convolve(np.interp(tu, t, acc[:, i]), hat, mode="same")
            am = am_motion.copy()
            for lo, hi, w, dv in impulses:
                am[lo:hi] += dv[i] * w
            jm = np.zeros(n_u)
            jm[M:-M] = (am[2 * M :] - am[: -2 * M]) / (2.0 * Ts)
            e = np.abs(lim.Kv[i] * vm + lim.Ka[i] * am + lim.Kj[i] * jm)
            u = np.abs(lim.M[i] * am + lim.b[i] * vm + lim.c[i] + lim.d[i] * np.sign(vm))
            probe = steps and (SAMPLED_IMPULSE_PROBES or SAMPLED_PLAIN_JERK)
            pr = _impulse_probes(tu, vm, am_motion, steps, i, Ts, M) if probe else None
            if pr is not None and SAMPLED_IMPULSE_PROBES:
                np.maximum.at(e, pr.index, np.abs(lim.Kv[i] * pr.vm + lim.Ka[i] * pr.am + lim.Kj[i] * pr.jm))
                np.maximum.at(u, pr.index, np.abs(lim.M[i] * pr.am + lim.b[i] * pr.vm + lim.c[i]
                                                  + lim.d[i] * np.sign(pr.vm)))
            e_s[valid, i] = e[valid] / lim.emax[i]
            u_s[valid, i] = u[valid] / lim.umax[i]
            plain = pr if SAMPLED_PLAIN_JERK else None
            if a_s is not None and lim.amax is not None:
                a_abs = np.abs(am)
                if plain is not None:
                    np.maximum.at(a_abs, plain.index, np.abs(plain.am))
                a_s[valid, i] = a_abs[valid] / lim.amax[i]
            if j_s is not None and lim.jmax is not None:
                # the promised jerk is the plain third difference (``tests/fdcheck``): two adjacent second
                # differences Ts apart, where the drive model's is their mean over 2 Ts (``jm``), which read a
                # velocity step's impulse and the motion's jerk next to it at half and its mean
                if SAMPLED_PLAIN_JERK:
                    jp = np.zeros(n_u)
                    jp[half:-half] = (am[2 * half :] - am[: -2 * half]) / Ts
                else:
                    jp = jm
                j_abs = np.abs(jp)
                if plain is not None:
                    np.maximum.at(j_abs, plain.index, np.abs(plain.jp))
                j_s[valid, i] = j_abs[valid] / lim.jmax[i]
        named = [("sampled_servo_error", e_s), ("sampled_control_signal", u_s)]
        named += [(k, x) for k, x in (("sampled_acceleration", a_s), ("sampled_jerk", j_s)) if x is not None]
        for name, val in named:
            spread = maximum_filter1d(val, size=4 * M + 1, axis=0)
            util[name] = np.column_stack([np.interp(t_fine, tu, spread[:, i]) for i in range(3)])
        if not SAMPLED_IMPULSE_PROBES:
            return None
        # (np.interp clamps to the window's own points where the checked centres reach into its context)
        t_lo, t_hi = tu[valid.start] + 2.0 * Ts, tu[valid.stop - 1] - 2.0 * Ts
        return float(np.interp(t_lo, t_fine, fine)), float(np.interp(t_hi, t_fine, fine))

    def _feed_bound(self, g: PathSamples) -> FloatArray:
        """Upper bound on f at points g: min(Fmax, min_x vmax_x / |x_s|) (inf if neither applies), (K,)."""
        ub = np.full(g.s.size, np.inf if self.lim.feed_max is None else self.lim.feed_max)
        if g.feed_limit is not None:
            ub = np.minimum(ub, g.feed_limit)
        if self.lim.vmax is not None:
            with np.errstate(divide="ignore"):
                ub = np.minimum(ub, kinematics.row_min(self.lim.vmax / np.abs(g.d1)))
        return ub

    def _fine_points(self, s0: float, s1: float, d: float, breaks: FloatArray) -> FloatArray:
        n_fine = max(1, round((s1 - s0) / d)) * self.N * VERIFY_SUBDIV
        s = np.linspace(s0, s1, n_fine + 1)
        br = breaks[(breaks > s0 + BREAK_EPS_MM) & (breaks < s1 - BREAK_EPS_MM)]
        extra = self.verify[(self.verify > s0) & (self.verify < s1)]
        # both sides of the feed's own knots: f'' (so j, e) jumps there, and without its two sides the
        # refinement (_fast_cells) bisected the cell next to every knot REFINE_LEVELS times, chasing the
        # one-sided limit (flower at 4.63 mm knots: ~10 cells a level, every level, every round)
        kn = d * np.arange(math.floor(s0 / d) + 1, math.ceil(s1 / d))
        kn = kn[(kn > s0 + 2 * BREAK_EPS_MM) & (kn < s1 - 2 * BREAK_EPS_MM)]
        return np.sort(np.concatenate([
            s, br - BREAK_EPS_MM, br, br + BREAK_EPS_MM, kn - BREAK_EPS_MM, kn + BREAK_EPS_MM, extra,
        ]))

    def _shrink_to_feasible(
        self,
        x0: FloatArray,
        fixed: dict[int, float],
        g: PathSamples,
        feed: Callable[[FloatArray], kinematics.FeedDerivs],
        Fs: float,
    ) -> FloatArray:
        """Scale the free control points down until the hand-over meets the limits at the checkpoints.

        If HANDOVER_MAX_STEPS steps do not get there, the hand-over is returned unscaled: a point scaled
        to 0.97^30 = 0.40 x and still over a limit is a worse start than the one it came from (bench
        seed 1885, lp+nlp: 296 of 304 windows ran all 30 steps, from a feed at Fmax to 1 + 1e-13 at the
        fixed states, or a fit that stops at an artificial rest with 25 x emax; Ipopt took 1239 iterations
        on the first 30 windows from the scaled points, 425 from the unscaled ones)."""
        free = np.ones(x0.size, dtype=bool)
        free[list(fixed)] = False
        x = x0.copy()
        for step in range(HANDOVER_MAX_STEPS + 1):
            fd = feed(x * Fs)
            util = self.lim.utilisation(g, fd)
            if max(float(np.max(u)) for u in util.values()) <= 1.0 and np.all(fd[0] >= 0):
                return x
            if step == HANDOVER_MAX_STEPS:
                break
            x[free] *= HANDOVER_SHRINK
            self.stats.handover_scaled += 1
        self.stats.handover_unscaled += 1
        return x0


def _place(spans: list[Span], p: FloatArray, mask: NDArray[np.bool_], rise: list[Rise]) -> None:
    """Write a chain's spans into the piece's f control points p, the mask of the knot intervals they cover,
    and the rise factors [first, last] of the rest intervals a span solved."""
    for a0, b0, vals, (r_head, r_tail) in spans:
        p[a0 : b0 + 2] = vals
        mask[a0:b0] = True
        if a0 == 0:
            rise[0] = r_head
        if b0 == mask.size:
            rise[1] = r_tail


def _split_rise(sol: FloatArray, a: int, b: int, n_int: int) -> tuple[FloatArray, tuple[Rise, Rise]]:
    """A window's solution over [a, b) (``_window``) as p_a .. p_{b+1} and the rise factors of the piece's
    first and last rest interval (none where the window has none)."""
    n = b - a
    r = sol[n + 2 :]
    nr = len(bspline.REST_RISE_POWERS)
    head = tuple(float(v) for v in r[:nr]) if a == 0 and r.size else ()
    tail = tuple(float(v) for v in r[-nr:]) if b == n_int and r.size else ()
    return sol[: n + 2], (head, tail)


def kept_parts(
    flags: NDArray[np.bool_], A: int, n_int: int, margin: int, min_run: int, window: int
) -> list[tuple[int, int, bool]]:
    """The parts (a, b, kept) of a chain over knots [A, A + flags.size) of a piece of n_int intervals, given
    which of its knot intervals may keep the LP's feed (``flags``).

    The intervals that may not are solved.  Each solved stretch takes ``margin`` intervals from the kept
    ones on either side (not past the chain's ends: there the LP's state is the join anyway), and then, while
    its grid (knots 1 .. n_int - 1, as ``NlpRefiner._chain`` walks it) spans fewer than ``window`` intervals,
    one more on either side, so that it is solved in windows of the chain's usual shape (a shorter one would
    need a shape of its own length); kept stretches shorter than ``min_run`` are solved too.  Solved parts
    then have at least 2 intervals."""
    n = flags.size
    solved = ~flags
    runs = _true_runs(solved)
    grown = np.zeros(n, dtype=bool)
    for i, j in runs:
        i, j = max(0, i - margin), min(n, j + margin)
        while _grid_span(A + i, A + j, n_int) < window and (i > 0 or j < n):
            i, j = max(0, i - 1), min(n, j + 1)
        grown[i:j] = True
    for i, j in _true_runs(~grown):
        if j - i < min_run:
            grown[i:j] = True
    edges = [0] + [int(k) for k in np.flatnonzero(np.diff(grown.astype(np.int8))) + 1] + [n]
    return [(A + i, A + j, not bool(grown[i])) for i, j in itertools.pairwise(edges)]


def _grid_span(a: int, b: int, n_int: int) -> int:
    """Knot intervals of [a, b) between the piece's rest intervals (knots 1 .. n_int - 1)."""
    return min(b, n_int - 1) - max(a, 1)


def _true_runs(flags: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """The runs [i, j) of True in ``flags``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[False], flags, [False]]).astype(np.int8)))
    return [(int(i), int(j)) for i, j in zip(edges[::2], edges[1::2], strict=True)]


def chain_spans(n_int: int, joins: list[int]) -> list[tuple[int, int]]:
    """The NLP chains (A, B) of a piece on n_int knot intervals whose LP windows meet at ``joins``: knot
    intervals [A, B) from the LP's state at knot A to its state at B, or from and to the piece's rest ends
    (REST_ENDS, on at least REST_ENDS_MIN_INTERVALS intervals; else between the rest intervals)."""
    ends = REST_ENDS and n_int >= REST_ENDS_MIN_INTERVALS
    knots = [0 if ends else 1] + [k for k in joins if 1 < k < n_int - 1] + [n_int if ends else n_int - 1]
    return [(A, B) for A, B in itertools.pairwise(knots) if B - A >= 2]


def _lp_state(c: FloatArray, d: float, k: int) -> tuple[float, float]:
    """f control points (p_k, p_{k+1}) reproducing the LP's feed and its slope at knot k.

    q = (c_k + c_{k+1})/2, q' = (c_{k+1} - c_k)/d; f = sqrt(q), f' = q'/(2 f);
    p_k = f - f' d/2, p_{k+1} = f + f' d/2.
    """
    q = 0.5 * (c[k] + c[k + 1])
    q1 = (c[k + 1] - c[k]) / d
    if not q > 0:
        raise NlpFailure("the LP feed is zero at a window join", -1, "rest")
    f = math.sqrt(q)
    f1 = q1 / (2.0 * f)
    return f - 0.5 * f1 * d, f + 0.5 * f1 * d


def rest_cps(p_in: float, p_out: float, d: float, head: bool) -> FloatArray:
    r"""q's three control points on a rest interval from the f spline's (p_k, p_{k+1}) at its inner knot k.

    With f = (p_k + p_{k+1}) / 2 and f' d = p_{k+1} - p_k there, q must meet f^2 and (f^2)' = 2 f f' at the
    inner knot and vanish at rest: the control points either side of the inner knot are f^2 -+ f f' d,
    and the one past rest is minus its neighbour (q = 0 at rest, q' = 2 c / d there, c the control point
    next to rest).  Head (knot 1 of the piece): (c_0, c_1, c_2); tail (knot n_int - 1): (c_{n-1}, c_n, c_{n+1})."""
    return np.array(_rest_cp_values(p_in, p_out, head))


def _rest_cp_values(p_in: Any, p_out: Any, head: bool) -> tuple[Any, Any, Any]:
    """``rest_cps``' three values, in plain arithmetic: floats, or CasADi expressions (``_Shape._rest_rows``)."""
    f = 0.5 * (p_in + p_out)
    near = f * (3.0 * p_in - p_out) / 2.0  # f^2 - f f' d at the inner knot
    far = f * (3.0 * p_out - p_in) / 2.0  # f^2 + f f' d
    return (-near, near, far) if head else (near, far, -far)


def _rest_g(p_rest: Any, p_in: Any, p_out: Any) -> Any:
    """A rest interval's bump amplitude g (q units: mm^2/s^2, or scaled by Fs^2) from its control point p_rest
    (p_0 or p_n+1) times the feed (p_in + p_out) / 2 at its inner knot (REST_BUMP): floats or CasADi
    expressions.  As a product with the feed, g scales as q does when the window's f is scaled."""
    return p_rest * (0.5 * (p_in + p_out))


def rest_profile(
    c: FloatArray, p: FloatArray, mask: NDArray[np.bool_], d: float, rise: tuple[Rise, Rise] = ((), ())
) -> tuple[FloatArray, NDArray[np.bool_], list[float], list[Rise]]:
    """The LP's q control points with the rest intervals the NLP solved (``mask`` True on a rest interval:
    ``refine``'s output, with its rise factors ``rise``) replaced by ``rest_cps``, the mask with them off (a
    rest interval's feed is always q: ``solvers.timing.PieceProfile``), and their bumps' and rises'
    amplitudes [first, last] (``_rest_g``; 0 where the LP's rest interval stays)."""
    c, mask = c.copy(), mask.copy()
    n_int = mask.size
    g = [0.0, 0.0]
    h: list[Rise] = [(), ()]
    if mask[0]:
        c[:3] = rest_cps(float(p[1]), float(p[2]), d, True)
        g[0] = float(_rest_g(p[0], p[1], p[2]))
        h[0] = tuple(float(_rest_g(r, p[1], p[2])) for r in rise[0])
        mask[0] = False
    if mask[-1]:
        c[-3:] = rest_cps(float(p[n_int - 1]), float(p[n_int]), d, False)
        g[1] = float(_rest_g(p[n_int + 1], p[n_int - 1], p[n_int]))
        h[1] = tuple(float(_rest_g(r, p[n_int - 1], p[n_int])) for r in rise[1])
        mask[-1] = False
    return c, mask, g, h


def _window_feed(
    pw: FloatArray, s: FloatArray, a: int, b: int, d: float, head: bool, tail: bool
) -> kinematics.FeedDerivs:
    """(sdot, sddot, sdddot) at piece-local s of a window's control points pw (p_a .. p_b+1, then its rise
    factors: ``_window``) over knot intervals [a, b): f, and the rest intervals' q (``rest_cps``) on the
    first (``head``, a = 0) or last (``tail``, b = n_int) interval."""
    rise = tuple(float(r) for r in pw[b - a + 2 :])
    nr = len(bspline.REST_RISE_POWERS)
    pw = pw[: b - a + 2]
    fd = kinematics.from_f(*bspline.evaluate(pw, s, d, col0=a, k_lo=a, k_hi=b - 1))
    if not (head or tail):
        return fd
    f, sdd, sddd = (x.copy() for x in fd)
    ends = []
    if head:
        ends.append((s < (a + 1) * d, a, pw[0], pw[1], pw[2], rise[:nr]))
    if tail:
        ends.append((s > (b - 1) * d, b - 1, pw[-1], pw[-3], pw[-2], rise[-nr:] if rise else ()))
    for sel, k, p_rest, p_in, p_out, p_rise in ends:
        if sel.any():
            f[sel], sdd[sel], sddd[sel] = _rest_feed(p_rest, p_in, p_out, s[sel], d, k, k == 0, p_rise)
    return f, sdd, sddd


def _rest_feed(p_rest: float, p_in: float, p_out: float, s: FloatArray, d: float, k: int,
               head: bool, p_rise: Rise = ()) -> kinematics.FeedDerivs:
    """(sdot, sddot, sdddot) at piece-local s on a rest interval k (the piece's first, ``head``, or last) that
    the NLP solved: q from ``rest_cps`` of (p_in, p_out) at its inner knot, plus the bump and the rise with
    amplitudes ``_rest_g`` of p_rest and of each of p_rise."""
    q, q1, q2 = bspline.evaluate(rest_cps(p_in, p_out, d, head), s, d, k_lo=k, k_hi=k, col0=k)
    g, h = float(_rest_g(p_rest, p_in, p_out)), tuple(float(_rest_g(r, p_in, p_out)) for r in p_rise)
    if g or any(h):
        b, b1, b2 = bspline.rest_bump(s, d, k, head, g, h)
        q, q1, q2 = q + b, q1 + b1, q2 + b2
    return kinematics.from_q(q, q1, q2)


class _Slots:
    """The cut slots of one window (``_Shape`` with ``slotted``): one per knot interval.

    A slot at piece-local s (interval k, tau) is a checkpoint placed per call: rows u, e (and a,
    j when kept) of every moving axis with the path's derivatives at s itself (no envelope),
    bounded like a checkpoint's, and f >= 0.  The worst point of a stretch of the fine grid over
    a limit gets its interval's slot (like the LP's cutting planes), if that slot is free and a
    free control point acts there (s in (s_lo, s_hi)).  Unused slots have unbounded rows.
    """

    def __init__(
        self, n: int, a: int, d: float, moving: tuple[int, ...], s_lo: float, s_hi: float, near: float
    ) -> None:
        """``near``: a violation this close to a used slot (mm) tightens that slot's bounds."""
        self.n, self.a, self.d, self.moving, self.near = n, a, d, moving, near
        self.s_lo, self.s_hi = s_lo, s_hi
        self.used = np.zeros(n, dtype=bool)
        #: bound factor of each slot's u, e, a, j rows (tightened when a violation next to the slot remains)
        self.fac = np.full(n, BOUND_FACTOR)
        self.tau = np.full(n, 0.5)
        self.d1 = np.zeros((n, 3))
        self.d2 = np.zeros((n, 3))
        self.d3 = np.zeros((n, 3))
        self.feed_limit = np.full(n, np.inf)

    @property
    def any(self) -> bool:
        return bool(self.used.any())

    def params(self) -> FloatArray:
        """tau (n), then x_s, x_ss, x_sss (n each) per moving axis, in ``_Shape``'s order."""
        ax = list(self.moving)
        return np.concatenate([self.tau, *self.d1[:, ax].T, *self.d2[:, ax].T, *self.d3[:, ax].T])

    def _samples(self) -> PathSamples:
        s = (self.a + np.arange(self.n) + self.tau) * self.d
        return PathSamples(s, np.zeros((self.n, 3)), self.d1, self.d2, self.d3, self.feed_limit)

    def bounds(self, ref: NlpRefiner, prev: FloatArray | None) -> tuple[FloatArray, FloatArray]:
        """Row bounds of the slot rows (scaled units), in ``_Shape``'s order."""
        lim, n, on = ref.lim, self.n, self.used
        per_axis = 6 if lim.amax is not None else 3
        lo = np.full((len(self.moving) * per_axis + 1, n), -np.inf)
        hi = np.full_like(lo, np.inf)
        if not on.any():
            return lo.ravel(), hi.ravel()
        g = self._samples()
        k = np.arange(n, dtype=np.int64)
        # on the intervals inherited from the previous window its (verified) solution stays admissible
        fu, fe = ref._inherited_floor(prev, g, g.d3, g.d3, k, self.tau, self.d, self.moving)
        lo[:-1, on], hi[:-1, on] = (x[:, on] for x in _point_bounds(
            lim, self.moving, g.d1, np.maximum(self.fac[:, None], fu), np.maximum(self.fac[:, None], fe),
            np.minimum(1.0, self.fac / BOUND_FACTOR)))
        lo[-1, on] = 0.0
        return lo.ravel(), hi.ravel()

    def place(self, fine: FloatArray, g_fine: PathSamples, util: dict[str, FloatArray]) -> dict[str, FloatArray]:
        """Put free slots on the worst point of each violated stretch of the fine grid (worst stretches
        first); returns ``util`` with the stretches that got a slot cleared (for the tightening)."""
        names = [k for k in ("control_signal", "servo_error", "acceleration", "jerk") if k in util]
        if not names:
            return util
        r = _worst_util(util, names)
        bad = r > 1.0 + VERIFY_TOL
        ok = bad & (fine > self.s_lo) & (fine < self.s_hi)
        if not self.used.any():  # the first slot needs a large overshoot (then the slotted shape is in use)
            for run in np.split(np.flatnonzero(bad), np.flatnonzero(np.diff(np.flatnonzero(bad)) > 1) + 1):
                if run.size and np.max(r[run]) <= SLOT_OVERSHOOT:
                    ok[run] = False
        if not ok.any():
            return util
        kint = np.clip(np.floor(fine / self.d) - self.a, 0, self.n - 1).astype(np.int64)
        idx = np.flatnonzero(bad)
        runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
        cand: list[tuple[float, int, NDArray[np.int64]]] = []
        for run in runs:
            run_ok = run[ok[run]]
            if run_ok.size:
                i = int(run_ok[np.argmax(r[run_ok])])
                cand.append((float(r[i]), i, run))
        cand.sort(key=lambda t: -t[0])
        out = util
        for worst, i, run in cand:
            k = int(kint[i])
            if self.used[k]:
                # the feature next to this interval's slot is still over: tighten the slot like a checkpoint
                if abs(fine[i] - (self.a + k + self.tau[k]) * self.d) <= self.near:
                    self.fac[k] = max(MIN_BOUND_FACTOR, self.fac[k] * _tighten_scale(worst))
                    if out is util:
                        out = {name: v.copy() for name, v in util.items()}
                    for name in names:
                        out[name][run] = 0.0
                continue
            if out is util:
                out = {name: v.copy() for name, v in util.items()}
            self.used[k] = True
            self.tau[k] = fine[i] / self.d - self.a - k
            self.d1[k], self.d2[k], self.d3[k] = g_fine.d1[i], g_fine.d2[i], g_fine.d3[i]
            if g_fine.feed_limit is not None:
                self.feed_limit[k] = g_fine.feed_limit[i]
            for name in names:
                out[name][run] = 0.0
        return out


def _rest_fine(fine: FloatArray, s_head: float | None, s_tail: float | None, d: float, n: int) -> FloatArray:
    """The fine grid with n - 1 more points in each rest interval (its rest end at ``s_head`` / ``s_tail``, or
    None) at the distance d (j / n)^2 from rest: even in time for a constant acceleration, where the even
    grid in s leaves the first cell next to rest a long time (t ~ sqrt(s)) over which ``_sampled``
    interpolates v and a linearly (bench-test seed 41: the sampled e at the path's last sample 1.013 x with
    the rises, where the window's check read it within its tolerance)."""
    w = (np.arange(1, n, dtype=np.float64) / n) ** 2 * d
    extra = [s_head + w] if s_head is not None else []
    extra += [s_tail - w] if s_tail is not None else []
    if not extra:
        return fine
    more = np.concatenate(extra)
    return np.unique(np.concatenate([fine, more[(more > fine[0]) & (more < fine[-1])]]))


def _rest_point(ts: FloatArray, cps: tuple[Any, Any, Any], g: Any, h: list[Any], head: bool, Fs: Any,
                inv_d: Any) -> tuple[Any, Any, Any, Any]:
    """(sqrt(q), sdot, sddot, sdddot) at the unit taus ``ts`` (T,) of a rest interval (``_rest_end``;
    CasADi columns of T, q scaled by Fs^2): the quadratic of control points ``cps``, plus g b (None: no bump)
    and sum_k h_k e_k (``bspline.rest_bump``).  sdot = Fs sqrt(q), sddot = q' / 2, sdddot = sqrt(q) q'' / 2.
    The constants are taken tau by tau, in floats, and the expressions are column operations: entry by
    entry the arithmetic of one tau at a time (built per tau before session 44: the terms the taus now share
    regroup the AD's sums, so solves agree to rounding, not bit for bit; motion within 3e-9 on 56 cases)."""
    c0, c1, c2 = cps
    t = [float(v) for v in ts]

    def col(vals: list[float]) -> Any:  # (a column of constants)
        return ca.DM(vals)

    qh = 0.5 * (c0 * col([(1 - v) ** 2 for v in t]) + c1 * col([1 + 2 * v - 2 * v * v for v in t])
                + c2 * col([v * v for v in t]))
    d2q = c0 - 2.0 * c1 + c2
    dq, d2q = (c1 - c0) + d2q * col(t), d2q * col([1.0] * len(t))
    if g is not None:
        bs = [[float(v[0]) for v in bspline.rest_bump(np.array([v]), 1.0, 0, head, 1.0)] for v in t]
        qh, dq, d2q = (qh + g * col([b[0] for b in bs]), dq + g * col([b[1] for b in bs]),
                       d2q + g * col([b[2] for b in bs]))
        for ir, hr in enumerate(h):
            unit = tuple(float(ir == jr) for jr in range(len(h)))
            es = [[float(w[0]) for w in bspline.rest_bump(np.array([v]), 1.0, 0, head, 0.0, unit)] for v in t]
            qh, dq, d2q = (qh + hr * col([e[0] for e in es]), dq + hr * col([e[1] for e in es]),
                           d2q + hr * col([e[2] for e in es]))
    r = ca.sqrt(ca.fmax(qh, REST_Q_FLOOR))
    sd = Fs * r
    return r, sd, 0.5 * Fs * Fs * inv_d * dq, 0.5 * sd * Fs * Fs * inv_d * inv_d * d2q


def _worst_util(util: dict[str, FloatArray], names: Sequence[str]) -> FloatArray:
    """The largest utilisation at each fine point (F,) over the ``names`` of ``util`` and their axes (each
    (F, 3) or (F,)): what a cut slot (``_Slots.place``) and a rest point (``_tighten_points``) answer to."""
    return kinematics.row_max(np.column_stack([u if u.ndim == 1 else kinematics.row_max(u)
                                               for u in (util[k] for k in names)]))


def _tighten_scale(overshoot: Any) -> Any:
    """The factor a bound is scaled by for a violation of ``overshoot`` (> 1) next to it:
    overshoot^-TIGHTEN_POWER - TIGHTEN_MARGIN (a checkpoint's: ``NlpRefiner._tighten``; a cut slot's:
    ``_Slots.place``; a rest point's: ``_tighten_points``)."""
    return overshoot**-TIGHTEN_POWER - TIGHTEN_MARGIN


def _tightened_checkpoints(fine: FloatArray, s0: float, d: float, K: int, N: int) -> NDArray[np.int64]:
    """(F, S): the indices of the K window checkpoints (N + 1 an interval from s0, spacing d mm) a violation at each
    fine point tightens: TIGHTEN_SPREAD around the checkpoint before it."""
    x = (fine - s0) / d
    kint = np.clip(np.floor(x), 0, K // (N + 1) - 1).astype(np.int64)
    kk = kint * (N + 1) + np.clip(np.floor((x - kint) * N), 0, N - 1).astype(np.int64)
    near: NDArray[np.int64] = np.clip(kk[:, None] + TIGHTEN_SPREAD[None, :], 0, K - 1)
    return near


def _vstep_reach(fine: FloatArray, f: FloatArray, vbr: FloatArray, Ts: float | None) -> NDArray[np.bool_] | None:
    """(F,): the fine points (mm, feed f mm/s) within reach of a velocity step at ``vbr`` (mm, sorted), or None if
    there is none (or no sample period).  The impulse of a step enters the sampled differences of the centres within
    2 Ts of it and each centre's utilisation is spread over the points within 2 Ts (``NlpRefiner._sampled``):
    reach 4 Ts f."""
    if Ts is None or not vbr.size:
        return None
    j = np.searchsorted(vbr, fine)
    gap = np.minimum(np.abs(fine - vbr[np.maximum(j - 1, 0)]), np.abs(vbr[np.minimum(j, vbr.size - 1)] - fine))
    reach: NDArray[np.bool_] = gap <= 4.0 * Ts * f + BREAK_EPS_MM
    return reach


def _vstep_boost(util: dict[str, FloatArray], reach: NDArray[np.bool_] | None) -> dict[str, FloatArray]:
    """``util`` with the sampled servo error and control signal over their limits at the points in ``reach``
    (``_vstep_reach``) raised to VSTEP_TIGHTEN_BOOST: a copy (the other entries shared), or ``util`` itself."""
    if reach is None:
        return util
    out = dict(util)
    for name in ("sampled_servo_error", "sampled_control_signal"):
        if name in util:
            arr = util[name]
            out[name] = np.where(reach[:, None] & (arr > 1.0), arr**VSTEP_TIGHTEN_BOOST, arr)
    return out


def _tighten_points(util: dict[str, FloatArray], fine: FloatArray, s_pts: FloatArray, h: float,
                    fac: FloatArray) -> None:
    """Scale the bound factor ``fac`` (P,) of each point at ``s_pts`` (a rest point: spacing ``h`` from its
    neighbours) by overshoot^-TIGHTEN_POWER - TIGHTEN_MARGIN of the worst violated fine point within h of
    it (``NlpRefiner._tighten``'s rule for the checkpoints), at least MIN_BOUND_FACTOR."""
    if not s_pts.size:
        return
    names = [k for k in ("control_signal", "servo_error", "sampled_control_signal", "sampled_servo_error",
                         "acceleration", "jerk", "sampled_acceleration", "sampled_jerk") if k in util]
    if not names:
        return
    r = _worst_util(util, names)
    bad = np.flatnonzero(r > 1.0 + VERIFY_TOL)
    if not bad.size:
        return
    near = np.abs(s_pts[:, None] - fine[None, bad]) <= h  # (P, B)
    if not near.any():
        return
    worst = np.max(np.where(near, r[None, bad], 1.0), axis=1)
    hit = worst > 1.0 + VERIFY_TOL
    fac[hit] = np.maximum(MIN_BOUND_FACTOR, fac[hit] * _tighten_scale(worst[hit]))


def _exact_layout(with_aj: bool) -> tuple[int, tuple[int, ...]]:
    """(rows per axis of ``_Shape._axis_rows_t``, the ones ``_exact_rows`` keeps: u, e_hi, [a, j_hi])."""
    return (6, (0, 1, 3, 4)) if with_aj else (3, (0, 1))


def _exact_rows(rows: list[Any], with_aj: bool) -> list[Any]:
    """``_Shape._axis_rows_t``'s rows at a point with one x_sss (no envelope: e_hi = e_lo, j_hi = j_lo) without
    the duplicates: per axis u, e, [a, j].  (Two equal rows make Ipopt's KKT matrix rank-deficient: a rest
    window's solve took twice as long with them.)"""
    per_axis, keep = _exact_layout(with_aj)
    return [r for i, r in enumerate(rows) if i % per_axis in keep]


def _exact_bounds(lo: FloatArray, hi: FloatArray, with_aj: bool) -> tuple[FloatArray, FloatArray]:
    """``_point_bounds``' (lo, hi) for ``_exact_rows``: e's bounds from e_hi's upper and e_lo's lower, j's alike."""
    per_axis, keep = _exact_layout(with_aj)
    row = np.arange(lo.shape[0]) % per_axis
    return (lo[np.isin(row, (0, 2, 3, 5) if with_aj else (0, 2))], hi[np.isin(row, keep)])


def _point_bounds(
    lim: NlpLimits, moving: tuple[int, ...], d1: FloatArray, bu: FloatArray, be: FloatArray, bk: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Row bounds (scaled units) at points with the path's exact derivatives (a cut slot, a rest point), each
    (rows, P): per moving axis u, e_hi, e_lo, [a, j_hi, j_lo] (``_Shape._axis_rows_t``'s order).  ``d1``: x_s
    (P, 3), for the friction's sign (both signs where |x_s| < SIGN_EPS); ``bu``, ``be`` (P, na): the u and e
    bound factors; ``bk`` (P,): the a and j rows'."""
    per_axis = 6 if lim.amax is not None else 3
    lo = np.full((len(moving) * per_axis, d1.shape[0]), -np.inf)
    hi = np.full_like(lo, np.inf)
    for i, ax in enumerate(moving):
        xs = d1[:, ax]
        unsure = np.abs(xs) < SIGN_EPS
        sg_hi = np.where(unsure, 1.0, np.sign(xs))
        sg_lo = np.where(unsure, -1.0, np.sign(xs))
        um, c, dd = lim.umax[ax], lim.c[ax], lim.d[ax]
        r = i * per_axis
        lo[r] = (-um * bu[:, i] - c - dd * sg_lo) / um
        hi[r] = (um * bu[:, i] - c - dd * sg_hi) / um
        hi[r + 1] = be[:, i]
        lo[r + 2] = -be[:, i]
        if per_axis == 6:
            lo[r + 3], hi[r + 3] = -bk, bk
            hi[r + 4] = bk
            lo[r + 5] = -bk
    return lo, hi


@dataclass
class _LpSideCaps:
    """Feed caps at curvature jumps whose checkpoints sit next to a state taken from the LP (a chain's
    start, a join to the LP at its end), deferred until the verification finds the step there over its
    limit.

    Those checkpoints' feed rows admit the LP's own feed (next to its state) and carry no step cap (without
    a drive vmax or Fmax they are unbounded), so nothing in the NLP held the step at such a break: the
    e rows and a cut slot do not see the step term.  Bench seed 2053 (lp+nlp): a curvature
    jump 0.9 of a knot interval into the piece's first NLP window, passed at 1.27 x the LP's feed (the
    sampled step's servo error 1.76 x emax) through all cut rounds; the window, the whole piece, fell back
    to the LP's feed.  The cap is max(f_cap, the LP's feed at the checkpoint): the LP's feed stays
    admissible, and the tightening of the feed rows acts on it.  Windows whose steps there hold keep
    their rows (their results are unchanged)."""

    #: piece-local s of each break (B,), its checkpoints (B, 2) (kc, kc + 1), which of them are next to
    #: the LP's state (B, 2), the cap at each (B, 2) mm/s, and whether it was added (B, 2)
    br: FloatArray
    idx: NDArray[np.int64]
    lp: NDArray[np.bool_]
    cap: FloatArray
    added: NDArray[np.bool_]

    @staticmethod
    def empty() -> _LpSideCaps:
        z = np.zeros((0, 2), dtype=bool)
        return _LpSideCaps(np.zeros(0), np.zeros((0, 2), dtype=np.int64), z, np.zeros((0, 2)), z.copy())

    @staticmethod
    def at(
        br: FloatArray, f_cap: FloatArray, kc: NDArray[np.int64], near_lp: NDArray[np.bool_], f_lp: FloatArray
    ) -> _LpSideCaps:
        """Breaks ``br`` with caps ``f_cap`` (B,) held at checkpoints kc, kc + 1; ``near_lp`` and the LP's
        feed ``f_lp`` (K,) at the window's checkpoints."""
        idx = kc[:, None] + np.arange(2)[None, :]
        cap = np.maximum(f_cap[:, None], f_lp[idx] * (1.0 + 1e-9))
        return _LpSideCaps(br, idx, near_lp[idx], cap, np.zeros(idx.shape, dtype=bool))

    def add_violated(self, fine: FloatArray, util: dict[str, FloatArray], feed_ub: FloatArray) -> NDArray[np.int64]:
        """Add (into ``feed_ub``) the deferred caps of the breaks whose ``util["step"]`` is over
        1 + VERIFY_TOL; returns the checkpoints whose cap was added now."""
        pending = self.lp & ~self.added
        if not pending.any() or "step" not in util:
            return np.zeros(0, dtype=np.int64)
        at = _find(fine, self.br + BREAK_EPS_MM)
        over = np.zeros(self.br.size, dtype=bool)
        over[at >= 0] = util["step"][at[at >= 0]] > 1.0 + VERIFY_TOL
        new = pending & over[:, None]
        np.minimum.at(feed_ub, self.idx[new], self.cap[new])
        self.added |= new
        return np.unique(self.idx[new])


def _moving_axes(g: PathSamples) -> tuple[int, ...]:
    """The axes that move along these points (``lp.axis_moves``: an NLP shape has rows for these only)."""
    return tuple(ax for ax in range(3) if axis_moves(g, ax))


def _find(sorted_s: FloatArray, s: FloatArray) -> NDArray[np.int64]:
    """Index of each s in sorted_s (exact match), -1 where absent."""
    i = np.minimum(np.searchsorted(sorted_s, s), sorted_s.size - 1)
    return np.where(sorted_s[i] == s, i, -1).astype(np.int64)


def _merge(fine: FloatArray, g: PathSamples, s_new: FloatArray, g_new: PathSamples) -> tuple[FloatArray, PathSamples]:
    """Verification points and their geometry with new points added, sorted by s."""
    order = np.argsort(np.concatenate([fine, s_new]), kind="stable")
    return np.concatenate([fine, s_new])[order], g.concat(g_new).subset(order)


def _refine_turns(geometry: GeometryFn, fine: FloatArray, g: PathSamples) -> tuple[FloatArray, PathSamples]:
    """Bisect fine-grid cells where the tangent turns by more than REFINE_TURN (REFINE_LEVELS times at most)."""
    for _ in range(REFINE_LEVELS):
        width = np.diff(fine)
        turn = np.linalg.norm(np.diff(g.d1, axis=0), axis=1)
        cells = (turn > REFINE_TURN) & (width > 4 * BREAK_EPS_MM)
        if not cells.any() or fine.size + int(cells.sum()) > REFINE_MAX_POINTS:
            break
        mids = 0.5 * (fine[:-1] + fine[1:])[cells]
        fine, g = _merge(fine, g, mids, geometry(mids))
    return fine, g


def _fast_cells(fine: FloatArray, util: dict[str, FloatArray]) -> FloatArray:
    """Midpoints of fine-grid cells across which some utilisation changes by more than REFINE_UTIL."""
    jump = np.zeros(fine.size - 1)
    for name, u in util.items():
        if name == "step" or name.startswith("sampled_"):
            continue
        du = np.abs(np.diff(u, axis=0))
        np.maximum(jump, du if du.ndim == 1 else kinematics.row_max(du), out=jump)
    cells = (jump > REFINE_UTIL) & (np.diff(fine) > 4 * BREAK_EPS_MM)
    return np.asarray(0.5 * (fine[:-1] + fine[1:])[cells], dtype=np.float64)


def _friction_signs(d1: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Friction sign used in the upper and lower control-signal bounds at each checkpoint, (K, 3).

    sign(x_s) where the axis moves one way around the checkpoint; +1 (upper)
    and -1 (lower) where |x_s| < SIGN_EPS or the sign differs at a neighbour.
    """
    sg = np.sign(d1)
    unsure = np.abs(d1) < SIGN_EPS
    unsure[1:] |= sg[1:] != sg[:-1]
    unsure[:-1] |= sg[:-1] != sg[1:]
    hi = np.where(unsure, 1.0, sg)
    lo = np.where(unsure, -1.0, sg)
    return hi, lo


def _envelope_points(k_loc: NDArray[np.int64], tau: FloatArray, a: int, d: float, N: int) -> FloatArray:
    """Piece-local s (K, 2 ENVELOPE_SUBDIV + 1) spanning each checkpoint's cell (``_third_derivative_envelope``)."""
    h = 0.5 / N
    lo = np.clip(tau - h, 0.0, 1.0)
    hi = np.clip(tau + h, 0.0, 1.0)
    frac = np.linspace(0.0, 1.0, 2 * ENVELOPE_SUBDIV + 1)
    return np.asarray((a + k_loc[:, None] + lo[:, None] + (hi - lo)[:, None] * frac[None, :]) * d, dtype=np.float64)


@dataclass(frozen=True)
class _ContextMotion:
    """Axis motion just outside a window, in the window's time (t = 0 at its first fine point, s):
    ``left_*`` before it (t < 0), ``right_*`` after its last fine point (``right_t`` from that point's time
    on: added to the window's own duration).  v, acc: (K, 3) mm/s, mm/s^2."""

    left_t: FloatArray
    left_v: FloatArray
    left_acc: FloatArray
    right_t: FloatArray
    right_v: FloatArray
    right_acc: FloatArray

    @property
    def left_size(self) -> int:
        return int(self.left_t.size)

    def joined(self, t: FloatArray, v: FloatArray, acc: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The window's (t, v, acc) with the context before and after it."""
        return (
            np.concatenate([self.left_t, t, t[-1] + self.right_t]),
            np.concatenate([self.left_v, v, self.right_v]),
            np.concatenate([self.left_acc, acc, self.right_acc]),
        )


#: Axis motion over a time grid: t (K,) s, v and a (K, 3) mm/s, mm/s^2 (``NlpRefiner.lead_in``).
Motion = tuple[FloatArray, FloatArray, FloatArray]
#: The piece's feed as a sample repair round's round before solved it (``NlpRefiner.outer``).
_Outer = PieceProfile
#: A sample repair round's chain part joins the chains either side as the round before solved them, not the LP's
#: feed: the sampled check of a part's first and last window reads the motion beyond its ends from
#: ``NlpRefiner.outer`` where the part's end state is the round before's to this relative tolerance (f, f' d).
#: Why: chains are solved independently from the LP's states at their joins, each reading the LP's feed beyond its
#: ends, so the differences across a join read two NLP feeds neither chain saw: bench seed 18692 (session 72, on
#: 128-interval rest plans) read e_x 1.0135 x emax 2.7 mm past a join, where each chain's check read 0.996 / 0.999,
#: and no repair round moved it (the verified points added there read under the limit with the LP's feed beside).
OUTER_JOIN_TOL = 1e-6


@dataclass(frozen=True)
class _OuterSides:
    """``NlpRefiner.outer``'s feed (piece-local s -> (f, f', f'')) read by ``_Context`` below ``lo`` and above
    ``hi`` (mm; -inf / inf: not on that side), and an upper bound of it (mm/s) for ``_context_span``."""

    feed: Callable[[FloatArray], kinematics.FeedDerivs]
    lo: float
    hi: float
    f_hi: float


def _standing(ctx: _ContextMotion | None, head: bool, tail: bool, Ts: float, lead_in: Motion | None = None
              ) -> _ContextMotion:
    """``ctx`` with the machine standing at rest before a window from the piece's start (``head``) and
    after one to its end (``tail``): CONTEXT_SAMPLES sample periods of v = a = 0; before the piece, the
    previous piece's motion up to the corner instead where it is given (``lead_in``: t < 0 from the corner).
    At a corner the samples see both pieces' rest accelerations, a step a_out - a_in, and the previous piece's
    jerk beside it: bench seed 5844 (14 samples a piece) read 1.10 x emax across a rest that the check of
    either piece alone, with the machine standing beyond the corner, held within the limit."""
    t = (CONTEXT_STEP * Ts) * np.arange(1, math.ceil(CONTEXT_SAMPLES / CONTEXT_STEP) + 1, dtype=np.float64)
    zero = np.zeros((t.size, 3))
    empty_t, empty = np.zeros(0), np.zeros((0, 3))
    lt, lv, la = (ctx.left_t, ctx.left_v, ctx.left_acc) if ctx is not None else (empty_t, empty, empty)
    rt, rv, ra = (ctx.right_t, ctx.right_v, ctx.right_acc) if ctx is not None else (empty_t, empty, empty)
    if head:
        lt, lv, la = (-t[::-1], zero, zero) if lead_in is None else lead_in
    if tail:
        rt, rv, ra = t, zero, zero
    return _ContextMotion(lt, lv, la, rt, rv, ra)


@dataclass(frozen=True)
class _Context:
    r"""The feed just outside an NLP window, fixed while the window is solved (piece-local s, mm).

    Before the window: the chain's committed NLP feed f = sum p_k B_k(s) on knot intervals [A, a),
    and the LP's f = sqrt(q) before A; after it (only where the window joins the LP state at its
    end): the LP's feed.  Each side is a grid from the window's end outward covering
    ``CONTEXT_SAMPLES`` sample periods of motion, t = integral ds / f (trapezoid, from the window's
    end), or up to the piece's end (rest: f -> 0 there, and the grid stops where the time is covered).
    Points in increasing s on both sides; ``left_t`` < 0 (before the window), ``right_t`` > 0 (after
    its last verified point); fd: (f, f', f'') in time, as ``kinematics.from_q``."""

    left_s: FloatArray
    left_t: FloatArray
    left_fd: kinematics.FeedDerivs
    right_s: FloatArray
    right_t: FloatArray
    right_fd: kinematics.FeedDerivs

    @staticmethod
    def around(
        c: FloatArray, d: float, s_a: float, s_b: float | None, left: _Left | None,
        Ts: float | None, c_final: int | None = None, outer: _OuterSides | None = None,
    ) -> _Context:
        """``c``: the LP's q control points over the piece; ``s_a``: the window's first s; ``s_b``: its
        last verified s if the LP's feed follows it (None: nothing after it); ``left``: (A, p_A .. p_{a+1}, rise);
        ``c_final``: how many leading entries of c are final (default all: ``_context_span``); ``outer``: the feed
        read instead of the LP's below ``outer.lo`` and above ``outer.hi`` (``NlpRefiner._outer_sides``)."""
        empty: kinematics.FeedDerivs = (np.zeros(0), np.zeros(0), np.zeros(0))
        none = (np.zeros(0), np.zeros(0), empty)
        if Ts is None:
            return _Context(*none, *none)
        length = (c.size - 2) * d
        rest: FloatArray | None = None
        rise: Rise = ()
        if left is not None and left[0] == 0:
            # the chain solved the rest interval: its q (``_rest_feed``), and f from knot 1 on
            rest = left[1][:3].copy()
            rise = left[2]
            c = c.copy()
            c[:3] = rest_cps(float(rest[1]), float(rest[2]), d, True)
            left = (1, left[1][1:], ())

        def feed(s: FloatArray) -> kinematics.FeedDerivs:
            f, f1, f2 = kinematics.from_q(*bspline.evaluate(c, s, d))
            if rest is not None and (rest[0] != 0.0 or any(rise)):
                on = s < d
                if on.any():
                    f, f1, f2 = f.copy(), f1.copy(), f2.copy()
                    f[on], f1[on], f2[on] = _rest_feed(float(rest[0]), float(rest[1]), float(rest[2]), s[on], d, 0,
                                                       True, rise)
            if outer is not None:
                out = (s < outer.lo) | (s > outer.hi)
                if out.any():
                    fo = outer.feed(s[out])
                    f, f1, f2 = f.copy(), f1.copy(), f2.copy()
                    f[out], f1[out], f2[out] = fo
            if left is not None:
                A, p, _ = left
                nlp = (s >= A * d) & (s <= s_a)
                if nlp.any():
                    a = A + p.size - 2
                    fn = kinematics.from_f(*bspline.evaluate(p, s[nlp], d, k_lo=A, k_hi=a - 1, col0=A))
                    f, f1, f2 = f.copy(), f1.copy(), f2.copy()
                    f[nlp], f1[nlp], f2[nlp] = fn
            return f, f1, f2

        def side(edge: float, far: float) -> tuple[FloatArray, FloatArray, kinematics.FeedDerivs]:
            need = CONTEXT_SAMPLES * Ts
            # the feed is at most the largest control point around (convex hull): the s the time needs
            f_left = float(np.max(left[1])) if left is not None else 0.0
            if outer is not None and (min(edge, far) < outer.lo or max(edge, far) > outer.hi):
                f_left = max(f_left, outer.f_hi)
            span = _context_span(c, d, edge, far, need, f_left, c_final)
            if span <= 0.0:
                return none
            s = edge + np.sign(far - edge) * np.linspace(0.0, span, CONTEXT_POINTS + 1)
            # midpoint rule: f = 0 at the piece's end (rest) is a point of the grid, not of the rule
            f_mid = feed(0.5 * (s[:-1] + s[1:]))[0]
            t = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(s)) / np.maximum(f_mid, 1e-300))])
            # points about CONTEXT_STEP apart in time up to the first one past the time needed (the
            # edge itself is the window's)
            m = min(s.size, int(np.searchsorted(t, need, side="right")) + 1)
            step = CONTEXT_STEP * Ts
            keep = np.unique(np.minimum(np.searchsorted(t[:m], np.arange(step, t[m - 1] + step, step)), m - 1))
            keep = keep[keep > 0]
            s_k, t_k = s[keep], t[keep]
            fd = feed(s_k)
            if m == s.size and span == abs(far - edge) and t[-1] < need:
                # the piece's end reached in less time: at rest after it, up to the time needed
                s_k = np.concatenate([s_k, [s[-1], s[-1]]])
                t_k = np.concatenate([t_k, [t[-1] + 1e-9 * Ts, need]])
                fd = (np.concatenate([fd[0], [0.0, 0.0]]), np.concatenate([fd[1], [0.0, 0.0]]),
                      np.concatenate([fd[2], [0.0, 0.0]]))
            if far < edge:
                return s_k[::-1], -t_k[::-1], (fd[0][::-1], fd[1][::-1], fd[2][::-1])
            return s_k, t_k, fd

        lft = side(s_a, 0.0)
        rgt = side(s_b, length) if s_b is not None else none
        return _Context(*lft, *rgt)

    def points(self) -> FloatArray:
        return np.concatenate([self.left_s, self.right_s])

    def motion(self, geometry: GeometryFn) -> _ContextMotion | None:
        """Axis v and acc at the context's points, with their times (None when there is no context)."""
        if not self.left_s.size and not self.right_s.size:
            return None

        def axis(s: FloatArray, fd: kinematics.FeedDerivs) -> tuple[FloatArray, FloatArray]:
            if not s.size:
                return np.zeros((0, 3)), np.zeros((0, 3))
            v, acc, _ = kinematics.axis_kinematics(geometry(s), *fd)
            return v, acc

        return _ContextMotion(self.left_t, *axis(self.left_s, self.left_fd),
                              self.right_t, *axis(self.right_s, self.right_fd))


class LpNotFinal(Exception):
    """A chain read LP control points past those final when it was handed out (``ChainPipeline``)."""


def _context_span(
    c: FloatArray, d: float, edge: float, far: float, need: float, f_floor: float, c_final: int | None
) -> float:
    """How far (mm) from ``edge`` towards ``far`` the feed takes at least ``need`` seconds, bounded from the
    LP's control points around: span = min(|far - edge|, need f_hi), with f_hi = max(f_floor, sqrt(max c_k))
    over the knot intervals the span covers (q on interval k is at most max(c_k, c_k+1, c_k+2)), grown
    until it covers itself.

    Local, so a chain reads only the LP's control points near it (until session 9 f_hi was the whole
    piece's largest: a chain's context then depended on every LP window of the piece).  Raises
    ``LpNotFinal`` if the span needs c beyond its first ``c_final`` entries."""
    n_int = c.size - 2
    room = abs(far - edge)
    direction = 1.0 if far >= edge else -1.0
    span = 0.0
    while True:
        lo_s, hi_s = sorted((edge, edge + direction * span))
        k_lo = min(max(math.floor(lo_s / d), 0), n_int - 1)
        k_hi = min(max(math.floor(hi_s / d), 0), n_int - 1)
        if c_final is not None and k_hi + 3 > c_final:
            raise LpNotFinal(f"context to s = {hi_s:.6g} reads c[{k_hi + 2}], final up to c[{c_final - 1}]")
        f_hi = max(f_floor, math.sqrt(max(float(np.max(c[k_lo : k_hi + 3])), 0.0)))
        grown = min(room, need * f_hi)
        if grown <= span:
            return span
        span = grown


class _Prefetched:
    """A geometry evaluated once at given points: a call at those exact points is served from them,
    other points are evaluated (the same values: the geometry is evaluated point by point)."""

    def __init__(self, geometry: GeometryFn, s: FloatArray) -> None:
        self.geometry = geometry
        self.s = np.unique(s)
        self.g = geometry(self.s)

    def __call__(self, s: FloatArray) -> PathSamples:
        s = np.asarray(s, dtype=np.float64)
        i = np.minimum(np.searchsorted(self.s, s), self.s.size - 1)
        hit = self.s[i] == s
        if hit.all():
            return self.g.subset(i)
        if not hit.any():
            return self.geometry(s)
        where = np.concatenate([np.flatnonzero(hit), np.flatnonzero(~hit)])
        both = self.g.subset(i[hit]).concat(self.geometry(s[~hit]))
        return both.subset(np.argsort(where, kind="stable"))


def _third_derivative_envelope(
    geometry: GeometryFn,
    g: PathSamples,
    k_loc: NDArray[np.int64],
    tau: FloatArray,
    a: int,
    d: float,
    N: int,
    breaks: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Largest and smallest x_sss (K, 3) over each checkpoint's cell.

    The cell of a checkpoint at tau is [tau - 1/(2N), tau + 1/(2N)] clipped to its
    knot interval; x_sss is sampled at ENVELOPE_SUBDIV points on each side and on
    both sides of every geometry knot inside the cell.
    """
    sub = _envelope_points(k_loc, tau, a, d, N)
    gs = geometry(sub.ravel())
    d3 = gs.d3.reshape(sub.shape[0], sub.shape[1], 3)
    top = np.maximum(np.max(d3, axis=1), g.d3)
    bot = np.minimum(np.min(d3, axis=1), g.d3)
    s_lo, s_hi = sub[:, 0], sub[:, -1]
    br = breaks[(breaks > s_lo[0]) & (breaks < s_hi[-1])]
    if br.size:
        gb = geometry(np.concatenate([br - BREAK_EPS_MM, br + BREAK_EPS_MM]))
        d3b = gb.d3.reshape(2, br.size, 3)
        # cells containing each break (a break lies in at most a few cells)
        i0 = np.searchsorted(s_hi, br, side="left")
        i1 = np.searchsorted(s_lo, br, side="right")
        for side in range(2):
            for off in range(int(np.max(i1 - i0, initial=0)) + 1):
                idx = i0 + off
                ok = idx < i1
                if not ok.any():
                    continue
                ii = idx[ok]
                np.maximum.at(top, ii, d3b[side][ok])
                np.minimum.at(bot, ii, d3b[side][ok])
    return top, bot


# ----- chains in forked workers ------------------------------------------------------
def _die_with_parent() -> None:
    """Pool initializer: the worker gets SIGKILL when its parent dies (Linux), so a killed job leaves no solver."""
    try:
        import ctypes
        import signal

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _merge_stats(into: NlpStats, st: NlpStats) -> None:
    """Add a worker's counters (one chain's) to ``into``; its window indices continue ``into``'s."""
    base = into.windows
    into.windows += st.windows
    into.iterations += st.iterations
    into.cut_rounds += st.cut_rounds
    into.softer_retries += st.softer_retries
    into.warm_resolves += st.warm_resolves
    into.resolve_iterations += st.resolve_iterations
    into.warm_first += st.warm_first
    into.safe_retries += st.safe_retries
    into.handover_scaled += st.handover_scaled
    into.handover_unscaled += st.handover_unscaled
    into.lp_kept_chains += st.lp_kept_chains
    into.lp_kept_spans += st.lp_kept_spans
    into.lp_kept_intervals += st.lp_kept_intervals
    into.slower_kept += st.slower_kept
    into.rest_retries += st.rest_retries
    into.rest_rises_capped += st.rest_rises_capped
    into.ipm_iterations += st.ipm_iterations
    into.ipm_handed += st.ipm_handed
    into.ipm_infeasible += st.ipm_infeasible
    into.worst_verified = max(into.worst_verified, st.worst_verified)
    into.window_times.extend(st.window_times)
    into.failures.extend({**f, "nlp_window": base + f["nlp_window"]} for f in st.failures)


# ----- chains while the LP still runs (fork) ----------------------------------------
#: What a pool worker solves a piece's chains with, from the piece's key (``ChainPool``): (refiner, geometry).
PieceContext = Callable[[Any], tuple[NlpRefiner, GeometryFn]]
#: A pool worker's context function, set by its initializer (``_pool_worker``).
_POOL_CONTEXT: PieceContext | None = None
#: A pool worker's contexts of the pieces it solved chains of, the last POOL_WORKER_PIECES of them.
_WORKER_PIECES: OrderedDict[Any, tuple[NlpRefiner, GeometryFn]] = OrderedDict()
POOL_WORKER_PIECES = 2
#: (key, A, B, c, c_final, d, breaks, bump, lead_in, verify, whole, outer): a chain of the piece ``key`` and the LP's
#: control points as handed out (NaN from c_final on; None: all final), with the piece's knot spacing, breaks, rest
#: ends and verified points (``NlpRefiner.refine``'s); ``whole``: solve [A, B) as it is (``refine``'s chains), not
#: split into the LP's kept and solved parts first (``ChainPipeline``'s); ``outer``: ``NlpRefiner.outer``
_PipeTask = tuple[Any, int, int, FloatArray, "int | None", float, FloatArray, tuple[bool, bool], "Motion | None",
                  FloatArray, bool, "_Outer | None"]


def _pool_worker(context: PieceContext) -> None:
    """Pool initializer: the worker reads pieces through ``context`` (inherited by the fork, not pickled)."""
    global _POOL_CONTEXT
    _POOL_CONTEXT = context
    _WORKER_PIECES.clear()
    _die_with_parent()


def _pipe_task(task: _PipeTask) -> tuple[bool | None, list[Span], NlpStats]:
    """One chain in a pool worker: (kept, spans, counters); kept None if it read LP control points
    that were not final yet (``LpNotFinal``: solved again once the LP is done)."""
    if _POOL_CONTEXT is None:  # pragma: no cover - set by the pool's initializer
        raise RuntimeError("NLP pool worker started without its context")
    key, A, B, c, c_final, d, breaks, bump, lead_in, verify, whole, outer = task
    if key not in _WORKER_PIECES:
        _WORKER_PIECES[key] = _POOL_CONTEXT(key)
        while len(_WORKER_PIECES) > POOL_WORKER_PIECES:
            _WORKER_PIECES.popitem(last=False)
    refiner, geometry = _WORKER_PIECES[key]
    refiner.stats = NlpStats()
    refiner.verify, refiner.bump, refiner.lead_in, refiner.outer = verify, bump, lead_in, outer
    refiner.c_final = c_final
    try:
        if whole:
            return False, refiner._spans(geometry, c, d, A, B, breaks), refiner.stats
        parts = refiner._chain_parts(geometry, c, d, A, B, breaks)
        spans = [sp for a, b, k in parts if not k for sp in refiner._spans(geometry, c, d, a, b, breaks)]
        return all(k for _, _, k in parts), spans, refiner.stats
    except LpNotFinal:
        return None, [], NlpStats()
    finally:
        refiner.c_final = None


class ChainPool:
    """Forked workers that solve the NLP chains of every piece of one schedule: those handed out while the LP runs
    (``ChainPipeline``) and those of ``NlpRefiner.refine`` after it (``spans``).

    The pool forks at the first chain handed out.  It forks again when this process has built an NLP shape since
    (``_SHAPE_BUILDS``: the workers would each build it themselves) and no chain is running, or after a piece
    abandoned chains still running (``ChainPipeline.close``); ``close`` stops it at the schedule's end.  A worker
    reads a piece's refiner and geometry through ``context(key)``, inherited by the fork; a task carries the rest
    (``_PipeTask``).  Until session 56 each piece forked a pool of its own (and ``refine`` another): ~13 ms to
    start and ~7.5 ms to stop, so on the router's pocket at F1800 (40 pieces, lp+nlp) 2 workers took 3.7 s of
    wall against 2.6-3.0 s on 1."""

    def __init__(self, workers: int, context: PieceContext) -> None:
        self.workers, self.context = workers, context
        self.pool: Any = None
        self.builds = -1  # _SHAPE_BUILDS when the pool forked
        self.pending: list[Any] = []  # the AsyncResults not known to be ready

    def submit(self, task: _PipeTask) -> Any:
        """The chain's ``AsyncResult`` of (kept, spans, counters) (``_pipe_task``)."""
        self.pending = [res for res in self.pending if not res.ready()]
        if self.pool is not None and self.builds != _SHAPE_BUILDS and not self.pending:
            self.close()  # (with chains still running the workers keep on, building the new shape themselves)
        if self.pool is None:
            import multiprocessing

            self.pool = multiprocessing.get_context("fork").Pool(
                self.workers, initializer=_pool_worker, initargs=(self.context,))
            self.builds = _SHAPE_BUILDS
        res = self.pool.apply_async(_pipe_task, (task,))
        self.pending.append(res)
        return res

    def spans(
        self, key: Any, refiner: NlpRefiner, geometry: GeometryFn, c: FloatArray, d: float, breaks: FloatArray,
        chains: list[tuple[int, int]],
    ) -> Iterator[list[Span]]:
        """``refiner._spans`` of each chain over the final c, in order, solved by the workers (``refine``: its
        ``verify``, ``bump`` and ``lead_in`` as set); their counters are merged into ``refiner.stats``."""
        refiner.prebuild(geometry, d, *chains[0], c.size - 2)
        sent = [self.submit((key, A, B, c, None, d, breaks, refiner.bump, refiner.lead_in, refiner.verify, True,
                             refiner.outer))
                for A, B in chains]
        for res in sent:
            _, spans, st = res.get()
            _merge_stats(refiner.stats, st)
            yield spans

    def close(self) -> None:
        """Stop the workers (the schedule's end; the next ``submit`` forks again)."""
        if self.pool is not None:
            self.pool.terminate()
            self.pool.join()
            self.pool = None
            self.pending = []


class ChainPipeline:
    r"""The NLP chains of one piece solved by a schedule's forked workers (``ChainPool``) while the LP still solves
    its later windows.

    With LP window joins J_0 < J_1 < ..., chain i runs from J_{i-1} to J_i (from knot 1, to knot n_int - 1
    at the ends, as ``NlpRefiner.refine``).  When the LP window after the one that set J_i is solved,
    c_0 .. c_{J_{i+1} - 1} are final (the window after it rewrites only c_{J_{i+1}} on), and chain i reads
    c only around its own knots (its LP states, its windows' hand-over, and the context of
    ``_context_span``): so it is handed out then, with c_{J_{i+1}} on set to NaN.  A chain whose context
    reaches past that (``LpNotFinal``), or whose c as handed out differs from the piece's final c, is
    solved again with the final c: the result is always the one ``refine`` gives on the final c.

    Against ``refine(workers=...)`` after the whole LP: the same feed bit for bit; the LP's windows and
    the NLP's chains share the cores instead of running one after the other (18.35 m path, 4.63 mm
    knots, 2 workers: the LP stage is 1.3 s of ~7 s).
    """

    def __init__(self, refiner: NlpRefiner, geometry: GeometryFn, d: float, n_int: int, breaks: FloatArray,
                 pool: ChainPool, key: Any, bump: tuple[bool, bool] = (True, True),
                 lead_in: Motion | None = None) -> None:
        """``pool``: the schedule's workers; ``key``: the piece's, for ``pool.context`` (which gives ``refiner``
        and ``geometry`` in a worker); ``bump``, ``lead_in``: as ``NlpRefiner.refine``'s."""
        self.refiner, self.geometry, self.d, self.n_int, self.breaks = refiner, geometry, d, n_int, breaks
        self.pool, self.key, self.bump, self.lead_in = pool, key, bump, lead_in
        self.sent: list[tuple[tuple[int, int, FloatArray, int], Any]] = []

    def chains(self, joins: list[int]) -> list[tuple[int, int]]:
        """The chains of ``refine`` for these joins."""
        return chain_spans(self.n_int, joins)

    def lp_progress(self, c: FloatArray, joins: list[int], done: bool = False) -> None:
        """After each LP window: the piece's c as far as solved, the joins so far, and whether the LP is done.
        Hands out every chain whose LP control points are now final."""
        if done:
            ready, c_final = self.chains(joins), c.size
        else:
            if len(joins) < 2:
                return
            c_final = joins[-1]
            ready = [ch for ch in self.chains(joins[:-1]) if ch[1] <= joins[-2]]
        for A, B in ready[len(self.sent):]:
            task_c = c.copy()
            task_c[c_final:] = np.nan
            task = (A, B, task_c, c_final)
            self.sent.append((task, self._submit(task)))

    def _submit(self, task: tuple[int, int, FloatArray, int]) -> Any:
        """Hand a chain (A, B, c, c_final) to the pool."""
        A, B, c, c_final = task
        if not self.sent:  # (the piece's first chain: its shapes built here, before the pool forks with them)
            self.refiner.prebuild(self.geometry, self.d, A, B, self.n_int)
        return self.pool.submit((self.key, A, B, c, c_final, self.d, self.breaks, self.bump, self.lead_in,
                                 np.zeros(0), False, None))

    def finish(
        self, c: FloatArray, joins: list[int], on_chain: Callable[[float], None] | None = None
    ) -> tuple[FloatArray, NDArray[np.bool_], tuple[Rise, Rise]]:
        """``refine``'s (p, mask, rise) on the piece's final c and joins, from the chains handed out (the rest
        handed out now)."""
        sent = [(A, B) for (A, B, _, _), _ in self.sent]
        if not sent or sent != self.chains(joins)[: len(sent)]:
            # nothing handed out (the LP was one window), or not the chains the LP ended with: as after the LP
            self.close()
            return self.refiner.refine(self.geometry, c, self.d, joins, self.breaks, on_chain, (self.pool, self.key),
                                       bump=self.bump, lead_in=self.lead_in)
        self.lp_progress(c, joins, True)
        p = np.zeros(self.n_int + 2)
        mask = np.zeros(self.n_int, dtype=bool)
        rise: list[Rise] = [(), ()]
        for (A, B, task_c, c_final), res in self.sent:
            kept, spans, st = res.get()
            if kept is None or not np.array_equal(task_c[:c_final], c[:c_final]):
                kept, spans, st = self._submit((A, B, c.copy(), c.size)).get()
            if kept is None:  # pragma: no cover - the final c is final everywhere
                raise RuntimeError("an NLP chain read LP control points past the piece")
            _merge_stats(self.refiner.stats, st)
            _place(spans, p, mask, rise)
            if on_chain is not None:
                on_chain(B * self.d)
        return p, mask, (rise[0], rise[1])

    def close(self) -> None:
        """Done with the piece: if chains it handed out still run (the piece abandoned), stop the workers."""
        if any(not res.ready() for _, res in self.sent):
            self.pool.close()


#: Neighbouring fine points closer than this (mm) straddle a break (``NlpRefiner._fine_points``: b - eps, b, b + eps).
STEP_PAIR_MM = 4.0 * BREAK_EPS_MM
#: A velocity change across such a pair beyond its smooth part over this share of the largest axis speed is a step.
STEP_MIN_SHARE = 1e-6


@dataclass(frozen=True)
class _Probes:
    """The sampled means of one axis at instants next to velocity steps (``_impulse_probes``), each (P,): the grid
    point nearest each instant, the box mean of v (mm/s), the hat mean of a (mm/s^2), the drive model's central
    jerk (the mean of two third differences) and the plain third difference (mm/s^3)."""

    index: NDArray[np.int64]
    vm: FloatArray
    am: FloatArray
    jm: FloatArray
    jp: FloatArray


def _impulse_probes(
    tu: FloatArray, vm: FloatArray, am_motion: FloatArray, steps: list[tuple[float, FloatArray]], axis: int,
    Ts: float, M: int,
) -> _Probes:
    r"""The sampled means of axis ``axis`` (``NlpRefiner._sampled``) at the instants where the velocity steps'
    impulses peak, exactly rather than on the uniform grid ``tu`` (step h = Ts / M).

    A step dv at t_b adds dv H(t - t_b) to the hat mean of a (the second difference centred at t), with
    H(x) = max(0, Ts - |x|) / Ts^2, dv (H(t + Ts - t_b) - H(t - Ts - t_b)) / (2 Ts) to the central jerk and
    dv (H(t + Ts/2 - t_b) - H(t - Ts/2 - t_b)) / Ts to the plain third difference: each piecewise linear in t,
    with its kinks (so the extremes of e, u, a and j where the impulse dominates) at t_b + k Ts / 2, k = -4 .. 4.
    On the grid a kink between two points read down to 1 - h / Ts of the plain jerk's peak (0.875 x at M = 8)
    and ~0.95 x of the servo error's.  At each such instant the motion's part is interpolated from the grid
    (``vm``; ``am_motion``, the hat mean of a without the steps, and the differences of it) and every step's
    part added exactly; each goes to the grid point nearest its instant."""
    tb = np.array([t_b for t_b, _ in steps])
    dv = np.array([d[axis] for _, d in steps])
    h = float(tu[1] - tu[0])
    half = M // 2
    at = (tb[:, None] + 0.5 * Ts * np.arange(-4, 5)[None, :]).ravel()

    def hat_sum(x: FloatArray) -> FloatArray:
        w = np.maximum(0.0, Ts - np.abs(x[:, None] - tb[None, :]))
        return np.asarray(w @ dv / Ts**2, dtype=np.float64)

    jm_motion = np.zeros(tu.size)
    jm_motion[M:-M] = (am_motion[2 * M :] - am_motion[: -2 * M]) / (2.0 * Ts)
    jp_motion = np.zeros(tu.size)
    jp_motion[half:-half] = (am_motion[2 * half :] - am_motion[: -2 * half]) / Ts
    return _Probes(
        np.asarray(np.clip(np.rint((at - tu[0]) / h), 0, tu.size - 1), dtype=np.int64),
        np.interp(at, tu, vm),
        np.interp(at, tu, am_motion) + hat_sum(at),
        np.interp(at, tu, jm_motion) + (hat_sum(at + Ts) - hat_sum(at - Ts)) / (2.0 * Ts),
        np.interp(at, tu, jp_motion) + (hat_sum(at + 0.5 * Ts) - hat_sum(at - 0.5 * Ts)) / Ts,
    )


def _velocity_steps(fine: FloatArray, t: FloatArray, v: FloatArray, acc: FloatArray) -> list[tuple[float, FloatArray]]:
    r"""The axis velocity steps (t_b, dv (3,)) of a feed on the fine grid: at a tangent break passed at speed
    (a junction turning by less than the corner tolerance) v = x_s f jumps by f |jump of x_s| between the two
    fine points either side of the break (``STEP_PAIR_MM`` apart), where the motion's own change over the pair,
    (a_0 + a_1) dt / 2, is ~0.  Sampled at Ts, the step is an impulse dv delta(t - t_b) in a: its hat mean
    (``NlpRefiner._sampled``) is dv (Ts - |t - t_b|) / Ts^2, and the central third difference follows from it.
    Left out, the sampled check saw the step only through ``_step_servo_error``'s bound at the break's own two
    points, not at the samples up to 2 Ts away, where the motion's e is larger: random program cam-bench 3
    (lp+nlp), a 0.31 degree turn at ~0.5 m/s, read 1.055 x emax_z in the samples."""
    if fine.size < 2:
        return []
    ds = np.diff(fine)
    dv = v[1:] - v[:-1] - 0.5 * (acc[1:] + acc[:-1]) * np.diff(t)[:, None]
    scale = float(np.max(np.abs(v))) if v.size else 0.0
    idx = np.flatnonzero((ds <= STEP_PAIR_MM) & (np.max(np.abs(dv), axis=1) > STEP_MIN_SHARE * scale))
    return [(0.5 * float(t[k] + t[k + 1]), dv[k]) for k in idx]
