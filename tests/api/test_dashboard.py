"""The dashboard in a real browser (Debian's Chromium driven by Playwright) against a real
server fed by a stream of steps. ``UPDATE_SCREENSHOTS=1`` writes the screenshot to docs/."""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from client.shield import ShieldClient
from tests.conftest import Server, start_server
from tests.utils import random_stream

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
playwright = pytest.importorskip("playwright.sync_api")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="needs Debian's chromium (.ci/run "
                                                          "installs it)")
TOKEN = "dash-token"
DOCS = Path(__file__).parents[2] / "docs"


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    s = start_server(tmp_path_factory.mktemp("dash") / "data", "--fsync", "never",
                     env={"EFSM_TOKEN": TOKEN})
    yield s
    s.stop()


def feed(url: str, seed: int, steps: int) -> None:
    with ShieldClient(url, token=TOKEN) as shield:
        for z, a, done in random_stream(seed, steps):
            shield.revise(z, None if done else a, done=done,
                          event="collision" if done and seed % 2 == 0 else None,
                          stream=f"car-{seed}")


def test_the_dashboard_follows_the_model_live(server: Server, tmp_path: Path) -> None:
    feed(server.url, 0, 150)
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page(viewport={"width": 1280, "height": 1500})
        errors: list[str] = []
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(f"{server.url}/dashboard#token={TOKEN}")
        page.wait_for_function("document.getElementById('status').textContent.startsWith('live')")

        with ShieldClient(server.url, token=TOKEN) as shield:
            n = shield.snapshot(tpm="none", exact=False)["n_states"]
            page.wait_for_function(f"document.getElementById('state-count').textContent == '{n}'",
                                   timeout=5000)
            feed(server.url, 2, 100)  # the page follows while steps stream in
            n = shield.snapshot(tpm="none", exact=False)["n_states"]
            page.wait_for_function(f"document.getElementById('state-count').textContent == '{n}'",
                                   timeout=5000)
            # a new state shows within a second of being created (a headway far beyond
            # the stream's 0-200 m makes one)
            decision = shield.revise([31.0, 400.0, 1.0], 0.0, stream="probe")
            assert decision.new_state
            created = time.monotonic()
            page.wait_for_function(
                f"document.getElementById('state-count').textContent == '{decision.n_states}'",
                timeout=1000)
            assert time.monotonic() - created < 1.0

        # a click on a state shows its transitions under every action (once the plot holds
        # every state: the probe widened its axes)
        page.wait_for_function(f"view.positions.length == {decision.n_states}", timeout=5000)
        index, x, y = page.evaluate("view.positions[0]")
        box = page.locator("#states").bounding_box()
        assert box is not None
        width, height = page.evaluate(
            "[document.getElementById('states').width, document.getElementById('states').height]")
        # every state is drawn inside the plot, the probe beyond the headway bound included
        assert page.evaluate(f"view.positions.every(([i, x, y]) => x >= 0 && x <= {width} "
                             f"&& y >= 0 && y <= {height})")
        page.locator("#states").click(position={"x": x * box["width"] / width,
                                                "y": y * box["height"] / height})
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

        page.wait_for_timeout(300)
        shots = DOCS if os.environ.get("UPDATE_SCREENSHOTS") else tmp_path
        page.screenshot(path=str(shots / "dashboard.png"), full_page=True)
        assert (shots / "dashboard.png").stat().st_size > 10_000
        browser.close()
    assert errors == []


def test_no_data_without_the_token(server: Server) -> None:
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        page = browser.new_page()
        page.goto(f"{server.url}/dashboard")
        page.wait_for_function(
            "document.getElementById('status').textContent.startsWith('no data')")
        assert "401" in page.locator("#status").inner_text()
        assert page.locator("#state-count").inner_text() == "0"
        browser.close()
