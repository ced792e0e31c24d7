"""ASGI app: thin routes over the executor, the job manager and the store.

Errors are RFC 9457 problem+json (service/errors.py is the only mapping).
Settings come from FEEDSCHED_* environment variables (service/config.py).
"""

from __future__ import annotations

import gc
from collections.abc import AsyncIterator
from contextlib import ExitStack, asynccontextmanager
from dataclasses import asdict
from typing import Annotated, Any, Literal

from fastapi import Depends, FastAPI, Header, Path, Query, Request
from fastapi.dependencies.models import Dependant
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse, Response
from fastapi.routing import APIRoute
from fastapi.staticfiles import StaticFiles
from pydantic import BeforeValidator, ValidationError
from starlette.concurrency import run_in_threadpool
from swagger_ui_bundle import swagger_ui_path

from service.config import Settings
from service.convert import Budget, control_point_count, load_result
from service.errors import DUPLICATE_KEY, ServiceError, WorkFailed, install_handlers, not_found, renamed, too_large
from service.executor import Executor, make_executor
from service.http import (
    FORMAT_NAMES,
    NDJSON_PROTOCOL,
    BodyLimit,
    HeadAsGet,
    UniqueNamesRoute,
    ndjson_stream,
    negotiate,
    render,
)
from service.jobs import JobManager
from service.limits import Gate
from service.plots import FORMATS as PLOT_MEDIA
from service.reports import EXAMPLES, PlotService, example, index_page, report_page, report_pending
from service.schemas import (
    MEDIA_CSV,
    MEDIA_JSON,
    MEDIA_NDJSON,
    MEDIA_PROBLEM,
    ExampleList,
    Health,
    JobOut,
    MachineList,
    MachineOut,
    PlotFormat,
    PlotName,
    ScheduleRequest,
    ScheduleResponse,
)
from service.store import Job, JobStore
from solvers.machine import PRESETS, derive_limits, preset

GCODE_MEDIA = "text/x-gcode"

VERSION = "0.2.0"
SWAGGER_STATIC = "/static/swagger-ui"
UNITS = {"vmax": "mm/s", "amax": "mm/s^2", "jmax": "mm/s^3", "M": "V s^2/mm", "b": "V s/mm", "c": "V", "d": "V",
         "Kv": "s", "Ka": "s^2", "Kj": "s^3", "umax": "V", "emax": "mm", "feed_max": "mm/s",
         "stopping_distance_mm": "mm"}


PROBLEM_CONTENT = {MEDIA_PROBLEM: {"schema": {"$ref": "#/components/schemas/Problem"}}}
#: Response headers in the OpenAPI document.
X_SAMPLES = {"X-Samples": {"description": "output samples in the body (JSON and CSV; NDJSON has it in its summary "
                           "line)", "schema": {"type": "integer"}}}
LOCATION = {"Location": {"description": "the job: /v1/jobs/{id}", "required": True, "schema": {"type": "string"}}}
RETRY_AFTER = {"Retry-After": {"description": "seconds to wait before retrying", "required": True,
                               "schema": {"type": "integer", "minimum": 1}}}
BUSY = {
    "schedule": "busy: FEEDSCHED_MAX_INFLIGHT synchronous schedules are already in flight (answered at once, "
                "never queued; retry after Retry-After seconds or POST the body to /v1/jobs), or the solver "
                "process was lost",
    "jobs": "busy: FEEDSCHED_JOB_QUEUE_DEPTH jobs are already queued or running; retry after Retry-After seconds",
}


def _problems(*codes: int, busy: str | None = None) -> dict[int | str, dict[str, Any]]:
    """Problem responses of a route; ``busy`` documents its 503 (with Retry-After)."""
    out: dict[int | str, dict[str, Any]] = {
        c: {"content": PROBLEM_CONTENT, "description": "RFC 9457 problem details"} for c in codes}
    if busy is not None:
        out[503] = {"content": PROBLEM_CONTENT, "headers": RETRY_AFTER,
                    "description": "RFC 9457 problem details; " + BUSY[busy]}
    return out


SAMPLE_FORMATS: dict[str, Any] = {
    MEDIA_JSON: {},
    MEDIA_CSV: {"schema": {"type": "string"}, "example": "t,s,feed,x,y,z,...\n0.0,0.0,0.0,0.0,0.0,0.0,...\n"},
    MEDIA_NDJSON: {"schema": {"type": "string", "description": NDJSON_PROTOCOL},
                   "example": '{"t":0.0,"s":0.0,...}\n{"t":0.001,"s":0.0002,...}\n'
                              '{"event":"summary","summary":{...},"diagnostics":{...}}\n'},
}


class Service:
    """What the routes use; created in the app's lifespan."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.store = JobStore(settings.data_dir)
        self.executor: Executor = make_executor(settings.workers, settings.dask_scheduler)
        self.jobs = JobManager(self.store, self.executor, settings)
        self.plots = PlotService(self.store.dir / "plots")
        self.sync_gate = Gate(settings.max_inflight, "synchronous schedules", "FEEDSCHED_MAX_INFLIGHT")
        self.sync_budget = Budget(settings.sync_max_samples, settings.sync_max_intervals,
                                  where="the synchronous API (POST /v1/jobs takes more)")

    async def start(self) -> None:
        await self.executor.start()
        await self.jobs.start()

    async def close(self) -> None:
        await self.jobs.close()
        await self.executor.close()
        self.plots.close()
        self.store.close()


#: The G-code upload's request fields by the names its client sent them under: the query parameters, and the
#: program itself (``body``) for what its moves and F words decide (the knots, the control points).
GCODE_UPLOAD_FIELDS = {"options.sample_period": "query.sample_period", "options.max_samples": "query.sample_period",
                       "options.method": "query.method", "machine": "query.machine",
                       "options.knot_spacing": "body", "toolpath.segments": "body", "toolpath.gcode": "body",
                       "toolpath.corner_blend_mm": "query.corner_blend_mm",
                       "toolpath.corner_tolerance_deg": "query.corner_tolerance_deg"}


def _upload_loc(loc: Any) -> tuple[Any, ...]:
    """A G-code upload's ScheduleRequest error location as the client sent it: ("query", parameter) or ("body",)."""
    text = ".".join(str(p) for p in loc)
    for fld, name in GCODE_UPLOAD_FIELDS.items():
        if text == fld or text.startswith(fld + "."):
            return tuple(name.split(".")) if name != "body" else ("body",)
    return tuple(loc)


def _query_method(v: Any) -> Any:
    """``method=lp+nlp`` typed into a URL unescaped arrives as "lp nlp" (a `+` in a query string is a space)."""
    return "lp+nlp" if v == "lp nlp" else v


def _json_content(request: Request) -> None:
    """415 for a JSON route's body sent as another media type or none (``curl -d`` without a content-type header
    sends a form; without any, the body's bytes failed validation as "not an object")."""
    ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if ctype != "application/json" and not ctype.endswith("+json"):
        raise ServiceError(415, "unsupported-media-type", "Unsupported Media Type", f"send the request as {MEDIA_JSON}",
                           field="content-type", value=ctype or None, rule="content-type must be application/json")


def _unique_names(request: Request) -> None:
    """422 for a JSON body that gives a name twice in one object (``service.http.UniqueNamesRequest``): JSON leaves
    its meaning open and the parser kept the last, so ``"feed_max"`` twice ran at whichever came second."""
    found = request.scope.get(DUPLICATE_KEY)
    if found:
        at, name, times = found
        raise RequestValidationError([{
            "type": "duplicate_name", "loc": ("body", *at, name), "input": name,
            "msg": f'the name "{name}" appears {times} times in one object; give each name once (JSON does not say '
                   "which one counts)"}])


def _query_names(dep: Dependant) -> set[str]:
    """The query parameters a route's dependency tree reads, by the names a client sends."""
    return {str(p.alias) for p in dep.query_params}.union(*(_query_names(d) for d in dep.dependencies))


def _known_query(request: Request) -> None:
    """422 for a query parameter a /v1 route does not read, each named ``query.<name>``: ignored, the G-code upload
    ran ``?feed_max=5`` uncapped and ``POST /v1/schedule?method=lp`` as lp+nlp, the client none the wiser."""
    route = request.scope.get("route")
    if not request.query_params or not isinstance(route, APIRoute) or not route.path.startswith("/v1/"):
        return
    known = _query_names(route.dependant)  # (a few fields; only where the request has a query)
    rule = (f"{route.path} reads the query parameters {', '.join(sorted(known))} only" if known
            else f"{route.path} reads no query parameters")
    if route.body_field is not None:
        rule += " (machine and options go in the JSON body)"
    errors = [{"type": "extra_forbidden", "loc": ("query", k), "msg": rule, "input": v}
              for k, v in request.query_params.multi_items() if k not in known]
    if errors:
        raise RequestValidationError(errors)


def _svc(request: Request) -> Service:
    svc: Service = request.app.state.service
    return svc


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        svc = Service(settings)
        app.state.service = svc
        await svc.start()
        # The objects alive now (imported modules: numpy, scipy, pydantic, the solvers; ~145k) live as
        # long as the server: frozen, the cyclic collector's full (generation 2) passes only walk what
        # requests create (~2k objects).  Unfrozen, such a pass held the event loop for 99 ms in the
        # middle of a 32-client load run (and 24-79 ms at start-up).
        gc.collect()
        gc.freeze()
        try:
            yield
        finally:
            gc.unfreeze()
            await svc.close()

    # (no redirect of a trailing slash: its 307 built an absolute Location from the request's Host header)
    app = FastAPI(title="feedsched", version=VERSION, lifespan=lifespan, docs_url=None, redoc_url=None,
                  redirect_slashes=False, dependencies=[Depends(_known_query)],
                  description="Time-optimal CNC feed scheduling along NURBS toolpaths. Errors are RFC 9457 "
                  "problem+json naming the field path, value and rule.")
    # Swagger UI from the swagger-ui-bundle-v2 package, not a CDN (the service may run offline)
    app.router.route_class = UniqueNamesRoute  # (before the routes: each reads its JSON body noting repeated names)
    app.mount(SWAGGER_STATIC, StaticFiles(directory=swagger_ui_path), name="swagger-ui")
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes)
    app.add_middleware(HeadAsGet)
    install_handlers(app)
    _routes(app)
    return app


def _job_out(svc: Service, job: Job) -> dict[str, Any]:
    timings: dict[str, Any] = {"created": job.created, "started": job.started, "finished": job.finished}
    if job.started is not None:
        timings["queued_s"] = job.started - job.created
        if job.finished is not None:
            timings["run_s"] = job.finished - job.started
    base = f"/v1/jobs/{job.id}"
    return {"id": job.id, "status": job.status, "progress": svc.jobs.progress(job), "attempts": job.attempts,
            "worker_pid": svc.executor.running_pids().get(job.id) if job.status == "running" else None,
            "timings": timings, "error": job.error, "summary": job.summary,
            "links": {"self": base, "result": base + "/result", "cancel": base, "report": base + "/report"}}


JobId = Annotated[str, Path(min_length=1, max_length=100, description="job id from POST /v1/jobs")]
ResultFormat = Annotated[Literal["json", "csv", "ndjson"] | None, Query(
    description="instead of the Accept header (for links): json, csv or ndjson")]
PLOT_CONTENT: dict[str, Any] = {
    "image/svg+xml": {"schema": {"type": "string"}},
    "image/png": {"schema": {"type": "string", "format": "binary"}},
}


def _succeeded(svc: Service, job_id: str) -> Job:
    """The job if it has succeeded; 404 if unknown, 409 otherwise."""
    job = svc.store.get(job_id)
    if job is None:
        raise not_found("job", job_id, "path.job_id")
    if job.status != "succeeded":
        raise ServiceError(409, "job-not-succeeded", "No result", f"the job is {job.status}",
                           field="path.job_id", value=job_id, rule="a result exists once the job has succeeded",
                           job_status=job.status, job_error=job.error)
    if not svc.store.result_path(job_id).exists():
        raise not_found("job result file", job_id, "path.job_id")
    return job


def _media(body: ScheduleRequest, accept: str | None) -> str:
    """The response's media type for ``accept``: with ``options.plots``, JSON wherever Accept admits it at all (the
    plots come in the JSON body only: ``application/json;q=0.1, text/csv`` was a 406), else a 406 naming them."""
    o = body.options
    if not o.plots:
        return negotiate(accept)
    try:
        return negotiate(accept, (MEDIA_JSON,))
    except ServiceError as exc:
        raise ServiceError(406, "not-acceptable", "Not Acceptable", "plots come in the JSON body only",
                           field="options.plots", value=o.plots,
                           rule=f"options.plots needs an Accept that admits {MEDIA_JSON}") from exc


def _check_plots(body: ScheduleRequest) -> None:
    o = body.options
    if o.plots and "comparison" in o.plots and o.method != "lp+nlp":
        raise ServiceError(422, "invalid-options", "Invalid options", "the comparison plot needs method lp+nlp",
                           field="options.plots", value=o.plots, rule='"comparison" needs options.method "lp+nlp"')


def _routes(app: FastAPI) -> None:
    @app.get("/healthz", response_model=Health)  # (HEAD too, for load balancers' probes: ``HeadAsGet``)
    async def healthz(request: Request) -> dict[str, Any]:
        """Liveness, and how full the service is (synchronous schedules in flight, jobs queued or running)."""
        svc = _svc(request)
        return {"status": "ok", "schedules_in_flight": svc.sync_gate.current,
                "schedules_limit": svc.sync_gate.limit, "schedules_refused": svc.sync_gate.refused,
                "jobs_active": svc.jobs.active_count(), "jobs_limit": svc.settings.job_queue_depth,
                "jobs_refused": svc.jobs.refused}

    @app.get("/v1/machines", response_model=MachineList)
    async def machines() -> dict[str, Any]:
        return {"machines": sorted(PRESETS)}

    @app.get("/v1/machines/{name}", response_model=MachineOut, responses=_problems(404, 422))
    async def machine(name: Annotated[str, Path(max_length=100)]) -> dict[str, Any]:
        if name not in PRESETS:
            raise not_found(f"machine preset {name!r}", name, "path.name")
        m = preset(name)
        axes = []
        for a in m.axes:
            d = asdict(a)
            if a.drive is not None:
                d["limits_from_drive"] = asdict(derive_limits(a.drive, a.limits.vmax, a.name))
            axes.append(d)
        return {"name": m.name, "feed_max": m.feed_max, "stopping_distance_mm": m.stopping_distance(),
                "axes": axes, "units": UNITS}

    @app.post(
        "/v1/schedule",
        response_model=ScheduleResponse,
        dependencies=[Depends(_json_content), Depends(_unique_names)],
        responses={200: {"content": SAMPLE_FORMATS, "headers": X_SAMPLES, "description": "the schedule (JSON "
                         "columns, CSV or NDJSON rows by Accept)"},
                   **_problems(400, 406, 413, 415, 422, busy="schedule")},
    )
    async def post_schedule(body: ScheduleRequest, request: Request) -> Response:
        """Schedule a toolpath now.  `Accept: text/csv` or `application/x-ndjson` for rows.

        NDJSON streams: the rows of each piece of the path (rest to rest, between corners) leave as soon as
        that piece is solved and re-checked, while later pieces are still being solved; the last line is
        `{"event": "summary", ...}` on success or `{"event": "error", ...problem+json}` on a failure after
        rows were sent.  A stream without the summary line is incomplete."""
        return await _schedule_now(body, request)

    async def _schedule_now(body: ScheduleRequest, request: Request, names: dict[str, str] | None = None) -> Response:
        """``POST /v1/schedule``'s work; ``names``: its problems' fields by the names the client sent them under
        (``service.errors.renamed``; the G-code upload's), in-band NDJSON error lines included."""
        svc = _svc(request)
        media = _media(body, request.headers.get("accept"))
        n = control_point_count(body)
        if n > svc.settings.sync_max_control_points:
            raise too_large(f"{n} control points exceed the synchronous limit of "
                            f"{svc.settings.sync_max_control_points}; POST the same body to /v1/jobs",
                            field="toolpath.segments", value=n,
                            rule=f"at most {svc.settings.sync_max_control_points} control points")
        _check_plots(body)
        if media == MEDIA_NDJSON:
            return await _stream_schedule(svc, body.model_dump(mode="json"), request.url.path, names)
        with svc.sync_gate.enter():  # 503 at once when FEEDSCHED_MAX_INFLIGHT schedules are in flight
            res = await svc.executor.run(body.model_dump(mode="json"), svc.sync_budget, svc.settings.sync_timeout)
            figs = None
            if body.options.plots:
                figs = await svc.plots.inline(res, body, list(dict.fromkeys(body.options.plots)),
                                              body.options.plot_format)
        return await render(res, media, plots=figs)

    @app.post(
        "/v1/schedule/gcode",
        response_model=ScheduleResponse,
        openapi_extra={"requestBody": {"required": True, "content": {GCODE_MEDIA: {"schema": {"type": "string"}}}}},
        responses={200: {"content": SAMPLE_FORMATS, "headers": X_SAMPLES, "description": "the schedule (JSON "
                         "columns, CSV or NDJSON rows by Accept)"},
                   **_problems(400, 406, 413, 415, 422, busy="schedule")},
    )
    async def post_schedule_gcode(
        request: Request,
        machine: Annotated[str, Query(max_length=64, description="machine preset")] = "router",
        method: Annotated[Literal["lp", "lp+nlp"], BeforeValidator(_query_method), Query(
            description="lp+nlp (default) or lp; a `+` left unescaped in the URL reads as a space: `lp nlp` is "
                        "lp+nlp")] = "lp+nlp",
        sample_period: Annotated[float, Query(ge=1e-5, le=0.1, allow_inf_nan=False, description="s")] = 0.001,
        corner_tolerance_deg: Annotated[float, Query(ge=0, lt=180, allow_inf_nan=False)] = 0.5,
        corner_blend_mm: Annotated[float, Query(ge=0, le=100, allow_inf_nan=False,
                                                description="mm; 0 stops, else >= 0.001")] = 0.0,
    ) -> Response:
        """Schedule a G-code program uploaded as `text/x-gcode` (machine preset and options as query parameters).
        Answers as `POST /v1/schedule` (JSON, CSV, or NDJSON streamed piece by piece with a final summary line)."""
        ctype = request.headers.get("content-type", "").split(";")[0].strip().lower()
        if ctype not in (GCODE_MEDIA, "text/plain"):
            raise ServiceError(415, "unsupported-media-type", "Unsupported Media Type",
                               f"send the program as {GCODE_MEDIA}", field="content-type", value=ctype,
                               rule=f"content-type must be {GCODE_MEDIA} or text/plain")
        raw = await request.body()
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ServiceError(422, "invalid-gcode", "Invalid G-code", "the program is not UTF-8 text",
                               field="body", value=None, rule="UTF-8 text") from exc
        try:
            body = ScheduleRequest.model_validate({
                "toolpath": {"gcode": text, "corner_tolerance_deg": corner_tolerance_deg,
                             "corner_blend_mm": corner_blend_mm},
                "machine": machine,
                "options": {"method": method, "sample_period": sample_period},
            })
        except ValidationError as exc:  # (the query parameters' own names; the program is the body)
            raise RequestValidationError([{**e, "loc": _upload_loc(e.get("loc", ()))} for e in exc.errors()]) from exc
        try:
            return await _schedule_now(body, request, GCODE_UPLOAD_FIELDS)
        except (ServiceError, WorkFailed) as exc:
            raise renamed(exc, GCODE_UPLOAD_FIELDS) from exc

    @app.post("/v1/jobs", status_code=202, response_model=JobOut,
              dependencies=[Depends(_json_content), Depends(_unique_names)],
              responses={202: {"headers": LOCATION, "description": "queued"},
                         200: {"model": JobOut, "headers": LOCATION, "description": "an existing job (same "
                               "Idempotency-Key)"},
                         **_problems(400, 413, 415, 422, busy="jobs")})
    async def post_job(
        body: ScheduleRequest, request: Request,
        idempotency_key: Annotated[str | None, Header(alias="Idempotency-Key", min_length=1, max_length=200)] = None,
    ) -> JSONResponse:
        """Queue a toolpath; poll the job at `Location`."""
        svc = _svc(request)
        keys = request.headers.getlist("idempotency-key")
        if len(keys) > 1:  # (the route read the first and ignored the rest)
            raise ServiceError(422, "invalid-request", "Invalid request", f"Idempotency-Key sent {len(keys)} times",
                               field="Idempotency-Key", value=keys, rule="one Idempotency-Key header per request")
        req = body.model_dump(mode="json")
        job, created = svc.jobs.submit(req, idempotency_key)
        if not created and job.request != req:
            raise ServiceError(422, "idempotency-key-reused", "Idempotency-Key reused",
                               "this Idempotency-Key was used for a different request", field="Idempotency-Key",
                               value=idempotency_key, rule="one key, one request body")
        return JSONResponse(_job_out(svc, job), status_code=202 if created else 200,
                            headers={"Location": f"/v1/jobs/{job.id}"})

    @app.get("/v1/jobs/{job_id}", response_model=JobOut, responses=_problems(404, 422))
    async def get_job(job_id: JobId, request: Request) -> dict[str, Any]:
        svc = _svc(request)
        job = svc.store.get(job_id)
        if job is None:
            raise not_found("job", job_id, "path.job_id")
        return _job_out(svc, job)

    @app.delete("/v1/jobs/{job_id}", response_model=JobOut, responses=_problems(404, 409, 422))
    async def delete_job(job_id: JobId, request: Request) -> dict[str, Any]:
        """Cancel a queued or running job (its solver process is killed)."""
        svc = _svc(request)
        job = svc.store.get(job_id)
        if job is None:
            raise not_found("job", job_id, "path.job_id")
        if job.status in ("queued", "running"):
            await svc.jobs.cancel(job_id)  # (the job may finish first: its status is read again below)
            job = svc.store.get(job_id) or job
        if job.status != "cancelled":
            raise ServiceError(409, "job-finished", "Job already finished", f"the job has {job.status}",
                               field="path.job_id", value=job_id, rule="only queued or running jobs can be cancelled")
        return _job_out(svc, job)

    @app.get("/v1/jobs/{job_id}/result", response_model=ScheduleResponse,
             responses={200: {"content": SAMPLE_FORMATS, "headers": X_SAMPLES, "description": "the schedule"},
                        **_problems(404, 406, 409, 422)})
    async def get_result(job_id: JobId, request: Request, format: ResultFormat = None) -> Response:
        svc = _svc(request)
        job = svc.store.get(job_id)
        if job is None:
            raise not_found("job", job_id, "path.job_id")
        media = FORMAT_NAMES[format] if format else negotiate(request.headers.get("accept"))
        if job.status != "succeeded":
            raise ServiceError(409, "job-not-succeeded", "No result", f"the job is {job.status}",
                               field="path.job_id", value=job_id, rule="a result exists once the job has succeeded",
                               job_status=job.status, job_error=job.error)
        path = svc.store.result_path(job_id)
        try:
            res = await _load(path)
        except FileNotFoundError:
            raise not_found("job result file", job_id, "path.job_id") from None
        return await render(res, media)

    @app.get("/v1/jobs/{job_id}/plots/{name}.{fmt}", response_class=Response,
             responses={200: {"content": PLOT_CONTENT, "description": "the plot (SVG or PNG)"},
                        **_problems(404, 409, 422)})
    async def get_plot(job_id: JobId, name: Annotated[PlotName, Path(description="which plot")],
                       fmt: Annotated[PlotFormat, Path(description="svg or png")], request: Request) -> Response:
        """A plot of a succeeded job: toolpath coloured by feed, feed profiles, axis profiles against limits,
        or (method lp+nlp) the LP vs LP+NLP comparison.  Rendered once, then cached."""
        svc = _svc(request)
        job = _succeeded(svc, job_id)
        if name == "comparison" and job.request.get("options", {}).get("method", "lp+nlp") != "lp+nlp":
            raise not_found("comparison plot (the job ran method lp only)", name, "path.name")
        data = await svc.plots.job_plot(job_id, svc.store.result_path(job_id), job.request, name, fmt)
        return Response(data, media_type=PLOT_MEDIA[fmt], headers={"Cache-Control": "public, max-age=86400"})

    @app.get("/v1/jobs/{job_id}/report", response_class=HTMLResponse, responses=_problems(404, 422))
    async def get_report(job_id: JobId, request: Request) -> HTMLResponse:
        """An HTML page: the plots, the summary table and download links (the job's status until it succeeds)."""
        svc = _svc(request)
        job = svc.store.get(job_id)
        if job is None:
            raise not_found("job", job_id, "path.job_id")
        if job.status != "succeeded":
            return HTMLResponse(report_pending(job))
        job = _succeeded(svc, job_id)
        res = await svc.plots.job_result(job_id, svc.store.result_path(job_id))
        page = await run_in_threadpool(report_page, job_id, res, job.request)
        return HTMLResponse(page)

    @app.get("/v1/examples", response_model=ExampleList)
    async def examples() -> dict[str, Any]:
        """Bundled example toolpaths (request bodies for POST /v1/schedule or /v1/jobs)."""
        return {"examples": [{"name": n, "description": d, "href": f"/v1/examples/{n}"} for n, d in EXAMPLES.items()]}

    @app.get("/v1/examples/{name}", response_model=ScheduleRequest, responses=_problems(404, 422))
    async def get_example(name: Annotated[str, Path(max_length=100)]) -> dict[str, Any]:
        if name not in EXAMPLES:
            raise not_found("example", name, "path.name")
        body: dict[str, Any] = await run_in_threadpool(example, name)
        return body

    @app.get("/docs", response_class=HTMLResponse, include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url="/openapi.json", title="feedsched - Swagger UI",
                                   swagger_js_url=f"{SWAGGER_STATIC}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{SWAGGER_STATIC}/swagger-ui.css",
                                   swagger_favicon_url=f"{SWAGGER_STATIC}/favicon-32x32.png")

    @app.get("/", response_class=HTMLResponse, include_in_schema=False)
    async def index() -> HTMLResponse:
        return HTMLResponse(index_page(sorted(PRESETS)))


async def _stream_schedule(svc: Service, req: dict[str, Any], instance: str,
                           names: dict[str, str] | None = None) -> Response:
    """``POST /v1/schedule`` as NDJSON rows while the solver works (NDJSON_PROTOCOL).

    Admission as for the other formats: 503 at once when FEEDSCHED_MAX_INFLIGHT schedules are in flight; the
    slot is held until the stream has ended (the solver process stopped).  A failure before the first row is an
    ordinary problem+json response with its own status; after it, an error line ends the 200 stream."""
    slot = ExitStack()
    slot.enter_context(svc.sync_gate.enter())
    events = svc.executor.stream(req, svc.sync_budget, svc.settings.sync_timeout)
    try:
        first = await anext(events)
    except BaseException:
        try:
            await events.aclose()
        finally:
            slot.close()
        raise
    return ndjson_stream(first, events, slot.close, instance, names)


async def _load(path: Any) -> Any:
    return await run_in_threadpool(load_result, path)


app = create_app()
