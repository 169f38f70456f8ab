"""The service's HTTP and WebSocket contract (``tests/api/test_api.py``,
``tests/api/test_idempotency.py``) through the ingress of a sharded service: the same tests,
with the clients below in place of the plain app's."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from app.settings import Settings
from tests.api.test_api import *  # noqa: F403 (the tests themselves run here)
from tests.api.test_idempotency import *  # noqa: F403
from tests.cluster.sharded import sharded_client

SHARD_SPECIFIC = {  # what a sharded service answers otherwise, and why
    "test_metrics_count_requests_decisions_and_states": (
        "metrics are the shards' own, each sample labelled with its shard (test_ingress.py)"
    ),
    "test_openapi_documents_every_request_field": (
        "the schema is the ingress's: its routes forward to the shards' documented ones"
    ),
    "test_the_default_model_takes_its_configuration_from_a_file": "builds the plain app itself",
}

for _name in SHARD_SPECIFIC:
    del globals()[_name]  # not collected here


@pytest.fixture
def client() -> Iterator[TestClient]:
    with sharded_client(Settings(), n_shards=3) as c:
        yield c


del globals()["strict_client"]  # test_api's, imported above: the one below replaces it


@pytest.fixture(name="strict_client")
def sharded_strict_client() -> Iterator[TestClient]:
    with sharded_client(Settings(token="s3cret", max_body_bytes=4096, max_batch=3)) as c:
        yield c
