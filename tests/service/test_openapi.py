"""The checked-in OpenAPI document is what the app serves; schemathesis fuzzes the served spec."""

from __future__ import annotations

import itertools
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from schemathesis.generation.modes import GenerationMode
from schemathesis.specs.openapi.checks import positive_data_acceptance

from service.openapi_dump import text
from tests.service.conftest import ROOT, Server

CHECKED_IN = ROOT / "openapi" / "openapi.json"
#: Cases per operation (small: `make test` has to stay quick on 2 cores).
MAX_EXAMPLES = 15


def test_checked_in_openapi_matches_the_app() -> None:
    assert CHECKED_IN.read_text() == text(), "openapi/openapi.json is stale: run `make openapi`"


def test_served_openapi_matches_checked_in(server: Server) -> None:
    assert httpx.get(server.url + "/openapi.json").json() == json.loads(CHECKED_IN.read_text())


def test_docs_example_runs_as_is(server: Server) -> None:
    spec = json.loads(CHECKED_IN.read_text())
    example = spec["components"]["schemas"]["ScheduleRequest"]["examples"][0]
    r = httpx.post(server.url + "/v1/schedule", json=example, timeout=120)
    assert r.status_code == 200, r.text
    assert httpx.get(server.url + "/docs").status_code == 200


@pytest.fixture(scope="module")
def fuzz_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    s = Server(tmp_path_factory.mktemp("fuzz"), FEEDSCHED_WORKERS="2", FEEDSCHED_SYNC_TIMEOUT="10",
               FEEDSCHED_JOB_TIMEOUT="10").start()
    yield s
    s.stop()


def test_api_conforms_to_its_spec(fuzz_server: Server) -> None:
    """Every operation: no 5xx, status codes, content types, headers and bodies as documented.

    (Driven through hypothesis directly: schemathesis' lazy pytest loader does not work with pytest 9.)
    """
    schema = schemathesis.openapi.from_url(fuzz_server.url + "/openapi.json")
    ops = [r.ok() for r in schema.get_all_operations()]
    assert len(ops) >= 8
    for mode, op in itertools.product((GenerationMode.POSITIVE, GenerationMode.NEGATIVE), ops):
        @given(case=op.as_strategy(mode))
        @settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck),
                  derandomize=True, database=None)
        def check(case: Any) -> None:
            # a schema-valid toolpath can still be geometrically invalid (knots, zero length): 422 is right for it
            case.call_and_validate(excluded_checks=[positive_data_acceptance], timeout=60)

        try:
            check()
        except Unsatisfiable:  # no way to break the input of a route without parameters
            assert mode is GenerationMode.NEGATIVE and not op.path_parameters and op.method == "get"


def test_schema_file_is_plain_json() -> None:
    assert isinstance(json.loads(Path(CHECKED_IN).read_text())["paths"], dict)
