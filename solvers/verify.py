r"""Last line of defence: the sampled output re-checked against every enforced limit.

The LP and NLP hold their limits at checkpoints and verify them on a finer
grid (4 points per checkpoint gap and both sides of every geometry knot), but
a curvature peak narrower than that grid can still sit between two
verification points (random case 63: |x_ss| peaks over 0.3 mm against a
0.22 mm grid and the sampled acceleration reached 1.085 x amax, with no
unverified point reported).  So the time samples themselves are checked, in
two ways, per sample k and axis i:

- analytic: the v, a, j (and u, e) the pipeline emits at sample k, over their limits;
- finite differences of the emitted positions, as a machine (or an independent
  checker) sees them, with ``REST_PAD`` samples of rest before and after:

      v_k = (x_k - x_{k-1}) / Ts,  a_k = (x_{k+1} - 2 x_k + x_{k-1}) / Ts^2,
      j_k = (x_{k+2} - 3 x_{k+1} + 3 x_k - x_{k-1}) / Ts^3,
      u = M a + b v + c + d sign(v),  e = Kv v + Ka a + Kj j   (central v, j).

Samples over ``1 + REPAIR_TOL`` (analytic) or ``1 + FD_REPAIR_TOL`` (finite
differences) give their arc lengths to the pipeline, which adds them to the
verification grid of their piece and solves that piece again; whatever is
still over ``1 + FAIL_TOL`` after the last round is a ``LimitViolationError``:
the schedule is never returned over its limits silently.

``check_rows`` checks any run of consecutive samples given the REST_PAD
samples on either side, so the pipeline checks piece by piece with the values
of a check of the whole schedule.  Rest padding at each piece's own ends would
not do: the rest instant at a corner falls between two samples, so the
neighbours across it are moving (on a zigzag, the differences at the samples
next to a corner changed by up to 0.31 of a limit; ``tests/solvers/test_stream.py``).

Units: mm, s; utilisations are dimensionless (1.0 = at the limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from solvers.kinematics import row_any, row_max
from solvers.machine import drive_outputs

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Analytic utilisation above 1 + this at a sample sends its s back to the solver.  Not the
#: solvers' own 0.2 % verification tolerance: between their verification points a bound that is
#: active anyway reaches 1.003-1.005 x (flower, v+a only), within the promise, and repairing that
#: re-solved most long paths twice (18.35 m: 22 -> 65 LP windows).
REPAIR_TOL = 5e-3
#: Finite-difference utilisation above 1 + this sends its s back (differences of a curve at the
#: limit overshoot it by O(Ts^2) terms).
FD_REPAIR_TOL = 5e-3
#: Utilisation above 1 + this after the last repair round is an error (the product's guarantee:
#: every sampled quantity within 1.01 x its limit).
FAIL_TOL = 1e-2
#: Samples of rest padded before and after the motion for the differences.
REST_PAD = 2
#: Samples checked per chunk (bounds the transient arrays: ~20 of (CHUNK, 3) float64).
CHUNK = 65_536


@dataclass(frozen=True)
class Limits:
    """The limits a schedule promises, (3,) per axis; None where not enforced.

    vmax, amax, jmax: mm/s, mm/s^2, mm/s^3; umax (V) and emax (mm) with the drive
    coefficients ``drive`` (keys M b c d Kv Ka Kj, each (3,)); feed_cap (K,) mm/s per sample.
    """

    vmax: FloatArray | None
    amax: FloatArray | None
    jmax: FloatArray | None
    drive: dict[str, FloatArray] | None
    feed_cap: FloatArray | None


#: What a re-check can find over its limit, in the order it is evaluated (``RowCheck.kind`` indexes it).
KINDS = ("velocity", "acceleration", "jerk", "control_signal", "servo_error", "feed")


@dataclass(frozen=True)
class SampleCheck:
    """``repair``: (K,) samples whose s should be verified by the solvers;
    ``worst``: (kind, axis, utilisation, sample index) of the largest utilisation."""

    repair: BoolArray
    worst: tuple[str, str, float, int]

    @property
    def failed(self) -> bool:
        return self.worst[2] > 1.0 + FAIL_TOL


@dataclass(frozen=True)
class RowCheck:
    """The re-check of K consecutive samples, per sample (before the neighbour spread of ``spread``).

    Attributes:
        over: (K,) bool, some enforced quantity is over 1 + its repair tolerance at the sample.
        util: (K,) the largest utilisation at the sample (analytic or by differences, any kind and axis).
        kind: (K,) int8 index into ``KINDS`` of that largest utilisation, -1 where nothing is enforced.
        axis: (K,) int8 axis (0 x, 1 y, 2 z) of it, -1 for the feed or nothing.
    """

    over: BoolArray
    util: FloatArray
    kind: NDArray[np.int8]
    axis: NDArray[np.int8]

    def worst(self, lo: int = 0, hi: int | None = None) -> tuple[str, str, float, int]:
        """(kind, axis, utilisation, sample index) of the largest utilisation among samples [lo, hi)."""
        hi = self.util.size if hi is None else hi
        if hi <= lo:
            return ("none", "", 0.0, lo)
        k = lo + int(np.argmax(self.util[lo:hi]))
        kind = int(self.kind[k])
        axis = int(self.axis[k])
        return (KINDS[kind] if kind >= 0 else "none", "xyz"[axis] if axis >= 0 else "", float(self.util[k]), k)


def _fd(
    p: FloatArray, lo: int, hi: int, Ts: float, central: bool
) -> tuple[FloatArray, FloatArray, FloatArray, tuple[FloatArray, FloatArray, FloatArray] | None]:
    """At padded indices k = lo .. hi - 1 of the rest-padded positions p (lo >= 2, hi + 2 <= len(p)):
    backward v, central a, the third difference over k-1..k+2, and if ``central`` (for the drive model)
    the central (v, a, j) (each (hi - lo, 3); slices, not gathered copies: the same values)."""
    pm2, pm1, p0, pp1, pp2 = (p[lo + d : hi + d] for d in (-2, -1, 0, 1, 2))
    v = (p0 - pm1) / Ts
    a = (pp1 - 2.0 * p0 + pm1) / Ts**2
    j = (pp2 - 3.0 * pp1 + 3.0 * p0 - pm1) / Ts**3
    if not central:
        return v, a, j, None
    v_next = (pp1 - p0) / Ts
    j_prev = (pp1 - 3.0 * p0 + 3.0 * pm1 - pm2) / Ts**3
    return v, a, j, (0.5 * (v + v_next), a, 0.5 * (j + j_prev))


def rest_padded(position: FloatArray) -> FloatArray:
    """(K + 2 REST_PAD, 3): the positions held at rest for REST_PAD samples before and after."""
    return np.concatenate([np.repeat(position[:1], REST_PAD, axis=0), position,
                           np.repeat(position[-1:], REST_PAD, axis=0)])


def check_rows(
    Ts: float, padded: FloatArray, feed: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits
) -> RowCheck:
    """Utilisation of every enforced limit at each of K samples, analytic and by finite differences.

    ``padded``: (K + 2 REST_PAD, 3) positions, mm: the K samples with the REST_PAD samples before and
    after them, which the differences read (the neighbouring samples of the schedule, or the rest
    position at a path end: ``rest_padded``).  ``feed`` (K,), ``v``, ``a``, ``j`` (K, 3) are the
    emitted values at the K samples; ``lim.feed_cap`` (K,) if given.  Every value at sample k depends
    only on sample k and ``padded``[k .. k + 2 REST_PAD], so checking a schedule in consecutive parts
    (each with its true neighbours as context) gives the same bits as checking it whole.  Runs in
    chunks of CHUNK samples (bounded transient arrays)."""
    K = feed.shape[0]
    if padded.shape[0] != K + 2 * REST_PAD:
        raise ValueError(f"padded has {padded.shape[0]} rows, expected K + {2 * REST_PAD} = {K + 2 * REST_PAD}")
    over = np.zeros(K, dtype=bool)
    util = np.zeros(K)
    kind = np.full(K, -1, dtype=np.int8)
    axis = np.full(K, -1, dtype=np.int8)
    for c0 in range(0, K, CHUNK):
        c1 = min(K, c0 + CHUNK)
        sl = slice(c0, c1)
        v_fd, a_fd, j_fd, vaj_c = _fd(padded, c0 + REST_PAD, c1 + REST_PAD, Ts, lim.drive is not None)
        # kind, analytic, fd, limit (the differences' u and e from the central v and j)
        per = [(kd, an, fd, limit) for (kd, an, limit), (_, fd, _) in zip(
            _terms(v[sl], a[sl], j[sl], lim), _terms(v_fd, a_fd, j_fd, lim, vaj_c), strict=True)]
        for kd, an, fd, limit in per:
            ua = np.abs(an) / limit
            uf = np.abs(fd) / limit
            over[sl] |= row_any(ua > 1.0 + REPAIR_TOL) | row_any(uf > 1.0 + FD_REPAIR_TOL)
            both = np.maximum(ua, uf)
            m = row_max(both)
            # (a value that is not finite is over every limit: never released; a NaN compares false otherwise)
            bad = np.isnan(m)
            if bad.any():
                m[bad] = np.inf
                over[sl] |= bad
            up = m > util[sl]
            util[sl] = np.where(up, m, util[sl])
            kind[sl] = np.where(up, kd, kind[sl])
            axis[sl][up] = np.argmax(both[up], axis=1)
    if lim.feed_cap is not None:
        uf_ = _feed_util(feed, lim.feed_cap)
        uf_ = np.where(np.isnan(uf_), np.inf, uf_)
        over |= uf_ > 1.0 + REPAIR_TOL
        up = uf_ > util
        util = np.where(up, uf_, util)
        kind[up] = KINDS.index("feed")
        axis[up] = -1
    return RowCheck(over, util, kind, axis)


def analytic_over(feed: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits) -> BoolArray:
    """(K,) samples whose emitted values alone (no differences: those need the next samples) are over
    1 + REPAIR_TOL of an enforced limit (feed cap included): ``check_rows``' analytic half."""
    over = np.zeros(feed.shape[0], dtype=bool)
    for _, an, limit in _terms(v, a, j, lim):
        over |= row_any(np.abs(an) / limit > 1.0 + REPAIR_TOL)
    if lim.feed_cap is not None:
        over |= _feed_util(feed, lim.feed_cap) > 1.0 + REPAIR_TOL
    return over


def _terms(
    v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits,
    drive_vaj: tuple[FloatArray, FloatArray, FloatArray] | None = None,
) -> list[tuple[int, FloatArray, FloatArray]]:
    """(kind index into KINDS, values (K, 3), limit (3,)) of every enforced limit, in KINDS order: v, a, j
    themselves, and u, e from the drive model at ``drive_vaj`` (default (v, a, j))."""
    out: list[tuple[int, FloatArray, FloatArray]] = []
    for kd, val, limit in ((0, v, lim.vmax), (1, a, lim.amax), (2, j, lim.jmax)):
        if limit is not None:
            out.append((kd, val, limit))
    if lim.drive is not None:
        dr = lim.drive
        u, e = drive_outputs(dr, *(drive_vaj if drive_vaj is not None else (v, a, j)))
        out += [(3, u, dr["umax"]), (4, e, dr["emax"])]
    return out


def _feed_util(feed: FloatArray, cap: FloatArray) -> FloatArray:
    """feed / cap (K,), 0 where the cap is infinite."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.where(np.isfinite(cap), feed / cap, 0.0), dtype=np.float64)


def spread(over: BoolArray, left: bool = False, right: bool = False) -> BoolArray:
    """Samples to send back: those over a limit and their neighbours (a difference spans
    neighbouring samples).  ``left`` / ``right``: whether the samples just outside are over."""
    out = over.copy()
    out[1:] |= over[:-1]
    out[:-1] |= over[1:]
    if out.size:
        out[0] |= left
        out[-1] |= right
    return out


def check(
    Ts: float, position: FloatArray, feed: FloatArray, v: FloatArray, a: FloatArray, j: FloatArray, lim: Limits
) -> SampleCheck:
    """The whole schedule at once, held at rest before the first and after the last sample."""
    rows = check_rows(Ts, rest_padded(position), feed, v, a, j, lim)
    return SampleCheck(spread(rows.over), rows.worst())


def noise_shares(lim: Limits, Ts: float, noise_mm: float) -> dict[str, FloatArray]:
    """Per axis (3,), the largest share of each promised limit (keys of ``KINDS`` but feed) that position noise of
    ``noise_mm`` (each sample off by up to that, independently) can put into the finite differences above: v by up
    to 2 n / Ts, a by 4 n / Ts^2, j by 8 n / Ts^3, and u, e by their drive terms' sums of those
    (|M| a + |b| v, |Kv| v + |Ka| a + |Kj| j; the constant c + d sign(v) is no difference).  Kinds not enforced
    are left out."""
    dv, da, dj = 2.0 * noise_mm / Ts, 4.0 * noise_mm / Ts**2, 8.0 * noise_mm / Ts**3
    out: dict[str, FloatArray] = {}
    for kind, d, limit in (("velocity", dv, lim.vmax), ("acceleration", da, lim.amax), ("jerk", dj, lim.jmax)):
        if limit is not None:
            out[kind] = np.asarray(d / limit, dtype=np.float64)
    if lim.drive is not None:
        dr = lim.drive
        out["control_signal"] = np.asarray((np.abs(dr["M"]) * da + np.abs(dr["b"]) * dv) / dr["umax"],
                                           dtype=np.float64)
        out["servo_error"] = np.asarray(
            (np.abs(dr["Kv"]) * dv + np.abs(dr["Ka"]) * da + np.abs(dr["Kj"]) * dj) / dr["emax"], dtype=np.float64)
    return out


def noise_share(lim: Limits, Ts: float, noise_mm: float) -> float:
    """The largest of ``noise_shares`` over kinds and axes; 0 with no limit enforced."""
    return max([0.0, *(float(np.max(v)) for v in noise_shares(lim, Ts, noise_mm).values())])
