"""Plot content (service/plots.py): colour bar range, limit lines, binding markers, decimation, PNG metadata."""

from __future__ import annotations

import io
import json
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np
import pytest
from PIL import Image

from geometry.examples import flower, square_corner
from service import plots
from service.convert import Result, from_schedule
from solvers.machine import router
from solvers.pipeline import Options, schedule

SVG = "{http://www.w3.org/2000/svg}"
FEED_MAX = 60.0


@pytest.fixture(scope="module")
def flower_nlp() -> tuple[Result, plots.Limits]:
    """The flower under lp+nlp (binding: velocity from the diagnostics, servo error from the samples)."""
    m = router()
    return from_schedule(schedule(flower(1, points_per_loop=180), m, Options(method="lp+nlp"))), \
        plots.Limits.from_machine(m)


@pytest.fixture(scope="module")
def corner_lp() -> tuple[Result, plots.Limits]:
    """Two lines at a right angle under lp with a feed limit (a corner; velocity/acceleration/jerk/feed kinds)."""
    m = router().with_feed_max(FEED_MAX)
    return from_schedule(schedule(square_corner(40.0), m, Options(method="lp"))), plots.Limits.from_machine(m)


def svg(name: str, res: Result, lim: plots.Limits) -> ET.Element:
    return ET.fromstring(plots.render(name, res, lim, "svg"))


def meta(root: ET.Element) -> dict[str, Any]:
    desc = [e.text for e in root.iter() if e.tag.endswith("}description")]
    assert len(desc) == 1 and desc[0]
    out: dict[str, Any] = json.loads(desc[0])
    return out


def by_id(root: ET.Element, prefix: str) -> dict[str, ET.Element]:
    return {e.get("id", ""): e for e in root.iter() if e.get("id", "").startswith(prefix)}


def texts(el: ET.Element) -> list[str]:
    return [t.text.strip() for t in el.iter(SVG + "text") if t.text and t.text.strip()]


def markers(el: ET.Element) -> int:
    """Scatter points in a group: <use> of one <defs> path each, or (few points) one <path> each."""
    uses = len(list(el.iter(SVG + "use")))
    return uses if uses else len(list(el.iter(SVG + "path")))


@pytest.mark.parametrize("case", ["flower_nlp", "corner_lp"])
def test_toolpath_colour_bar_spans_the_feed_range(case: str, request: pytest.FixtureRequest) -> None:
    res, lim = request.getfixturevalue(case)
    root = svg("toolpath", res, lim)
    md = meta(root)
    feed = res.columns["feed"]
    assert md["feed_range"] == [float(feed.min()), float(feed.max())]
    assert md["feed_range"][0] == 0.0  # starts and ends at rest
    bar = by_id(root, "colorbar")["colorbar"]
    labels = texts(bar)
    assert "feed (mm/s)" in labels
    ticks = [float(t) for t in labels if t != "feed (mm/s)"]
    assert ticks[0] == 0.0 and len(ticks) == 6
    assert ticks[-1] == pytest.approx(float(feed.max()), rel=5e-3)  # the top of the bar is the top feed
    assert md["colorbar"]["max"] == float(feed.max())
    # start and end markers, and the path itself
    ids = by_id(root, "")
    assert {"start", "end", "toolpath-line"} <= set(ids)


def test_lp_binding_markers_are_where_the_diagnostics_say(corner_lp: tuple[Result, plots.Limits]) -> None:
    res, lim = corner_lp
    root = svg("toolpath", res, lim)
    md = meta(root)
    diag = res.diagnostics["binding"]
    binds = {k for k, v in diag.items() if v["count"] > 0}
    assert {"velocity", "feed"} <= binds or {"acceleration", "feed"} <= binds  # this case binds the feed limit
    groups = by_id(root, "binding-")
    assert set(groups) == {f"binding-{k}" for k in binds}
    for k in binds:
        want = diag[k]["s"][:: max(1, -(-len(diag[k]["s"]) // plots.MAX_MARKERS))]
        assert markers(groups[f"binding-{k}"]) == md["binding_markers"][k] == min(len(diag[k]["s"]),
                                                                                   plots.MAX_MARKERS)
        assert set(md["binding"][k]) <= set(diag[k]["s"]) and len(want) >= 1
    # the markers sit on the path at the arc lengths the diagnostics give
    fig, _ = plots.figure("toolpath", res, lim)
    offsets = {c.get_gid(): np.asarray(c.get_offsets()) for ax in fig.axes for c in ax.collections}
    for k in binds:
        s_b = np.asarray(md["binding"][k])
        want_xy = np.column_stack([np.interp(s_b, res.columns["s"], res.columns[a]) for a in "xy"])
        assert np.allclose(offsets[f"binding-{k}"], want_xy)
    corner = res.diagnostics["corners"][0]["position"]
    assert np.allclose(offsets["corners"], [corner[:2]])
    # method lp does not constrain the drive: no control-signal / servo-error markers
    assert "binding-control_signal" not in groups and "binding-servo_error" not in groups
    # the corner is marked where the diagnostics put it
    assert markers(by_id(root, "corners")["corners"]) == len(res.diagnostics["corners"]) == 1


def test_lp_nlp_binding_markers_include_drive_limits_from_samples(flower_nlp: tuple[Result, plots.Limits]) -> None:
    res, lim = flower_nlp
    root = svg("toolpath", res, lim)
    md = meta(root)
    groups = by_id(root, "binding-")
    c = res.columns
    e_util = np.max([np.abs(c[f"e_{a}"]) / lim.per_axis["servo_error"][i] for i, a in enumerate("xyz")], axis=0)
    u_util = np.max([np.abs(c[f"u_{a}"]) / lim.per_axis["control_signal"][i] for i, a in enumerate("xyz")], axis=0)
    assert e_util.max() >= plots.BINDING_UTILISATION  # the flower is servo-error bound under the NLP
    assert "binding-servo_error" in groups
    assert ("binding-control_signal" in groups) == bool(u_util.max() >= plots.BINDING_UTILISATION)
    s_hit = c["s"][e_util >= plots.BINDING_UTILISATION]
    assert set(md["binding"]["servo_error"]) <= set(s_hit.tolist())
    assert markers(groups["binding-servo_error"]) == min(s_hit.size, plots.MAX_MARKERS)
    diag = res.diagnostics["binding"]
    # the LP's kinematic limits are not constraints of the NLP (default options): not reported, not marked
    assert not {"velocity", "acceleration", "jerk"} & set(diag)
    assert not {"binding-velocity", "binding-acceleration", "binding-jerk"} & set(groups)
    assert not res.diagnostics["corners"] and "corners" not in by_id(root, "corners")


@pytest.mark.parametrize("case,enforced,reference", [
    ("flower_nlp", ("control_signal", "servo_error"), ("velocity", "acceleration", "jerk")),
    ("corner_lp", ("velocity", "acceleration", "jerk"), ("control_signal", "servo_error")),
])
def test_one_limit_line_per_constrained_quantity(case: str, enforced: tuple[str, ...], reference: tuple[str, ...],
                                                 request: pytest.FixtureRequest) -> None:
    res, lim = request.getfixturevalue(case)
    root = svg("axes", res, lim)
    md = meta(root)
    want = {f"limit-{q}-{a}" for q in enforced for a in "xyz"}
    assert set(by_id(root, "limit-")) == want
    assert set(by_id(root, "reference-")) == {f"reference-{q}-{a}" for q in reference for a in "xyz"}
    for q in enforced:
        for i, a in enumerate("xyz"):
            assert md["limits"][f"limit-{q}-{a}"] == lim.per_axis[q][i]
            # utilisation in percent in the panel title, from the samples
            col = {"velocity": "v", "acceleration": "a", "jerk": "j", "control_signal": "u", "servo_error": "e"}[q]
            peak = 100 * float(np.max(np.abs(res.columns[f"{col}_{a}"]))) / lim.per_axis[q][i]
            assert f"{q.replace('_', ' ')} {a}: peak {peak:.1f} %" in texts(root)
    # one drawn line per limit (both signs in one path)
    for el in by_id(root, "limit-").values():
        assert len(list(el.iter(SVG + "path"))) == 1
    feed = svg("feed", res, lim)
    feed_limits = set(by_id(feed, "limit-"))
    assert feed_limits == ({"limit-feed-s", "limit-feed-t"} if lim.feed_max else set())


def test_comparison_only_when_both_methods_ran(flower_nlp: tuple[Result, plots.Limits],
                                              corner_lp: tuple[Result, plots.Limits]) -> None:
    res, lim = flower_nlp
    assert plots.available(res) == list(plots.PLOTS)
    assert "comparison" not in plots.available(corner_lp[0])
    with pytest.raises(KeyError):
        plots.render("comparison", *corner_lp)
    root = svg("comparison", res, lim)
    md = meta(root)
    s = res.summary
    assert md["gain_percent"] == pytest.approx(100 * (s["lp_motion_time"] - s["motion_time"]) / s["lp_motion_time"])
    assert md["gain_percent"] > 0
    assert {"feed-lp", "feed-lpnlp"} <= set(by_id(root, "feed-"))
    lp = res.diagnostics["lp_feed"]
    assert lp["s"][0] == 0.0 and lp["s"][-1] == pytest.approx(s["path_length"])
    # the NLP is faster: its feed is above the LP's on average along the path
    assert np.mean(np.interp(lp["s"], res.columns["s"], res.columns["feed"])) > np.mean(lp["feed"])


def test_png_size_content_and_metadata(corner_lp: tuple[Result, plots.Limits]) -> None:
    res, lim = corner_lp
    data = plots.render("toolpath", res, lim, "png")
    img = Image.open(io.BytesIO(data))
    fig, _ = plots.figure("toolpath", res, lim)
    w, h = fig.get_size_inches() * plots.PNG_DPI
    assert img.size == (round(w), round(h))
    md = json.loads(img.text["feedsched"])  # type: ignore[attr-defined]
    assert md["plot"] == "toolpath" and md["feed_range"][1] == float(res.columns["feed"].max())
    px = np.asarray(img.convert("RGB")).reshape(-1, 3)
    assert (px.min(axis=1) < 200).mean() > 0.01  # not blank
    assert len(np.unique(px[::7], axis=0)) > 50  # a colour map, not one colour


def test_minmax_decimation_keeps_every_peak() -> None:
    n = 1_000_000
    rng = np.random.default_rng(1)
    y = np.sin(np.linspace(0, 40, n)) + 0.01 * rng.standard_normal(n)
    y[123_457] = 9.0
    y[876_543] = -7.0
    idx = plots.minmax_indices(y, 1000)
    assert idx.size <= 2 * 1000 + 2 and np.all(np.diff(idx) > 0)
    assert idx[0] == 0 and idx[-1] == n - 1
    assert {123_457, 876_543} <= set(idx.tolist())
    # every bin's extremes survive
    w = -(-n // 1000)
    for b in (0, 123, 999):
        seg = y[b * w:(b + 1) * w]
        kept = y[idx[(idx >= b * w) & (idx < (b + 1) * w)]]
        assert kept.max() == seg.max() and kept.min() == seg.min()


@pytest.mark.parametrize("seed", range(8))
def test_minmax_indices_are_each_runs_first_extremes(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Against a loop over the runs (the oracle): each run of w samples keeps the first index of its min and of its
    max, the last run shorter when w does not divide n; ties (rounded values) and a last sample at the minimum
    included.  The runs are views of the column, their extremes found by chunks of runs (session 57: no copy of a
    stored result's column; half the seeds with chunks of a few runs)."""
    if seed >= 4:
        monkeypatch.setattr(plots, "MINMAX_CHUNK", 997)
    rng = np.random.default_rng(seed)
    n, bins = int(rng.integers(1_000, 50_000)), int(rng.integers(3, 400))
    y = np.round(3 * rng.standard_normal(n)) if seed % 2 else np.cumsum(rng.standard_normal(n))
    y[-1] = y.min()
    w = -(-n // bins)
    want = {0, n - 1}
    for a in range(0, n, w):
        want |= {a + int(np.argmin(y[a:a + w])), a + int(np.argmax(y[a:a + w]))}
    assert plots.minmax_indices(y, bins).tolist() == sorted(want)


def test_peaks_and_ratios_without_temporaries_match_numpy() -> None:
    rng = np.random.default_rng(5)
    cols = [rng.standard_normal(10_001) * k for k in (1.0, 3.0, 0.5)]
    lim = (0.7, 2.0, 9.0)
    want = np.max(np.column_stack([np.abs(c) / li for c, li in zip(cols, lim, strict=True)]), axis=1)
    assert np.array_equal(plots._max_ratio(cols, lim), want)
    for c in (*cols, -np.abs(cols[0]), np.abs(cols[1]), np.zeros(4)):
        assert plots._peak(c) == float(np.max(np.abs(c)))


LIM = plots.Limits({"velocity": (150.0, 150.0, 150.0), "acceleration": (1e3, 1e3, 1e3), "jerk": (1e5, 1e5, 1e5)})


def synthetic(n: int, z_amp: float = 0.0) -> Result:
    """A made-up lp result of n samples along a helix-like path (no drive columns, nothing binds)."""
    t = np.arange(n) * 1e-4
    feed = 50 + 40 * np.sin(t) ** 2
    feed[0] = feed[-1] = 0.0
    s = np.cumsum(feed) * 1e-4
    cols = {"t": t, "s": s, "feed": feed, "x": np.cos(s / 50) * 50, "y": np.sin(s / 50) * 50,
            "z": z_amp * np.sin(s / 20)}
    for q in "vaj":
        for a in "xyz":
            cols[f"{q}_{a}"] = np.zeros(n)
    cols["v_x"] = feed.copy()
    return Result(summary={"method": "lp", "path_length": float(s[-1]), "motion_time": float(t[-1])},
                  diagnostics={"binding": {k: {"count": 0, "s": []} for k in ("velocity", "acceleration", "jerk")},
                               "corners": []}, columns=cols)


def test_a_3d_view_when_z_moves() -> None:
    flat = ET.fromstring(plots.render("toolpath", synthetic(5000), LIM))
    assert meta(flat)["has_3d"] is False and "toolpath-line-3d" not in by_id(flat, "toolpath-line")
    helix = ET.fromstring(plots.render("toolpath", synthetic(5000, z_amp=5.0), LIM))
    assert meta(helix)["has_3d"] is True and "toolpath-line-3d" in by_id(helix, "toolpath-line")
    assert "z (mm)" in texts(helix)


def test_a_million_samples_are_drawn_decimated_with_the_peaks() -> None:
    res = synthetic(1_000_000)
    res.columns["feed"][654_321] = 123.0
    lim = LIM
    fig, md = plots.figure("feed", res, lim)
    lines = {ln.get_gid(): ln for ax in fig.axes for ln in ax.get_lines()}
    for gid in ("feed-vs-s", "feed-vs-t"):
        yd = np.asarray(lines[gid].get_ydata())
        assert yd.size <= 2 * plots.DECIMATE_BINS + 2 and yd.max() == 123.0
    fig, md = plots.figure("toolpath", res, lim)
    assert md["points_drawn"] <= 2 * plots.DECIMATE_BINS + 2 and md["feed_range"] == [0.0, 123.0]
    root = ET.fromstring(plots.render("toolpath", res, lim, "svg"))
    assert [float(x) for x in texts(by_id(root, "colorbar")["colorbar"])[:-1]][-1] == 123.0
    assert not by_id(root, "binding-")


#: Agreement of ``plots.interp_sorted`` with np.interp (rounding of the two formulas).
INTERP_RTOL = 1e-12


@pytest.mark.parametrize("seed", range(4))
def test_interp_sorted_matches_numpy_on_read_only_columns(seed: int) -> None:
    """The binding markers' positions: ``interp_sorted`` against np.interp (the oracle) on increasing abscissae
    with runs of equal values (a standing corner's samples share s), queries on them, between them and outside;
    and without a copy of a read-only column (np.interp copies one whole: 48 MB for a stored 3 M-sample result's
    s and x, session 58)."""
    import tracemalloc

    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5_000))
    xp = np.cumsum(np.where(rng.random(n) < 0.1, 0.0, rng.random(n)))
    fp = rng.standard_normal(n)
    xq = np.concatenate([rng.uniform(xp[0] - 1.0, xp[-1] + 1.0, 300), xp[rng.integers(0, n, 50)], xp[[0, -1]]])
    # (at a value that a run of equal xp shares, fp jumps: either end of the run is right, and np.interp's pick
    # is its own; the positions there are one point)
    jump = np.isin(xq, xp[np.flatnonzero(np.diff(xp) == 0)])
    got = plots.interp_sorted(xq, xp, fp)
    want = np.interp(xq, xp, fp)
    np.testing.assert_allclose(got[~jump], want[~jump], rtol=INTERP_RTOL, atol=INTERP_RTOL)
    assert (~jump).sum() >= 300
    big = np.linspace(0.0, 1.0, 1_000_000)
    big.flags.writeable = False
    tracemalloc.start()
    try:
        plots.interp_sorted(xq, big, big)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < big.nbytes / 10
