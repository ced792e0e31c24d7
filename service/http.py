"""HTTP plumbing: content negotiation, response rendering, the request body cap, JSON bodies' duplicate names."""

from __future__ import annotations

import json
from collections.abc import AsyncGenerator, AsyncIterator, Callable, Coroutine
from typing import Any

import anyio
from fastapi import Request
from fastapi.routing import APIRoute
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.responses import Response, StreamingResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.convert import (
    JSON_STREAM_ROWS,
    Result,
    encode_json,
    iter_csv,
    iter_json,
    iter_ndjson,
    ndjson_error,
    ndjson_summary,
)
from service.errors import (
    DUPLICATE_KEY,
    HEAD_KEY,
    NESTED_TOO_DEEP,
    ServiceError,
    WorkerLost,
    problem_from_exception,
    problem_response,
    renamed,
)
from service.schemas import MEDIA_CSV, MEDIA_JSON, MEDIA_NDJSON

FORMATS = (MEDIA_JSON, MEDIA_CSV, MEDIA_NDJSON)
#: ?format= values of the result routes (links cannot set Accept).
FORMAT_NAMES = {"json": MEDIA_JSON, "csv": MEDIA_CSV, "ndjson": MEDIA_NDJSON}


def negotiate(accept: str | None, offers: tuple[str, ...] = FORMATS) -> str:
    """Best of ``offers`` (JSON, CSV, NDJSON) for an Accept header (the first offer when absent or */*); 406 when
    none fits.  A request that only JSON can carry (``options.plots``) offers JSON alone: ``application/json;q=0.1,
    text/csv`` then reads JSON, the one format the client takes that can answer it.

    As RFC 9110 12.5.1: each format takes the q of the most specific range that matches it (``text/csv;q=0,
    text/*`` refuses CSV), parameter names are case-insensitive, and a q that is not a number in [0, 1] makes its
    range refuse (it was read as given: ``q=nan`` or ``q=inf`` won).  Ties go to the range named first, then to
    JSON, CSV, NDJSON in that order."""
    if not accept:
        return offers[0]
    ranges: list[tuple[str, float, int]] = []
    for i, part in enumerate(accept.split(",")):
        fields = [f.strip() for f in part.split(";")]
        q = 1.0
        for f in fields[1:]:
            key, _, val = f.partition("=")
            if key.strip().lower() == "q":
                q = _qvalue(val.strip())
        ranges.append((fields[0].lower(), q, i))
    best: tuple[float, int, str] | None = None
    for m in offers:
        names = (m, m.split("/")[0] + "/*", "*/*")  # most specific first
        matched = [(names.index(r), q, i) for r, q, i in ranges if r in names]
        if not matched:
            continue
        _, q, i = min(matched, key=lambda t: (t[0], t[2]))
        if q > 0 and (best is None or (q, -i) > best[:2]):
            best = (q, -i, m)
    if best is None:
        raise ServiceError(406, "not-acceptable", "Not Acceptable", f"Accept {accept!r} matches none of "
                           f"{', '.join(offers)}", field="Accept", value=accept,
                           rule=f"Accept must admit one of {', '.join(offers)} (or */*)")
    return best[2]


class _Pairs(list[tuple[str, Any]]):
    """A JSON object as its name/value pairs in order (``json.loads``' ``object_pairs_hook``)."""


def duplicate_name(body: bytes | str) -> tuple[tuple[str | int, ...], str, int] | None:
    """The first name given twice in one object of a JSON document: (the object's path, the name, how many
    times), in document order; None when every object's names are distinct.  Only run on a body whose parse saw
    one (``UniqueNamesRequest``): it keeps every pair.  Walked with a stack of its own, not recursion (a body
    nested ~900 deep parses)."""
    stack: list[tuple[Any, tuple[str | int, ...]]] = [(json.loads(body, object_pairs_hook=_Pairs), ())]
    while stack:
        v, at = stack.pop()
        if isinstance(v, _Pairs):
            seen: set[str] = set()
            for k, _ in v:  # (one pass: a count per name took 4.5 s on 20,000 names repeating the last, 0.01 s so)
                if k in seen:
                    return at, k, sum(1 for n, _ in v if n == k)
                seen.add(k)
            items: list[tuple[str | int, Any]] = list(v)
        elif isinstance(v, list):
            items = list(enumerate(v))
        else:
            continue
        stack.extend(((x, (*at, step)) for step, x in reversed(items)))  # (document order: the first on top)
    return None


class _NameCheck:
    """``object_pairs_hook`` building the dicts ``json.loads`` would, noting whether any object repeats a name."""

    def __init__(self) -> None:
        self.repeated = False

    def __call__(self, pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        d = dict(pairs)
        if len(d) != len(pairs):
            self.repeated = True
        return d


class UniqueNamesRequest(Request):
    """A request whose JSON body notes a name given twice in one object (RFC 8259 4: such an object's meaning is
    not defined; Python's parser kept the last, so ``{"feed_max": 500, ..., "feed_max": 5000}`` ran at 5000)
    under ``scope[DUPLICATE_KEY]`` as ``duplicate_name``'s finding, for the route's dependency to refuse.  The body
    is parsed once, as FastAPI would."""

    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            body = await self.body()
            check = _NameCheck()
            try:
                self._json = json.loads(body, object_pairs_hook=check)
                if check.repeated:  # (parsed again a frame deeper: inside the try too)
                    self.scope[DUPLICATE_KEY] = duplicate_name(body)
            except RecursionError as exc:  # (FastAPI read it as any other failure: 400 "must be UTF-8 JSON")
                raise json.JSONDecodeError(NESTED_TOO_DEEP, "", 0) from exc
        return self._json


class UniqueNamesRoute(APIRoute):
    """The routes' class: their handlers read the request as a ``UniqueNamesRequest``."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def route_handler(request: Request) -> Response:
            return await handler(UniqueNamesRequest(request.scope, request.receive))
        return route_handler


def _qvalue(text: str) -> float:
    """An Accept range's weight: a number in [0, 1], else 0 (the range refuses)."""
    try:
        q = float(text)
    except ValueError:
        return 0.0
    return q if 0.0 <= q <= 1.0 else 0.0


async def render(res: Result, media: str, headers: dict[str, str] | None = None,
                 plots: dict[str, str] | None = None) -> Response:
    hdrs = {"X-Samples": str(len(res.columns.get("t", ()))), **(headers or {})}
    if media == MEDIA_CSV:
        return StreamingResponse(iter_csv(res), media_type="text/csv; charset=utf-8", headers=hdrs)
    if media == MEDIA_NDJSON:
        return StreamingResponse(iter_ndjson(res), media_type=MEDIA_NDJSON, headers=hdrs)
    if int(hdrs["X-Samples"]) > JSON_STREAM_ROWS:  # (a long job's result: never the whole body at once)
        return StreamingResponse(iter_json(res, plots), media_type=MEDIA_JSON, headers=hdrs)
    body = await run_in_threadpool(encode_json, res, plots)
    return Response(body, media_type=MEDIA_JSON, headers=hdrs)


#: The NDJSON protocol, as the README and the OpenAPI description state it.
NDJSON_PROTOCOL = (
    "NDJSON (`Accept: application/x-ndjson`): one JSON object per sample and line (the sample columns as keys; "
    "from POST /v1/schedule streamed: a piece's rows, rest to rest between corners, are sent once that piece has "
    "been solved and its samples re-checked, while later pieces are solved), then exactly one final line with "
    "an `event` key: `{\"event\": \"summary\", \"summary\": "
    "{...}, \"diagnostics\": {...}}` when the schedule is complete, or `{\"event\": \"error\", \"type\": "
    "..., \"title\": ..., \"status\": ..., \"detail\": ..., \"errors\": [...]}` (the problem+json fields) "
    "when it failed after rows were sent (the HTTP status is 200 by then; a failure before the first row is an "
    "ordinary problem+json response). The rows before an error line are not a schedule: discard them. A stream "
    "that ends without the summary line (connection lost) is incomplete as well."
)


def ndjson_stream(first: tuple[str, Any], events: AsyncGenerator[tuple[str, Any], None], release: Callable[[], None],
                  instance: str | None = None, names: dict[str, str] | None = None) -> StreamingResponse:
    """A 200 NDJSON response from an executor stream whose ``first`` event has already arrived (so failures
    before any row can still be answered with their own status).  Rows are forwarded as they come; the
    stream ends with the summary line, or with an error line (NDJSON_PROTOCOL).  ``release`` (the admission
    slot) runs once the work has stopped, however the response ends.  ``names``: an error line's fields by the
    names the client sent them under (``errors.renamed``)."""

    async def body() -> AsyncIterator[bytes]:
        try:
            item = first
            while True:
                kind, payload = item
                if kind != "rows":
                    yield ndjson_summary(payload["summary"], payload["diagnostics"])
                    return
                yield payload
                item = await anext(events)
        except StopAsyncIteration:
            yield ndjson_error({**problem_from_exception(WorkerLost("the solver stream ended without its "
                                                                    "summary")), "instance": instance})
        except Exception as exc:  # after rows: the failure goes in-band, as the last line
            yield ndjson_error({**problem_from_exception(renamed(exc, names) if names else exc), "instance": instance})
        finally:
            try:
                await events.aclose()
            finally:
                release()

    return ClosingStream(body(), media_type=MEDIA_NDJSON)


class ClosingStream(StreamingResponse):
    """A streaming response that notices a client going away while it waits for the next chunk (not only
    when a send fails), and always closes its body iterator (runs its ``finally``: stops the work)."""

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            async with anyio.create_task_group() as tg:

                async def watch() -> None:
                    await self.listen_for_disconnect(receive)
                    tg.cancel_scope.cancel()

                tg.start_soon(watch)
                try:
                    await self.stream_response(send)
                except OSError:  # the client went away while we were sending
                    pass
                tg.cancel_scope.cancel()
        finally:
            with anyio.CancelScope(shield=True):
                aclose = getattr(self.body_iterator, "aclose", None)
                if aclose is not None:
                    await aclose()


class BodyTooLarge(HTTPException):
    """A body streamed past the cap (no Content-Length to refuse it by): raised while the route reads it."""

    def __init__(self, limit: int, seen: int) -> None:
        super().__init__(413, f"request body larger than {limit} bytes (FEEDSCHED_MAX_BODY_BYTES)")
        #: the problem's entry (``service.errors``' handler of HTTP exceptions reads these)
        self.field, self.value = "body", f"more than {limit} bytes ({seen} read)"
        self.rule = f"body must be <= {limit} bytes (FEEDSCHED_MAX_BODY_BYTES)"


class BodyLimit:
    """ASGI middleware: 413 problem+json for bodies over ``max_bytes`` (declared or streamed)."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        for k, v in scope.get("headers", ()):
            if k == b"content-length":
                try:
                    declared = int(v)
                except ValueError:
                    declared = 0
                if declared > self.max_bytes:
                    resp = problem_response(problem_from_exception(_as_service_error(self.max_bytes, declared)),
                                            scope.get("path"))
                    await resp(scope, receive, send)
                    return
        seen = 0

        async def limited() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > self.max_bytes:
                    raise BodyTooLarge(self.max_bytes, seen)
            return msg

        await self.app(scope, limited, send)


class HeadAsGet:
    """ASGI middleware: HEAD is answered as GET without its body (RFC 9110 9.3.2: the same status and headers).
    FastAPI routes take only the methods they name, and ``HEAD /v1/machines`` or a job's result was a 405; a path
    with no GET route still answers 405, its ``Allow`` from ``errors.allowed_methods``."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return

        async def headers_only(msg: Message) -> None:
            if msg["type"] == "http.response.body":
                if msg.get("more_body", False):
                    return
                msg = {"type": "http.response.body", "body": b"", "more_body": False}
            await send(msg)

        await self.app({**scope, "method": "GET", HEAD_KEY: True}, receive, headers_only)


def _as_service_error(limit: int, size: Any) -> Exception:
    return ServiceError(413, "too-large", "Request body too large", f"request body of {size} bytes is larger than "
                        f"{limit} bytes", field="body", value=size, rule=f"body must be <= {limit} bytes "
                        "(FEEDSCHED_MAX_BODY_BYTES)")
