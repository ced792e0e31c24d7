"""Load on loopback: N concurrent clients POST small toolpaths to /v1/schedule for a while.

    python -m bench.load [--duration 60] [--clients 32] [--url http://127.0.0.1:8000]

Without --url a uvicorn server is started on a free loopback port (FEEDSCHED_* from the environment) and
stopped at the end.  A separate process probes /healthz every 50 ms meanwhile: the event loop must never
block on solver work.  Reports errors, p50/p95 latency, throughput and /healthz latency; writes
bench/results/load.json.  Every loop is bounded by --duration; only loopback addresses are used.
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


async def client_loop(url: str, idx: int, stop: float, lat: list[float], errors: list[str]) -> None:
    i = idx
    async with httpx.AsyncClient(timeout=120.0) as c:
        while time.monotonic() < stop:
            body = small_toolpath(i)
            i += 32
            t0 = time.perf_counter()
            try:
                r = await c.post(url + "/v1/schedule", json=body)
                ok = r.status_code == 200 and r.content.startswith(b'{"summary"')
                if not ok:
                    errors.append(f"{r.status_code}: {r.text[:200]}")
            except httpx.HTTPError as exc:
                errors.append(f"{type(exc).__name__}: {exc}")
                continue
            lat.append(time.perf_counter() - t0)


def probe(url: str, duration: float, out: Any) -> None:
    """Process: GET /healthz every 50 ms; send the latencies back."""
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
    out.send((lat, fails))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(data_dir: str) -> tuple[subprocess.Popen[bytes], str]:
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = {"FEEDSCHED_DATA_DIR": data_dir, **os.environ}
    proc = subprocess.Popen([sys.executable, "-m", "uvicorn", "service.app:app", "--host", "127.0.0.1",
                             "--port", str(port), "--log-level", "warning"], cwd=ROOT, env=env)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/healthz", timeout=1).status_code == 200:
                return proc, url
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise SystemExit("server did not start")


async def run(url: str, clients: int, duration: float) -> dict[str, Any]:
    # warm-up: the first request pays for nothing extra (forkserver is started at startup), but be fair
    async with httpx.AsyncClient(timeout=60) as c:
        assert (await c.post(url + "/v1/schedule", json=small_toolpath(0))).status_code == 200
    recv, send = mp.Pipe(duplex=False)
    prober = mp.get_context("spawn").Process(target=probe, args=(url, duration, send))
    prober.start()
    lat: list[float] = []
    errors: list[str] = []
    t0 = time.monotonic()
    stop = t0 + duration
    await asyncio.gather(*(client_loop(url, i, stop, lat, errors) for i in range(clients)))
    wall = time.monotonic() - t0
    h_lat, h_fails = recv.recv()
    prober.join()
    return {
        "clients": clients, "duration_s": duration, "wall_s": wall, "requests": len(lat), "errors": len(errors),
        "error_samples": errors[:5], "throughput_rps": len(lat) / wall,
        "latency_p50_ms": 1e3 * pct(lat, 50), "latency_p95_ms": 1e3 * pct(lat, 95),
        "latency_p99_ms": 1e3 * pct(lat, 99), "latency_max_ms": 1e3 * max(lat, default=math.nan),
        "healthz_probes": len(h_lat), "healthz_failures": h_fails,
        "healthz_p50_ms": 1e3 * pct(h_lat, 50), "healthz_p95_ms": 1e3 * pct(h_lat, 95),
        "healthz_max_ms": 1e3 * max(h_lat, default=math.nan),
        "healthz_over_50ms": sum(1 for x in h_lat if x > 0.05),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--clients", type=int, default=32)
    ap.add_argument("--url", default=None, help="an already running server (loopback); default: start one")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "load.json"))
    a = ap.parse_args()
    proc = None
    tmp = tempfile.TemporaryDirectory(prefix="feedsched-load-")
    url = a.url
    if url is None:
        proc, url = start_server(tmp.name)
    host = httpx.URL(url).host
    if host not in ("127.0.0.1", "localhost", "::1"):
        raise SystemExit("load only against loopback")
    try:
        res = asyncio.run(run(url, a.clients, a.duration))
    finally:
        if proc is not None:
            proc.terminate()
            proc.wait(timeout=30)
        tmp.cleanup()
    res.update({"cpus": os.cpu_count(), "python": platform.python_version(),
                "workers": os.environ.get("FEEDSCHED_WORKERS", str(os.cpu_count())),
                "median_note": "one run on a shared 2-core machine; client, server and solvers share the cores"})
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(res, indent=2))
    print(f"\n| clients | duration | requests | errors | p50 | p95 | throughput | healthz p50 / p95 / max |\n"
          f"| --- | --- | --- | --- | --- | --- | --- | --- |\n"
          f"| {res['clients']} | {res['duration_s']:.0f} s | {res['requests']} | {res['errors']} | "
          f"{res['latency_p50_ms']:.0f} ms | {res['latency_p95_ms']:.0f} ms | {res['throughput_rps']:.1f} req/s | "
          f"{res['healthz_p50_ms']:.1f} / {res['healthz_p95_ms']:.1f} / {res['healthz_max_ms']:.1f} ms |")
    if res["errors"]:
        sys.exit(1)


if __name__ == "__main__":
    main()
