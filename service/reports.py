"""Plots and report pages for the service: rendering off the event loop, a per-job plot cache, bundled examples.

Rendering runs in one dedicated thread (matplotlib's shared state - font and
text caches - is not meant for concurrent figures), so the event loop only
awaits it.  Job results never change once a job has succeeded, so each job's
plots are cached as files next to its result (``<data>/plots/<id>.<name>.v<plots.VERSION>.<fmt>``)
and concurrent requests for the same plot share one rendering.
"""

from __future__ import annotations

import asyncio
import base64
import html
import json
import threading
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, TypeVar

from service import plots
from service.convert import Result, load_result, to_machine
from service.schemas import ScheduleRequest

T = TypeVar("T")
#: Loaded job results kept in memory for rendering (a report asks for several plots of one job at once).
RESULT_MEMO = 2


def machine_limits(request: dict[str, Any] | ScheduleRequest) -> plots.Limits:
    """The limits a request was scheduled under (preset or custom machine, options.feed_max override)."""
    req = request if isinstance(request, ScheduleRequest) else ScheduleRequest.model_validate(request)
    m = to_machine(req.machine)
    if req.options.feed_max is not None:
        m = m.with_feed_max(float(req.options.feed_max))
    return plots.Limits.from_machine(m)


def data_uri(fmt: str, data: bytes) -> str:
    return f"data:{plots.FORMATS[fmt]};base64,{base64.b64encode(data).decode()}"


class PlotService:
    def __init__(self, cache_dir: Path) -> None:
        self.cache_dir = Path(cache_dir)
        self.cache_dir.mkdir(parents=True, exist_ok=True)
        self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="feedsched-plots")
        self._inflight: dict[tuple[str, str, str], asyncio.Future[bytes]] = {}
        self._memo: OrderedDict[str, Result] = OrderedDict()
        self._memo_lock = threading.Lock()

    def close(self) -> None:
        self._thread.shutdown(wait=False, cancel_futures=True)

    async def _off_loop(self, fn: Callable[..., T], *args: Any) -> T:
        return await asyncio.get_running_loop().run_in_executor(self._thread, fn, *args)

    def cache_path(self, job_id: str, name: str, fmt: str) -> Path:
        return self.cache_dir / f"{job_id}.{name}.v{plots.VERSION}.{fmt}"

    async def job_plot(self, job_id: str, result_path: Path, request: dict[str, Any], name: str, fmt: str) -> bytes:
        """The plot of a succeeded job, from the cache or rendered once (concurrent callers share it)."""
        key = (job_id, name, fmt)
        path = self.cache_path(*key)
        if path.exists():
            return await asyncio.to_thread(path.read_bytes)  # not queued behind a rendering
        fut = self._inflight.get(key)
        if fut is None:
            fut = asyncio.ensure_future(self._off_loop(self._render_job, job_id, result_path, request, name, fmt))
            self._inflight[key] = fut
            fut.add_done_callback(lambda _: self._inflight.pop(key, None))
        return await asyncio.shield(fut)

    def _render_job(self, job_id: str, result_path: Path, request: dict[str, Any], name: str, fmt: str) -> bytes:
        res = self.load(job_id, result_path)
        data = plots.render(name, res, machine_limits(request), fmt)
        path = self.cache_path(job_id, name, fmt)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_bytes(data)
        tmp.replace(path)
        return data

    def load(self, job_id: str, result_path: Path) -> Result:
        with self._memo_lock:
            res = self._memo.get(job_id)
            if res is not None:
                self._memo.move_to_end(job_id)
                return res
        res = load_result(result_path)
        with self._memo_lock:
            self._memo[job_id] = res
            while len(self._memo) > RESULT_MEMO:
                self._memo.popitem(last=False)
        return res

    async def job_result(self, job_id: str, result_path: Path) -> Result:
        return await self._off_loop(self.load, job_id, result_path)

    async def inline(self, res: Result, request: dict[str, Any] | ScheduleRequest, names: list[str],
                     fmt: str) -> dict[str, str]:
        """Plots of a synchronous result as data: URIs (not cached: there is no id to cache them under)."""
        def work() -> dict[str, str]:
            limits = machine_limits(request)
            return {n: data_uri(fmt, plots.render(n, res, limits, fmt)) for n in names}

        return await self._off_loop(work)


# --- bundled examples ---------------------------------------------------------------------
EXAMPLES: dict[str, str] = {
    "flower": "r = 40 + 15 cos(5θ) mm, one closed loop (407.7 mm, cubic NURBS through 720 points)",
    "quarter-arc": "quarter circle of radius 40 mm (exact rational quadratic NURBS)",
    "square-corner": "two 50 mm lines meeting at a 90° corner (the tool stops there)",
    "wave3d": "a 3-D path: an ellipse in XY with Z rising and waving (330 mm)",
}
_example_cache: dict[str, dict[str, Any]] = {}


def _segment_json(seg: Any) -> dict[str, Any]:
    return {"type": "nurbs", "degree": int(seg.degree), "knots": [float(k) for k in seg.knots],
            "control_points": [[float(v) for v in p] for p in seg.control_points],
            "weights": [float(w) for w in seg.weights]}


def example(name: str) -> dict[str, Any]:
    """A bundled example as a ScheduleRequest body (router, method lp+nlp).  KeyError if unknown."""
    if name not in EXAMPLES:
        raise KeyError(name)
    if name not in _example_cache:
        from geometry import Toolpath
        from geometry.examples import flower, square_corner, wave3d
        from service.schemas import EXAMPLE

        if name == "quarter-arc":
            body: dict[str, Any] = json.loads(json.dumps(EXAMPLE))
        else:
            tp = {"flower": lambda: flower(1), "square-corner": square_corner,
                  "wave3d": lambda: Toolpath([wave3d()])}[name]()
            body = {"toolpath": {"segments": [_segment_json(s) for s in tp.segments]}, "machine": "router",
                    "options": {"method": "lp+nlp", "sample_period": 0.001}}
        _example_cache[name] = body
    out: dict[str, Any] = json.loads(json.dumps(_example_cache[name]))
    return out


# --- HTML -------------------------------------------------------------------------------------
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1d2330;background:#f6f7f9}
header{background:#1d2330;color:#fff;padding:.8rem 1.5rem;display:flex;gap:1.5rem;align-items:baseline}
header a{color:#9cc3ff}main{padding:1rem 1.5rem;max-width:1400px}
h1{font-size:1.3rem;margin:0}h2{font-size:1.1rem;margin:1.4rem 0 .5rem}
table{border-collapse:collapse;background:#fff;font-size:.9rem}td,th{border:1px solid #d5d9e0;padding:.25rem .6rem;
text-align:left}th{background:#eef1f5}td.num{text-align:right;font-variant-numeric:tabular-nums}
.bind{color:#b00000;font-weight:600}.muted{color:#6b7280}
figure{background:#fff;border:1px solid #d5d9e0;margin:0 0 1rem;padding:.5rem}figure img{max-width:100%;height:auto;
display:block}figcaption{font-size:.85rem;color:#4b5563;margin-top:.3rem}
.grid{display:flex;gap:1.5rem;flex-wrap:wrap;align-items:flex-start}
textarea{width:100%;height:16rem;font-family:ui-monospace,monospace;font-size:.8rem}
label{display:block;margin:.6rem 0 .2rem;font-weight:600}select,button,input{font-size:1rem}
button{background:#2563eb;color:#fff;border:0;padding:.5rem 1.2rem;border-radius:4px;cursor:pointer}
button:disabled{background:#9ca3af}#error{color:#b00000;white-space:pre-wrap}
"""


def _page(title: str, body: str, head: str = "") -> str:
    return (f'<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<link rel="icon" href="data:,"><style>{CSS}</style>{head}</head><body>'
            f'<header><h1>feedsched</h1><a href="/">run a toolpath</a><a href="/docs">API (Swagger UI)</a></header>'
            f"<main>{body}</main></body></html>")


def _fmt(v: Any, unit: str = "", digits: int = 4) -> str:
    if isinstance(v, float):
        return f"{v:.{digits}g}{unit}"
    return html.escape(str(v)) + unit


def report_pending(job: Any) -> str:
    """The report of a job that has not succeeded: its status (refreshing itself while the job runs)."""
    active = job.status in ("queued", "running")
    body = f"<h2>Job {html.escape(job.id)}: {html.escape(job.status)}</h2>"
    if active:
        body += f'<p id="status">{html.escape(job.status)}… this page reloads until the job is done.</p>'
    if job.error:
        body += f'<p id="error">{html.escape(job.error.get("detail", ""))}</p>'
        body += f"<pre>{html.escape(json.dumps(job.error, indent=2))}</pre>"
    head = '<meta http-equiv="refresh" content="1">' if active else ""
    return _page(f"feedsched job {job.id}", body, head)


SUMMARY_ROWS = (
    ("path_length", "path length", " mm"), ("motion_time", "motion time", " s"),
    ("lp_motion_time", "LP motion time", " s"), ("compute_time", "compute time", " s"),
    ("lp_time", "LP compute time", " s"), ("nlp_time", "NLP compute time", " s"), ("method", "method", ""),
    ("solver", "LP solver", ""), ("samples", "samples", ""), ("sample_period", "sample period", " s"),
    ("knot_spacing", "knot spacing", " mm"), ("windows", "LP windows", ""), ("nlp_windows", "NLP windows", ""),
    ("nlp_failures", "NLP window failures", ""),
)


def report_page(job_id: str, res: Result, request: dict[str, Any]) -> str:
    """The report of a succeeded job: plots, summary table, utilisation, diagnostics, downloads."""
    limits = machine_limits(request)
    s = res.summary
    base = f"/v1/jobs/{job_id}"
    rows = "".join(f"<tr><th>{label}</th><td class=num>{_fmt(s[k], unit)}</td></tr>"
                   for k, label, unit in SUMMARY_ROWS if k in s)
    if s.get("method") == "lp+nlp" and s.get("lp_motion_time"):
        gain = 100.0 * (s["lp_motion_time"] - s["motion_time"]) / s["lp_motion_time"]
        rows += f"<tr><th>NLP gain over LP</th><td class=num>{gain:.1f} %</td></tr>"
    enf = plots.enforced(res)
    util = plots.utilisation(res, limits)
    urows = ""
    for q in plots.QUANTITIES:
        if f"{q.key}_x" not in util:
            continue
        cells = "".join(_util_cell(util[f"{q.key}_{a}"], q.key in enf) for a in plots.AXES)
        tag = "enforced" if q.key in enf else '<span class="muted">not enforced</span>'
        urows += f"<tr><th>{q.label}</th>{cells}<td>{tag}</td></tr>"
    if "feed" in util:
        urows += f'<tr><th>feed</th><td colspan=3 class=num>{100 * util["feed"]:.1f} %</td><td>enforced</td></tr>'
    bind = plots.binding(res, limits)
    d = res.diagnostics
    diag = f"<tr><th>corners (rest points)</th><td class=num>{len(d.get('corners', []))}</td></tr>"
    kinds = [*enf, *(["feed"] if limits.feed_max is not None else [])]
    for kind in kinds:
        if kind in ("control_signal", "servo_error"):
            n, where = (len(bind[kind]) if kind in bind else 0), "samples"
        else:
            n, where = int(d.get("binding", {}).get(kind, {}).get("count", 0)), "checkpoints"
        diag += f"<tr><th>{kind.replace('_', ' ')} binds at</th><td class=num>{n} {where}</td></tr>"
    if "nlp_fallbacks" in d:
        diag += f"<tr><th>NLP fallbacks to the LP feed</th><td class=num>{len(d['nlp_fallbacks'])}</td></tr>"
    figs = ""
    captions = {"toolpath": "toolpath coloured by feed, binding constraints marked",
                "feed": "feed against arc length and time", "axes": "per-axis profiles against their limits",
                "comparison": "LP vs LP+NLP feed along the path"}
    for name in plots.available(res):
        figs += (f'<figure id="fig-{name}"><img class="plot" src="{base}/plots/{name}.svg" alt="{captions[name]}">'
                 f'<figcaption>{captions[name]} — <a href="{base}/plots/{name}.svg">SVG</a> · '
                 f'<a href="{base}/plots/{name}.png">PNG</a></figcaption></figure>')
    downloads = " · ".join(f'<a href="{base}/result?format={f}" download="feedsched-{job_id}.{ext}">{label}</a>'
                           for f, ext, label in (("csv", "csv", "CSV"), ("json", "json", "JSON"),
                                                 ("ndjson", "ndjson", "NDJSON")))
    body = (f'<h2>Report of job <code>{html.escape(job_id)}</code></h2>'
            f'<p id="downloads">Samples: {downloads} · <a href="{base}">job status (JSON)</a></p>'
            '<div class="grid">'
            f'<div><h2>Summary</h2><table id="summary">{rows}</table></div>'
            '<div><h2>Peak utilisation</h2><table id="utilisation"><tr><th></th><th>x</th><th>y</th><th>z</th>'
            f'<th></th></tr>{urows}</table></div>'
            f'<div><h2>Diagnostics</h2><table id="diagnostics">{diag}</table></div></div>'
            f"<h2>Plots</h2>{figs}")
    return _page(f"feedsched report {job_id}", body)


def _util_cell(u: float, enforced: bool) -> str:
    cls = "num bind" if enforced and u >= plots.BINDING_UTILISATION else "num"
    return f"<td class='{cls}'>{100 * u:.1f} %</td>"


def index_page(machines: list[str]) -> str:
    """The start page: paste, upload or pick a toolpath, choose machine and method, run it as a job."""
    opts = "".join(f'<option value="{html.escape(n)}"{" selected" if n == "flower" else ""}>'
                   f"{html.escape(n)} — {html.escape(t)}</option>" for n, t in EXAMPLES.items())
    mach = "".join(f'<option value="{html.escape(m)}">{html.escape(m)}</option>' for m in machines)
    mach += '<option value="">as in the JSON (a custom machine)</option>'
    body = f"""
<p>Schedule the fastest feed along a toolpath within the machine's limits, then look at where it slows down and
which limit holds it back.  The toolpath is JSON: a whole <code>/v1/jobs</code> request body or just its
<code>toolpath</code> (<code>{{"segments": [NURBS...]}}</code>); see <a href="/docs">the API docs</a>.</p>
<form id="run-form">
<label for="example">Example</label><select id="example"><option value="">(none)</option>{opts}</select>
<label for="file">or upload a JSON file</label><input type="file" id="file" accept=".json,application/json">
<label for="toolpath">Toolpath JSON</label><textarea id="toolpath" spellcheck="false"></textarea>
<div class="grid"><div><label for="machine">Machine preset</label><select id="machine">{mach}</select></div>
<div><label for="method">Method</label><select id="method"><option value="lp+nlp">lp+nlp (LP, then NLP under the
drive's control-signal and servo-error limits)</option><option value="lp">lp (velocity, acceleration, jerk
only)</option></select></div></div>
<p><button id="run" type="submit">Run</button> <span id="status"></span></p><p id="error"></p>
</form>
<script>{INDEX_JS}</script>"""
    return _page("feedsched", body)


INDEX_JS = r"""
const $ = (id) => document.getElementById(id);
async function loadExample(name) {
  if (!name) return;
  $("status").textContent = "loading example…";
  const r = await fetch("/v1/examples/" + encodeURIComponent(name));
  if (!r.ok) { $("error").textContent = "could not load example " + name; return; }
  const body = await r.json();
  $("toolpath").value = JSON.stringify(body.toolpath);
  if (body.options && body.options.method) $("method").value = body.options.method;
  $("status").textContent = "";
}
$("example").addEventListener("change", (e) => loadExample(e.target.value));
$("file").addEventListener("change", async (e) => {
  const f = e.target.files[0];
  if (f) { $("toolpath").value = await f.text(); $("example").value = ""; }
});
$("run-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  $("error").textContent = "";
  let parsed;
  try { parsed = JSON.parse($("toolpath").value); } catch (err) {
    $("error").textContent = "the toolpath is not valid JSON: " + err.message; return;
  }
  const body = parsed.toolpath ? parsed : {toolpath: parsed};
  if ($("machine").value || !body.machine) body.machine = $("machine").value || "router";
  body.options = Object.assign({}, body.options || {}, {method: $("method").value});
  $("run").disabled = true;
  $("status").textContent = "submitting…";
  try {
    const r = await fetch("/v1/jobs", {method: "POST", headers: {"Content-Type": "application/json"},
                                       body: JSON.stringify(body)});
    const out = await r.json();
    if (!r.ok) {
      const errs = (out.errors || []).map((x) => (x.field || "") + ": " + x.rule).join("\n");
      $("error").textContent = (out.detail || r.statusText) + (errs ? "\n" + errs : "");
      $("status").textContent = "";
      return;
    }
    $("status").textContent = "job " + out.id + " " + out.status + "…";
    window.location.href = "/v1/jobs/" + out.id + "/report";
  } finally { $("run").disabled = false; }
});
loadExample($("example").value);
"""
