"""Result files written as the schedule is computed (service.resultfile), read through a memory map, and the
JSON body sent in pieces (convert.iter_json): the same bytes and values as the whole-result paths.

The oracles are numpy (``np.load`` reads what ``ResultWriter`` writes; ``np.savez`` wrote the files of earlier
versions), ``compute`` (the schedule held whole) and ``encode_json`` (the body encoded at once)."""

from __future__ import annotations

import io
import json
import mmap
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pytest
from fastapi.testclient import TestClient

from service import convert, resultfile, worker
from service.convert import Budget, Result, encode_json, iter_json, load_result, result_bytes, save_result
from service.resultfile import ResultFileError, ResultWriter
from service.schemas import EXAMPLE
from solvers.errors import LimitViolationError
from solvers.pipeline import SampleBlock
from tests.service.conftest import long_line, pid_gone, wait_for
from tests.service.test_jobs import poll_done

BUDGET = Budget(max_samples=5_000_000, max_intervals=1_000_000, where="a job")


def _columns(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    # (full-precision values: every bit must survive)
    return {"t": np.arange(n) * 1e-3, "x": rng.standard_normal(n) * 123.456789, "v_x": rng.standard_normal(n)}


def _mapped(a: np.ndarray) -> bool:
    base: Any = a
    while isinstance(base, np.ndarray):
        base = base.base
    return isinstance(getattr(base, "obj", base), mmap.mmap)


def test_blocks_written_are_read_back_bit_for_bit_by_numpy_and_mapped(tmp_path: Path) -> None:
    cols = _columns(10_007)
    path = tmp_path / "r.npz"
    w = ResultWriter(path)
    for a, b in ((0, 3), (3, 5000), (5000, 5000), (5000, 10_007)):  # (an empty block too)
        w.append({k: v[a:b] for k, v in cols.items()})
    summary, diag = {"motion_time": 1.25, "samples": 10_007}, {"corners": [], "lp_feed": {"s": [0.0]}}
    w.finish(summary, diag)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.npz"]  # (parts and temporary zip removed)
    with np.load(path, allow_pickle=False) as z:  # the oracle: numpy's own reader
        meta = json.loads(bytes(z["__meta__"]).decode())
        assert meta == {"summary": summary, "diagnostics": diag, "columns": list(cols)}
        for i, (k, v) in enumerate(cols.items()):
            assert z[f"c{i}"].tobytes() == v.tobytes(), k
    res = load_result(path)
    assert res.summary == summary and res.diagnostics == diag and list(res.columns) == list(cols)
    for k, v in cols.items():
        got = res.columns[k]
        assert got.dtype == np.float64 and got.tobytes() == v.tobytes(), k
        assert _mapped(got) and not got.flags.writeable, k  # (no copy of the file in memory)


def test_a_file_of_earlier_versions_loads(tmp_path: Path) -> None:
    """Results stored before this module (``np.savez`` of the whole result in the service process)."""
    cols = _columns(777, seed=3)
    res = Result(summary={"a": 1}, diagnostics={"b": [2]}, columns=cols)
    path = tmp_path / "old.npz"
    path.write_bytes(result_bytes(res))  # (what save_result wrote before)
    got = load_result(path)
    assert got.summary == res.summary and got.diagnostics == res.diagnostics
    assert all(got.columns[k].tobytes() == v.tobytes() and _mapped(got.columns[k]) for k, v in cols.items())


def test_a_compressed_member_is_read_into_memory(tmp_path: Path) -> None:
    cols = _columns(500, seed=4)
    path = tmp_path / "z.npz"
    buf = io.BytesIO()
    meta = json.dumps({"summary": {}, "diagnostics": {}, "columns": list(cols)}).encode()
    np.savez_compressed(buf, **{f"c{i}": v for i, v in enumerate(cols.values())},
                        __meta__=np.frombuffer(meta, dtype=np.uint8))
    path.write_bytes(buf.getvalue())
    got = load_result(path)
    assert all(got.columns[k].tobytes() == v.tobytes() for k, v in cols.items())


def test_a_damaged_file_is_an_error_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "bad.npz"
    save_result(Result(summary={}, diagnostics={}, columns=_columns(100)), path)
    with zipfile.ZipFile(path) as zf:
        members = {n: zf.read(n) for n in zf.namelist() if n != "c1.npy"}
    with zipfile.ZipFile(path, "w") as zf:
        for n, data in members.items():
            zf.writestr(n, data)
    with pytest.raises(ResultFileError, match=r"bad\.npz: column 'x' \(c1\.npy\) is missing"):
        load_result(path)


def test_a_block_with_other_columns_is_refused_and_abort_leaves_nothing(tmp_path: Path) -> None:
    path = tmp_path / "r.npz"
    w = ResultWriter(path)
    w.append(_columns(10))
    with pytest.raises(ValueError, match="differ from the first block's"):
        w.append({"t": np.zeros(3)})
    with pytest.raises(ValueError, match="unequal lengths"):
        w.append({"t": np.zeros(3), "x": np.zeros(2), "v_x": np.zeros(3)})
    w.abort()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("rows", [0, 1, 9, 10, 31])
@pytest.mark.parametrize("with_plots", [False, True])
def test_json_in_pieces_is_the_whole_body(rows: int, with_plots: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(convert, "JSON_CHUNK_VALUES", 10)
    res = Result(summary={"motion_time": 1.0 / 3.0, "n": np.int64(5), "nested": {"x": [np.float64(0.1)]}},
                 diagnostics={"corners": [{"s": 2.0}], "s\"q": None}, columns=_columns(rows, seed=rows))
    plots = {"feed": "data:image/svg+xml;base64,AAAA"} if with_plots else None
    whole = encode_json(res, plots)
    assert b"".join(iter_json(res, plots)) == whole
    assert orjson.loads(whole)["samples"]["x"] == res.columns["x"].tolist()


def _two_slow_legs(feed: float = 0.1, leg: float = 12.5) -> dict[str, Any]:
    """Two legs at a right angle (two pieces: rest at the corner) at a low feed cap: 2 x 125,000 samples."""
    return {"toolpath": {"segments": [{"type": "line", "start": [0.0, 0.0, 0.0], "end": [leg, 0.0, 0.0]},
                                      {"type": "line", "end": [leg, leg, 0.0]}]},
            "machine": "router", "options": {"method": "lp", "feed_max": feed}}


def test_a_job_file_has_the_columns_of_the_schedule_held_whole(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Written block by block (the stream's smallest block, 100,000 samples: two per piece) against ``compute``'s
    result held whole."""
    monkeypatch.setattr(worker, "JOB_BLOCK_SAMPLES", 1)
    request = _two_slow_legs()
    blocks: list[int] = []
    real = worker.schedule_stream

    def counted(*args: Any, **kwargs: Any) -> Any:
        for item in real(*args, **kwargs):
            if isinstance(item, SampleBlock):
                blocks.append(item.piece)
            yield item

    monkeypatch.setattr(worker, "schedule_stream", counted)
    seen: list[float] = []
    summary = worker.compute_to_file(request, BUDGET, tmp_path / "job.npz", seen.append)
    whole = worker.compute(request, BUDGET)
    got = load_result(tmp_path / "job.npz")
    n = len(whole.columns["t"])
    assert blocks.count(0) >= 2 and blocks.count(1) >= 2
    assert n > 250_000 and summary["samples"] == n and got.summary == summary and seen and seen[-1] == 1.0
    assert list(got.columns) == list(whole.columns)
    for k, v in whole.columns.items():
        assert got.columns[k].tobytes() == v.tobytes(), k
    timing = ("compute_time", "lp_time", "nlp_time")
    assert {k: v for k, v in got.summary.items() if k not in timing} == \
        {k: v for k, v in whole.summary.items() if k not in timing}
    assert got.diagnostics == whole.diagnostics
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.npz"]


def test_a_job_failing_after_its_first_blocks_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    real = worker.schedule_stream
    written: list[Path] = []

    def failing(*args: Any, **kwargs: Any) -> Any:
        for item in real(*args, **kwargs):
            if isinstance(item, SampleBlock) and item.piece == 1:  # (piece 0 written)
                written.extend(resultfile.parts_dir(tmp_path / "job.npz").iterdir())
                raise LimitViolationError("injected by the test", field="toolpath")
            yield item

    monkeypatch.setattr(worker, "schedule_stream", failing)
    with pytest.raises(LimitViolationError, match="injected"):
        worker.compute_to_file(_two_slow_legs(), BUDGET, tmp_path / "job.npz")
    assert written and list(tmp_path.iterdir()) == []


def test_a_long_job_result_is_sent_in_pieces_with_the_same_samples(client: TestClient,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The job's JSON sent in pieces (no Content-Length) against the same schedule answered synchronously."""
    from service import http

    loc = client.post("/v1/jobs", json=EXAMPLE).headers["location"]
    assert poll_done(client, loc)["status"] == "succeeded"
    sync = client.post("/v1/schedule", json=EXAMPLE)
    assert "content-length" in sync.headers
    monkeypatch.setattr(http, "JSON_STREAM_ROWS", 100)
    r = client.get(loc + "/result")
    assert r.status_code == 200 and "content-length" not in r.headers
    assert int(r.headers["x-samples"]) == len(r.json()["samples"]["t"]) > 100
    assert r.json()["samples"] == sync.json()["samples"]


def test_a_cancelled_job_leaves_no_file(client: TestClient) -> None:
    results = Path(client.app.state.service.store.results)  # type: ignore[attr-defined]
    loc = client.post("/v1/jobs", json=long_line(40_000.0)).headers["location"]
    jid = loc.rsplit("/", 1)[1]
    running = wait_for(lambda: (j := client.get(loc).json())["progress"] > 0 and j["worker_pid"] and j, "progress")
    assert client.delete(loc).status_code == 200
    wait_for(lambda: pid_gone(running["worker_pid"]), "the solver process to die")
    wait_for(lambda: not [p for p in results.iterdir() if p.name.startswith(jid)], "the job's files to go")


def test_zip_member_offsets_follow_the_local_headers(tmp_path: Path) -> None:
    """A member whose local header carries an extra field (zip64 sizes) still maps at its data."""
    path = tmp_path / "r.npz"
    cols = _columns(64, seed=9)
    with zipfile.ZipFile(path, "w") as zf:
        meta = json.dumps({"summary": {}, "diagnostics": {}, "columns": list(cols)}).encode()
        for i, v in enumerate(cols.values()):
            with zf.open(f"c{i}.npy", "w", force_zip64=True) as f:
                np.lib.format.write_array(f, v)
        with zf.open("__meta__.npy", "w") as f:
            np.lib.format.write_array(f, np.frombuffer(meta, dtype=np.uint8))
    got = resultfile.load(path)[2]
    assert all(got[k].tobytes() == v.tobytes() and _mapped(got[k]) for k, v in cols.items())
