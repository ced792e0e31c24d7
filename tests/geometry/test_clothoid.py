"""Clothoids (Fresnel form) against numerical integration, and G2 corner blends.

Truth: C(s) = P0 + integral of (cos phi, sin phi) by scipy.integrate.quad; the
blend's deviation is measured on dense samples against the original polyline.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy.integrate import quad

from geometry import primitives
from geometry.arcblend import MIN_BLEND_TOLERANCE_MM, blend_path
from geometry.clothoid import (
    ClothoidSegment,
    blend_corner,
    blend_factors,
    blend_polyline,
    blend_polyline_legs,
)
from geometry.errors import GeometryError
from geometry.nurbs import NurbsSegment
from geometry.toolpath import Toolpath

#: Fresnel position vs. quad of the tangent (mm).
POS_TOL_MM = 1e-11
#: Unit tangent, frame orthogonality (dimensionless).
UNIT_TOL = 1e-13
#: Arc length of a clothoid through the Toolpath tables vs. its parameter length (relative).
LENGTH_REL_TOL = 1e-13
#: Curvature / derivative identities (relative to the curvature scale).
CURVATURE_REL_TOL = 1e-10
#: Derivatives vs. central differences of the next lower derivative (step FD_STEP_MM).
FD_STEP_MM = 1e-5
FD_TOL = 1e-8
#: Deviation of a blend vs. the tolerance asked for: equal to rounding ...
DEVIATION_REL_TOL = 1e-12
#: ... and the two-sided distance: blend samples to the polyline exactly, polyline samples
#: to the blend by Newton from the best of N_COARSE clothoid samples.
HAUSDORFF_REL_TOL = 1e-9
N_DENSE = 2000
N_COARSE = 200
NEWTON_STEPS = 6


def frame(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q[:, 0], q[:, 1]


def quad_points(seg: ClothoidSegment, s: np.ndarray) -> np.ndarray:
    def phi(x: float) -> float:
        return float(seg.angle(np.array([x]))[0])

    out = []
    for si in s:
        cx = quad(lambda x: math.cos(phi(x)), 0.0, si, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
        cy = quad(lambda x: math.sin(phi(x)), 0.0, si, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
        out.append(seg.start + cx * seg.e1 + cy * seg.e2)
    return np.array(out)


CLOTHOIDS = [
    # phi0, kappa0 (1/mm), sharpness (1/mm^2), length (mm)
    (0.0, 0.0, 0.8, 2.0),
    (0.3, 0.4, -0.25, 5.0),
    (-1.2, -0.5, 1.5, 1.5),
    (2.0, 0.1, -0.05, 10.0),
]


@pytest.mark.parametrize(("phi0", "kappa0", "c", "length"), CLOTHOIDS)
def test_clothoid_matches_integrated_tangent(phi0: float, kappa0: float, c: float, length: float) -> None:
    rng = np.random.default_rng(int(1000 * (phi0 + kappa0 + c)) % 2**31)
    e1, e2 = frame(rng)
    seg = ClothoidSegment.create(rng.uniform(-20, 20, 3), e1, e2, phi0, kappa0, c, length)
    s = np.linspace(0.0, length, 23)
    np.testing.assert_allclose(seg.points(s), quad_points(seg, s), rtol=0, atol=POS_TOL_MM)

    D = seg.derivatives(s)
    np.testing.assert_allclose(np.linalg.norm(D[1], axis=1), 1.0, rtol=0, atol=UNIT_TOL)
    kappa = kappa0 + c * s
    scale = max(1.0, float(np.abs(kappa).max()))
    np.testing.assert_allclose(np.einsum("ij,ij->i", D[1], D[2]), 0.0, atol=UNIT_TOL * scale)
    np.testing.assert_allclose(np.linalg.norm(D[2], axis=1), np.abs(kappa), rtol=0, atol=CURVATURE_REL_TOL * scale)
    # signed curvature about the plane normal
    normal = np.cross(e1, e2)
    np.testing.assert_allclose(np.cross(D[1], D[2]) @ normal, kappa, atol=CURVATURE_REL_TOL * scale)
    # each derivative is the derivative of the one before (central differences)
    inner = s[1:-1]
    h = FD_STEP_MM
    Dp, Dm = seg.derivatives(inner + h), seg.derivatives(inner - h)
    for k in range(3):
        fd = (Dp[k] - Dm[k]) / (2 * h)
        np.testing.assert_allclose(fd, seg.derivatives(inner)[k + 1], rtol=0, atol=FD_TOL * scale**2)


@pytest.mark.parametrize(("phi0", "kappa0", "c", "length"), CLOTHOIDS)
def test_clothoid_in_a_toolpath_is_arc_length_parameterised(
    phi0: float, kappa0: float, c: float, length: float
) -> None:
    seg = ClothoidSegment.create([0, 0, 0], [1, 0, 0], [0, 1, 0], phi0, kappa0, c, length)
    tp = Toolpath([seg])
    assert tp.length == pytest.approx(length, rel=LENGTH_REL_TOL)
    s = np.linspace(0.0, length, 101)
    ev = tp.evaluate(s)
    np.testing.assert_allclose(ev.position, seg.points(s), rtol=0, atol=1e-13 * length)
    np.testing.assert_allclose(ev.d2[:, :2], seg.derivatives(s)[2][:, :2], rtol=0, atol=1e-12)
    assert tp.knot_s.size == 0


@pytest.mark.parametrize(
    ("kwargs", "fld", "text"),
    [
        ({"sharpness": 0.0}, "c.sharpness", "non-zero"),
        ({"length": 0.0}, "c.length", "length must be >"),
        ({"kappa0": math.nan}, "c.kappa0", "finite"),
        ({"e1": [2.0, 0.0, 0.0]}, "c.e1", "unit"),
        ({"e2": [0.6, 0.8, 0.0]}, "c.e2", "orthogonal"),
        ({"start": [0.0, 0.0]}, "c.start", "3-vector"),
        ({"start": [0.0, math.inf, 0.0]}, "c.start", "finite"),
    ],
)
def test_clothoid_validation(kwargs: dict[str, object], fld: str, text: str) -> None:
    args: dict[str, object] = {
        "start": [0.0, 0.0, 0.0], "e1": [1.0, 0.0, 0.0], "e2": [0.0, 1.0, 0.0],
        "phi0": 0.0, "kappa0": 0.0, "sharpness": 1.0, "length": 1.0,
    }
    args.update(kwargs)
    with pytest.raises(GeometryError) as info:
        ClothoidSegment.create(name="c", **args)  # type: ignore[arg-type]
    assert info.value.field == fld
    assert text in info.value.rule


# --------------------------------------------------------------------------- corner blends


def point_to_polyline(q: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Exact distance from each q (K, 3) to the polyline through pts."""
    a, b = pts[:-1], pts[1:]
    ab = b - a
    t = np.einsum("kij,ij->ki", q[:, None, :] - a[None], ab) / np.einsum("ij,ij->i", ab, ab)
    foot = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.asarray(np.min(np.linalg.norm(q[:, None, :] - foot, axis=2), axis=1))


def dense(tp: Toolpath, n: int = N_DENSE) -> np.ndarray:
    return tp.positions(np.linspace(0.0, tp.length, n))


def nearest_on_clothoid(q: np.ndarray, seg: ClothoidSegment) -> np.ndarray:
    """Distance from each q to the clothoid: best of N_COARSE samples, then Newton on
    f(s) = (C(s) - q) . T(s), f'(s) = 1 + (C(s) - q) . C''(s), clipped to [0, L]."""
    grid = np.linspace(0.0, seg.length, N_COARSE)
    pts = seg.points(grid)
    s = grid[np.argmin(np.linalg.norm(q[:, None, :] - pts[None], axis=2), axis=1)]
    for _ in range(NEWTON_STEPS):
        D = seg.derivatives(s)
        r = D[0] - q
        s = np.clip(s - np.einsum("ij,ij->i", r, D[1]) / (1.0 + np.einsum("ij,ij->i", r, D[2])), 0.0, seg.length)
    return np.asarray(np.linalg.norm(seg.points(s) - q, axis=1))


def distance_to_path(q: np.ndarray, tp: Toolpath) -> np.ndarray:
    """Distance from each q to the blended path (its lines exactly, its clothoids by Newton)."""
    best = np.full(q.shape[0], np.inf)
    for seg in tp.segments:
        if isinstance(seg, ClothoidSegment):
            d = nearest_on_clothoid(q, seg)
        else:
            d = point_to_polyline(q, seg.points(np.array(seg.domain)))
        best = np.minimum(best, d)
    return best


def two_sided_deviation(tp: Toolpath, pts: np.ndarray) -> tuple[float, float]:
    """(max distance of the blended path from the polyline, max distance of the polyline from
    the blended path) over dense samples of each."""
    blend = dense(tp)
    for seg in tp.segments:
        if isinstance(seg, ClothoidSegment):
            blend = np.concatenate([blend, seg.points(np.linspace(0.0, seg.length, N_DENSE // 4))])
    poly = np.concatenate([np.linspace(p, q, N_DENSE // 4) for p, q in itertools.pairwise(pts)])
    return float(point_to_polyline(blend, pts).max()), float(distance_to_path(poly, tp).max())


TURNS_DEG = [5.0, 45.0, 90.0, 135.0, 175.0]


@pytest.mark.parametrize("turn_deg", TURNS_DEG)
@pytest.mark.parametrize("tol", [0.01, 0.5])
def test_single_corner_blend_meets_the_tolerance_and_is_g2(turn_deg: float, tol: float) -> None:
    th = math.radians(turn_deg)
    V = np.array([100.0, 0.0, 0.0])
    pts = np.array([[0.0, 0.0, 0.0], V, V + 100.0 * np.array([math.cos(th), math.sin(th), 0.0])])
    segs = blend_polyline(pts, tol)
    assert [type(s) for s in segs] == [NurbsSegment, ClothoidSegment, ClothoidSegment, NurbsSegment]
    first, second = segs[1], segs[2]
    assert isinstance(first, ClothoidSegment) and isinstance(second, ClothoidSegment)
    # deviation: the junction M sits exactly tol from the corner, on the bisector
    M = first.points(np.array([first.length]))[0]
    assert np.linalg.norm(M - V) == pytest.approx(tol, rel=DEVIATION_REL_TOL)
    bisector = np.array([-math.sin(th / 2), math.cos(th / 2), 0.0])
    np.testing.assert_allclose((M - V) / tol, bisector, atol=1e-9)
    # G2: position, tangent and curvature vector agree at all three joins
    joins = [(segs[0], segs[1]), (segs[1], segs[2]), (segs[2], segs[3])]
    for left, right in joins:
        dl = left.derivatives(np.array([left.domain[1]]))[:3, 0]
        dr = right.derivatives(np.array([right.domain[0]]))[:3, 0]
        dl[1] /= np.linalg.norm(dl[1])
        dr[1] /= np.linalg.norm(dr[1])
        np.testing.assert_allclose(dl, dr, rtol=0, atol=1e-11 * max(1.0, th / first.length))
    assert first.curvature(np.array([first.length]))[0] == pytest.approx(th / first.length, rel=1e-14)
    tp = Toolpath(segs)
    assert tp.corners == [] and len(tp.pieces) == 1
    out_of_poly, poly_out = two_sided_deviation(tp, pts)
    assert out_of_poly <= tol * (1 + DEVIATION_REL_TOL)
    assert poly_out <= tol * (1 + HAUSDORFF_REL_TOL)
    assert poly_out >= tol * (1 - 1e-9)  # attained: the corner point itself is tol away
    # curvature along the blend rises and falls linearly: |C_ss| = kappa(s)
    s = np.linspace(tp.offsets[1], tp.offsets[3], 501)
    k = np.linalg.norm(tp.evaluate(s).d2, axis=1)
    kappa_m = th / first.length
    np.testing.assert_allclose(k, kappa_m * (1 - np.abs(s - tp.offsets[2]) / first.length), atol=1e-9 * kappa_m)


def test_blend_factors_match_the_geometry() -> None:
    """d = g L and delta = h L against a blend built with L = 1 (independent of the tolerance)."""
    for th in np.radians(TURNS_DEG):
        g, h = blend_factors(float(th))
        t_out = np.array([math.cos(th), math.sin(th), 0.0])
        b = blend_corner(np.zeros(3), np.array([1.0, 0, 0]), t_out, h, 1e9, "c")
        assert b is not None
        assert b.length == pytest.approx(1.0, rel=1e-14)
        assert b.setback == pytest.approx(g, rel=1e-14)
        end = b.spirals[1].points(np.array([1.0]))[0]
        np.testing.assert_allclose(end, g * t_out, atol=1e-13)


def test_short_legs_limit_the_setback() -> None:
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0], [2.0, 1.0, 0]])
    segs = blend_polyline(pts, 5.0)  # far more than the 1 mm legs allow
    tp = Toolpath(segs)
    assert tp.corners == []
    clothoids = [s for s in segs if isinstance(s, ClothoidSegment)]
    assert len(clothoids) == 4
    # each set-back is half the shared middle leg: the two blends touch, no line between them
    assert [type(s) for s in segs] == [NurbsSegment] + [ClothoidSegment] * 4 + [NurbsSegment]
    out_of_poly, _ = two_sided_deviation(tp, pts)
    assert out_of_poly < 5.0


def test_zigzag_in_3d_is_one_piece_within_tolerance() -> None:
    rng = np.random.default_rng(5)
    pts = np.cumsum(rng.uniform(-10, 10, (12, 3)) + np.array([12.0, 0, 0]), axis=0)
    tol = 0.05
    tp = Toolpath(blend_polyline(pts, tol))
    assert tp.corners == [] and len(tp.pieces) == 1
    np.testing.assert_allclose(tp.positions(np.array([0.0, tp.length])), pts[[0, -1]], atol=1e-12)
    legs = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    assert tp.length < legs
    out_of_poly, poly_out = two_sided_deviation(tp, pts)
    assert out_of_poly <= tol * (1 + DEVIATION_REL_TOL)
    assert poly_out <= tol * (1 + HAUSDORFF_REL_TOL)
    # curvature continuous along the whole path: no jumps beyond what the sampling step explains
    s = np.linspace(0.0, tp.length, 20001)
    k = np.linalg.norm(tp.evaluate(s).d2, axis=1)
    kmax = k.max()
    sharp = max(abs(c.sharpness) for c in tp.segments if isinstance(c, ClothoidSegment))
    assert np.abs(np.diff(k)).max() <= 1.01 * sharp * (s[1] - s[0]) + 1e-9 * kmax


def test_reversal_stays_a_corner_and_zero_tolerance_keeps_lines() -> None:
    pts = np.array([[0.0, 0, 0], [10.0, 0, 0], [5.0, 0, 0], [5.0, 5.0, 0]])
    segs = blend_polyline(pts, 0.1)
    tp = Toolpath(segs)
    assert len(tp.corners) == 1 and tp.corners[0].angle_deg == pytest.approx(180.0)
    assert sum(isinstance(s, ClothoidSegment) for s in segs) == 2
    plain = blend_polyline(pts, 0.0)
    assert all(isinstance(s, NurbsSegment) and s.degree == 1 for s in plain)
    assert len(Toolpath(plain).corners) == 2


@pytest.mark.parametrize("tol", [-0.1, math.nan, math.inf])
def test_blend_tolerance_validation(tol: float) -> None:
    with pytest.raises(GeometryError) as info:
        blend_polyline([[0, 0], [1, 0], [1, 1]], tol)
    assert info.value.field == "corner_tolerance_mm"


@pytest.mark.parametrize("tol", [1e-9, 4.6e-4, 0.000999])
def test_blend_path_refuses_tolerances_under_the_path_fidelity(tol: float) -> None:
    """``blend_path`` (the G-code and JSON routes' blending) takes 0 or at least MIN_BLEND_TOLERANCE_MM."""
    segs = [primitives.line([0, 0, 0], [1, 0, 0]), primitives.line([1, 0, 0], [1, 1, 0])]
    with pytest.raises(GeometryError) as info:
        blend_path(segs, tol)
    assert info.value.field == "corner_tolerance_mm" and "0.001" in info.value.rule
    assert len(blend_path(segs, MIN_BLEND_TOLERANCE_MM).segments) == 4  # line, two spirals, line
    assert len(blend_path(segs, 0.0).segments) == 2


def test_blend_rejects_repeated_points() -> None:
    with pytest.raises(GeometryError) as info:
        blend_polyline([[0, 0], [1, 0], [1, 0], [1, 1]], 0.1, name="p")
    assert info.value.field == "p.points[2]"


def test_blend_polyline_legs_names_the_legs_of_every_segment() -> None:
    """Lines lie on one leg (before = after), a corner's spirals between legs j and j + 1; a reversal
    stays unblended (lines on both legs), a 0.2 mm leg used up by its two blends leaves no line."""
    pts = np.array([[0, 0, 0], [10, 0, 0], [10, 0.2, 0], [20, 0.2, 0], [10, 0.2, 0], [20, 0.2 + 1e-12, 0], [30, 5, 0]],
                   dtype=float)
    segs, before, after = blend_polyline_legs(pts, 0.05)
    assert [type(s) for s in segs] == [type(s) for s in blend_polyline(pts, 0.05)]
    assert len(before) == len(after) == len(segs)
    assert np.all(np.diff(before) >= 0) and before[0] == 0 and after[-1] == len(pts) - 2
    for s, b, a in zip(segs, before, after, strict=True):
        if isinstance(s, ClothoidSegment):
            assert a == b + 1
            # the first spiral of a pair leaves leg b, the second lands on leg a
            first = s.name.endswith(".in")
            p, leg = s.points(np.array([0.0 if first else s.length]))[0], b if first else a
            d = pts[leg + 1] - pts[leg]
            t = np.clip((p - pts[leg]) @ d / (d @ d), 0, 1)
            assert np.linalg.norm(p - (pts[leg] + t * d)) < 1e-9
        else:
            assert a == b
            cp = s.control_points
            d = pts[b + 1] - pts[b]
            assert np.linalg.norm(np.cross(cp[1] - cp[0], d)) <= 1e-9 * np.linalg.norm(d) ** 2
