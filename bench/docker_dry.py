"""The Dockerfile's steps without a Docker engine (this machine has the docker client only).

    python -m bench.docker_dry [--keep]

``docker build`` cannot run here, so this carries out what the Dockerfile says, step by step, on the
host's Python 3.11 (the image's base is python:3.11-slim):

1. ENV, WORKDIR and COPY: a fresh directory (the image's /app) gets only the files the COPY lines
   name, so a runtime import of anything else (tests/, bench/) fails here as it would in the image;
2. RUN pip install: a fresh virtual environment (the image's site-packages) installs exactly the
   RUN line's requirement, with the same constraints file, from the package registry;
3. RUN useradd / USER: the CMD runs as an unprivileged uid (``setpriv``) that owns only the data
   directory (the image's /data volume), with the ENV of the Dockerfile (HOST set to loopback);
4. CMD: the Dockerfile's command line, as written; then /healthz, the README's curl example
   (``POST /v1/schedule``), ``/v1/machines`` and the HEALTHCHECK command are tried against it.

Prints one line per step and a JSON summary; exits non-zero if a step fails.  It does not check
the base image itself, the layer cache or the image size.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
#: uid/gid the CMD runs as (the Dockerfile's `useradd --uid`).
UID_RE = re.compile(r"useradd\b.*--uid\s+(\d+)")
READY_TIMEOUT_S = 60.0
#: The README's curl example body (the bundled quarter circle, radius 40 mm, on the router preset).
EXAMPLE = {
    "toolpath": {"segments": [{"type": "nurbs", "degree": 2, "knots": [0, 0, 0, 1, 1, 1],
                               "control_points": [[0, 0, 0], [40, 0, 0], [40, 40, 0]],
                               "weights": [1, 0.7071067811865476, 1]}]},
    "machine": "router",
}


def parse(dockerfile: Path) -> dict[str, Any]:
    """The instructions this script carries out: ENV (merged), WORKDIR, COPY (src, dst), RUN lines,
    USER, HEALTHCHECK CMD and CMD (exec form), with line continuations joined."""
    text = re.sub(r"\\\n\s*", " ", dockerfile.read_text())
    out: dict[str, Any] = {"env": {}, "copy": [], "run": [], "user": None, "cmd": None, "healthcheck": None,
                           "workdir": "/", "from": None}
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        op, _, rest = line.partition(" ")
        op = op.upper()
        if op == "FROM":
            out["from"] = rest.strip()
        elif op == "ENV":
            for tok in shlex.split(rest):
                k, _, v = tok.partition("=")
                out["env"][k] = v
        elif op == "WORKDIR":
            out["workdir"] = rest.strip()
        elif op == "COPY":
            *srcs, dst = shlex.split(rest)
            out["copy"].append((srcs, dst))
        elif op == "RUN":
            out["run"].append(rest.strip())
        elif op == "USER":
            out["user"] = rest.strip()
        elif op == "HEALTHCHECK":
            out["healthcheck"] = rest.split(" CMD ", 1)[1].strip()
        elif op == "CMD":
            out["cmd"] = json.loads(rest)
    return out


def _base_python() -> str:
    """A Python 3.11 that the unprivileged uid can run: the system one (Debian's /usr/bin/python3 is
    3.11), as the image's is under /usr/local; pyenv's lives under /root, which that uid cannot read."""
    for cand in ("/usr/bin/python3.11", "/usr/bin/python3"):
        if Path(cand).exists():
            v = subprocess.run([cand, "-c", "import sys; print(sys.version_info[:2] == (3, 11))"],
                               capture_output=True, text=True)
            if v.stdout.strip() == "True":
                return cand
    return sys.executable


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _step(name: str, ok: bool, detail: str, results: list[dict[str, Any]]) -> None:
    results.append({"step": name, "ok": ok, "detail": detail})
    print(f"{'ok  ' if ok else 'FAIL'} {name}: {detail}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--keep", action="store_true", help="keep the temporary image directory")
    args = ap.parse_args(argv)
    df = parse(ROOT / "Dockerfile")
    results: list[dict[str, Any]] = []
    tmp = Path(tempfile.mkdtemp(prefix="feedsched-image-"))
    proc: subprocess.Popen[bytes] | None = None
    try:
        base_py = _base_python()
        ver = subprocess.run([base_py, "--version"], capture_output=True, text=True).stdout.strip()
        _step("FROM", bool(df["from"] and df["from"].startswith("python:3.11")),
              f"{df['from']}; here: {ver} ({base_py})", results)
        # 1. WORKDIR + COPY: only what the Dockerfile copies
        app = tmp / df["workdir"].lstrip("/")
        app.mkdir(parents=True)
        copied = []
        for srcs, dst in df["copy"]:
            for src in srcs:
                s = ROOT / src
                d = app / (src if dst.endswith("/") or dst == "./" else dst)
                if s.is_dir():
                    shutil.copytree(s, d, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
                else:
                    d.parent.mkdir(parents=True, exist_ok=True)
                    shutil.copy2(s, d)
                copied.append(src)
        _step("COPY", True, f"{', '.join(copied)} -> {df['workdir']}", results)
        # 2. RUN pip install, in a fresh venv standing for the image's interpreter
        venv = tmp / "python"
        subprocess.run([_base_python(), "-m", "venv", str(venv)], check=True)
        py = venv / "bin" / "python"
        pips = [r for r in df["run"] if r.startswith("pip install")]
        t0 = time.perf_counter()
        for r in pips:
            cmd = [str(py), "-m", *shlex.split(r)]
            done = subprocess.run(cmd, cwd=app, capture_output=True, text=True)
            if done.returncode:
                _step("RUN pip", False, done.stderr[-2000:], results)
                return 1
        _step("RUN pip", bool(pips), f"{'; '.join(pips)} ({time.perf_counter() - t0:.0f} s)", results)
        # 3. useradd / USER: an unprivileged uid that owns only the data volume
        m = next((UID_RE.search(r) for r in df["run"] if UID_RE.search(r)), None)
        uid = int(m.group(1)) if m else 10001
        data = tmp / df["env"].get("FEEDSCHED_DATA_DIR", "/data").lstrip("/")
        data.mkdir(parents=True, exist_ok=True)
        home = tmp / "home" / "app"  # useradd --create-home
        home.mkdir(parents=True)
        if os.geteuid() == 0:
            os.chown(data, uid, uid)
            os.chown(home, uid, uid)
            for p in (tmp, app, venv):
                os.chmod(p, 0o755)
        _step("USER", df["user"] is not None and df["user"] != "root", f"USER {df['user']} (uid {uid})", results)
        # 4. CMD with the image's ENV (loopback instead of 0.0.0.0, a free port, the data dir here)
        port = _free_port()
        env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "HOME": str(home), **df["env"],
               "HOST": "127.0.0.1", "PORT": str(port), "FEEDSCHED_DATA_DIR": str(data)}
        cmd = list(df["cmd"])
        if cmd and cmd[0] in ("sh", "/bin/sh"):
            cmd[0] = "/bin/sh"
        drop = ["setpriv", f"--reuid={uid}", f"--regid={uid}", "--clear-groups"] if os.geteuid() == 0 else []
        proc = subprocess.Popen([*drop, *cmd], cwd=app, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        base = f"http://127.0.0.1:{port}"
        t0 = time.perf_counter()
        ready = False
        while time.perf_counter() - t0 < READY_TIMEOUT_S and proc.poll() is None:
            try:
                with urllib.request.urlopen(base + "/healthz", timeout=2) as r:
                    ready = r.status == 200
                    break
            except OSError:
                time.sleep(0.3)
        if not ready:
            out = proc.stdout.read().decode(errors="replace") if proc.poll() is not None and proc.stdout else ""
            _step("CMD", False, f"no /healthz within {READY_TIMEOUT_S:.0f} s; {out[-2000:]}", results)
            return 1
        status = Path(f"/proc/{proc.pid}/status").read_text()
        ruid = int(re.search(r"^Uid:\s+(\d+)", status, re.M).group(1))  # type: ignore[union-attr]
        _step("CMD", ruid != 0, f"{' '.join(df['cmd'])} -> /healthz 200 after {time.perf_counter() - t0:.1f} s, "
              f"running as uid {ruid}", results)
        req = urllib.request.Request(base + "/v1/schedule", data=json.dumps(EXAMPLE).encode(),
                                     headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(req, timeout=120) as r:
            body = json.loads(r.read())
        n = len(body["samples"]["t"])
        _step("POST /v1/schedule", n > 0, f"{n} samples, motion {body['summary']['motion_time']:.4f} s", results)
        with urllib.request.urlopen(base + "/v1/machines/router", timeout=10) as r:
            _step("GET /v1/machines/router", r.status == 200, f"HTTP {r.status}", results)
        if df["healthcheck"]:
            hc = subprocess.run([*drop, "/bin/sh", "-c", df["healthcheck"]], env=env, cwd=app, timeout=30)
            _step("HEALTHCHECK", hc.returncode == 0, f"exit {hc.returncode}", results)
        wrote = [p.name for p in data.iterdir()]
        _step("VOLUME /data", bool(wrote), f"the service wrote {wrote} to the data directory as uid {uid}", results)
    finally:
        if proc is not None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)
    ok = all(r["ok"] for r in results)
    print(json.dumps({"ok": ok, "steps": results}, indent=1))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
