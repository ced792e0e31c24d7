"""Memory of a long job through the service: the solver process, the web process, and the result's downloads.

A uvicorn server is started (a fresh data dir, FEEDSCHED_* from the environment) from ``--root`` (default this
checkout; give another worktree to measure an older commit with the same script).  One job is posted: a straight
line at a low feed cap (method lp), ``--samples`` output samples at 1 ms.  While it runs, and then while its
result is downloaded as JSON, CSV and NDJSON (each read to the end and counted, never held), the resident memory
of the web process and of every process under it (the forkserver and the job's solver process) is read from
/proc every ``--every`` s: VmRSS and RssAnon (anonymous pages: what the kernel cannot drop; file pages of a
mapped result file are page cache).

Then the report page and three plots are fetched (rendered from the stored result).
Reported per phase (job, json, csv, ndjson, plots): the peak RSS and anonymous RSS of the web process, and the peak of
the largest other process; the job's wall time and the bytes of each download.  The downloads' SHA-256 are
printed so that two commits can be checked to serve the same bytes.

Rows (two jobs, 1 M and 3 M samples, in one run): the solver process's peak anonymous RSS at both sizes (flat:
it holds one block of samples and writes the rest to the result file), and the web process's peak anonymous RSS
over idle across the job and the downloads (it maps the file and sends it in pieces).
``python -m bench.job_memory [--samples 1000000 3000000] [--root DIR]`` prints one JSON line (in ``make bench``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import orjson

from bench._common import emit, env_info, row, verdict
from bench.load import start_server

ROOT = Path(__file__).resolve().parents[1]
#: Output samples of the two jobs compared (the peaks must not grow with them).
SIZES = (1_000_000, 3_000_000)
#: Feed cap of the job's line, mm/s: ``--samples`` ms of motion cover samples * FEED / 1000 mm.
FEED = 0.1


def _status_kb(pid: int) -> dict[str, int]:
    out: dict[str, int] = {}
    try:
        for ln in Path(f"/proc/{pid}/status").read_text().splitlines():
            key, _, rest = ln.partition(":")
            if key in ("VmRSS", "RssAnon"):
                out[key] = int(rest.split()[0])
    except (OSError, ValueError):
        pass
    return out


def _descendants(pid: int) -> list[int]:
    kids: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        kids.setdefault(ppid, []).append(int(d.name))
    out: list[int] = []
    todo = [pid]
    while todo:
        p = todo.pop()
        for c in kids.get(p, []):
            out.append(c)
            todo.append(c)
    return out


class Sampler:
    """Peaks of the web process's VmRSS / RssAnon and of the largest descendant's, in MB, per phase."""

    def __init__(self, pid: int, every: float) -> None:
        self.pid, self.every = pid, every
        self.phase = "idle"
        self.peaks: dict[str, dict[str, float]] = {}
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._loop, daemon=True)
        self._t.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            web = _status_kb(self.pid)
            kids = [_status_kb(p) for p in _descendants(self.pid)]
            pk = self.peaks.setdefault(self.phase, {})
            for key, val in (("web_rss_mb", web.get("VmRSS", 0)), ("web_anon_mb", web.get("RssAnon", 0)),
                             ("child_rss_mb", max((k.get("VmRSS", 0) for k in kids), default=0)),
                             ("child_anon_mb", max((k.get("RssAnon", 0) for k in kids), default=0))):
                pk[key] = max(pk.get(key, 0.0), val / 1024.0)
            time.sleep(self.every)

    def stop(self) -> None:
        self._stop.set()
        self._t.join()


def request(samples: int) -> dict[str, Any]:
    length = samples * FEED / 1000.0
    return {"toolpath": {"segments": [{"type": "line", "start": [0.0, 0.0, 0.0],
                                       "end": [length, 0.0, 0.0]}]},
            "machine": "router", "options": {"method": "lp", "feed_max": FEED}}


def download(url: str, fmt: str) -> tuple[int, str]:
    """Bytes of the download and the SHA-256 of its samples: the body without the summary (whose timings differ
    from run to run): JSON's ``samples`` re-encoded, NDJSON without its last line, CSV whole."""
    n = 0
    body = bytearray() if fmt == "json" else None
    h = hashlib.sha256()
    tail = b""
    with httpx.stream("GET", url, params={"format": fmt}, timeout=3600) as r:
        r.raise_for_status()
        for chunk in r.iter_bytes():
            n += len(chunk)
            if body is not None:
                body += chunk
            elif fmt == "ndjson":  # (every line but the last, the summary)
                data = tail + chunk
                cut = data.rfind(b"\n", 0, len(data) - 1) + 1
                h.update(data[:cut])
                tail = data[cut:]
            else:
                h.update(chunk)
    if body is not None:
        h.update(orjson.dumps(orjson.loads(bytes(body))["samples"]))
    return n, h.hexdigest()


def run_job(samples: int, root: Path, every: float) -> dict[str, Any]:
    """One server, one job of ``samples`` samples and its three downloads; the peaks per phase."""
    with tempfile.TemporaryDirectory() as data:
        proc, url = start_server(data, root)
        try:
            sampler = Sampler(proc.pid, every)
            time.sleep(1.0)
            sampler.phase = "job"
            t0 = time.perf_counter()
            r = httpx.post(url + "/v1/jobs", json=request(samples), timeout=60)
            r.raise_for_status()
            jid = r.json()["id"]
            while True:
                st = httpx.get(f"{url}/v1/jobs/{jid}", timeout=60).json()
                if st["status"] not in ("queued", "running"):
                    break
                time.sleep(0.2)
            job_wall = time.perf_counter() - t0
            if st["status"] != "succeeded":
                raise SystemExit(f"job {st['status']}: {json.dumps(st)[:800]}")
            out: dict[str, Any] = {"samples": st["summary"]["samples"], "job_wall_s": job_wall,
                                   "motion_time": st["summary"]["motion_time"], "downloads": {}}
            time.sleep(1.0)
            for fmt in ("json", "csv", "ndjson"):
                sampler.phase = fmt
                t0 = time.perf_counter()
                n, digest = download(f"{url}/v1/jobs/{jid}/result", fmt)
                out["downloads"][fmt] = {"bytes": n, "sha256": digest, "wall_s": time.perf_counter() - t0}
                time.sleep(1.0)
            sampler.phase = "plots"  # (the report page and its three plots, rendered from the mapped file)
            t0 = time.perf_counter()
            for part in ("report", "plots/toolpath.svg", "plots/feed.svg", "plots/axes.png"):
                httpx.get(f"{url}/v1/jobs/{jid}/{part}", timeout=3600).raise_for_status()
            out["plots_wall_s"] = time.perf_counter() - t0
            time.sleep(1.0)
            sampler.stop()
            out["peaks"] = sampler.peaks
        finally:
            proc.terminate()
            proc.wait(30)
    return out


def main(sizes: tuple[int, ...], root: Path, every: float) -> dict[str, Any]:
    runs = [run_job(n, root, every) for n in sizes]
    rows: list[dict[str, str]] = []
    if len(runs) == 2:
        a, b = runs
        k = b["samples"] / a["samples"]

        def peak(run: dict[str, Any], who: str, phases: tuple[str, ...]) -> float:
            return max(run["peaks"][ph][who] for ph in phases)

        def growth(run: dict[str, Any], who: str, phases: tuple[str, ...]) -> float:
            return peak(run, who, phases) - run["peaks"]["idle"][who]

        cols = {r["samples"]: r["samples"] * 21 * 8 / 2**20 for r in runs}  # (21 float64 columns, MB)
        child = (peak(a, "child_anon_mb", ("job",)), peak(b, "child_anon_mb", ("job",)))
        rows.append(row(
            f"job memory, solver process peak anonymous RSS at {a['samples']:,} / {b['samples']:,} samples "
            "(a line at 0.1 mm/s, method lp; `bench.job_memory`)",
            f"{child[0]:.0f} / {child[1]:.0f} MB", f"the result's columns {cols[a['samples']]:.0f} / "
            f"{cols[b['samples']]:.0f} MB", f"{child[1] / child[0]:.2f}x for {k:.1f}x the samples",
            "flat in the samples (< 1.2x)", verdict(child[1] / child[0] < 1.2)))
        phases = ("job", "json", "csv", "ndjson")
        plots = (growth(a, "web_anon_mb", ("plots",)), growth(b, "web_anon_mb", ("plots",)))
        web = (growth(a, "web_anon_mb", phases), growth(b, "web_anon_mb", phases))
        rows.append(row(
            "job memory, web process peak anonymous RSS over idle, job and its JSON / CSV / NDJSON downloads",
            f"+{web[0]:.0f} / +{web[1]:.0f} MB", "the result's columns as above",
            f"{web[1] / cols[b['samples']]:.3f} of the larger result", "< 0.1 of the result",
            verdict(web[1] < 0.1 * cols[b["samples"]])))
        rows.append(row(
            "same, while the report page and the toolpath, feed and axes plots are rendered",
            f"+{plots[0]:.0f} / +{plots[1]:.0f} MB", "the result's columns as above",
            f"{plots[1] / cols[b['samples']]:.3f} of the larger result", "report", verdict(None)))
    return {"runs": runs, "rows": rows}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--root", type=Path, default=ROOT)
    ap.add_argument("--every", type=float, default=0.05)
    a = ap.parse_args()
    emit({"env": env_info(), "root": str(a.root), **main(tuple(a.samples), a.root, a.every)})
