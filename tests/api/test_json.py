"""Decision records leave the service as orjson writes them: the same JSON as the record's
fields (its candidates' fields) through the standard library, revisions included; and the
API's schema of a decision (``app.api.schemas``) names exactly the record's fields, so the two
declarations cannot drift apart."""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import orjson

from app.api import schemas
from app.api.convert import to_json
from app.core import Candidate, Decision, Shield
from tests.core.recorded import preset


def test_orjson_writes_the_records_to_dict_does() -> None:
    for name in ("default", "paper"):
        shield = Shield(preset(name))
        revised = 0
        for t in range(3000):  # a point that crashes when it goes fast near a wall
            x = float(t % 40)
            event = "collision" if x == 39 else None
            decision = shield.step(
                [10.0, 40.0 - x, 10.0], None if event else 2.0, event=event, done=event is not None
            )
            revised += decision.revised
            written = orjson.loads(to_json(decision))
            assert written == json.loads(json.dumps(fields(decision)))
            assert orjson.loads(to_json({"decisions": [decision]})) == {"decisions": [written]}
        assert revised, name  # the candidates of revisions were written too


def fields(decision: Decision) -> dict[str, Any]:
    """The record's dataclass fields, each candidate's too, read one by one."""
    data = {f.name: getattr(decision, f.name) for f in dataclasses.fields(decision)}
    data["candidates"] = [dataclasses.asdict(c) for c in decision.candidates]
    return data


def test_the_api_schema_names_the_records_fields_and_validates_every_kind_of_record() -> None:
    assert list(schemas.Decision.model_fields) == [f.name for f in dataclasses.fields(Decision)]
    assert list(schemas.Candidate.model_fields) == [f.name for f in dataclasses.fields(Candidate)]
    reasons: set[str] = set()
    for name in ("default", "paper"):
        shield = Shield(preset(name))
        for t in range(3000):
            x = float(t % 40)
            event = "collision" if x == 39 else None
            decision = shield.step(
                [10.0, 40.0 - x, 10.0], None if event else 2.0, event=event, done=event is not None
            )
            written = orjson.loads(to_json(decision))
            assert schemas.Decision.model_validate(written).model_dump() == written
            reasons.add(decision.reason)
    assert {"pass", "revised_safety", "cold_start", "done"} <= reasons
