"""Load on loopback: N concurrent clients POST small toolpaths to /v1/schedule for a while.

    python -m bench.load [--duration 60] [--clients 32 | --overload 2] [--url http://127.0.0.1:8000]

Without --url a uvicorn server is started on a free loopback port (FEEDSCHED_* from the environment) and
stopped at the end.  A separate process probes /healthz every 50 ms meanwhile: the event loop must never
block on solver work.  ``--overload F`` runs F x the server's concurrency limit (``schedules_limit`` of
/healthz, FEEDSCHED_MAX_INFLIGHT) clients: the excess must get 503 at once and every admitted request must
succeed.  A client answered 503 waits the Retry-After (at most --retry-cap s) and tries again.  Every
--rss-every s the resident memory of the server process and of its descendants (forkserver, resource tracker,
solver processes) is read from /proc (servers this script started, or --pid).

Reports 200 / 503 / other counts, latency of admitted requests and of 503s, throughput, /healthz latency
and the RSS start / end / peak and slope; writes --out (default bench/results/load.json).  Every loop is
bounded by --duration and --max-requests; only loopback addresses are used.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing as mp
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]


def small_toolpath(i: int) -> dict[str, Any]:
    """A quarter circle, radius 10..40 mm (varies per request so no two bodies are the same)."""
    r = 10.0 + (i * 7.3) % 30.0
    return {
        "toolpath": {"segments": [{"type": "nurbs", "degree": 2, "knots": [0, 0, 0, 1, 1, 1],
                                   "control_points": [[0, 0, 0], [r, 0, 0], [r, r, 0]],
                                   "weights": [1, math.sqrt(0.5), 1]}]},
        "machine": "router",
        "options": {"method": "lp", "sample_period": 0.001},
    }


def pct(xs: list[float], p: float) -> float:
    if not xs:
        return math.nan
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, math.ceil(p / 100 * len(s)) - 1))]


class Tally:
    """What the clients saw."""

    def __init__(self, max_requests: int) -> None:
        self.lat: list[float] = []  # 200 answers
        self.busy_lat: list[float] = []  # 503 answers
        self.errors: list[str] = []  # anything else
        self.retry_after: dict[str, int] = {}
        self.budget = max_requests

    def take(self) -> bool:
        self.budget -= 1
        return self.budget >= 0


async def client_loop(url: str, idx: int, stop: float, t: Tally, retry_cap: float) -> None:
    i = idx
    async with httpx.AsyncClient(timeout=120.0) as c:
        while time.monotonic() < stop and t.take():
            body = small_toolpath(i)
            i += 32
            t0 = time.perf_counter()
            try:
                r = await c.post(url + "/v1/schedule", json=body)
            except httpx.HTTPError as exc:
                t.errors.append(f"{type(exc).__name__}: {exc}")
                continue
            dt = time.perf_counter() - t0
            if r.status_code == 200 and r.content.startswith(b'{"summary"'):
                t.lat.append(dt)
            elif (r.status_code == 503 and r.headers.get("content-type") == "application/problem+json"
                  and r.json().get("type") == "urn:feedsched:problem:busy" and r.headers.get("retry-after")):
                t.busy_lat.append(dt)
                ra = r.headers["retry-after"]
                t.retry_after[ra] = t.retry_after.get(ra, 0) + 1
                await asyncio.sleep(min(retry_cap, float(ra), max(0.0, stop - time.monotonic())))
            else:
                t.errors.append(f"{r.status_code}: {r.text[:200]}")


def probe(url: str, duration: float, out: Any, nice: int = 0) -> None:
    """Process: GET /healthz every 50 ms; send the latencies back.  ``nice`` (< 0 needs root): the
    probe's own priority, so that on a machine whose cores the load generator and the solvers keep
    busy its latencies are the server's and not the probe's own wait for a core (a remote probe)."""
    if nice:
        try:
            os.nice(nice)
        except PermissionError:
            nice = 0
    lat: list[float] = []
    fails = 0
    stop = time.monotonic() + duration
    with httpx.Client(timeout=10.0) as c:
        while time.monotonic() < stop:
            t0 = time.perf_counter()
            try:
                ok = c.get(url + "/healthz").status_code == 200
            except httpx.HTTPError:
                ok = False
            dt = time.perf_counter() - t0
            if ok:
                lat.append(dt)
            else:
                fails += 1
            time.sleep(max(0.0, 0.05 - dt))
    out.send((lat, fails, nice))


def _proc_table() -> dict[int, tuple[int, int, str]]:
    """pid -> (parent pid, RSS bytes, command line) of every process we can read."""
    page = os.sysconf("SC_PAGE_SIZE")
    out: dict[int, tuple[int, int, str]] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
            fields = stat[stat.rindex(")") + 2:].split()
            rss = int(Path(f"/proc/{d}/statm").read_text().split()[1]) * page
            cmd = Path(f"/proc/{d}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except (OSError, ValueError, IndexError):
            continue
        out[int(d)] = (int(fields[1]), rss, cmd)
    return out


def rss_sample(root: int) -> dict[str, float]:
    """RSS (MB) of the server process, its long-lived helpers (its children: forkserver, resource tracker) and
    the solver processes alive at this instant (their children), read from /proc."""
    table = _proc_table()
    kids: dict[int, list[int]] = {}
    for pid, (ppid, _, _) in table.items():
        kids.setdefault(ppid, []).append(pid)
    mb = 1.0 / 2**20
    server = table.get(root, (0, 0, ""))[1] * mb
    helpers = workers = 0.0
    n_workers = 0
    stack = [(pid, 1) for pid in kids.get(root, [])]
    while stack:  # children of the server: forkserver, resource tracker; below them: solver processes
        pid, depth = stack.pop()
        rss = table[pid][1]
        if depth == 1:
            helpers += rss * mb
        else:
            workers += rss * mb
            n_workers += 1
        stack += [(k, depth + 1) for k in kids.get(pid, [])]
    return {"server_mb": server, "helpers_mb": helpers, "workers_mb": workers, "workers": n_workers,
            "total_mb": server + helpers + workers}


async def sample_rss(pid: int, every: float, stop: float, out: list[dict[str, float]]) -> None:
    t0 = time.monotonic()
    while True:
        s = await asyncio.to_thread(rss_sample, pid)
        out.append({"t_s": time.monotonic() - t0, **s})
        if time.monotonic() >= stop:
            return
        await asyncio.sleep(min(every, max(0.0, stop - time.monotonic())))


def slope_per_min(ts: list[float], ys: list[float]) -> float:
    """Least-squares slope of ys against ts (s), per minute."""
    n = len(ts)
    if n < 2:
        return math.nan
    mt, my = sum(ts) / n, sum(ys) / n
    var = sum((t - mt) ** 2 for t in ts)
    return 60.0 * sum((t - mt) * (y - my) for t, y in zip(ts, ys, strict=True)) / var if var else math.nan


def rss_summary(samples: list[dict[str, float]]) -> dict[str, Any]:
    if not samples:
        return {}
    ts = [x["t_s"] for x in samples]
    out: dict[str, Any] = {"rss_samples": len(samples)}
    for key in ("server_mb", "helpers_mb", "total_mb"):
        ys = [x[key] for x in samples]
        half = len(ys) // 2
        out[key.replace("_mb", "")] = {
            "start_mb": ys[0], "end_mb": ys[-1], "peak_mb": max(ys), "min_mb": min(ys),
            "slope_mb_per_min": slope_per_min(ts, ys),
            "slope_second_half_mb_per_min": slope_per_min(ts[half:], ys[half:]),
        }
    out["workers_alive_max"] = max(int(x["workers"]) for x in samples)
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(data_dir: str, root: Path = ROOT) -> tuple[subprocess.Popen[bytes], str]:
    """uvicorn serving ``root``'s service (another checkout's, to measure an older commit) with its data in
    ``data_dir``; the process and its URL once /healthz answers."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "FEEDSCHED_DATA_DIR": data_dir}
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "service.app:app", "--host", "127.0.0.1",
                             "--port", str(port), "--log-level", "warning"], cwd=root, env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("server did not start")


async def run(url: str, clients: int, duration: float, *, pid: int | None = None, rss_every: float = 5.0,
              max_requests: int = 1_000_000, retry_cap: float = 5.0, probe_nice: int = 0) -> dict[str, Any]:
    # warm-up: the first request pays for nothing extra (forkserver is started at startup), but be fair
    async with httpx.AsyncClient(timeout=60) as c:
        assert (await c.post(url + "/v1/schedule", json=small_toolpath(0))).status_code == 200
        limit = (await c.get(url + "/healthz")).json().get("schedules_limit")
    recv, send = mp.Pipe(duplex=False)
    prober = mp.get_context("spawn").Process(target=probe, args=(url, duration, send, probe_nice))
    prober.start()
    tally = Tally(max_requests)
    rss: list[dict[str, float]] = []
    t0 = time.monotonic()
    stop = t0 + duration
    tasks = [client_loop(url, i, stop, tally, retry_cap) for i in range(clients)]
    if pid is not None:
        tasks.append(sample_rss(pid, rss_every, stop, rss))
    await asyncio.gather(*tasks)
    wall = time.monotonic() - t0
    h_lat, h_fails, h_nice = recv.recv()
    prober.join()
    async with httpx.AsyncClient(timeout=60) as c:
        health = (await c.get(url + "/healthz")).json()
    lat, busy = tally.lat, tally.busy_lat
    return {
        "clients": clients, "schedules_limit": limit, "duration_s": duration, "wall_s": wall,
        "requests": len(lat) + len(busy) + len(tally.errors), "ok_200": len(lat), "busy_503": len(busy),
        "errors": len(tally.errors), "error_samples": tally.errors[:5], "retry_after_values": tally.retry_after,
        "server_refused_count": health.get("schedules_refused"),
        "throughput_rps": len(lat) / wall,
        "latency_p50_ms": 1e3 * pct(lat, 50), "latency_p95_ms": 1e3 * pct(lat, 95),
        "latency_p99_ms": 1e3 * pct(lat, 99), "latency_max_ms": 1e3 * max(lat, default=math.nan),
        "busy_latency_p50_ms": 1e3 * pct(busy, 50), "busy_latency_p95_ms": 1e3 * pct(busy, 95),
        "busy_latency_max_ms": 1e3 * max(busy, default=math.nan),
        "healthz_probes": len(h_lat), "healthz_failures": h_fails, "healthz_probe_nice": h_nice,
        "healthz_p50_ms": 1e3 * pct(h_lat, 50), "healthz_p95_ms": 1e3 * pct(h_lat, 95),
        "healthz_p99_ms": 1e3 * pct(h_lat, 99), "healthz_max_ms": 1e3 * max(h_lat, default=math.nan),
        "healthz_over_50ms": sum(1 for x in h_lat if x > 0.05),
        "rss": rss_summary(rss), "rss_series": rss,
    }


def loadavg() -> list[float]:
    return [float(x) for x in Path("/proc/loadavg").read_text().split()[:3]]


def healthz_limit(url: str) -> int:
    return int(httpx.get(url + "/healthz", timeout=10).json()["schedules_limit"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--clients", type=int, default=32)
    ap.add_argument("--overload", type=float, default=None,
                    help="clients = this x the server's schedules_limit (overrides --clients)")
    ap.add_argument("--max-requests", type=int, default=1_000_000, help="bound on requests sent, all clients")
    ap.add_argument("--retry-cap", type=float, default=5.0, help="longest Retry-After wait honoured (s)")
    ap.add_argument("--rss-every", type=float, default=5.0, help="seconds between RSS samples")
    ap.add_argument("--pid", type=int, default=None, help="server pid for RSS with --url")
    ap.add_argument("--url", default=None, help="an already running server (loopback); default: start one")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "load.json"))
    ap.add_argument("--probe-nice", type=int, default=0,
                    help="niceness of the /healthz probe process (e.g. -5, as root: a probe that does not wait "
                         "for a core behind the load generator)")
    a = ap.parse_args()
    proc = None
    tmp = tempfile.TemporaryDirectory(prefix="feedsched-load-")
    url = a.url
    if url is None:
        proc, url = start_server(tmp.name)
    host = httpx.URL(url).host
    if host not in ("127.0.0.1", "localhost", "::1"):
        raise SystemExit("load only against loopback")
    pid = proc.pid if proc is not None else a.pid
    load_before = loadavg()
    try:
        clients = a.clients if a.overload is None else max(1, round(a.overload * healthz_limit(url)))
        res = asyncio.run(run(url, clients, a.duration, pid=pid, rss_every=a.rss_every,
                              max_requests=a.max_requests, retry_cap=a.retry_cap, probe_nice=a.probe_nice))
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=30)
        tmp.cleanup()
    res.update({"cpus": os.cpu_count(), "python": platform.python_version(), "loadavg_before": load_before,
                "loadavg_after": loadavg(), "overload_factor": a.overload,
                "workers": os.environ.get("FEEDSCHED_WORKERS", str(os.cpu_count())),
                "median_note": "one run on a shared 2-core machine; client, server and solvers share the cores"})
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps({k: v for k, v in res.items() if k != "rss_series"}, indent=2))
    print(f"\n| clients | duration | 200 | 503 | other | p50 / p95 (200) | p95 (503) | throughput | "
          f"healthz p50 / p95 / p99 / max | > 50 ms |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n"
          f"| {res['clients']} | {res['duration_s']:.0f} s | {res['ok_200']} | {res['busy_503']} | {res['errors']} | "
          f"{res['latency_p50_ms']:.0f} / {res['latency_p95_ms']:.0f} ms | {res['busy_latency_p95_ms']:.1f} ms | "
          f"{res['throughput_rps']:.1f} req/s | {res['healthz_p50_ms']:.1f} / {res['healthz_p95_ms']:.1f} / "
          f"{res['healthz_p99_ms']:.1f} / {res['healthz_max_ms']:.1f} ms | {res['healthz_over_50ms']} of "
          f"{res['healthz_probes']} |")
    for key, r in res["rss"].items():
        if isinstance(r, dict):
            print(f"RSS {key}: start {r['start_mb']:.1f} MB, end {r['end_mb']:.1f}, peak {r['peak_mb']:.1f}, "
                  f"slope {r['slope_mb_per_min']:+.3f} MB/min (second half {r['slope_second_half_mb_per_min']:+.3f})")
    if res["errors"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
