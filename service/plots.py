"""Plots of a schedule for engineers (SVG and PNG), pure numpy + matplotlib (Agg): no web framework here.

Input is anything with ``summary``, ``diagnostics`` and ``columns`` (a
``service.convert.Result``) plus the machine's ``Limits``.  Plots:

- ``toolpath``: the path in XY (and a 3-D view when Z moves) coloured by feed,
  colour bar in mm/s, start/end and corners marked, binding constraints
  marked by type;
- ``feed``: feed against arc length and against time;
- ``axes``: per axis velocity, acceleration, jerk, control signal and servo
  error against time, each with its limit and the peak utilisation in %;
- ``comparison`` (method lp+nlp only): the LP feed and the LP+NLP feed along
  the path and the motion-time gain.

Which limits are *enforced* depends on the method: ``lp`` keeps velocity,
acceleration and jerk (and the feed limit); ``lp+nlp`` keeps the
control signal and servo error (and the feed limit).  Enforced limits are
drawn as solid red lines (SVG id ``limit-<quantity>-<axis>``); the others as
grey dotted reference lines (``reference-<quantity>-<axis>``).  Binding
markers (SVG id ``binding-<kind>``) are drawn for the enforced kinds only:
velocity/acceleration/jerk/feed where the schedule's diagnostics report them,
control signal/servo error where the samples reach ``BINDING_UTILISATION`` of
their limit.  Every image carries a JSON description of what it shows (SVG
``<metadata>`` dc:description, PNG text chunk ``feedsched``).

Long results are decimated for drawing with min/max per column
(``minmax_indices``): every peak survives.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import matplotlib
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

PLOTS = ("toolpath", "feed", "axes", "comparison")
#: Bumped whenever a plot changes, so that cached plots of older versions are not served.
VERSION = 1
FORMATS = {"svg": "image/svg+xml", "png": "image/png"}
AXES = ("x", "y", "z")
#: Utilisation at or above which a drive limit is marked as binding (as solvers.pipeline does for the LP kinds).
BINDING_UTILISATION = 0.98
#: Bins per drawn series: (min, max) kept per bin, so at most 2 x this many points (>= pixel columns at PNG_DPI).
DECIMATE_BINS = 1500
#: Samples per chunk of ``minmax_indices``'s per-run extremes (numpy copies a read-only array, such as a stored
#: result's memory-mapped column, before an argmin along an axis: 24 MB for 3 M samples at once).
MINMAX_CHUNK = 2**18
#: Most binding markers drawn per kind (evenly thinned beyond).
MAX_MARKERS = 80
PNG_DPI = 100
CMAP = "turbo"


class ResultLike(Protocol):
    """``service.convert.Result`` or anything shaped like it."""

    @property
    def summary(self) -> Mapping[str, Any]: ...

    @property
    def diagnostics(self) -> Mapping[str, Any]: ...

    @property
    def columns(self) -> Mapping[str, FloatArray]: ...


@dataclass(frozen=True)
class Quantity:
    key: str
    column: str
    label: str
    unit: str


QUANTITIES = (
    Quantity("velocity", "v", "velocity", "mm/s"),
    Quantity("acceleration", "a", "acceleration", "mm/s²"),
    Quantity("jerk", "j", "jerk", "mm/s³"),
    Quantity("control_signal", "u", "control signal", "V"),
    Quantity("servo_error", "e", "servo error", "mm"),
)
ENFORCED = {"lp": ("velocity", "acceleration", "jerk"), "lp+nlp": ("control_signal", "servo_error")}
#: Binding kinds, marker and colour on the toolpath plot.
BINDING_STYLE = {
    "velocity": ("o", "#000000"),
    "acceleration": ("s", "#e7298a"),
    "jerk": ("^", "#555555"),
    "control_signal": ("D", "#d95f02"),
    "servo_error": ("v", "#7570b3"),
    "feed": ("P", "#1b9e77"),
}


@dataclass(frozen=True)
class Limits:
    """Per-axis limits (x, y, z) of each quantity (velocity mm/s, acceleration mm/s^2, jerk mm/s^3,
    control_signal V, servo_error mm; the last two None without a drive model) and the feed limit (mm/s)."""

    per_axis: dict[str, tuple[float, float, float]]
    feed_max: float | None = None

    @classmethod
    def from_machine(cls, machine: Any) -> Limits:
        """From a ``solvers.machine.Machine`` (duck-typed so this module needs no solver import)."""
        vmax, amax, jmax = machine.limit_arrays()
        per: dict[str, tuple[float, float, float]] = {
            "velocity": _t3(vmax), "acceleration": _t3(amax), "jerk": _t3(jmax)}
        if machine.has_drives:
            d = machine.drive_arrays()
            per["control_signal"] = _t3(d["umax"])
            per["servo_error"] = _t3(d["emax"])
        return cls(per, machine.feed_max)


def _t3(a: Any) -> tuple[float, float, float]:
    v = [float(x) for x in a]
    return (v[0], v[1], v[2])


def available(res: ResultLike) -> list[str]:
    """Plot names this result has (``comparison`` only when the LP and the LP+NLP feed were both computed)."""
    return [p for p in PLOTS if p != "comparison" or "lp_feed" in res.diagnostics]


def enforced(res: ResultLike) -> tuple[str, ...]:
    """The limits the schedule's method enforces.  Under lp+nlp the kinematic limits count only where the
    schedule reports them as constraints (``diagnostics.binding`` lists a kind exactly when it is enforced:
    axis velocity with ``nlp_axis_velocity`` or a drive speed limit, acceleration/jerk with ``nlp_kinematic``)."""
    method = str(res.summary.get("method", "lp"))
    binding = res.diagnostics.get("binding", {})
    if method == "lp+nlp":
        return tuple(k for k in ("velocity", "acceleration", "jerk") if k in binding) + ENFORCED["lp+nlp"]
    keys: tuple[str, ...] = ENFORCED["lp"]
    if "jerk" not in binding:
        keys = ("velocity", "acceleration")  # options.jerk = false
    return keys


# --- decimation -------------------------------------------------------------------
def minmax_indices(y: FloatArray, bins: int = DECIMATE_BINS) -> IntArray:
    """Sorted sample indices keeping the first, the last, and the min and the max of ``y`` in each of
    ``bins`` equal runs of samples: drawn as a line, no peak is lost (at most 2 bins + 2 points)."""
    y = np.asarray(y, dtype=np.float64)
    n = y.size
    if n <= 2 * bins + 2:
        return np.arange(n, dtype=np.int64)
    w = -(-n // bins)
    full = n // w
    runs = y[: full * w].reshape(full, w)  # (a view: a stored result's column is not copied)
    lo, hi = np.empty(full, dtype=np.int64), np.empty(full, dtype=np.int64)
    step = max(1, MINMAX_CHUNK // w)
    for r in range(0, full, step):  # (argmin along an axis copies a read-only array, a mapped column: by chunks)
        lo[r : r + step] = np.argmin(runs[r : r + step], axis=1)
        hi[r : r + step] = np.argmax(runs[r : r + step], axis=1)
    base = np.arange(full, dtype=np.int64) * w
    parts = [base + lo, base + hi, np.array([0, n - 1], dtype=np.int64)]
    if full * w < n:  # (the last, shorter run)
        parts.append(full * w + np.array([np.argmin(y[full * w :]), np.argmax(y[full * w :])], dtype=np.int64))
    return np.unique(np.concatenate(parts))


def decimate(x: FloatArray, y: FloatArray, bins: int = DECIMATE_BINS) -> tuple[FloatArray, FloatArray]:
    idx = minmax_indices(y, bins)
    return np.asarray(x)[idx], np.asarray(y)[idx]


def _thin(a: FloatArray, most: int = MAX_MARKERS) -> FloatArray:
    return a if a.size <= most else a[np.linspace(0, a.size - 1, most).round().astype(np.int64)]


def _peak(y: FloatArray) -> float:
    """max |y| without an array of |y| (a column of a long result is tens of MB)."""
    return float(max(np.max(y), -np.min(y)))


def interp_sorted(xq: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """``np.interp(xq, xp, fp)`` for xp increasing, without copying xp and fp: np.interp copies a read-only
    array whole (a mapped column of a stored result: 48 MB for x and s at 3 M samples); a binary search does not.
    Outside [xp[0], xp[-1]] the end values, as np.interp."""
    n = xp.size
    i = np.clip(np.searchsorted(xp, xq, side="right"), 1, n - 1)
    x0, x1, f0, f1 = xp[i - 1], xp[i], fp[i - 1], fp[i]
    dx = x1 - x0
    w = np.clip(np.divide(xq - x0, dx, out=np.zeros_like(xq, dtype=np.float64), where=dx > 0), 0.0, 1.0)
    return np.asarray(f0 + w * (f1 - f0), dtype=np.float64)


def _max_ratio(cols: list[FloatArray], lim: tuple[float, float, float]) -> FloatArray:
    """max over the axes of |col_i| / lim_i, sample by sample, in two arrays of a column's length."""
    out = np.abs(cols[0])
    out /= lim[0]
    tmp = np.empty_like(out)
    for col, li in zip(cols[1:], lim[1:], strict=True):
        np.abs(col, out=tmp)
        tmp /= li
        np.maximum(out, tmp, out=out)
    return out


# --- what binds where ---------------------------------------------------------------
def binding(res: ResultLike, limits: Limits) -> dict[str, FloatArray]:
    """Arc lengths (mm) where each enforced constraint binds: LP kinds from the diagnostics (their thinned list of
    checkpoints), drive kinds from the samples (every sample with utilisation >= BINDING_UTILISATION); kinds that
    never bind are left out."""
    out: dict[str, FloatArray] = {}
    enf = enforced(res)
    diag = res.diagnostics.get("binding", {})
    for kind in ("velocity", "acceleration", "jerk", "feed"):
        if (kind in enf or kind == "feed") and kind in diag and diag[kind]["count"] > 0:
            out[kind] = np.asarray(diag[kind]["s"], dtype=np.float64)
    cols = res.columns
    for q in QUANTITIES[3:]:
        lim = limits.per_axis.get(q.key)
        if q.key not in enf or lim is None or f"{q.column}_x" not in cols:
            continue
        util = _max_ratio([cols[f"{q.column}_{a}"] for a in AXES], lim)
        hit = cols["s"][util >= BINDING_UTILISATION]
        if hit.size:
            out[q.key] = np.asarray(hit, dtype=np.float64)
    return out


def utilisation(res: ResultLike, limits: Limits) -> dict[str, float]:
    """Peak |quantity| / limit per quantity and axis (``velocity_x``...) and ``feed``."""
    out: dict[str, float] = {}
    for q in QUANTITIES:
        lim = limits.per_axis.get(q.key)
        if lim is None or f"{q.column}_x" not in res.columns:
            continue
        for i, a in enumerate(AXES):
            out[f"{q.key}_{a}"] = _peak(res.columns[f"{q.column}_{a}"]) / lim[i]
    if limits.feed_max is not None:
        out["feed"] = float(np.max(res.columns["feed"])) / limits.feed_max
    return out


# --- figures ----------------------------------------------------------------------------
def figure(name: str, res: ResultLike, limits: Limits) -> tuple[Figure, dict[str, Any]]:
    """The named figure and its description (what is drawn, for the image metadata)."""
    if name not in available(res):
        raise KeyError(name)
    build = {"toolpath": _toolpath, "feed": _feed, "axes": _axes, "comparison": _comparison}[name]
    fig, meta = build(res, limits)
    meta = {"plot": name, "method": res.summary.get("method"), "samples": int(res.columns["t"].size), **meta}
    return fig, meta


def render(name: str, res: ResultLike, limits: Limits, fmt: str = "svg") -> bytes:
    """The named plot as SVG or PNG bytes.  Raises KeyError for a plot this result does not have."""
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {sorted(FORMATS)}")
    fig, meta = figure(name, res, limits)
    text = json.dumps(meta, separators=(",", ":"))
    buf = io.BytesIO()
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "feedsched"}):
        if fmt == "svg":
            fig.savefig(buf, format="svg", metadata={"Title": f"feedsched {name}", "Description": text, "Date": None})
        else:
            fig.savefig(buf, format="png", dpi=PNG_DPI, metadata={"feedsched": text})
    return buf.getvalue()


def _fig(w: float, h: float) -> Figure:
    return Figure(figsize=(w, h), layout="constrained")


def _toolpath(res: ResultLike, limits: Limits) -> tuple[Figure, dict[str, Any]]:
    c = res.columns
    feed = c["feed"]
    fmax = float(np.max(feed)) if feed.size else 0.0
    fmin = float(np.min(feed)) if feed.size else 0.0
    top = fmax if fmax > 0 else 1.0
    idx = minmax_indices(feed)
    xyz = np.column_stack([c["x"][idx], c["y"][idx], c["z"][idx]])
    fseg = 0.5 * (feed[idx][:-1] + feed[idx][1:]) if idx.size > 1 else feed[idx]
    span = max(float(np.ptp(c["x"])), float(np.ptp(c["y"]))) if feed.size else 0.0
    has_z = feed.size > 0 and float(np.ptp(c["z"])) > 1e-6 * max(1.0, span)
    norm = Normalize(0.0, top)
    fig = _fig(15.0 if has_z else 9.5, 7.5)
    ax = fig.add_subplot(1, 2 if has_z else 1, 1)
    lc = LineCollection(list(np.stack([xyz[:-1, :2], xyz[1:, :2]], axis=1)), cmap=CMAP, norm=norm, linewidths=2.5)
    lc.set_array(fseg)
    lc.set_gid("toolpath-line")
    ax.add_collection(lc)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.grid(True, alpha=0.3)
    summary = res.summary
    ax.set_title(f"toolpath coloured by feed: {summary.get('path_length', 0.0):.1f} mm in "
                 f"{summary.get('motion_time', 0.0):.3f} s ({summary.get('method', '?')})")
    axes_3d = None
    if has_z:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        axes_3d = fig.add_subplot(1, 2, 2, projection="3d")
        lc3 = Line3DCollection(np.stack([xyz[:-1], xyz[1:]], axis=1), cmap=CMAP, norm=norm, linewidths=2.0)
        lc3.set_array(fseg)
        lc3.set_gid("toolpath-line-3d")
        axes_3d.add_collection3d(lc3)
        for k, a in enumerate(AXES):
            lo, hi = float(np.min(xyz[:, k])), float(np.max(xyz[:, k]))
            pad = 0.05 * (hi - lo) + 1e-9
            getattr(axes_3d, f"set_{a}lim")(lo - pad, hi + pad)
            getattr(axes_3d, f"set_{a}label")(f"{a} (mm)")
        axes_3d.set_title("3-D view")
    ticks = np.linspace(0.0, top, 6)
    cb = fig.colorbar(lc, ax=[ax] if axes_3d is None else [ax, axes_3d], ticks=ticks, shrink=0.9)
    cb.set_label("feed (mm/s)")
    cb.ax.set_yticklabels([_num(t) for t in ticks])
    cb.ax.set_gid("colorbar")
    # start / end / corners
    if feed.size:
        ax.plot([c["x"][0]], [c["y"][0]], marker="o", ms=11, color="#2ca02c", ls="none", label="start", gid="start",
                zorder=4)
        ax.plot([c["x"][-1]], [c["y"][-1]], marker="s", ms=7, color="#d62728", ls="none", label="end", gid="end",
                zorder=5)
    corners = res.diagnostics.get("corners", [])
    if corners:
        cp = np.array([k["position"] for k in corners], dtype=np.float64)
        ax.scatter(cp[:, 0], cp[:, 1], marker="X", s=90, color="#000000", label=f"corner ({len(corners)})",
                   gid="corners", zorder=5)
    bind = binding(res, limits)
    drawn: dict[str, int] = {}
    for kind, s_b in bind.items():
        s_b = _thin(s_b)
        bx, by = interp_sorted(s_b, c["s"], c["x"]), interp_sorted(s_b, c["s"], c["y"])
        marker, colour = BINDING_STYLE[kind]
        ax.scatter(bx, by, marker=marker, s=36, facecolors="none", edgecolors=colour, linewidths=1.3,
                   label=f"{kind.replace('_', ' ')} binds", gid=f"binding-{kind}", zorder=6)
        drawn[kind] = int(s_b.size)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.08), ncol=4, fontsize="small", frameon=False)
    meta = {
        "feed_range": [fmin, fmax],
        "colorbar": {"label": "feed (mm/s)", "min": 0.0, "max": top, "ticks": [float(t) for t in ticks]},
        "corners": len(corners),
        "binding": {k: [float(v) for v in _thin(s)] for k, s in bind.items()},
        "binding_markers": drawn,
        "has_3d": bool(has_z),
        "points_drawn": int(idx.size),
    }
    return fig, meta


def _num(v: float) -> str:
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"


def _limit_line(ax: Any, t0: float, t1: float, lim: float, gid: str, enforced: bool) -> None:
    style = dict(color="#d62728", lw=1.2, ls="-") if enforced else dict(color="#888888", lw=1.0, ls=":")
    ax.plot([t0, t1, math.nan, t0, t1], [lim, lim, math.nan, -lim, -lim], gid=gid,
            label="limit" if enforced else "limit (not enforced by this method)", **style)


def _feed(res: ResultLike, limits: Limits) -> tuple[Figure, dict[str, Any]]:
    c = res.columns
    fig = _fig(12.0, 7.0)
    axs = fig.subplots(2, 1)
    lims: dict[str, float] = {}
    for ax, xcol, xlabel in ((axs[0], "s", "arc length s (mm)"), (axs[1], "t", "time t (s)")):
        x, y = decimate(c[xcol], c["feed"])
        ax.plot(x, y, color="#1f77b4", lw=1.2, label="feed", gid=f"feed-vs-{xcol}")
        if limits.feed_max is not None and x.size:
            ax.plot([x[0], x[-1]], [limits.feed_max] * 2, color="#d62728", lw=1.2, label="feed limit",
                    gid=f"limit-feed-{xcol}")
            lims[f"limit-feed-{xcol}"] = limits.feed_max
        ax.set_xlabel(xlabel)
        ax.set_ylabel("feed (mm/s)")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="lower center", fontsize="small")
    peak = float(np.max(c["feed"])) if c["feed"].size else 0.0
    util = f", {100 * peak / limits.feed_max:.0f} % of the feed limit" if limits.feed_max else ""
    axs[0].set_title(f"feed: peak {peak:.1f} mm/s{util}")
    return fig, {"limits": lims, "feed_range": [float(np.min(c["feed"])), peak]}


def _axes(res: ResultLike, limits: Limits) -> tuple[Figure, dict[str, Any]]:
    c = res.columns
    quantities = [q for q in QUANTITIES if f"{q.column}_x" in c]
    enf = enforced(res)
    fig = _fig(16.0, 2.6 * len(quantities) + 0.6)
    grid = fig.subplots(len(quantities), 3, sharex=True, squeeze=False)
    t = c["t"]
    lims: dict[str, float] = {}
    refs: dict[str, float] = {}
    util: dict[str, float] = {}
    for r, q in enumerate(quantities):
        lim3 = limits.per_axis.get(q.key)
        for k, a in enumerate(AXES):
            ax = grid[r][k]
            y = c[f"{q.column}_{a}"]
            xd, yd = decimate(t, y)
            ax.plot(xd, yd, color="#1f77b4", lw=0.9, gid=f"trace-{q.key}-{a}")
            ax.grid(True, alpha=0.3)
            ax.set_ylabel(f"{q.column}_{a} ({q.unit})", fontsize="small")
            peak = _peak(y) if y.size else 0.0
            if lim3 is not None and t.size:
                lim = lim3[k]
                is_enf = q.key in enf
                gid = f"{'limit' if is_enf else 'reference'}-{q.key}-{a}"
                _limit_line(ax, float(t[0]), float(t[-1]), lim, gid, is_enf)
                (lims if is_enf else refs)[gid] = lim
                u = peak / lim
                util[f"{q.key}_{a}"] = u
                ax.secondary_yaxis("right", functions=(lambda v, L=lim: 100.0 * v / L,
                                                       lambda p, L=lim: p * L / 100.0)).set_ylabel("% of limit",
                                                                                                  fontsize="small")
                tag = "" if is_enf else " (not enforced)"
                ax.set_title(f"{q.label} {a}: peak {100 * u:.1f} %{tag}", fontsize="medium",
                             color="#b00000" if is_enf and u >= BINDING_UTILISATION else "black")
            else:
                ax.set_title(f"{q.label} {a}: no limit", fontsize="medium")
    for k in range(3):
        grid[-1][k].set_xlabel("time t (s)")
    fig.suptitle(f"axis profiles against limits ({res.summary.get('method', '?')}: solid red = enforced limit, "
                 "dotted grey = limit this method does not enforce)")
    return fig, {"limits": lims, "references": refs, "utilisation": util, "enforced": list(enf)}


def _comparison(res: ResultLike, limits: Limits) -> tuple[Figure, dict[str, Any]]:
    c = res.columns
    lp = res.diagnostics["lp_feed"]
    t_lp = float(res.summary.get("lp_motion_time", math.nan))
    t_nlp = float(res.summary.get("motion_time", math.nan))
    gain = 100.0 * (t_lp - t_nlp) / t_lp if t_lp > 0 else math.nan
    fig = _fig(12.0, 5.5)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(lp["s"], lp["feed"], color="#ff7f0e", lw=1.2, label=f"LP ({t_lp:.3f} s)", gid="feed-lp")
    x, y = decimate(c["s"], c["feed"])
    ax.plot(x, y, color="#1f77b4", lw=1.2, label=f"LP+NLP ({t_nlp:.3f} s)", gid="feed-lpnlp")
    if limits.feed_max is not None and x.size:
        ax.plot([x[0], x[-1]], [limits.feed_max] * 2, color="#d62728", lw=1.2, label="feed limit", gid="limit-feed")
    ax.set_xlabel("arc length s (mm)")
    ax.set_ylabel("feed (mm/s)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower center", fontsize="small")
    ax.set_title(f"LP vs LP+NLP: motion time {t_lp:.3f} s → {t_nlp:.3f} s ({gain:.1f} % less)")
    return fig, {"lp_motion_time": t_lp, "motion_time": t_nlp, "gain_percent": gain}
