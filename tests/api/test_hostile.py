"""No accepted configuration or snapshot leaves a model that any route answers with a server
error (issue 69, items 2-5): every number is finite and in range, every size bounded, every
snapshot invariant checked, an upload inflates only what the format names.

Property tests (Hypothesis): configurations with extreme numbers in any field, and snapshots
(JSON and .npz) with any number, size or configuration key changed. Whatever the server
accepts, every route then answers without a 5xx: steps, views, snapshots and restores.
"""

from __future__ import annotations

import copy
import io
import json
import math
import tracemalloc
import zipfile
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import given, settings
from hypothesis import strategies as st

from app.main import create_app
from app.service import codec
from app.settings import Settings
from tests.api.test_api import episode
from tests.utils import rewrite_npz_member

LIMIT = 8 * 2**20  # the test server's snapshot limit [bytes]
NPZ = {"content-type": "application/x-npz"}

EXTREME = st.sampled_from(
    [
        math.inf,
        -math.inf,
        math.nan,
        1.7976931348623157e308,
        -1e308,
        1e100,
        1e13,
        1e12,
        1e7,
        4097,
        2**31,
        2**62,
        2**63,
        2**64,
        10**30,
        5e-324,
        1e-13,
        1e-7,
        0,
        0.0,
        -1,
        -0.5,
        0.5,
        1,
        2,
        3,
        16,
        257,
        1025,
    ]
)
FIELDS = {  # section -> numeric fields (a list field: one number per observation name)
    "observation": ["low", "high", "knee"],
    "action": ["low", "high", "step"],
    "clustering": ["rho", "epsilon", "min_variance"],
    "transitions": ["learning_rate", "prior"],
    "reviser": ["activate_after_episodes", "noise_k", "horizon", "flag_min_rate", "seed"],
    "risk": ["horizon", "threshold", "margin", "reach_horizon", "reach_radius"],
    "limits": ["max_states", "max_streams", "belief_top_k"],
}
LISTS = {("observation", "low"), ("observation", "high"), ("observation", "knee")}


@st.composite
def configs(draw: st.DrawFn) -> dict[str, Any]:
    """A configuration with one to three numbers extreme, maybe the paper's reviser or the
    dense matrices."""
    config: dict[str, Any] = {}
    for _ in range(draw(st.integers(1, 3))):
        section = draw(st.sampled_from(sorted(FIELDS)))
        name = draw(st.sampled_from(FIELDS[section]))
        value = draw(EXTREME)
        setting: float | list[float] = value
        if (section, name) in LISTS:
            default = {
                "low": [0.0, 0.0, 0.0],
                "high": [32.0, 50.0, 32.0],
                "knee": [0.0, 20.0, 0.0],
            }[name]
            setting = [*default[:1], value, *default[2:]]
        config.setdefault(section, {})[name] = setting
    if draw(st.booleans()):
        config.setdefault("reviser", {})["method"] = draw(st.sampled_from(["paper", "risk"]))
    if draw(st.booleans()):
        config.setdefault("limits", {})["tpm_backend"] = draw(st.sampled_from(["lazy", "dense"]))
    return config


def post(client: TestClient, path: str, body: Any) -> Any:
    """JSON as Python writes it: NaN and Infinity included."""
    return client.post(path, content=json.dumps(body), headers={"content-type": "application/json"})


def exercise(client: TestClient, name: str) -> None:
    """Every route of a model, none answering 5xx: steps on two streams (a failure, an end
    of episode, a what-if), its views, its snapshots in both forms restored as another."""
    size = len(
        client.get(f"/models/{name}", params={"tpm": "none", "exact": False}).json()["config"][
            "observation"
        ]["names"]
    )
    rng = np.random.default_rng(0)
    answers = []
    for i in range(12):
        body: dict[str, Any] = {
            "observation": rng.uniform(-5, 60, size).tolist(),
            "action": float(rng.uniform(-3, 3)),
            "stream": f"s{i % 2}",
        }
        if i == 7:
            body.update(event="collision", done=True, action=None)
        if i == 9:
            body["learn"] = False
        answers.append(post(client, f"/models/{name}/revise", body))
    answers.append(
        post(
            client,
            f"/models/{name}/revise/batch",
            {"steps": [{"observation": [1.0] * size, "action": 0.0}] * 3},
        )
    )
    answers += [
        client.get(f"/models/{name}", params={"tpm": tpm}) for tpm in ("sparse", "dense", "none")
    ]
    answers.append(client.get(f"/models/{name}/states/0"))
    npz = client.get(f"/models/{name}", params={"format": "npz"})
    answers.append(npz)
    snapshot = client.get(f"/models/{name}", params={"tpm": "none"})
    answers.append(snapshot)
    if snapshot.status_code == 200:
        answers.append(
            client.put(
                f"/models/{name}-copy",
                content=snapshot.content,
                headers={"content-type": "application/json"},
            )
        )
    if npz.status_code == 200:
        answers.append(client.put(f"/models/{name}-copy", content=npz.content, headers=NPZ))
    answers += [client.get("/models"), client.get("/metrics"), client.get("/readyz")]
    for answer in answers:
        assert answer.status_code < 500, (answer.request.url, answer.text[:500])
    client.delete(f"/models/{name}-copy")


@pytest.fixture(scope="module")
def client() -> Iterator[TestClient]:
    with TestClient(
        create_app(Settings(max_snapshot_bytes=LIMIT)), raise_server_exceptions=False
    ) as c:
        yield c


def test_no_accepted_configuration_leaves_a_model_that_answers_5xx(client: TestClient) -> None:
    accepted = []

    @given(configs())
    @settings(max_examples=80, deadline=None)
    def check(config: dict[str, Any]) -> None:
        r = post(client, "/models", {"name": "x", "config": config})
        assert r.status_code in (201, 422), r.text
        if r.status_code == 422:
            error = r.json()["error"]
            assert error["code"] == "invalid_config" and error["field"].startswith("config."), error
            assert client.get("/models/x").status_code == 404  # nothing made
            return
        accepted.append(config)
        for fields in config.values():  # whatever was accepted is finite
            for value in fields.values():
                values = value if isinstance(value, list) else [value]
                assert all(not isinstance(v, float) or math.isfinite(v) for v in values)
        exercise(client, "x")
        assert client.delete("/models/x").status_code == 204

    check()
    assert accepted  # the property saw accepted models, not refusals only


@pytest.mark.parametrize(
    ("config", "field"),
    [
        ({"clustering": {"min_variance": math.inf}}, "config.clustering.min_variance"),
        ({"action": {"low": 0, "high": 1e7, "step": 1}}, "config.action.step"),
        ({"action": {"low": 0, "high": 1e9, "step": 1}}, "config.action.step"),
        ({"action": {"low": 0, "high": 1000, "step": 1}}, "config.action.step"),  # the server's
        ({"limits": {"belief_top_k": 10**12}}, "config.limits.belief_top_k"),
        ({"limits": {"max_states": 100_000, "max_streams": 1_000_000}}, "config.limits.max_states"),
        ({"limits": {"tpm_backend": "dense"}}, "config.limits.max_states"),
        (
            {
                "observation": {
                    "names": [f"x{i}" for i in range(100)],
                    "low": [0] * 100,
                    "high": [1] * 100,
                    "knee": [],
                },
                "criteria": [{"name": "far", "direction": "increase"}],
            },
            "config.observation.names",
        ),
        ({"transitions": {"prior": 1e308}}, "config.transitions.prior"),
        ({"clustering": {"epsilon": 1e308}}, "config.clustering.epsilon"),
    ],
)
def test_the_issue_s_configurations_are_refused_naming_their_field(
    client: TestClient, config: dict[str, Any], field: str
) -> None:
    r = post(client, "/models", {"name": "y", "config": config})
    assert r.status_code == 422, r.text
    assert r.json()["error"] | {"message": ""} == {
        "code": "invalid_config",
        "message": "",
        "field": field,
    }


@pytest.fixture(scope="module")
def snapshots(client: TestClient) -> dict[str, dict[str, Any]]:
    """The exact JSON snapshots of a risk model and a paper model on dense matrices, after
    three episodes and a step of an open stream."""
    out = {}
    for name, config in (
        ("risky", {}),
        (
            "paper",
            {"reviser": {"method": "paper"}, "limits": {"tpm_backend": "dense", "max_states": 200}},
        ),
    ):
        assert post(client, "/models", {"name": name, "config": config}).status_code == 201
        for _ in range(3):
            episode(client, f"/models/{name}/revise")
        post(
            client,
            f"/models/{name}/revise",
            {"observation": [12.0, 30.0, 11.0], "action": 0.3, "stream": "open"},
        )
        out[name] = client.get(f"/models/{name}", params={"tpm": "none"}).json()["exact"]
    return out


def leaves(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """The paths of every number, array entry, array shape and key of a tagged snapshot."""
    if isinstance(value, dict):
        if codec.ARRAY in value:
            data = value["data"]
            for i in sorted({0, len(data) // 2, len(data) - 1} if data else set()):
                yield (*path, "data", i)
            yield (*path, "shape", 0) if value["shape"] else (*path, "shape")
            return
        for key, item in value.items():
            yield (*path, key, None)  # the key itself: removed
            yield from leaves(item, (*path, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            yield from leaves(item, (*path, i))
    elif isinstance(value, int | float) and not isinstance(value, bool):
        yield path


def mutate(snapshot: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    """A copy with the number at ``path`` replaced by ``value`` (a key path ending in None:
    the key removed)."""
    out = copy.deepcopy(snapshot)
    part: Any = out
    for key in path[:-2] if path[-1] is None else path[:-1]:
        part = part[key]
    if path[-1] is None:
        del part[path[-2]]
    else:
        part[path[-1]] = value
    return out


@st.composite
def mutations(draw: st.DrawFn, snapshots: dict[str, dict[str, Any]]) -> dict[str, Any]:
    snapshot = snapshots[draw(st.sampled_from(sorted(snapshots)))]
    paths = sorted(leaves(snapshot), key=str)
    path = draw(st.sampled_from(paths))
    return mutate(snapshot, path, draw(EXTREME))


def restore_and_exercise(client: TestClient, body: bytes, headers: dict[str, str]) -> None:
    before = client.get("/models").json()
    r = client.put("/models/m", content=body, headers=headers)
    assert r.status_code in (200, 413, 422), r.text
    if r.status_code != 200:
        assert r.json()["error"]["code"] in ("invalid_snapshot", "too_large"), r.text
        assert client.get("/models").json() == before
        return
    exercise(client, "m")
    client.delete("/models/m")


def test_no_accepted_json_snapshot_leaves_a_model_that_answers_5xx(
    client: TestClient, snapshots: dict[str, dict[str, Any]]
) -> None:

    @given(mutations(snapshots))
    @settings(max_examples=120, deadline=None)
    def check(snapshot: dict[str, Any]) -> None:
        restore_and_exercise(
            client, json.dumps({"exact": snapshot}).encode(), {"content-type": "application/json"}
        )

    check()


def test_no_accepted_npz_snapshot_leaves_a_model_that_answers_5xx(
    client: TestClient, snapshots: dict[str, dict[str, Any]]
) -> None:

    @given(mutations(snapshots))
    @settings(max_examples=120, deadline=None)
    def check(snapshot: dict[str, Any]) -> None:
        try:
            data = codec.from_json(snapshot)
        except (ValueError, TypeError):  # not an array any more: only JSON can carry it
            return
        restore_and_exercise(client, codec.to_npz(data), NPZ)

    check()


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (("transitions", "actions", "learned", "nnz", "data"), "transitions.actions.{a}.row_sum"),
        (("counters", "steps"), "clustering.k"),
        (("clustering", "k"), "clustering.k"),
        (("transitions", "backend"), "transitions.backend"),
        (("config", "clustering", "epsilon"), "config.clustering.epsilon"),
        (("config", "limits", "belief_top_k"), "config.limits.belief_top_k"),
        (("streams", "open", "prob", "data"), "streams.open.prob"),
    ],
)
def test_the_issue_s_snapshots_are_refused_naming_their_field(
    client: TestClient, snapshots: dict[str, dict[str, Any]], change: tuple[Any, ...], field: str
) -> None:
    """nnz 0 under learned mass, counts beyond the steps (2^62 of them too), clustering.k
    1e7, an unknown backend, a configuration key missing, a belief scaled past 1."""
    broken = copy.deepcopy(snapshots["risky"])
    actions = broken["transitions"]["actions"]
    a = next(i for i, action in enumerate(actions) if any(action["row_sum"]["data"]))
    part: Any = broken
    for key in change[:-1]:
        part = part[a if key == "learned" else key]
    last = change[-1]
    if change[-2] == "nnz":  # no entries, while the row's learned sum says otherwise
        part[last] = [0] * len(part[last])
        actions[a]["cols"] = {codec.ARRAY: "<i4", "shape": [0], "data": []}
        actions[a]["vals"] = {codec.ARRAY: "<f8", "shape": [0], "data": []}
    elif last == "steps":
        part[last] -= 1  # one step fewer than the observations clustered
    elif last == "k":
        part[last] = 10**7
    elif last == "backend":
        part[last] = 7
    elif change[0] == "config":
        del part[last]
    else:
        part[last] = [p * 2 for p in part[last]]
    r = client.put(
        "/models/b",
        content=json.dumps({"exact": broken}),
        headers={"content-type": "application/json"},
    )
    assert r.status_code == 422, r.text
    assert r.json()["error"]["field"] == field.format(a=a), r.text


def test_a_count_beyond_any_model_s_life_is_refused(
    client: TestClient, snapshots: dict[str, dict[str, Any]]
) -> None:
    broken = copy.deepcopy(snapshots["risky"])
    broken["counters"]["steps"] = broken["counters"]["model_version"] = 2**62
    r = client.put("/models/b", json={"exact": broken})
    assert r.status_code == 422 and r.json()["error"]["field"] == "counters.steps", r.text


def with_member(npz: bytes, name: str, size: int) -> bytes:
    """``npz`` with one more member: a valid float64 array of ``size`` bytes of zeros, a few
    hundred kilobytes compressed."""
    buffer = io.BytesIO()
    with (
        zipfile.ZipFile(io.BytesIO(npz)) as source,
        zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as target,
    ):
        for info in source.infolist():
            target.writestr(info, source.read(info))
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(
            header, {"descr": "<f8", "fortran_order": False, "shape": (size // 8,)}
        )
        with target.open(name, "w", force_zip64=True) as member:
            member.write(header.getvalue())
            chunk = bytes(2**20)
            for _ in range(size // len(chunk)):
                member.write(chunk)
    return buffer.getvalue()


def test_a_member_the_format_does_not_name_is_refused_before_it_is_inflated() -> None:
    size = 200 * 2**20
    with TestClient(create_app(Settings(max_snapshot_bytes=256 * 2**20))) as c:
        npz = c.get("/model", params={"format": "npz"}).content
        blob = with_member(npz, "padding.npy", size)
        assert len(blob) < 2**20
        tracemalloc.start()
        try:
            r = c.put("/models/padded", content=blob, headers=NPZ)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert r.status_code == 422, r.text
        assert r.json()["error"] | {"message": ""} == {
            "code": "invalid_snapshot",
            "message": "",
            "field": "padding",
        }
        assert peak < 16 * 2**20, peak  # the member's 200 MiB were never inflated
        assert c.put("/models/padded", content=npz, headers=NPZ).status_code == 200


def test_a_member_whose_size_differs_from_its_header_is_refused(client: TestClient) -> None:
    npz = client.get("/model", params={"format": "npz"}).content
    trailing = rewrite_npz_member(
        npz, "/clustering/beta.npy", lambda data: data + bytes(4096)
    )  # bytes no array holds
    r = client.put("/models/trailing", content=trailing, headers=NPZ)
    assert r.status_code == 422 and r.json()["error"]["field"] == "/clustering/beta", r.text


def test_a_json_snapshot_beyond_its_share_of_the_limit_is_413(client: TestClient) -> None:
    """Parsed, JSON takes about eight times its bytes: a JSON snapshot may be an eighth of
    the limit, its .npz the whole."""
    body = b'{"exact": {"pad": "' + b"x" * (LIMIT // 8) + b'"}}'
    r = client.put("/models/big", content=body, headers={"content-type": "application/json"})
    assert r.status_code == 413 and r.json()["error"] | {"message": ""} == {
        "code": "too_large",
        "message": "",
        "field": "body",
    }, r.text
