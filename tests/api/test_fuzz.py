"""Arbitrary bodies and frames against the API: a decision, or a clear error that changes nothing.

Property tests over what a buggy or hostile controller might send: any JSON value in any field,
unknown fields, batches with any step broken. Every request gets a decision or the documented
error body (never a server error), a refused one leaves the model exactly as it was, and an
accepted one counts once.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st

from app.main import create_app
from app.settings import Settings

FIELDS = ("observation", "action", "stream", "event", "done", "applied_action", "learn", "shadow")
CODES = {
    "invalid_json",
    "invalid_body",
    "invalid_observation",
    "invalid_action",
    "unknown_criterion",
    "too_large",
}

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=False, allow_infinity=False),
    st.text(max_size=8),
)
json_values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=4), inner, max_size=3)
    ),
    max_leaves=8,
)
valid = st.fixed_dictionaries(
    {
        "observation": st.lists(st.floats(-50, 250), min_size=3, max_size=3),
        "action": st.floats(-3, 3),
    },
    optional={
        "stream": st.sampled_from(["0", "car-1"]),
        "event": st.sampled_from(["collision", "large_distance"]),
        "done": st.just(True),
        "learn": st.booleans(),
        "shadow": st.booleans(),
        "applied_action": st.floats(-3, 3),
    },
)
EXTREME = st.sampled_from([1e300, -1e300, 5e-324, -5e-324, 1.7976931348623157e308])
WRONG = {  # well-typed values that only the model can refuse (or must survive)
    "observation": st.lists(st.one_of(st.floats(-50, 250), EXTREME), min_size=1, max_size=5),
    "action": st.one_of(st.none(), EXTREME),
    "applied_action": EXTREME,
    "event": st.sampled_from(["meteor", ""]),
}


@st.composite
def broken(draw: st.DrawFn) -> dict[str, Any]:
    """A valid step with one or two fields replaced (by anything, or by a value of the right
    type that the model refuses), dropped, or one added."""
    step = dict(draw(valid))
    for name in draw(st.lists(st.sampled_from([*FIELDS, "colour"]), min_size=1, max_size=2)):
        if draw(st.booleans()):
            step[name] = draw(st.one_of(json_values, WRONG.get(name, json_values)))
        else:
            step.pop(name, None)
    return step


anything = st.dictionaries(st.sampled_from(FIELDS), json_values)
steps = st.one_of(valid, valid, broken(), broken(), anything)  # about half of them accepted


def exact(c: TestClient, name: str = "default") -> Any:
    """The model's exact state, everything that decides its next answer."""
    return c.get(f"/models/{name}", params={"tpm": "none"}).json()["exact"]


def version(c: TestClient) -> int:
    snapshot = c.get("/model", params={"tpm": "none", "exact": False}).json()
    return int(snapshot["model_version"])


def check_refusal(response: Any) -> None:
    """The documented error body: a code, a message, the field at fault (or null)."""
    assert response.status_code in (413, 422), response.text
    error = response.json()["error"]
    assert error["code"] in CODES and error["message"]
    assert error["field"] is None or isinstance(error["field"], str)


def learns(step: dict[str, Any]) -> bool:
    return step.get("learn", True) is not False


def test_any_single_step_is_answered_or_refused_without_a_trace() -> None:
    with TestClient(create_app(Settings()), raise_server_exceptions=False) as c:

        @given(steps)
        @settings(max_examples=150)
        def check(body: dict[str, Any]) -> None:
            before, count = exact(c), version(c)
            r = c.post(
                "/revise", content=json.dumps(body), headers={"content-type": "application/json"}
            )
            if r.status_code == 200:
                assert version(c) == count + learns(body)
                assert r.json()["model_version"] == version(c)
            else:
                check_refusal(r)
                assert exact(c) == before

        check()


def test_a_batch_with_any_step_broken_is_all_or_nothing() -> None:
    with TestClient(create_app(Settings()), raise_server_exceptions=False) as c:

        @given(st.lists(steps, min_size=1, max_size=5))
        @settings(max_examples=80)
        def check(batch: list[dict[str, Any]]) -> None:
            before, count = exact(c), version(c)
            r = c.post("/models/default/revise/batch", json={"steps": batch})
            if r.status_code == 200:
                decisions = r.json()["decisions"]
                assert len(decisions) == len(batch)
                assert version(c) == count + sum(map(learns, batch))
            else:
                check_refusal(r)
                assert exact(c) == before

        check()


def test_any_websocket_frame_gets_one_reply_and_the_stream_goes_on() -> None:
    with (
        TestClient(create_app(Settings()), raise_server_exceptions=False) as c,
        c.websocket_connect("/ws") as ws,
    ):

        @given(st.one_of(steps.map(json.dumps), st.text(max_size=40)))
        @settings(max_examples=100)
        def check(frame: str) -> None:
            count = version(c)
            ws.send_text(frame)
            reply = json.loads(ws.receive_text())
            if "error" in reply:
                assert reply["error"]["code"] in CODES
                assert version(c) == count
            else:
                assert reply["model_version"] == version(c) >= count

        check()
        ws.send_text(json.dumps({"observation": [14.2, 38.5, 15.0], "action": 0.8}))
        assert json.loads(ws.receive_text())["action"] is not None


mostly_valid = st.one_of(valid, valid, valid, broken())
requests = st.lists(
    st.tuples(
        st.sampled_from(["default", "other"]),
        st.booleans(),
        st.lists(mostly_valid, min_size=1, max_size=3),
    ),
    min_size=3,
    max_size=8,
)


@given(requests, st.sampled_from([10**6, 3]))  # the journal alone, or snapshots too
@settings(max_examples=30)
def test_after_a_crash_every_accepted_step_and_no_refused_one_is_replayed(
    sequence: list[tuple[str, bool, list[dict[str, Any]]]], snapshot_every: int
) -> None:
    """Steps and batches, some refused, on two models; then a second server starts on the same
    data directory before the first shuts down (as after a crash, only the snapshots and the
    journal tell it anything): its models are the first's, bit for bit."""
    with tempfile.TemporaryDirectory() as data:
        config = Settings(data_dir=Path(data), fsync="always", snapshot_every=snapshot_every)
        with TestClient(create_app(config), raise_server_exceptions=False) as first:
            first.post("/models", json={"name": "other"})
            for name, batch, bodies in sequence:
                if batch:
                    first.post(f"/models/{name}/revise/batch", json={"steps": bodies})
                else:
                    first.post(f"/models/{name}/revise", json=bodies[0])
            with TestClient(create_app(config)) as second:
                for name in ("default", "other"):
                    assert exact(second, name) == exact(first, name)
