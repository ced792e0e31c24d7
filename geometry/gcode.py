"""G-code reader: our own tokenizer and interpreter, output one exact NurbsSegment per motion.

Output is a frozen :class:`Program`: ``segments[k]`` (mm), its programmed feed
``feed[k]`` in mm/s (None for rapids), ``rapid[k]`` and the source ``line[k]``.
Every word of the input is either interpreted, listed in ``Program.ignored``
(M, S, T, O words and the accepted no-op modes) or rejected with a
:class:`GcodeError` naming ``gcode:line L:col C``, the word and the rule;
nothing is dropped silently. Columns are 1-based characters (a tab counts 1).

Lexical rules
    Case-insensitive. Comments ``( ... )`` (not nested, closed on the same line)
    and ``;`` to the end of the line. A word is a letter, optional blanks, an
    optional ``=`` and a decimal number (``X10``, ``X 10``, ``X=10``, ``X-.5``;
    no exponents). Numbers without a decimal point mean the same value as with
    one (``X10`` = 10 mm: the calculator-type input of LinuxCNC, Siemens and Fanuc
    with parameter DPI = 1, *not* Fanuc's default of least input increments).
    Multi-letter words: the Siemens keyword ``BSPLINE`` and the Siemens
    parameters ``SD=``, ``PW=``, ``PL=``. A ``/`` before the first word is block
    delete: the block is skipped when ``block_delete=True`` (the switch on),
    executed otherwise. A line holding only ``%`` is the tape marker.

Modal state (initial: G17 G21 or ``units``, G90, G91.1, G94, no motion mode, no
feed, position ``start``). Within a block the order is: G20/G21, G17-G19,
G90/G91, G90.1/G91.1, then F (converted with the block's units), then motion.

    G00 / G01           line (rapid / cut); axis-only blocks repeat the modal motion
    G02 / G03           arc cw / ccw in the active plane; centre I J K (incremental from
                        the start by default, G91.1; absolute with G90.1) or R (R < 0 for
                        the arc over 180 degrees); IJK without axis words: a full circle
                        (Fanuc); P n: n turns (LinuxCNC); helical arcs are rejected
    G06.2               Fanuc NURBS (below)
    BSPLINE             Siemens B spline (below)
    G05.2 / G05.3       LinuxCNC NURBS (below)
    G17 G18 G19         plane;   G20 / G21 inch / mm (1 in = 25.4 mm exactly)
    G90 / G91           absolute / incremental X Y Z;   G90.1 / G91.1 absolute / incremental I J K
    G94                 feed per minute (the only feed mode): F in mm/min or inch/min -> mm/s
    G40 G49 G80 G54 G61 G64, G05 P0 / P10000, G05.1 Q0 / Q1: accepted no-ops, listed in ``ignored``
    M S T O             listed in ``ignored`` (not motion); M02 / M30 end the program
                        (later lines are not interpreted); M98 / M99 (sub-programs) rejected

A motion block whose end equals the current position makes no segment; its
line is listed in ``Program.null_moves``.

Fanuc G06.2 (Fanuc Series 15i/150i-MA Operator's Manual B-63324EN/03, 4.17
"NURBS interpolation"; PS alarms 1004-1009)::

    G06.2 [P_] [K_] [X_ Y_ Z_] [R_] [F_] ;   first control point
    K_ X_ Y_ Z_ [R_] ;                        one block per further control point
    ...
    K_ ;                                      exactly P knot-only blocks end the curve
    K_ ;

    P rank = order = degree + 1, 2..4, default 4, first block only. R weight > 0,
    default 1. One knot per control-point block plus P knot-only blocks: n + P knots
    (absolute parameter values, never unit-converted: an affine change of all knots
    does not change the curve). The first P and the last P knots must be equal
    (clamped: the curve starts at the first and ends at the last control point);
    knots never decrease; no interior knot repeats more than P - 1 times. The first
    control point is the current position: if its axis words are omitted it is taken
    from there, otherwise it must equal it (within ``START_TOL_MM``; in G91 it must be
    a zero increment). A knot omitted in the first block equals the second block's
    knot. Axis words omitted in a block keep the previous control point's value
    (G90) or add zero (G91: increments from the previous control point). G06.2 is
    modal (group 01): after a completed curve a block with K and axis words starts
    the next curve; a group-01 code or the end of the program before the P-th
    knot-only block is an error (PS1004/PS1005). Only K, axis words, R, N (and P, F
    in the first block) may appear while a curve is open.

Siemens BSPLINE (SINUMERIK Programming Manual Job Planning 6FC5398-2BP40-0BA0,
07/2010, 4.2 "Spline interpolation", and 6FC5398-2EP40-0BA0, 12/2019, 3.7)::

    BSPLINE [SD=2|3] ; X_ Y_ Z_ [PW=w] [PL=h] ; ... ; G01 (or any other motion: ends the spline)

    The programmed points are control points; the start point (the current position
    when BSPLINE becomes active) is the first control point, weight 1; the curve is
    tangent to the control polygon at both ends (clamped). SD = degree, 2 or 3,
    default 3, on the BSPLINE block or the first point's block. PW = point weight, 0 < w <= 3,
    default 1. PL = parameter interval length: Siemens "suitably calculates" the
    knot distances internally when PL is absent and does not publish the rule.
    Our rule: with n control points P_0 (start) .. P_{n-1} and degree p the knot
    vector is clamped with n - p spans; the PL of the block programming P_j is the
    length of span j = [u_{p+j-1}, u_{p+j}] for j = 1 .. n - p (the last p - 1 points
    have no span: their PL must be absent or 0). Either every P_1 .. P_{n-p} carries a
    PL > 0 or none does; with none the spans are uniform (all 1). The span mapping is our
    convention, not Siemens' (their manuals do not define it); it is the one an
    open-source NURBS-to-Sinumerik writer uses (PL of point i = u_{p+i} - u_{p+i-1}).
    Uniform spacing of any
    length gives the same curve (an affine change of the knots leaves it unchanged),
    so only the *relative* spacing matters; a control that computes chord-length
    spacing draws a different curve between the end points, so posts that need
    fidelity must write PL. The spline ends at the next G00/G01/G02/G03/G06.2/G05.2,
    at M02/M30 or at the end of the text; it needs at least p points after the start.

LinuxCNC G5.2 / G5.3 (LinuxCNC G-code reference "G5.2 G5.3 NURBS Block";
src/emc/rs274ngc/interp_convert.cc convert_nurbs and
nurbs_additional_functions.cc knot_vector_creator)::

    G5.2 [L order] [X_ Y_ P w] ; X_ Y_ P w ; ... ; G5.3

    Planar (G17, X and Y only). The current position is the first control point,
    weight 1 (or P of a first block without X Y). Every further control point needs
    X, Y and P > 0. L (order = degree + 1) only in the first block, default 3, >= 3
    (LinuxCNC silently uses 3 for L < 3; we reject it). Knots: clamped uniform
    integers, u_i = 0 (i < k), i - k + 1 (k <= i <= n), n - k + 2 (i > n), n + 1
    control points, order k. G5.3 closes the curve (needs >= k control points); any
    other motion code or the end of the text while it is open is an error. G91 is
    rejected (LinuxCNC's increments inside G5.2 refer to the curve's start, not to
    the previous point).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from geometry import arcblend, primitives
from geometry.errors import GeometryError
from geometry.nurbs import MAX_DEGREE, FloatArray, NurbsSegment
from geometry.segment import Segment
from geometry.toolpath import CORNER_TOL_DEG, MIN_FEED_MM_S, Toolpath

MM_PER_INCH: Final = 25.4
SECONDS_PER_MINUTE: Final = 60.0
#: Fanuc: the first control point must equal the current position (PS alarm 1009) within this (mm).
START_TOL_MM: Final = 1e-6
FANUC_RANK_DEFAULT: Final = 4
FANUC_RANKS: Final = (2, 3, 4)
SIEMENS_DEGREE_DEFAULT: Final = 3
SIEMENS_DEGREES: Final = (2, 3)
SIEMENS_MAX_WEIGHT: Final = 3.0
LINUXCNC_ORDER_DEFAULT: Final = 3

_AXES: Final = "XYZ"
_OFFSETS: Final = "IJK"
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)", re.ASCII)  # (ASCII digits: not Arabic-Indic or full-width ones)
_NAME = re.compile(r"[A-Z_]+")
#: Siemens multi-letter parameter addresses (written with '=').
_NAMED: Final = frozenset({"SD", "PW", "PL"})
_KEYWORDS: Final = frozenset({"BSPLINE"})
#: single-letter addresses we interpret somewhere (others are unsupported words)
_KNOWN: Final = frozenset("GMXYZIJKRPLFSTNOQ")

# G codes as round(10 * value)
_G_MOTION: Final = {0: "G00", 10: "G01", 20: "G02", 30: "G03", 62: "G06.2", 52: "G05.2"}
_G_PLANE: Final = {170: "G17", 180: "G18", 190: "G19"}
_G_NOOP: Final = frozenset({400, 490, 800, 540, 610, 640, 940})


class GcodeError(GeometryError):
    """A G-code program that cannot be read exactly.

    Attributes (besides GeometryError's field / value / rule):
        line: 1-based source line; col: 1-based column of the offending word; word: its text.
        ``field`` is ``gcode:line L:col C``.
    """

    def __init__(self, line: int, col: int, word: str, rule: str) -> None:
        self.line = line
        self.col = col
        self.word = word
        super().__init__(f"gcode:line {line}:col {col}", word, rule)


@dataclass(frozen=True)
class Word:
    """One word: ``name`` is the address ("G", "X", "SD") or a keyword ("BSPLINE", value None)."""

    name: str
    value: float | None
    text: str
    col: int


@dataclass(frozen=True)
class Block:
    """The words of one source line (1-based ``line``); ``deleted``: it starts with '/'."""

    line: int
    words: tuple[Word, ...]
    deleted: bool


@dataclass(frozen=True)
class Program:
    """An interpreted G-code program.

    Attributes:
        segments: exact geometry, one per motion (a whole NURBS / spline is one segment), mm.
        feed: programmed tangential feed per segment in mm/s (F is per minute, G94); None for rapids.
        rapid: True for G00 segments.
        line: 1-based source line of each segment (a NURBS: the line of its first block).
        units: "mm" or "inch" as programmed for the motions ("mixed" if both were used);
            the segments are always in mm.
        ignored: (line, word) of every word accepted but not interpreted (M, S, T, O, no-op G codes).
        null_moves: lines of motion blocks that ended where they started (no segment).
    """

    segments: tuple[NurbsSegment, ...]
    feed: tuple[float | None, ...]
    rapid: tuple[bool, ...]
    line: tuple[int, ...]
    units: str
    ignored: tuple[tuple[int, str], ...] = ()
    null_moves: tuple[int, ...] = ()

    def toolpath(self, corner_tol_deg: float = CORNER_TOL_DEG, blend_mm: float = 0.0) -> Toolpath:
        """The segments as a Toolpath (corners between them found as usual), each with its programmed feed.

        With ``blend_mm`` > 0, every run of consecutive cutting lines and arcs (G01 / G02 / G03, at
        any F), and every run of consecutive rapids (G00), has its corners replaced by G2 clothoid
        pairs within ``blend_mm`` of the corner (``geometry.arcblend.blend_path``: line-line
        corners by ``geometry.clothoid.blend_polyline``, corners with an arc by a clothoid pair
        fitted on the line and the circle), so the schedule runs through them instead of
        stopping. A blend between two moves of different F gets the lower of the two feeds as its
        feed limit (it lies in the tolerance zone of both moves); every other segment keeps its
        own F. Rapid-to-cut and cut-to-rapid transitions stay rest points: the rapid ends exactly
        at its programmed point, at rest, before cutting starts (and cutting ends there before a
        rapid leaves). Corners at splines, out of the arc's plane, or where no blend fits stay
        rest points too; the last two are listed in ``Toolpath.unblended``.
        """
        if blend_mm == 0.0:
            return self._toolpath(list(self.segments), list(self.line), corner_tol_deg=corner_tol_deg,
                                  feed_limits=list(self.feed))
        # runs are split only where a rapid meets a cutting move (the F of a cutting move may change)
        bp = arcblend.blend_path(self.segments, blend_mm, keys=list(self.rapid),
                                 names=[f"gcode:line {ln}" for ln in self.line])
        feed = self.feed
        limits = [feed[a] if a == b else _lower(feed[a], feed[b]) for a, b in zip(bp.origin, bp.after, strict=True)]
        return self._toolpath(list(bp.segments), [self.line[k] for k in bp.origin], corner_tol_deg=corner_tol_deg,
                              feed_limits=limits, unblended=bp.unblended)

    @staticmethod
    def _toolpath(segments: list[Segment], lines: list[int], **kw: Any) -> Toolpath:
        """``Toolpath(segments, **kw)``, its errors about segment i named by i's source line (``lines``): a program
        has no ``segments[i]`` to point at (session 58's probe: "segments[1]: zero-length segment")."""
        try:
            return Toolpath(segments, **kw)
        except GcodeError:
            raise
        except GeometryError as exc:
            m = re.match(r"segments\[(\d+)\]", exc.field)
            if m is None or int(m.group(1)) >= len(lines):
                raise
            raise GcodeError(lines[int(m.group(1))], 1, str(exc.value), exc.rule) from exc


def _lower(a: float | None, b: float | None) -> float | None:
    """The lower of two feed limits (None: no limit, a rapid; rapids and cuts are never blended together)."""
    if a is None:
        return b
    if b is None:
        return a
    return min(a, b)


# --------------------------------------------------------------------------- tokenizer


#: A program's line ends: LF, CR LF or a lone CR (old Mac CAM files).  Not ``str.splitlines``'s others (VT, FF,
#: NEL, U+2028...): inside a line those are whitespace or an unexpected character.
LINE_END = re.compile(r"\r\n|\r|\n")


def lines(text: str) -> list[str]:
    """The program's lines (a trailing line end starts no line)."""
    out = LINE_END.split(text)
    return out[:-1] if out and out[-1] == "" else out


def tokenize(text: str) -> list[Block]:
    """Split G-code text into blocks of words; raises GcodeError on lexical errors.  A leading byte-order mark
    (Windows CAM files often start with one) is not part of the program."""
    blocks: list[Block] = []
    if text.startswith("\ufeff"):
        text = text[1:]
    for ln, raw in enumerate(lines(text), start=1):
        block = _tokenize_line(raw, ln)
        if block is not None:
            blocks.append(block)
    return blocks


def _tokenize_line(raw: str, ln: int) -> Block | None:
    s = raw.upper()
    words: list[Word] = []
    deleted = False
    i = 0
    n = len(s)
    while i < n:
        ch = s[i]
        if ch in " \t\r\f\v":
            i += 1
        elif ch == ";":
            break
        elif ch == "(":
            j = s.find(")", i + 1)
            if j < 0:
                raise GcodeError(ln, i + 1, raw[i:].strip(), "comment '(' is not closed on its line")
            i = j + 1
        elif ch == ")":
            raise GcodeError(ln, i + 1, ")", "')' without an opening '('")
        elif ch == "/" and not words and not deleted:
            deleted = True
            i += 1
        elif ch == "%" and not words and not deleted and _only_comments(s[i + 1 :]):
            return None
        elif "A" <= ch <= "Z":
            m = _NAME.match(s, i)
            if m is None:  # unreachable: a letter always matches
                raise GcodeError(ln, i + 1, raw[i], "unexpected character")
            name = m.group(0)
            j = _skip_blank(s, m.end())
            has_eq = j < n and s[j] == "="
            if len(name) > 1 and not has_eq:
                words.append(Word(name, None, raw[i : m.end()], i + 1))
                i = m.end()
                continue
            if has_eq:
                j = _skip_blank(s, j + 1)
            num = _NUMBER.match(s, j)
            if num is None:
                text = raw[i : max(j + 1, m.end())].strip()
                raise GcodeError(ln, i + 1, text, f"{name} must be followed by a number")
            value = float(num.group(0))
            if not math.isfinite(value):
                raise GcodeError(ln, i + 1, raw[i : num.end()], "number out of range")
            words.append(Word(name, value, raw[i : num.end()].replace(" ", ""), i + 1))
            i = num.end()
        else:
            raise GcodeError(ln, i + 1, raw[i], f"unexpected character {raw[i]!r} (expressions, parameters and "
                             "checksums are not supported)")
    if not words:
        return None
    return Block(ln, tuple(words), deleted)


def _skip_blank(s: str, i: int) -> int:
    while i < len(s) and s[i] in " \t":
        i += 1
    return i


def _only_comments(rest: str) -> bool:
    stripped = re.sub(r"\([^)]*\)", "", rest).split(";", 1)[0]
    return stripped.strip() == ""


# --------------------------------------------------------------------------- interpreter


def parse(
    text: str,
    *,
    units: str = "mm",
    start: Sequence[float] = (0.0, 0.0, 0.0),
    block_delete: bool = False,
) -> Program:
    """Read a G-code program (see the module docstring for what is supported).

    Args:
        text: the program.
        units: units in effect before any G20/G21: "mm" (default) or "inch".
        start: position (mm, program coordinates) before the first motion.
        block_delete: the block-delete switch: True skips blocks starting with '/'.
    Raises:
        GcodeError: naming line, column, word and rule.
    """
    if units not in ("mm", "inch"):
        raise GeometryError("units", units, "units must be 'mm' or 'inch'")
    p0 = np.asarray(start, dtype=np.float64)
    if p0.shape != (3,) or not np.all(np.isfinite(p0)):
        raise GeometryError("start", start, "start must be a finite [x, y, z] point in mm")
    interp = _Interpreter(units, p0)
    blocks = tokenize(text)
    for block in blocks:
        if block.deleted and block_delete:
            continue
        interp.block(block)
        if interp.ended:
            break
    interp.finish()
    return interp.program()


@dataclass
class _Fanuc:
    """An open G06.2 curve."""

    line: int
    col: int
    rank: int
    points: list[FloatArray] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)
    knots: list[tuple[float | None, int, int]] = field(default_factory=list)  # value, line, col
    knot_only: int = 0


@dataclass
class _Siemens:
    """An open BSPLINE."""

    line: int
    col: int
    degree: int | None = None
    points: list[FloatArray] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)
    spans: list[tuple[float | None, int, int]] = field(default_factory=list)  # PL, line, col
    first_line: int = 0


@dataclass
class _LinuxCnc:
    """An open G5.2 curve."""

    line: int
    col: int
    order: int
    points: list[FloatArray] = field(default_factory=list)
    weights: list[float] = field(default_factory=list)


class _Interpreter:
    def __init__(self, units: str, start: FloatArray) -> None:
        self.inch = units == "inch"
        self.pos = start.copy()
        self.plane = "G17"
        self.absolute = True
        self.arc_absolute = False
        self.motion: str | None = None
        self.feed: float | None = None  # mm/s
        self.ended = False
        self.segments: list[NurbsSegment] = []
        self.feeds: list[float | None] = []
        self.rapids: list[bool] = []
        self.lines: list[int] = []
        self.units_used: set[str] = set()
        self.ignored: list[tuple[int, str]] = []
        self.null_moves: list[int] = []
        self.fanuc: _Fanuc | None = None
        self.siemens: _Siemens | None = None
        self.lcnc: _LinuxCnc | None = None

    # ----------------------------------------------------------------- block

    def block(self, b: Block) -> None:
        ln = b.line
        words: dict[str, Word] = {}
        gcodes: list[tuple[int, Word]] = []
        mcodes: list[Word] = []
        for w in b.words:
            if w.name == "G":
                gcodes.append((self._gcode(w, ln), w))
            elif w.name == "M":
                mcodes.append(w)
            elif w.name in words:
                raise GcodeError(ln, w.col, w.text, f"{w.name} appears twice in one block")
            else:
                words[w.name] = w
        used: set[str] = set()
        if "N" in words:
            used.add("N")

        motion_word: Word | None = None
        new_motion: str | None = None
        end_lcnc: Word | None = None
        groups: dict[str, Word] = {}
        for code, w in gcodes:
            group = self._group(code, w, ln)
            if group in groups:
                raise GcodeError(ln, w.col, w.text, f"two G codes of one modal group in a block ({groups[group].text})")
            groups[group] = w
            if group == "motion":
                motion_word = w
                new_motion = _G_MOTION[code]
            elif group == "nurbs_end":
                end_lcnc = w
        if "BSPLINE" in words:
            kw = words["BSPLINE"]
            if motion_word is not None:
                raise GcodeError(ln, kw.col, kw.text, f"two motion commands in one block ({motion_word.text})")
            motion_word, new_motion = kw, "BSPLINE"
            used.add("BSPLINE")

        if self.fanuc is not None or self.lcnc is not None:
            self._check_curve_block(b, gcodes, words, motion_word)

        # close an open Siemens spline when the motion mode changes or the program ends
        if self.siemens is not None and new_motion is not None and new_motion != "BSPLINE":
            self._finish_siemens()

        for code, w in gcodes:
            self._modal(code, w, ln, words, used)
        for w in mcodes:
            self._mcode(w, ln)
        for name in ("S", "T", "O"):
            if name in words:
                self.ignored.append((ln, words[name].text))
                used.add(name)
        if "F" in words:
            self._feed(words["F"], ln, used)

        if new_motion is not None:
            self.motion = new_motion
        if end_lcnc is not None:
            self._end_lcnc(end_lcnc, ln, words, used)
        elif self.motion is not None:
            self._motion(b, words, used, motion_word, new_motion)
        self._leftovers(b, words, used)

    def _gcode(self, w: Word, ln: int) -> int:
        v = _val(w)
        code = round(v * 10)
        if abs(v * 10 - code) > 1e-9 or code < 0:
            raise GcodeError(ln, w.col, w.text, "unsupported G code (at most one decimal)")
        return code

    def _group(self, code: int, w: Word, ln: int) -> str:
        if code in _G_MOTION:
            return "motion"
        if code in _G_PLANE:
            return "plane"
        if code in (200, 210):
            return "units"
        if code in (900, 910):
            return "distance"
        if code in (901, 911):
            return "arc_distance"
        if code == 53:
            return "nurbs_end"
        if code in _G_NOOP or code in (50, 51):
            return f"noop{code}"
        if code in (930, 950):
            raise GcodeError(ln, w.col, w.text, "only feed per minute (G94) is supported (no inverse time G93 / per "
                             "revolution G95)")
        raise GcodeError(ln, w.col, w.text, f"unsupported G code {w.text}")

    def _modal(self, code: int, w: Word, ln: int, words: dict[str, Word], used: set[str]) -> None:
        if code in _G_PLANE:
            self.plane = _G_PLANE[code]
        elif code in (200, 210):
            self.inch = code == 200
        elif code in (900, 910):
            self.absolute = code == 900
        elif code in (901, 911):
            self.arc_absolute = code == 901
        elif code in (50, 51):
            # Fanuc high-speed modes G05 P10000 / P0 and G05.1 Q1 / Q0 (not LinuxCNC splines: no axis words)
            arg = "P" if code == 50 else "Q"
            allowed = {50: (0.0, 10000.0), 51: (0.0, 1.0)}[code]
            a = words.get(arg)
            if a is None or a.value not in allowed or any(x in words for x in _AXES):
                raise GcodeError(ln, w.col, w.text, f"only the Fanuc high-speed mode switch {w.text} {arg}"
                                 f"{int(allowed[1])} / {arg}0 is supported (LinuxCNC G5 / G5.1 splines are not)")
            used.add(arg)
            self.ignored.append((ln, f"{w.text} {a.text}"))
        elif code in _G_NOOP:
            self.ignored.append((ln, w.text))

    def _mcode(self, w: Word, ln: int) -> None:
        v = _val(w)
        if not v.is_integer():
            raise GcodeError(ln, w.col, w.text, "unsupported M code")
        m = int(v)
        if m in (98, 99):
            raise GcodeError(ln, w.col, w.text, "sub-programs (M98 / M99) are not supported")
        if self.fanuc is not None or self.lcnc is not None:
            raise GcodeError(ln, w.col, w.text, "M codes are not allowed inside a NURBS definition")
        self.ignored.append((ln, w.text))
        if m in (2, 30):
            self.ended = True

    def _feed(self, w: Word, ln: int, used: set[str]) -> None:
        value = _val(w)
        used.add("F")
        if not value > 0.0:
            raise GcodeError(ln, w.col, w.text, "feed rate F must be > 0")
        scale = MM_PER_INCH if self.inch else 1.0
        if value * scale / SECONDS_PER_MINUTE < MIN_FEED_MM_S:
            raise GcodeError(ln, w.col, w.text,
                             f"feed rate F must be at least {MIN_FEED_MM_S * SECONDS_PER_MINUTE:g} mm/min")
        if self.fanuc is not None and self.fanuc.points:
            raise GcodeError(ln, w.col, w.text, "F can only be given in the first block of a G06.2 curve")
        if self.lcnc is not None:
            raise GcodeError(ln, w.col, w.text, "F cannot change inside a G5.2 NURBS (one feed per curve)")
        if self.siemens is not None and self.siemens.first_line:
            raise GcodeError(ln, w.col, w.text, "F cannot change inside a B spline (one feed per curve)")
        self.feed = value * scale / SECONDS_PER_MINUTE

    # ----------------------------------------------------------------- motion

    def _motion(
        self, b: Block, words: dict[str, Word], used: set[str], motion_word: Word | None, new_motion: str | None
    ) -> None:
        mode = self.motion
        ln = b.line
        if mode in ("G00", "G01"):
            if any(a in words for a in _AXES):
                target = self._target(words, used)
                self._line(target, ln, words, mode == "G00", motion_word)
        elif mode in ("G02", "G03"):
            if any(a in words for a in _AXES) or any(k in words for k in "IJKR"):
                self._arc(words, used, ln, mode, motion_word)
        elif mode == "G06.2":
            self._fanuc_block(words, used, ln, motion_word if new_motion == "G06.2" else None)
        elif mode == "BSPLINE":
            self._siemens_block(words, used, ln, motion_word if new_motion == "BSPLINE" else None)
        elif mode == "G05.2":
            self._lcnc_block(words, used, ln, motion_word if new_motion == "G05.2" else None)

    def _target(self, words: dict[str, Word], used: set[str]) -> FloatArray:
        scale = MM_PER_INCH if self.inch else 1.0
        t = self.pos.copy()
        for k, a in enumerate(_AXES):
            if a in words:
                v = _val(words[a]) * scale
                t[k] = v if self.absolute else self.pos[k] + v
                used.add(a)
        return t

    def _first_col(self, words: dict[str, Word], names: str, fallback: Word | None) -> Word:
        for w in sorted(words.values(), key=lambda w: w.col):
            if w.name in names:
                return w
        if fallback is not None:
            return fallback
        return min(words.values(), key=lambda w: w.col)

    def _need_feed(self, ln: int, w: Word) -> float:
        if self.feed is None:
            raise GcodeError(ln, w.col, w.text, "cutting move without a feed rate: program F before or in this block")
        return self.feed

    def _emit(self, seg: NurbsSegment, ln: int, rapid: bool, feed: float | None) -> None:
        self.segments.append(seg)
        self.rapids.append(rapid)
        self.feeds.append(feed)
        self.lines.append(ln)
        self.units_used.add("inch" if self.inch else "mm")

    def _line(
        self, target: FloatArray, ln: int, words: dict[str, Word], rapid: bool, motion_word: Word | None
    ) -> None:
        feed = None if rapid else self._need_feed(ln, self._first_col(words, _AXES, motion_word))
        if float(np.linalg.norm(target - self.pos)) <= primitives.MIN_LENGTH_MM:
            self.null_moves.append(ln)
            return
        try:
            seg = primitives.line(self.pos, target, name=f"gcode:line {ln}")
        except GeometryError as exc:
            w = self._first_col(words, _AXES, motion_word)
            raise GcodeError(ln, w.col, w.text, exc.rule) from exc
        self._emit(seg, ln, rapid, feed)
        self.pos = target

    def _arc(self, words: dict[str, Word], used: set[str], ln: int, mode: str, motion_word: Word | None) -> None:
        a, b, nrm = primitives.PLANES[self.plane]
        scale = MM_PER_INCH if self.inch else 1.0
        feed = self._need_feed(ln, self._first_col(words, _AXES + "IJKR", motion_word))
        target = self._target(words, used)
        in_plane = (_OFFSETS[a], _OFFSETS[b])
        offsets = [words[k] for k in in_plane if k in words]
        centre: FloatArray | None = None
        radius: float | None = None
        if "R" in words and offsets:
            raise GcodeError(ln, words["R"].col, words["R"].text, "give either R or I J K for an arc, not both")
        if "R" in words:
            radius = _val(words["R"]) * scale
            used.add("R")
        elif offsets:
            if self.arc_absolute:
                missing = [k for k in in_plane if k not in words]
                if missing:
                    w = offsets[0]
                    raise GcodeError(ln, w.col, w.text, f"absolute arc centre (G90.1) needs both {in_plane[0]} and "
                                     f"{in_plane[1]} in plane {self.plane}")
                centre = self.pos.copy()
            else:
                centre = self.pos.copy()
            for k in in_plane:
                if k in words:
                    axis = _OFFSETS.index(k)
                    v = _val(words[k]) * scale
                    centre[axis] = v if self.arc_absolute else self.pos[axis] + v
                    used.add(k)
        else:
            w = self._first_col(words, _AXES, motion_word)
            raise GcodeError(ln, w.col, w.text, f"arc needs a centre ({in_plane[0]} {in_plane[1]} in plane "
                             f"{self.plane}) or a radius R")
        turns = 0
        if "P" in words:
            pw = words["P"]
            p = _val(pw)
            if not (p.is_integer() and p >= 1):
                raise GcodeError(ln, pw.col, pw.text, "P (number of turns) must be an integer >= 1")
            turns = int(p) - 1
            used.add("P")
        try:
            seg = primitives.arc(
                self.pos,
                target,
                centre=centre,
                radius=radius,
                plane=self.plane,
                direction="cw" if mode == "G02" else "ccw",
                turns=turns,
                name="arc",
            )
        except GeometryError as exc:
            w = self._arc_error_word(exc.field, words, motion_word, nrm)
            raise GcodeError(ln, w.col, w.text, exc.rule) from exc
        self._emit(seg, ln, False, feed)
        self.pos = target

    def _arc_error_word(self, fld: str, words: dict[str, Word], motion_word: Word | None, nrm: int) -> Word:
        if fld == f"arc.end[{nrm}]" and _AXES[nrm] in words:
            return words[_AXES[nrm]]
        if fld.startswith("arc.radius") and "R" in words:
            return words["R"]
        if fld.startswith("arc.centre"):
            return self._first_col(words, _OFFSETS, motion_word)
        if fld.startswith("arc.turns") and "P" in words:
            return words["P"]
        return self._first_col(words, _AXES + _OFFSETS, motion_word)

    # ----------------------------------------------------------------- Fanuc G06.2

    def _fanuc_block(self, words: dict[str, Word], used: set[str], ln: int, g62: Word | None) -> None:
        has_axes = any(a in words for a in _AXES)
        scale = MM_PER_INCH if self.inch else 1.0
        cur = self.fanuc
        if cur is None:
            if g62 is None and not (has_axes and "K" in words):
                if any(x in words for x in "KRP" + _AXES):
                    w = self._first_col(words, "KRP" + _AXES, None)
                    raise GcodeError(ln, w.col, w.text, "a G06.2 curve starts with a block holding K and a control "
                                     "point (or with G06.2)")
                return
            start = g62 if g62 is not None else self._first_col(words, "K" + _AXES, None)
            rank = FANUC_RANK_DEFAULT
            if "P" in words:
                pw = words["P"]
                if _val(pw) not in FANUC_RANKS:
                    raise GcodeError(ln, pw.col, pw.text, "NURBS rank P must be 2, 3 or 4 (degree 1 to 3)")
                rank = int(_val(pw))
                used.add("P")
            self._need_feed(ln, start)
            cur = _Fanuc(ln, start.col, rank)
            self.fanuc = cur
            # first control point: the current position
            if has_axes:
                first = self._fanuc_point(words, used, self.pos, scale)
                dev = float(np.linalg.norm(first - self.pos))
                if dev > START_TOL_MM:
                    w = self._first_col(words, _AXES, start)
                    raise GcodeError(ln, w.col, w.text, f"the first control point {_fmt(first)} must equal the current "
                                     f"position {_fmt(self.pos)} (Fanuc alarm PS1009; off by {dev:.6g} mm)")
            cur.points.append(self.pos.copy())
            cur.weights.append(self._fanuc_weight(words, used, ln))
            if "K" in words:
                cur.knots.append((_val(words["K"]), ln, words["K"].col))
                used.add("K")
            else:
                cur.knots.append((None, ln, start.col))
            return
        if "P" in words:
            raise GcodeError(ln, words["P"].col, words["P"].text, "rank P only in the first block of a G06.2 curve")
        if "K" not in words:
            w = self._first_col(words, _AXES + "R", g62)
            raise GcodeError(ln, w.col, w.text, "every block of a G06.2 curve needs a knot K (Fanuc alarm PS1002)")
        kw = words["K"]
        used.add("K")
        if has_axes:
            if cur.knot_only:
                w = self._first_col(words, _AXES, None)
                raise GcodeError(ln, w.col, w.text, f"control point after a knot-only block: a G06.2 curve ends with "
                                 f"exactly {cur.rank} knot-only blocks (Fanuc alarm PS1004)")
            cur.points.append(self._fanuc_point(words, used, cur.points[-1], scale))
            cur.weights.append(self._fanuc_weight(words, used, ln))
            cur.knots.append((_val(kw), ln, kw.col))
            return
        if "R" in words:
            raise GcodeError(ln, words["R"].col, words["R"].text, "a weight R needs a control point in its block")
        cur.knots.append((_val(kw), ln, kw.col))
        cur.knot_only += 1
        if cur.knot_only == cur.rank:
            self._finish_fanuc()

    def _fanuc_point(self, words: dict[str, Word], used: set[str], prev: FloatArray, scale: float) -> FloatArray:
        p = prev.copy()
        for k, a in enumerate(_AXES):
            if a in words:
                v = _val(words[a]) * scale
                p[k] = v if self.absolute else prev[k] + v
                used.add(a)
        return p

    def _fanuc_weight(self, words: dict[str, Word], used: set[str], ln: int) -> float:
        if "R" not in words:
            return 1.0
        rw = words["R"]
        used.add("R")
        if not _val(rw) > 0.0:
            raise GcodeError(ln, rw.col, rw.text, "NURBS weight R must be > 0")
        return _val(rw)

    def _finish_fanuc(self) -> None:
        cur = self.fanuc
        if cur is None:
            return
        self.fanuc = None
        knots = list(cur.knots)
        if knots[0][0] is None:
            if len(knots) < 2 or knots[1][0] is None:
                raise GcodeError(cur.line, cur.col, "G06.2", "knot K missing in the first block")
            knots[0] = (knots[1][0], knots[0][1], knots[0][2])
        U = np.array([k[0] for k in knots], dtype=np.float64)
        n, rank = len(cur.points), cur.rank
        p = rank - 1
        if n < rank:
            raise GcodeError(cur.line, cur.col, "G06.2", f"rank {rank} needs at least {rank} control points (got {n})")
        dec = np.flatnonzero(np.diff(U) < 0.0)
        if dec.size:
            i = int(dec[0]) + 1
            _, kl, kc = knots[i]
            raise GcodeError(kl, kc, f"K{U[i]:g}", f"knots must not decrease (previous knot {U[i - 1]:g})")
        for i in range(1, rank):
            for j in (i, len(U) - 1 - i):
                ref = 0 if j == i else len(U) - 1
                if U[j] != U[ref]:
                    _, kl, kc = knots[j]
                    end = "first" if j == i else "last"
                    raise GcodeError(kl, kc, f"K{U[j]:g}", f"the {end} {rank} knots must be equal (clamped curve, "
                                     f"Fanuc alarm PS1007); got {U[j]:g} and {U[ref]:g}")
        if not U[-1] > U[0]:
            _, kl, kc = knots[-1]
            raise GcodeError(kl, kc, f"K{U[-1]:g}", "the knots span an empty parameter range")
        run = 0
        for i in range(rank, len(U) - rank + 1):
            run = run + 1 if U[i] == U[i - 1] else 1
            limit = rank if i in (rank, len(U) - rank) else p
            if run > limit:
                _, kl, kc = knots[i]
                raise GcodeError(kl, kc, f"K{U[i]:g}", f"knot {U[i]:g} repeats too often: at most {rank} times at "
                                 f"the ends and {p} (rank - 1) inside (Fanuc alarm PS1008)")
        self._emit_nurbs(p, U, cur.points, cur.weights, cur.line, cur.col, "G06.2")

    def _fanuc_incomplete(self, cur: _Fanuc, ln: int, w: Word) -> None:
        raise GcodeError(ln, w.col, w.text, f"the G06.2 curve of line {cur.line} is not complete: it needs "
                         f"{cur.rank} knot-only blocks, got {cur.knot_only} (Fanuc alarm PS1005)")

    # ----------------------------------------------------------------- Siemens BSPLINE

    def _siemens_block(self, words: dict[str, Word], used: set[str], ln: int, kw: Word | None) -> None:
        scale = MM_PER_INCH if self.inch else 1.0
        cur = self.siemens
        if cur is None:
            start = kw if kw is not None else self._first_col(words, _AXES, None)
            cur = _Siemens(ln, start.col)
            cur.points.append(self.pos.copy())
            cur.weights.append(1.0)
            self.siemens = cur
        if "SD" in words:
            sd = words["SD"]
            used.add("SD")
            if _val(sd) not in SIEMENS_DEGREES:
                raise GcodeError(ln, sd.col, sd.text, "B spline degree SD must be 2 or 3")
            if len(cur.points) > 1 or (cur.degree is not None and cur.degree != int(_val(sd))):
                raise GcodeError(ln, sd.col, sd.text, "SD must be programmed on or before the first point of a "
                                 "B spline")
            cur.degree = int(_val(sd))
        has_axes = any(a in words for a in _AXES)
        if not has_axes:
            for name in ("PW", "PL"):
                if name in words:
                    w = words[name]
                    raise GcodeError(ln, w.col, w.text, f"{name} needs a point (X Y Z) in its block")
            return
        if not cur.first_line:
            cur.first_line = ln
            self._need_feed(ln, self._first_col(words, _AXES, kw))
        p = cur.points[-1].copy()
        for k, a in enumerate(_AXES):
            if a in words:
                v = _val(words[a]) * scale
                p[k] = v if self.absolute else cur.points[-1][k] + v
                used.add(a)
        weight = 1.0
        if "PW" in words:
            pw = words["PW"]
            used.add("PW")
            weight = _val(pw)
            if not 0.0 < weight <= SIEMENS_MAX_WEIGHT:
                raise GcodeError(ln, pw.col, pw.text, f"point weight PW must be in (0, {SIEMENS_MAX_WEIGHT:g}]")
        pl: float | None = None
        col = self._first_col(words, _AXES, None).col
        if "PL" in words:
            plw = words["PL"]
            used.add("PL")
            pl = _val(plw)
            col = plw.col
            if pl < 0.0:
                raise GcodeError(ln, plw.col, plw.text, "parameter interval length PL must be >= 0")
        cur.points.append(p)
        cur.weights.append(weight)
        cur.spans.append((pl, ln, col))
        self.pos = p

    def _finish_siemens(self) -> None:
        cur = self.siemens
        if cur is None:
            return
        self.siemens = None
        n = len(cur.points)
        if n == 1:
            return
        p = cur.degree if cur.degree is not None else SIEMENS_DEGREE_DEFAULT
        if n < p + 1:
            raise GcodeError(cur.line, cur.col, "BSPLINE", f"a degree-{p} B spline needs at least {p} points after "
                             f"its start point (got {n - 1})")
        spans = cur.spans[: n - p]
        tail = cur.spans[n - p :]
        for pl, kl, kc in tail:
            if pl is not None and pl != 0.0:
                raise GcodeError(kl, kc, f"PL={pl:g}", f"the last {p - 1} points of a degree-{p} B spline have no "
                                 "parameter interval: PL must be absent or 0 there")
        given = [s for s in spans if s[0] is not None]
        if given and len(given) != len(spans):
            _, kl, kc = next(s for s in spans if s[0] is None)
            raise GcodeError(kl, kc, "PL", "PL must be given on every point of the B spline or on none")
        for pl, kl, kc in given:
            if not (pl is not None and pl > 0.0):
                raise GcodeError(kl, kc, f"PL={pl:g}", f"the first {n - p} points of this B spline start a knot span: "
                                 "their PL must be > 0")
        h = np.array([s[0] for s in spans], dtype=np.float64) if given else np.ones(n - p)
        if not h.sum() > 0.0:
            raise GcodeError(cur.line, cur.col, "BSPLINE", "the parameter intervals PL sum to zero")
        inner = np.cumsum(h)
        U = np.concatenate([np.zeros(p + 1), inner[:-1], np.full(p + 1, inner[-1])])
        self._emit_nurbs(p, U, cur.points, cur.weights, cur.line, cur.col, "BSPLINE")

    # ----------------------------------------------------------------- LinuxCNC G5.2

    def _lcnc_block(self, words: dict[str, Word], used: set[str], ln: int, g52: Word | None) -> None:
        scale = MM_PER_INCH if self.inch else 1.0
        cur = self.lcnc
        if cur is None:
            if g52 is None:
                # G5.2 mode after G5.3: a block with words but no new G5.2 is not a control point
                if any(x in words for x in _AXES + "PL"):
                    w = self._first_col(words, _AXES + "PL", None)
                    raise GcodeError(ln, w.col, w.text, "control point outside a G5.2 ... G5.3 NURBS block")
                return
            if self.plane != "G17":
                raise GcodeError(ln, g52.col, g52.text, "G5.2 NURBS are planar in XY: select G17")
            if not self.absolute:
                raise GcodeError(ln, g52.col, g52.text, "G5.2 control points must be absolute (G90)")
            self._need_feed(ln, g52)
            order = LINUXCNC_ORDER_DEFAULT
            if "L" in words:
                lw = words["L"]
                used.add("L")
                if not (_val(lw).is_integer() and _val(lw) >= LINUXCNC_ORDER_DEFAULT):
                    raise GcodeError(ln, lw.col, lw.text, "NURBS order L must be an integer >= 3 (LinuxCNC uses 3 "
                                     "for smaller L)")
                if _val(lw) > MAX_DEGREE + 1:
                    raise GcodeError(ln, lw.col, lw.text, f"NURBS order L must be <= {MAX_DEGREE + 1} (degree "
                                     f"<= {MAX_DEGREE})")
                order = int(_val(lw))
            cur = _LinuxCnc(ln, g52.col, order)
            self.lcnc = cur
            w0 = 1.0
            if "X" not in words and "Y" not in words and "P" in words:
                w0 = self._lcnc_weight(words["P"], ln)
                used.add("P")
            cur.points.append(self.pos.copy())
            cur.weights.append(w0)
            if "X" not in words and "Y" not in words:
                return
        elif "L" in words:
            raise GcodeError(ln, words["L"].col, words["L"].text, "order L only in the first G5.2 block")
        if not self.absolute:
            w = self._first_col(words, _AXES, g52)
            raise GcodeError(ln, w.col, w.text, "G5.2 control points must be absolute (G90)")
        missing = [x for x in ("X", "Y", "P") if x not in words]
        if missing:
            w = self._first_col(words, _AXES + "P", g52)
            raise GcodeError(ln, w.col, w.text, f"a G5.2 control point needs X, Y and a weight P (missing "
                             f"{' '.join(missing)})")
        p = cur.points[-1].copy()
        p[0] = _val(words["X"]) * scale
        p[1] = _val(words["Y"]) * scale
        used.update(("X", "Y", "P"))
        cur.points.append(p)
        cur.weights.append(self._lcnc_weight(words["P"], ln))

    def _lcnc_weight(self, w: Word, ln: int) -> float:
        if not _val(w) > 0.0:
            raise GcodeError(ln, w.col, w.text, "G5.2 weight P must be > 0")
        return _val(w)

    def _end_lcnc(self, w: Word, ln: int, words: dict[str, Word], used: set[str]) -> None:
        cur = self.lcnc
        if cur is None:
            raise GcodeError(ln, w.col, w.text, "G5.3 without an open G5.2 NURBS")
        self.lcnc = None
        n, k = len(cur.points), cur.order
        if n < k:
            raise GcodeError(ln, w.col, w.text, f"an order-{k} G5.2 NURBS needs at least {k} control points "
                             f"(including the start point; got {n})")
        nn = n - 1
        i = np.arange(nn + k + 1)
        U = np.where(i < k, 0.0, np.where(i <= nn, i - k + 1.0, nn - k + 2.0))
        self._emit_nurbs(k - 1, U, cur.points, cur.weights, cur.line, cur.col, "G5.2")
        self.motion = None

    # ----------------------------------------------------------------- shared

    def _emit_nurbs(
        self,
        degree: int,
        knots: FloatArray,
        points: list[FloatArray],
        weights: list[float],
        ln: int,
        col: int,
        word: str,
    ) -> None:
        try:
            seg = NurbsSegment.create(degree, knots, np.array(points), np.array(weights), name=f"gcode:line {ln}")
        except GeometryError as exc:
            raise GcodeError(ln, col, word, exc.rule) from exc
        self._emit(seg, ln, False, self.feed)
        self.pos = points[-1].copy()

    def _check_curve_block(
        self, b: Block, gcodes: list[tuple[int, Word]], words: dict[str, Word], motion_word: Word | None
    ) -> None:
        ln = b.line
        if self.lcnc is not None and motion_word is not None:
            raise GcodeError(ln, motion_word.col, motion_word.text, f"the G5.2 NURBS of line {self.lcnc.line} must be "
                             "closed with G5.3 first")
        if self.fanuc is not None and motion_word is not None:
            self._fanuc_incomplete(self.fanuc, ln, motion_word)
        for code, w in gcodes:
            if code in _G_MOTION or code == 53:
                continue
            raise GcodeError(ln, w.col, w.text, "only control-point words may appear inside a NURBS definition")
        for name in ("S", "T", "O"):
            if name in words:
                w = words[name]
                raise GcodeError(ln, w.col, w.text, "only control-point words may appear inside a NURBS definition")

    def _leftovers(self, b: Block, words: dict[str, Word], used: set[str]) -> None:
        for w in sorted(words.values(), key=lambda w: w.col):
            if w.name in used:
                continue
            if len(w.name) == 1 and w.name in "ABCUVW":
                rule = f"axis {w.name} is not supported (only X Y Z)"
            elif w.name in _NAMED:
                rule = f"{w.name} is only used on B spline points (BSPLINE mode)"
            elif len(w.name) > 1 or w.name not in _KNOWN:
                rule = f"unsupported word {w.text}"
            elif w.name in _AXES and self.motion is None:
                rule = f"{w.name} is not used here: no motion mode is active (program G00/G01/G02/G03 first)"
            else:
                rule = f"word {w.name} is not used in this block ({self.motion}, plane {self.plane})"
                if self.motion == "G05.2" and w.name == "Z":
                    rule += ": G5.2 NURBS are planar in XY"
            raise GcodeError(b.line, w.col, w.text, rule)

    def finish(self) -> None:
        if self.fanuc is not None:
            cur = self.fanuc
            raise GcodeError(cur.line, cur.col, "G06.2", f"the program ends inside this G06.2 curve: it needs "
                             f"{cur.rank} knot-only blocks, got {cur.knot_only} (Fanuc alarm PS1004)")
        if self.lcnc is not None:
            cur2 = self.lcnc
            raise GcodeError(cur2.line, cur2.col, "G5.2", "the program ends inside this G5.2 NURBS: close it with G5.3")
        if self.siemens is not None:
            self._finish_siemens()

    def program(self) -> Program:
        units = "mixed" if len(self.units_used) > 1 else (next(iter(self.units_used)) if self.units_used else
                                                          ("inch" if self.inch else "mm"))
        return Program(
            segments=tuple(self.segments),
            feed=tuple(self.feeds),
            rapid=tuple(self.rapids),
            line=tuple(self.lines),
            units=units,
            ignored=tuple(self.ignored),
            null_moves=tuple(self.null_moves),
        )


def _val(w: Word) -> float:
    """A word's number (every non-keyword word has one)."""
    if w.value is None:  # keywords never reach here; kept for the type checker
        raise GcodeError(0, w.col, w.text, "word without a value")
    return w.value


def _fmt(p: FloatArray) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"
