"""HTTP plumbing: content negotiation, response rendering, the request body cap."""

from __future__ import annotations

from typing import Any

from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException
from starlette.responses import Response, StreamingResponse
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.convert import Result, encode_json, iter_csv, iter_ndjson
from service.errors import problem_from_exception, problem_response
from service.schemas import MEDIA_CSV, MEDIA_JSON, MEDIA_NDJSON

FORMATS = (MEDIA_JSON, MEDIA_CSV, MEDIA_NDJSON)
#: ?format= values of the result routes (links cannot set Accept).
FORMAT_NAMES = {"json": MEDIA_JSON, "csv": MEDIA_CSV, "ndjson": MEDIA_NDJSON}


def negotiate(accept: str | None) -> str:
    """Best of JSON, CSV, NDJSON for an Accept header (JSON when absent or */*); 406 when none fits."""
    if not accept:
        return MEDIA_JSON
    best: tuple[float, int, str] | None = None
    for i, part in enumerate(accept.split(",")):
        fields = [f.strip() for f in part.split(";")]
        media = fields[0].lower()
        q = 1.0
        for f in fields[1:]:
            if f.startswith("q="):
                try:
                    q = float(f[2:])
                except ValueError:
                    q = 0.0
        if q <= 0:
            continue
        matches = [m for m in FORMATS if media in (m, "*/*", m.split("/")[0] + "/*")]
        for m in matches:
            cand = (q, -i, m)
            if best is None or cand[:2] > best[:2]:
                best = cand
    if best is None:
        raise HTTPException(406, f"Accept {accept!r} matches none of {', '.join(FORMATS)}")
    return best[2]


async def render(res: Result, media: str, headers: dict[str, str] | None = None,
                 plots: dict[str, str] | None = None) -> Response:
    hdrs = {"X-Samples": str(len(res.columns.get("t", ()))), **(headers or {})}
    if media == MEDIA_CSV:
        return StreamingResponse(iter_csv(res), media_type="text/csv; charset=utf-8", headers=hdrs)
    if media == MEDIA_NDJSON:
        return StreamingResponse(iter_ndjson(res), media_type=MEDIA_NDJSON, headers=hdrs)
    body = await run_in_threadpool(encode_json, res, plots)
    return Response(body, media_type=MEDIA_JSON, headers=hdrs)


class BodyTooLarge(HTTPException):
    def __init__(self, limit: int) -> None:
        super().__init__(413, f"request body larger than {limit} bytes (FEEDSCHED_MAX_BODY_BYTES)")


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
                    raise BodyTooLarge(self.max_bytes)
            return msg

        await self.app(scope, limited, send)


def _as_service_error(limit: int, size: Any) -> Exception:
    from service.errors import ServiceError

    return ServiceError(413, "too-large", "Request body too large", f"request body of {size} bytes is larger than "
                        f"{limit} bytes", field="body", value=size, rule=f"body must be <= {limit} bytes "
                        "(FEEDSCHED_MAX_BODY_BYTES)")
