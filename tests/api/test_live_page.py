"""The live page in a real headless Chromium (Debian's ``chromium``, driven by Playwright).

Playwright never downloads a browser here: it launches the system executable. The
test skips, saying why, only where Chromium or Playwright is not installed. The
screenshot is kept under the test's tmp dir and copied to ``tests/artifacts/``
(ignored by git), with the measured time from POST to object on the page.
"""

from __future__ import annotations

import copy
import json
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import api_knowledge
import httpx
import pytest

from api.settings import Settings
from api.testing import running_server
from semwm.knowledge import KnowledgeDocument
from semwm.knowledge.loader import dump_document

ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
REGION = [[-1.0, 6.0], [-1.0, 4.0]]
STEP = 0.2  # s between scans


def chromium_executable() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = shutil.which(name)
        if found:
            return found
    return None


def scan(t: float) -> list[dict[str, Any]]:
    """A cup, a coke can (seen with a wide, tilted noise), and robot r1 driving at (0.5, 0.4) m/s."""
    return [
        {"time": t, "class": "Cup", "position": [1.0, 2.0], "source": "r1"},
        {"time": t, "class": "CokeCan", "position": [3.0, 2.0], "source": "r1",
         "covariance": [[0.04, 0.03], [0.03, 0.09]]},
        {"time": t, "class": "Robot", "position": [0.5 * t, 0.4 * t], "label": "r1",
         "source": "r1"},
    ]  # fmt: skip


def title(obj: dict[str, Any]) -> str:
    """What the page writes beside an object: id, class, class probability, label."""
    text = f"#{obj['id']} {obj['class']}"
    probabilities = obj.get("class_probabilities")
    if probabilities and obj["class"] in probabilities:
        text += f" {100 * probabilities[obj['class']]:.0f}%"
    return text + (f" · {obj['label']}" if obj["label"] else "")


@pytest.fixture
def browser() -> Iterator[Any]:
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="Playwright is not installed (pip install '.[test]')"
    )
    executable = chromium_executable()
    if executable is None:
        pytest.skip("no Chromium executable: apt-get install chromium (.ci/apt-packages.txt)")
    with sync_api.sync_playwright() as playwright:
        launched = playwright.chromium.launch(
            executable_path=executable,
            headless=True,
            args=["--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"],
        )
        try:
            yield launched
        finally:
            launched.close()


@pytest.fixture
def region_knowledge(tmp_path: Path) -> Path:
    document = copy.deepcopy(api_knowledge.DOCUMENT)
    document["world"]["region"] = REGION
    path = tmp_path / "live.yaml"
    dump_document(KnowledgeDocument.model_validate(document), path)
    return path


def test_the_page_shows_the_world_live(
    browser: Any, region_knowledge: Path, tmp_path: Path
) -> None:
    problems: list[str] = []
    with running_server(Settings(knowledge=region_knowledge, port=0)) as url:
        page = browser.new_page(viewport={"width": 1280, "height": 760})
        page.on(
            "console",
            lambda m: problems.append(f"console {m.type}: {m.text}") if m.type == "error" else None,
        )
        page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
        page.goto(f"{url}/")
        page.wait_for_function("document.getElementById('status').textContent === 'live'")
        assert page.locator("[data-object-id]").count() == 0

        with httpx.Client(base_url=url, timeout=30) as client:
            # The first scan publishes the objects (GET /world says so); the page must
            # draw them from the stream, without polling.
            posted = time.monotonic()
            assert client.post("/detections", json={"detections": scan(0.0)}).status_code == 200
            assert len(client.get("/world").json()["objects"]) == 3
            page.wait_for_selector("[data-class=Robot]", timeout=10_000)
            latency = time.monotonic() - posted
            for k in range(1, 12):
                response = client.post("/detections", json={"detections": scan(k * STEP)})
                assert response.status_code == 200, response.text
            world = client.get("/world").json()

        robot = next(o for o in world["objects"] if o["class"] == "Robot")
        page.wait_for_function(
            f"window.semwmLive.world.time === {11 * STEP!r} "
            "&& document.querySelectorAll('.velocity').length > 0"
        )
        page.click(f"[data-object-id='{robot['id']}'] circle")
        page.wait_for_selector("#details table")

        # Every element of the page, as the DOM has it.
        assert page.locator("#view .region").count() == 1
        assert page.locator("[data-object-id]").count() == len(world["objects"]) == 3
        assert page.locator(".object ellipse").count() == 3
        assert page.locator(".object .velocity").count() == 1  # only the robot moves
        labels = page.locator(".object text").all_text_contents()
        assert sorted(labels) == sorted(title(o) for o in world["objects"])
        assert title(robot).startswith(f"#{robot['id']} Robot") and title(robot).endswith("· r1")
        assert page.locator(".detection").count() > 0  # recent detections, fading
        assert page.locator(".track.selected").count() == 1
        details = page.locator("#details").inner_text()
        assert "existence" in details and "Recent track" in details and "r1" in details
        assert int(page.locator("#stat-hypotheses").inner_text()) >= 1
        assert page.locator("#stat-time").inner_text() == f"{11 * STEP:.2f} s"  # scenario time
        assert page.locator("#stat-rate").inner_text() != "0.0 det/s"
        opacities = page.eval_on_selector_all(
            ".object .dot", "nodes => nodes.map(n => Number(n.getAttribute('fill-opacity')))"
        )
        expected = sorted(round(0.15 + 0.8 * o["existence"], 2) for o in world["objects"])
        assert sorted(round(v, 2) for v in opacities) == pytest.approx(expected, abs=0.02)

        screenshot = tmp_path / "live-page.png"
        page.screenshot(path=str(screenshot))

        # Fields the tracking core is adding (class probabilities, confidence) are
        # shown when the stream carries them.
        page.evaluate(
            """() => {
              const w = structuredClone(window.semwmLive.world);
              const o = w.objects.find(o => o.class === 'Cup');
              o.class_probabilities = {Cup: 0.87, Can: 0.13};
              o.confidence = {value: 0.9, state: 'valid'};
              window.semwmLivePage.onWorld(w);
            }"""
        )
        page.wait_for_function(
            "[...document.querySelectorAll('.object text')]"
            ".some(t => t.textContent.endsWith('Cup 87%'))"
        )
        page.click("[data-class=Cup] circle")
        assert "Cup 87.0%, Can 13.0%" in page.locator("#details").inner_text()
        # a robot's epoch seconds are a time of day (the page's own time zone)
        expected_clock = page.evaluate(
            "() => { const d = new Date(1764066060250); "
            "const p = (n) => String(n).padStart(2, '0'); "
            "return `${p(d.getHours())}:${p(d.getMinutes())}:00.25`; }"
        )
        page.evaluate(
            """() => {
              const w = structuredClone(window.semwmLive.world);
              w.time = 1764066060.25;
              window.semwmLivePage.onWorld(w);
            }"""
        )
        page.wait_for_function(
            f"document.getElementById('stat-time').textContent === {expected_clock!r}"
        )
        assert "0.900 (valid)" in page.locator("#details").inner_text()
        injected = tmp_path / "live-page-class-probabilities.png"
        page.screenshot(path=str(injected))

        # Pan and zoom change the view, not the world.
        before = page.eval_on_selector("#view .region", "r => r.getAttribute('width')")
        page.mouse.move(500, 400)
        page.mouse.wheel(0, -400)
        page.wait_for_function(
            f"document.querySelector('#view .region').getAttribute('width') !== '{before}'"
        )
        page.close()

    ARTIFACTS.mkdir(exist_ok=True)
    shutil.copy(screenshot, ARTIFACTS / "live-page.png")
    shutil.copy(injected, ARTIFACTS / "live-page-class-probabilities.png")
    (ARTIFACTS / "live-page.json").write_text(
        json.dumps({"post_to_object_on_page_s": round(latency, 3)}, indent=1)
    )
    print(f"object on the page {latency * 1000:.0f} ms after its POST")
    assert problems == []
