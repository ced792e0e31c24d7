"""The one exception -> problem mapping (service/errors.py)."""

from __future__ import annotations

from geometry import GeometryError
from service.errors import WorkerLost, WorkFailed, WorkTimeout, field_path, problem_from_exception, too_large
from solvers.errors import InfeasibleError, InvalidMachineError


def test_mapping_statuses_and_fields() -> None:
    g = problem_from_exception(GeometryError("toolpath.segments[2].weights[1]", -1.0, "weights must be > 0", 2))
    assert g["status"] == 422 and g["errors"][0] == {"field": "toolpath.segments[2].weights[1]",
                                                     "pointer": "#/toolpath/segments/2/weights/1",
                                                     "value": -1.0, "rule": "weights must be > 0"}
    m = problem_from_exception(InvalidMachineError("must be > 0", field="machine.axes.x.amax", value=float("nan")))
    assert m["status"] == 422 and m["type"].endswith("invalid-machine") and m["errors"][0]["value"] == "nan"
    i = problem_from_exception(InfeasibleError("no feasible feed", window=3, axis="z", status="Infeasible"))
    assert i["type"].endswith("infeasible") and i["window"] == 3 and i["axis"] == "z"
    assert problem_from_exception(too_large("big"))["status"] == 413
    assert problem_from_exception(WorkTimeout("slow"))["jobs"] == "/v1/jobs"
    assert problem_from_exception(WorkerLost("gone"))["status"] == 503
    p = {"type": "urn:x", "title": "t", "status": 422, "detail": "d", "errors": []}
    assert problem_from_exception(WorkFailed(p)) == p


def test_unexpected_exception_is_500_problem() -> None:
    p = problem_from_exception(ZeroDivisionError("float division by zero"))
    assert p["status"] == 500 and p["type"].endswith("internal") and "ZeroDivisionError" in p["detail"]
    assert p["errors"][0]["rule"]


def test_field_path_from_pydantic_locations() -> None:
    assert field_path(("body", "toolpath", "segments", 0, "control_points", 1, 0)) == (
        "toolpath.segments[0].control_points[1][0]", "#/toolpath/segments/0/control_points/1/0")
    assert field_path(("body", "machine", "custom", "axes", "z")) == ("machine.axes.z", "#/machine/axes/z")
    assert field_path(("path", "job_id")) == ("path.job_id", "#/path/job_id")
