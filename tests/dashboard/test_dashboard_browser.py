"""The dashboard in a real browser: headless Chromium (Debian's chromium + chromium-driver, driven by
selenium) on the page of a real ``koopguide dashboard`` watching two real guidance services steering
two boats of the real simulator (``tests/dashboard/rig.py``). The screenshot lands in tmp_path."""

from __future__ import annotations

import math
import os
import shutil
import time
from pathlib import Path

import pytest
import zenoh

from koopguide.bus.control import decode_control
from koopguide.bus.zenoh_config import load_zenoh_config
from tests.dashboard.rig import BOATS, running_rig, train_small_model

webdriver = pytest.importorskip("selenium.webdriver")
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
TOKEN = "test-token-0123456789abcdef"
WATCH_S = 3.0


def chromium(profile: Path):
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--no-first-run",
        "--disable-dev-shm-usage",
        f"--user-data-dir={profile}",
        "--window-size=1500,900",
    ):
        options.add_argument(flag)
    return webdriver.Chrome(options=options, service=webdriver.ChromeService(executable_path=str(CHROMEDRIVER)))


def boats_in_page(driver) -> dict[str, dict[str, float]]:
    """Each table row's data attributes: position N, E [m], updates received, state."""
    rows = driver.find_elements(By.CSS_SELECTOR, "#vehicles tbody tr[data-n]")
    return {
        r.get_attribute("data-vehicle"): {
            "n": float(r.get_attribute("data-n")),
            "e": float(r.get_attribute("data-e")),
            "updates": int(r.get_attribute("data-updates")),
            "state": r.get_attribute("data-state"),
        }
        for r in rows
    }


def canvas_counts(driver) -> dict[str, int]:
    canvas = driver.find_element(By.ID, "map")
    return {k: int(canvas.get_attribute(f"data-{k}") or 0) for k in ("frames", "streamlines", "boats")}


@pytest.mark.skipif(
    not (CHROMIUM.exists() and CHROMEDRIVER.exists()),
    reason="needs Debian's chromium and chromium-driver (.ci/run installs them)",
)
@pytest.mark.timeout(150)
def test_two_guided_boats_move_over_the_streamlines_in_headless_chromium(tmp_path: Path) -> None:
    model = train_small_model(tmp_path / "zshape.pt")
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN + "\n")
    started = time.monotonic()
    with running_rig(model, tmp_path, ("--allow-control", "--control-token-file", str(token_file))) as rig:
        driver = chromium(tmp_path / "chromium-profile")
        listener = zenoh.open(load_zenoh_config(rig.zenoh_config))
        requests = listener.declare_subscriber("koopguide/*/control", zenoh.handlers.RingChannel(64))
        try:
            driver.get(rig.url)
            wait = WebDriverWait(driver, 40, poll_frequency=0.2)
            wait.until(lambda d: len(d.find_elements(By.CSS_SELECTOR, "#vehicles tbody tr")) == 2)  # waiting
            rig.start_simulator()
            wait.until(lambda d: set(boats_in_page(d)) == set(BOATS) and canvas_counts(d)["streamlines"] > 0)
            wait.until(lambda d: all(b["state"] == "guiding" for b in boats_in_page(d).values()))
            before, frames_before, t0 = boats_in_page(driver), canvas_counts(driver)["frames"], time.monotonic()
            time.sleep(WATCH_S)
            after, counts, t1 = boats_in_page(driver), canvas_counts(driver), time.monotonic()
            for vid, goal in rig.goals.items():
                moved = math.hypot(after[vid]["n"] - before[vid]["n"], after[vid]["e"] - before[vid]["e"])
                # >= 0.05 m/s commanded x speed-up 3 x 3 s = 0.45 m at the slowest; 0.1 m leaves room for turns
                assert moved >= 0.1, f"{vid} moved only {moved:.3f} m in {t1 - t0:.1f} s"
                rate = (after[vid]["updates"] - before[vid]["updates"]) / (t1 - t0)
                assert rate >= 5.0, f"{vid}: {rate:.1f} updates/s in the page (services publish at 10 Hz)"
                print(f"{vid}: moved {moved:.2f} m and {rate:.1f} updates/s in the page over {t1 - t0:.1f} s")
                # each boat is drawn near its own goal, 2.5 m from the other's: positions are not mixed up
                assert math.hypot(after[vid]["n"] - goal[0], after[vid]["e"] - goal[1]) < 2.5
            assert counts["boats"] == 2 and counts["streamlines"] >= 20
            assert counts["frames"] > frames_before  # the canvas is redrawn without a reload
            shot = tmp_path / "dashboard.png"
            assert driver.save_screenshot(str(shot))
            assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and shot.stat().st_size > 20_000

            # operator control: a wrong token is refused and nothing is published; the right one signs a hold
            driver.find_element(By.ID, "token").send_keys("wrong-token-wrong-token")
            driver.find_element(By.CSS_SELECTOR, 'tr[data-vehicle="boat1"] button.hold').click()
            result = driver.find_element(By.ID, "control-result")
            wait.until(lambda _: result.get_attribute("data-result") == "refused")
            token_box = driver.find_element(By.ID, "token")
            token_box.clear()
            token_box.send_keys(TOKEN)
            driver.find_element(By.CSS_SELECTOR, 'tr[data-vehicle="boat1"] button.hold').click()
            wait.until(lambda _: result.get_attribute("data-result") == "sent")
            sample = None
            deadline = time.monotonic() + 10
            while sample is None and time.monotonic() < deadline:
                sample = requests.try_recv()
                time.sleep(0.05)
            assert sample is not None, "no control request on zenoh within 10 s"
            assert str(sample.key_expr) == "koopguide/boat1/control"
            request = decode_control(sample.payload.to_bytes(), TOKEN, "boat1", time.time())
            assert request.action == "hold" and request.source.startswith("dashboard@")
            assert requests.try_recv() is None  # the wrong token published nothing
        finally:
            driver.quit()
            listener.close()
            if (target := _keep_screenshot()) is not None:
                shutil.copy(tmp_path / "dashboard.png", target)
    elapsed = time.monotonic() - started
    print(f"dashboard browser test: {elapsed:.1f} s")


def _keep_screenshot() -> Path | None:
    """``KOOPGUIDE_KEEP_SCREENSHOT=docs/img/dashboard.png`` copies the screenshot there (how the docs' was made)."""
    target = os.environ.get("KOOPGUIDE_KEEP_SCREENSHOT")
    return Path(target) if target else None
