"""ASGI app: thin routes over the solver pipeline.  Errors are RFC 9457 problem+json."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any

from fastapi import FastAPI, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from geometry import GeometryError
from service.convert import from_schedule, to_problem
from service.schemas import ScheduleRequest, ScheduleResponse
from solvers.errors import ScheduleError
from solvers.machine import PRESETS, preset
from solvers.pipeline import schedule

app = FastAPI(title="feedsched", version="0.1.0", description="Time-optimal CNC feed scheduling along NURBS toolpaths")
PROBLEM = "application/problem+json"


def _problem(status: int, title: str, detail: str, **extra: Any) -> JSONResponse:
    return JSONResponse({"type": "about:blank", "title": title, "status": status, "detail": detail, **extra},
                        status_code=status, media_type=PROBLEM)


@app.exception_handler(RequestValidationError)
async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
    errors = [
        {"field": ".".join(str(p) for p in e["loc"]), "value": e.get("input"), "rule": e["msg"]}
        for e in exc.errors()
    ]
    return _problem(422, "Invalid request", errors[0]["rule"] if errors else "invalid", errors=_jsonable(errors))


@app.exception_handler(GeometryError)
async def _geometry(_: Request, exc: GeometryError) -> JSONResponse:
    return _problem(422, "Invalid toolpath", str(exc), errors=[{"field": exc.field, "value": _jsonable(exc.value),
                                                                "rule": exc.rule}])


@app.exception_handler(ScheduleError)
async def _schedule(_: Request, exc: ScheduleError) -> JSONResponse:
    return _problem(422, "Cannot schedule", str(exc), errors=[{"field": exc.field, "value": _jsonable(exc.value),
                                                               "rule": exc.rule}],
                    window=exc.window, axis=exc.axis, status_detail=exc.status)


def _jsonable(v: Any) -> Any:
    if isinstance(v, float) and v != v:
        return "NaN"
    if isinstance(v, float) and v in (float("inf"), float("-inf")):
        return str(v)
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {k: _jsonable(x) for k, x in v.items()}
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    return repr(v)


@app.get("/healthz")
async def healthz() -> dict[str, str]:
    return {"status": "ok"}


@app.get("/v1/machines")
async def machines() -> dict[str, Any]:
    return {"machines": sorted(PRESETS)}


@app.get("/v1/machines/{name}")
async def machine(name: str) -> dict[str, Any]:
    m = preset(name)
    return {"name": m.name, "feed_max": m.feed_max, "stopping_distance_mm": m.stopping_distance(),
            "axes": [asdict(a) for a in m.axes],
            "units": {"vmax": "mm/s", "amax": "mm/s^2", "jmax": "mm/s^3", "M": "V s^2/mm", "b": "V s/mm",
                      "c": "V", "d": "V", "Kv": "s", "Ka": "s^2", "Kj": "s^3", "umax": "V", "emax": "mm"}}


@app.post("/v1/schedule", response_model=ScheduleResponse)
async def post_schedule(req: ScheduleRequest) -> dict[str, Any]:
    def work() -> dict[str, Any]:
        tp, m, opts = to_problem(req)
        return from_schedule(schedule(tp, m, opts))

    return await run_in_threadpool(work)
