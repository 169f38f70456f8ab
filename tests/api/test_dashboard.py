"""The dashboard in a real browser (Debian's Chromium driven by Playwright) against a real
server fed by a stream of steps. ``UPDATE_SCREENSHOTS=1`` writes the screenshot of a model
with 60 episodes of history, opened afresh, to docs/dashboard.png."""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from client.shield import ShieldClient
from tests.conftest import Server, start_server
from tests.utils import random_stream

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
playwright = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(
    CHROMIUM is None, reason="needs Debian's chromium (.ci/run installs it)"
)
TOKEN = "dash-token"
DOCS = Path(__file__).parents[2] / "docs"
CHARTS = ("chart-revisions", "chart-share", "chart-states", "chart-failures")
# How many pixels of a canvas have a saturated colour (a series, a flag): the axes, grid and
# labels are grey, the legend's swatches a few dozen pixels.
COLOURED = """(id) => {
  const canvas = document.getElementById(id);
  const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  let n = 0;
  for (let i = 0; i < data.length; i += 4) {
    const high = Math.max(data[i], data[i + 1], data[i + 2]);
    const low = Math.min(data[i], data[i + 1], data[i + 2]);
    if (data[i + 3] > 0 && high - low > 80) n += 1;
  }
  return n;
}"""


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    s = start_server(
        tmp_path_factory.mktemp("dash") / "data", "--fsync", "never", env={"EFSM_TOKEN": TOKEN}
    )
    yield s
    s.stop()


def feed(url: str, seed: int, steps: int) -> None:
    with ShieldClient(url, token=TOKEN) as shield:
        for z, a, done in random_stream(seed, steps):
            shield.revise(
                z,
                None if done else a,
                done=done,
                event="collision" if done and seed % 2 == 0 else None,
                stream=f"car-{seed}",
            )


@contextlib.contextmanager
def live_dashboard(url: str, query: str = "") -> Iterator[tuple[Any, list[str]]]:
    """The dashboard open in Chromium, once it says it is live: the page, and the errors its
    console and scripts report."""
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1280, "height": 1500})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{url}/dashboard{query}#token={TOKEN}")
        page.wait_for_function("document.getElementById('status').textContent.startsWith('live')")
        yield page, errors
        browser.close()


def test_the_dashboard_follows_the_model_live(server: Server, tmp_path: Path) -> None:
    feed(server.url, 0, 150)
    with live_dashboard(server.url) as (page, errors):
        with ShieldClient(server.url, token=TOKEN) as shield:
            n = shield.snapshot(tpm="none", exact=False)["n_states"]
            page.wait_for_function(
                f"document.getElementById('state-count').textContent == '{n}'", timeout=5000
            )
            feed(server.url, 2, 100)  # the page follows while steps stream in
            n = shield.snapshot(tpm="none", exact=False)["n_states"]
            page.wait_for_function(
                f"document.getElementById('state-count').textContent == '{n}'", timeout=5000
            )
            # a new state shows within a second of being created (a headway far beyond
            # the stream's 0-200 m makes one)
            decision = shield.revise([31.0, 400.0, 1.0], 0.0, stream="probe")
            assert decision.new_state
            created = time.monotonic()
            page.wait_for_function(
                f"document.getElementById('state-count').textContent == '{decision.n_states}'",
                timeout=1000,
            )
            assert time.monotonic() - created < 1.0

        # a click on a state shows its transitions under every action (once the plot holds
        # every state: the probe widened its axes)
        page.wait_for_function(f"view.positions.length == {decision.n_states}", timeout=5000)
        index, x, y = page.evaluate("view.positions[0]")
        box = page.locator("#states").bounding_box()
        assert box is not None
        width, height = page.evaluate(
            "[document.getElementById('states').width, document.getElementById('states').height]"
        )
        # every state is drawn inside the plot, the probe beyond the headway bound included
        assert page.evaluate(
            f"view.positions.every(([i, x, y]) => x >= 0 && x <= {width} "
            f"&& y >= 0 && y <= {height})"
        )
        page.locator("#states").click(
            position={"x": x * box["width"] / width, "y": y * box["height"] / height}
        )
        page.wait_for_selector("#next-states")
        assert page.locator("#next-states tbody tr").count() == 20
        picked = page.locator("#picked").inner_text()
        assert f"#{index}" in picked and re.search(r"\d+ visits, (no failures|\d+ \w+)", picked)

        # the snapshot downloads carry the exact state (JSON) and a NumPy archive
        with page.expect_download() as download:
            page.click("#download-json")
        assert "exact" in json.loads(Path(download.value.path()).read_text())
        with page.expect_download() as download:
            page.click("#download-npz")
        assert Path(download.value.path()).read_bytes()[:2] == b"PK"  # a zip archive

    assert errors == []


def feed_episodes(url: str, model: str, episodes: int, seed: int) -> None:
    """``episodes`` episodes of 25 steps into ``model``, one batch each; every third ends in
    a collision."""
    steps = random_stream(seed, 25 * episodes)
    with ShieldClient(url, token=TOKEN, model=model) as shield:
        for e in range(episodes):
            shield.revise_batch(
                [
                    {
                        "observation": z,
                        "action": None if done else a,
                        "done": done,
                        "stream": "car",
                        "event": "collision" if done and e % 3 == 0 else None,
                    }
                    for z, a, done in steps[25 * e : 25 * (e + 1)]
                ]
            )


def history_of(url: str, model: str) -> dict[str, Any]:
    r = httpx.get(f"{url}/models/{model}/history", headers={"Authorization": f"Bearer {TOKEN}"})
    r.raise_for_status()
    result: dict[str, Any] = r.json()
    return result


def test_the_history_is_drawn_on_open_with_labelled_axes(server: Server, tmp_path: Path) -> None:
    with ShieldClient(server.url, token=TOKEN) as shield:
        shield.create_model("history")
    feed_episodes(server.url, "history", 60, seed=5)
    history = history_of(server.url, "history")
    assert history["episodes"] == list(range(1, 61))

    with live_dashboard(server.url, "?model=history") as (page, errors):
        page.wait_for_function("view.drawn['chart-failures'] && view.drawn.tpm")

        # before any new step: the 60 episodes are on the charts, as the model counted them
        assert (
            page.evaluate("view.rows.map((r) => r.failures.collision)")
            == history["failures"]["collision"]
        )
        drawn = page.evaluate("view.drawn")
        assert drawn["chart-revisions"]["points"] == 2 * 60  # per criterion, per episode
        assert drawn["chart-share"]["points"] == 60
        assert drawn["chart-states"]["points"] == 60 + 1  # and the totals now
        assert drawn["chart-failures"]["points"] == 2 * (60 + 1)  # from the start
        for chart in CHARTS:
            assert page.evaluate(COLOURED, chart) > 400, chart  # the lines, not just a legend
        # every axis has values and a title; the episode axes reach the 60th
        for name, chart in drawn.items():
            assert chart["xTitle"] and chart["yTitle"], name
            assert len(chart["xTicks"]) >= 3 and len(chart["yTicks"]) >= 3, (name, chart)
            assert all(
                re.fullmatch(r"-?\d+(\.\d+)?[kM]?", t) for t in chart["xTicks"] + chart["yTicks"]
            ), (name, chart)
        for chart in ("chart-revisions", "chart-share", "chart-failures"):
            assert drawn[chart]["xTitle"] == "episode"
            assert 50 <= float(drawn[chart]["xTicks"][-1]) <= 60, drawn[chart]["xTicks"]
        assert drawn["chart-share"]["yTitle"] == "revised actions [%]"
        assert (drawn["states"]["xTitle"], drawn["states"]["yTitle"]) == (
            "headway [m]",
            "v_ego [m/s]",
        )
        assert drawn["tpm"]["xTicks"][0] == "0" and drawn["tpm"]["scale"][-1] == "1"
        assert drawn["tpm"]["points"] > 0
        # the shield's trial of itself, as the model counts it
        with ShieldClient(server.url, token=TOKEN, model="history") as shield:
            trial = shield.snapshot(tpm="none", exact=False)["trial"]
        assert sum(arm["episodes"] for arm in trial.values()) > 0
        assert page.locator("#trial").inner_text() == (
            f"trial of itself: {trial['shielded']['episodes']} episodes shielded "
            f"({trial['shielded']['failed']} failed), {trial['audited']['episodes']} audited "
            f"({trial['audited']['failed']} failed)"
        )

        page.wait_for_timeout(300)
        shots = DOCS if os.environ.get("UPDATE_SCREENSHOTS") else tmp_path
        page.screenshot(path=str(shots / "dashboard.png"), full_page=True)
        assert (shots / "dashboard.png").stat().st_size > 10_000

        # then it goes on live: one more episode is one more row, with the model's own totals
        feed_episodes(server.url, "history", 1, seed=6)
        page.wait_for_function("view.rows.length == 61", timeout=5000)
        history = history_of(server.url, "history")
        last = page.evaluate("view.rows[view.rows.length - 1]")
        assert last == {
            "episodes": 61,
            "steps": history["steps"][-1],
            "n_states": history["n_states"][-1],
            "interventions": {c: v[-1] for c, v in history["interventions"].items()},
            "failures": {c: v[-1] for c, v in history["failures"].items()},
        }
        page.wait_for_function("view.drawn['chart-share'].points == 61")
    assert errors == []


def test_no_data_without_the_token(server: Server) -> None:
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page()
        page.goto(f"{server.url}/dashboard")
        page.wait_for_function(
            "document.getElementById('status').textContent.startsWith('no data')"
        )
        assert "401" in page.locator("#status").inner_text()
        assert page.locator("#state-count").inner_text() == "0"
        browser.close()
