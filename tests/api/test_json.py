"""Decision records leave the service as orjson writes them: the same JSON as
:meth:`Decision.to_dict` through the standard library, revisions with candidates included."""

from __future__ import annotations

import json

import orjson

from app.api.convert import to_json
from app.core import Shield
from tests.core.recorded import preset


def test_orjson_writes_the_records_to_dict_does() -> None:
    for name in ("default", "paper"):
        shield = Shield(preset(name))
        revised = 0
        for t in range(3000):  # a point that crashes when it goes fast near a wall
            x = float(t % 40)
            event = "collision" if x == 39 else None
            decision = shield.step([10.0, 40.0 - x, 10.0], None if event else 2.0,
                                   event=event, done=event is not None)
            revised += decision.revised
            assert orjson.loads(to_json(decision)) == json.loads(json.dumps(decision.to_dict()))
        assert revised, name  # the candidates of revisions were written too
