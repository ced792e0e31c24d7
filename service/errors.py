"""The one place where failures become HTTP: RFC 9457 problem documents.

``problem_from_exception`` turns any exception (validation, geometry, solver,
budget, internal) into a plain dict ``{"type", "title", "status", "detail",
"errors": [{"field", "pointer", "value", "rule"}]}``.  Worker processes use it
too, so a failure crosses the process boundary as JSON-able data (typed
exceptions with keyword-only fields do not survive pickling).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from pydantic import ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match, Route

from geometry import GeometryError
from service.schemas import MEDIA_PROBLEM, UNION_TAGS
from solvers.errors import OutputTooLargeError, ScheduleError

log = logging.getLogger("feedsched.service")
TYPE_BASE = "urn:feedsched:problem:"


class ServiceError(Exception):
    """A failure the service itself detects (budget, missing job, conflict...)."""

    def __init__(self, status: int, slug: str, title: str, detail: str, *, field: str | None = None,
                 value: Any = None, rule: str | None = None, headers: dict[str, str] | None = None,
                 **extra: Any) -> None:
        super().__init__(detail)
        self.status = status
        self.slug = slug
        self.title = title
        self.detail = detail
        self.field = field
        self.value = value
        self.rule = rule or detail
        self.headers = headers
        self.extra = extra


class WorkFailed(Exception):
    """Solver-side work ended with a problem document (computed where the work ran)."""

    def __init__(self, problem: dict[str, Any]) -> None:
        super().__init__(problem.get("detail", "failed"))
        self.problem = problem


class WorkTimeout(Exception):
    """Solver work ran over its time budget and was killed."""


class WorkerLost(Exception):
    """The process (or Dask worker) doing the work died without a result."""


def too_large(detail: str, *, field: str | None = None, value: Any = None, rule: str | None = None) -> ServiceError:
    """413 for work over the synchronous budget, pointing at the job API."""
    return ServiceError(413, "too-large", "Request over the synchronous budget", detail, field=field, value=value,
                        rule=rule, jobs="/v1/jobs")


def not_found(what: str, value: Any = None, field: str = "path") -> ServiceError:
    """404; ``field``: the path parameter that names the missing resource (``path.job_id``), as a 422 names it."""
    return ServiceError(404, "not-found", "Not found", f"{what} not found", field=field, value=value,
                        rule="must name an existing resource")


#: Characters of a string echoed as an error's value (a program of megabytes is not sent back whole).
VALUE_CHARS = 1000


def text_of(s: str, most: int = VALUE_CHARS) -> str:
    """``s`` as UTF-8 can carry it: a lone surrogate (JSON's "\\ud800", which no UTF-8 encodes) as its escape,
    and at most ``most`` characters."""
    s = s.encode("utf-8", "backslashreplace").decode("utf-8")
    return s if len(s) <= most else s[: most - 3] + "..."


#: How deep ``jsonable`` echoes lists and objects; deeper ones read "...".
VALUE_DEPTH = 8


def jsonable(v: Any, depth: int = VALUE_DEPTH) -> Any:
    """Plain JSON value (NaN/Inf become strings, unknown objects their repr, strings ``text_of``), at most 20 items
    a level and ``depth`` levels deep (a body nested 900 deep was echoed level by level: RecursionError, a 500)."""
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    if isinstance(v, (list, tuple, dict)) and depth <= 0:
        return "..."
    if isinstance(v, (list, tuple)):
        return [jsonable(x, depth - 1) for x in v[:20]] + (["..."] if len(v) > 20 else [])
    if isinstance(v, dict):
        return {text_of(str(k), 200): jsonable(x, depth - 1) for k, x in list(v.items())[:20]}
    if isinstance(v, str):
        return text_of(v)
    if isinstance(v, (int, float, bool)) or v is None:
        return v
    return text_of(repr(v), 200)


def field_path(loc: Sequence[Any]) -> tuple[str, str]:
    """("body", "toolpath", "segments", 0, "knots") -> ("toolpath.segments[0].knots", "#/toolpath/segments/0/knots")."""
    parts = [text_of(p, 200) if isinstance(p, str) else p for p in loc if p not in UNION_TAGS]
    if parts and parts[0] in ("body", "query", "path", "header"):
        parts = parts[1:] if parts[0] in ("body", "header") else parts  # (a header by its own name)
    text = ""
    for p in parts:
        text += f"[{p}]" if isinstance(p, int) else (f".{p}" if text else str(p))
    pointer = "#/" + "/".join(str(p).replace("~", "~0").replace("/", "~1") for p in parts)
    return text, pointer


def pointer_of(field: str | None) -> str | None:
    """'toolpath.segments[0].knots' -> '#/toolpath/segments/0/knots'."""
    if not field:
        return None
    if field.startswith("gcode:"):  # a program's line ("gcode:line 3:col 5"): the program's own field
        return "#/toolpath/gcode"
    return "#/" + field.replace("[", ".").replace("]", "").replace(".", "/")


def _problem(status: int, slug: str, title: str, detail: str, errors: list[dict[str, Any]],
             **extra: Any) -> dict[str, Any]:
    return {"type": TYPE_BASE + slug, "title": title, "status": status, "detail": detail, "errors": errors,
            **{k: jsonable(v) for k, v in extra.items() if v is not None}}


def _entry(field: str | None, value: Any, rule: str) -> dict[str, Any]:
    return {"field": field, "pointer": pointer_of(field), "value": jsonable(value), "rule": rule}


def validation_problem(errors: Sequence[Any]) -> dict[str, Any]:
    out = []
    for e in errors:
        if e.get("type") == "json_invalid":  # (loc ("body", character offset): not a field of the body)
            loc = e.get("loc", ())
            why = (e.get("ctx") or {}).get("error")
            at = loc[-1] if len(loc) > 1 and isinstance(loc[-1], int) and why != NESTED_TOO_DEEP else None
            rule = "the body must be JSON" + (f": {why}" if why else "") + ("" if at is None else f" at character {at}")
            out.append({"field": "body", "pointer": "#", "value": None if at is None else f"character {at}",
                        "rule": rule})
            continue
        text, pointer = field_path(e.get("loc", ()))
        out.append({"field": text, "pointer": pointer, "value": jsonable(e.get("input")),
                    "rule": text_of(str(e.get("msg", "")))})
    first: dict[str, Any] = out[0] if out else {"field": None, "rule": "invalid"}
    detail = f"{first['field']}: {first['rule']}" if first["field"] else str(first["rule"])
    return _problem(422, "invalid-request", "Invalid request", detail, out)


def renamed(exc: BaseException, names: dict[str, str]) -> BaseException:
    """``exc`` as a WorkFailed whose problem names its fields by ``names`` (request field -> the name the client
    sent it under; e.g. the G-code upload's query parameters), or ``exc`` itself when it names none of them."""
    problem = problem_from_exception(exc)
    errs = problem.get("errors") or []
    if not any(e.get("field") in names or e.get("pointer") in map(pointer_of, names) for e in errs):
        return exc
    pointers = {pointer_of(k): "#" if v == "body" else pointer_of(v) for k, v in names.items()}
    out = [{**e, "field": names.get(e.get("field"), e.get("field")),
            "pointer": pointers.get(e.get("pointer"), e.get("pointer"))} for e in errs]
    detail = str(problem.get("detail", ""))
    for old, new in names.items():  # (a detail that starts with the field's name: ScheduleError's str)
        if detail.startswith(old + ":"):
            detail = new + detail[len(old):]
            break
    return WorkFailed({**problem, "errors": out, "detail": detail})


def problem_from_exception(exc: BaseException) -> dict[str, Any]:
    """Map any failure to a problem dict (the only exception -> HTTP status mapping)."""
    if isinstance(exc, WorkFailed):
        return dict(exc.problem)
    if isinstance(exc, WorkTimeout):
        return _problem(413, "too-large", "Over the time budget", str(exc),
                        [_entry(None, None, "solver work must finish within the time budget; submit long paths "
                                "to /v1/jobs")], jobs="/v1/jobs")
    if isinstance(exc, WorkerLost):
        return _problem(503, "worker-lost", "Solver worker lost", str(exc),
                        [_entry(None, None, "the worker process died; retry")])
    if isinstance(exc, ServiceError):
        return _problem(exc.status, exc.slug, exc.title, exc.detail, [_entry(exc.field, exc.value, exc.rule)],
                        **exc.extra)
    if isinstance(exc, (RequestValidationError, ValidationError)):
        return validation_problem(exc.errors())
    if isinstance(exc, GeometryError):
        return _problem(422, "invalid-toolpath", "Invalid toolpath", str(exc), [_entry(exc.field, exc.value, exc.rule)],
                        segment=exc.segment)
    if isinstance(exc, OutputTooLargeError):
        return _problem(413, "too-large", "Output over the budget", str(exc), [_entry(exc.field, exc.value, exc.rule)],
                        jobs="/v1/jobs")
    if isinstance(exc, ScheduleError):
        kind = type(exc).__name__
        slug = {"InvalidMachineError": "invalid-machine", "ResolutionError": "invalid-machine",
                "InvalidOptionsError": "invalid-options",
                "InfeasibleError": "infeasible", "SolverFailure": "solver-failure"}.get(kind, "cannot-schedule")
        return _problem(422, slug, "Cannot schedule", str(exc), [_entry(exc.field, exc.value, exc.rule)],
                        window=exc.window, axis=exc.axis, solver_status=exc.status)
    if isinstance(exc, MemoryError):
        return _problem(413, "too-large", "Out of memory", "the request needs more memory than the service has",
                        [_entry(None, None, "submit a smaller path or a coarser sample period")], jobs="/v1/jobs")
    log.error("internal error", exc_info=exc)
    return _problem(500, "internal", "Internal error", f"{type(exc).__name__}: {exc}"[:500],
                    [_entry(None, None, "unexpected failure; please report it")])


class _ProblemJSON(JSONResponse):
    def render(self, content: Any) -> bytes:
        try:
            return super().render(content)
        except UnicodeEncodeError:  # a lone surrogate that ``text_of`` did not see: ASCII escapes carry it
            return json.dumps(content, ensure_ascii=True, allow_nan=False, separators=(",", ":")).encode("ascii")


def problem_response(problem: dict[str, Any], instance: str | None = None,
                     headers: dict[str, str] | None = None) -> JSONResponse:
    body = dict(problem)
    if instance:
        body.setdefault("instance", instance)
    return _ProblemJSON(body, status_code=int(body["status"]), media_type=MEDIA_PROBLEM, headers=headers)


#: The scope key ``service.http.HeadAsGet`` sets on a HEAD request it passes on as GET (a 405 names HEAD).
HEAD_KEY = "feedsched.head"
#: The parse error of a JSON body nested deeper than Python's parser goes (~900 levels: what the stack leaves;
#: ``service.http.UniqueNamesRequest``), a 422 with no character offset.
NESTED_TOO_DEEP = "arrays and objects nested too deep (Python's parser takes about 900 levels)"
#: The scope key ``service.http.UniqueNamesRequest`` sets when a JSON body names a member twice in one object.
DUPLICATE_KEY = "feedsched.duplicate_name"


def allowed_methods(request: Request) -> list[str]:
    """Every method some route of the app takes at the request's path: Starlette's 405 named the first route's only
    (``Allow: GET`` on /v1/jobs/{job_id}, which DELETE cancels; FastAPI makes a route per method)."""
    methods = {m for r in request.app.router.routes if isinstance(r, Route)
               and r.matches(request.scope)[0] != Match.NONE for m in (r.methods or ())}
    if "GET" in methods:  # (``service.http.HeadAsGet`` answers HEAD wherever GET is taken)
        methods.add("HEAD")
    return sorted(methods)


def install_handlers(app: FastAPI) -> None:
    """Every 4xx/5xx leaves as application/problem+json."""

    async def _any(request: Request, exc: Exception) -> JSONResponse:
        headers = dict(exc.headers or {}) if isinstance(exc, ServiceError) else {}
        problem = problem_from_exception(exc)
        if problem["status"] == 503:  # busy, worker lost: worth retrying, say when
            headers.setdefault("Retry-After", str(problem.get("retry_after_s", 1)))
        return problem_response(problem, request.url.path, headers=headers or None)

    async def _http(request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, StarletteHTTPException)
        slug = {400: "bad-request", 404: "not-found", 405: "method-not-allowed", 406: "not-acceptable",
                413: "too-large", 415: "unsupported-media-type"}.get(exc.status_code, "http-error")
        title = {400: "Bad request", 404: "Not found", 405: "Method not allowed", 413: "Request body too large",
                 415: "Unsupported Media Type"}.get(exc.status_code, "HTTP error")
        rule = {400: "the body must be UTF-8 JSON", 404: "no such route",
                405: "method not allowed on this route"}.get(exc.status_code, str(exc.detail))
        field = {400: "body", 404: "path", 405: "path", 413: "body"}.get(exc.status_code)
        value = None if exc.status_code in (400, 413) else request.url.path
        # an exception that names its own entry (``service.http.BodyTooLarge``)
        field, value, rule = (getattr(exc, "field", field), getattr(exc, "value", value), getattr(exc, "rule", rule))
        headers = dict(exc.headers or {})
        if exc.status_code == 405:
            allowed = allowed_methods(request)
            headers["Allow"] = ", ".join(allowed)
            method = "HEAD" if request.scope.get(HEAD_KEY) else request.method
            rule = f"{method} is not allowed on this route; it allows {', '.join(allowed)}"
        p = _problem(exc.status_code, slug, title, str(exc.detail), [_entry(field, value, rule)])
        return problem_response(p, request.url.path, headers=headers)

    for cls in (RequestValidationError, GeometryError, ScheduleError, ServiceError, WorkFailed, WorkTimeout,
                WorkerLost):
        app.add_exception_handler(cls, _any)
    app.add_exception_handler(StarletteHTTPException, _http)
    app.add_exception_handler(Exception, _any)
