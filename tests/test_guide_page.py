"""vical-guide's page in a real browser (Debian's headless Chromium, driven by Selenium), with a simulated person: the
page follows the guidance live (new images of the sensor, in order, while each pose is held; every instruction the
guide shows; the bars moving) until "done", then shows the result with the calibration's plots, and its Close button
ends the app with status 0; a closed tab, or a lost sensor, stops the recording with one line and keeps it
calibratable. How fast the page follows (the image's rate and pauses, the instructions' latency) is a speed target,
measured beside a peer by ``experiments/guide_live_image.py`` and ``experiments/guide_page_latency.py``; here it is
printed only, as a test on a loaded machine measures the load.

Integration tier: it needs Debian's ``chromium`` and ``chromium-driver`` (``make test-all`` installs them as root, and
with sudo in CI); without them these tests skip with a line saying so, and fail in CI (``CI`` set)."""

import itertools
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait
from stopped_collections import calibrate_joint, kill_if_running

from vical.io.euroc import read_euroc
from vical.io.kalibr import read_target_yaml

pytestmark = pytest.mark.integration

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
# Chromium on a machine without the internet: no background connections, no first-run pages (technical notes).
FLAGS = (
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
)  # fmt: skip


@pytest.fixture
def browser(tmp_path):
    if not (CHROMIUM.is_file() and CHROMEDRIVER.is_file()):
        missing = "the page's browser test needs Debian's chromium and chromium-driver: sudo apt-get install chromium "
        missing += "chromium-driver (make test-all installs them as root)"
        (pytest.fail if os.environ.get("CI") else pytest.skip)(missing)
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*FLAGS, f"--user-data-dir={tmp_path / 'chromium'}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()


class Output:
    """A process's output lines, read as they come (so that its pipe never fills), each with its wall time [ms], and
    the page's address."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self.stamped: list[tuple[float, str]] = []  # (time.time() in ms, line)
        self.url: str | None = None
        self.found = threading.Event()
        self._thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self._thread.start()

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            self.stamped.append((1e3 * time.time(), line))
            self.lines.append(line)
            match = re.search(r"the guide's page: (http://\S+)", line)
            if match:
                self.url = match.group(1)
                self.found.set()
        self.found.set()

    def text(self) -> str:
        return "".join(self.lines)


def _guide(out: Path, *settings: str) -> tuple[subprocess.Popen, Output]:
    cmd = [sys.executable, "-m", "vical.apps.guide", f"out={out}", "page.port=0", "page.linger=300", "seed=3",
           *settings]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    output = Output(proc)
    assert output.found.wait(120) and output.url, output.text()
    return proc, output


# What the page showed and when (Date.now() [ms]): each loaded live image (with its frame count; the first, loaded
# with the page, has none), each new instruction, each new set of bars.
WATCH = """
const log = window.vicalLog = {images: [], words: [], bars: []};
const keep = (list, text) => { if (!list.length || list[list.length - 1][1] !== text) list.push([Date.now(), text]); };
const live = document.getElementById("live");  // each image with the sensor's frame count it shows
live.addEventListener("load", () => log.images.push([Date.now(), +new URL(live.src).searchParams.get("n")]));
new MutationObserver(() => keep(log.words, document.getElementById("words").textContent))
  .observe(document.getElementById("words"), {childList: true, characterData: true, subtree: true});
new MutationObserver(() => keep(log.bars, document.getElementById("bars").textContent))
  .observe(document.getElementById("bars"), {childList: true, characterData: true, subtree: true});
"""


BAR_TEXTS = "return [...document.querySelectorAll('#bars .group')].map(g => g.firstChild.textContent)"


def _instruction_latencies(output: Output, words: list[list]) -> list[float]:
    """[s] from each instruction's line (printed as the guide shows it) to the page showing its words; instructions
    that repeat the one before are not a change the page can show."""
    latencies, previous = [], None
    for at, line in output.stamped:
        if not line.startswith("next: "):
            continue
        text = line.removeprefix("next: ").strip()
        if text != previous:
            seen = [t for t, w in words if w == text and t >= at - 50]  # 50 ms: the two clocks' reading order
            assert seen, f"the page never showed {text!r}"
            latencies.append(max(0.0, seen[0] - at) / 1e3)
        previous = text
    return latencies


def test_the_page_guides_a_simulated_person_live_until_done_and_shows_the_result(tmp_path, browser):
    out = tmp_path / "out"
    proc, output = _guide(out)
    try:
        browser.get(output.url)
        browser.execute_script(WATCH)
        wait = WebDriverWait(browser, 600, poll_frequency=0.2)
        # Live: an instruction in words, the image as the sensor sees it, a bar per parameter group; then "done".
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#history li"))
        wait.until(lambda d: d.execute_script("return document.getElementById('live').naturalWidth") == 640)
        # read in one script: the page rebuilds the bars at every poll
        bars = wait.until(lambda d: d.execute_script(BAR_TEXTS))
        assert all(re.fullmatch(r"\w+: \d+\.\d\dx tolerance", b.strip()) for b in bars), bars
        wait.until(lambda d: d.find_element(By.ID, "words").get_attribute("class") == "done")
        log = browser.execute_script("return window.vicalLog")
        assert browser.find_element(By.ID, "words").text.startswith("done")
        # The result: the outcome, the calibration's results and plots.
        wait.until(lambda d: d.find_element(By.ID, "result").is_displayed())
        outcome = browser.find_element(By.ID, "outcome").text
        assert "goal reached: true" in outcome and "calibration: done" in outcome, outcome
        summary = browser.find_element(By.ID, "summary").text
        assert summary.startswith("vical calibration results: task joint") and "fx" in summary, summary
        plotted = "return [...document.querySelectorAll('#files img')].some(i => i.complete && i.naturalWidth > 0)"
        wait.until(lambda d: d.execute_script(plotted))
        browser.find_element(By.ID, "close").click()
        assert proc.wait(timeout=60) == 0, output.text()
    finally:
        kill_if_running(proc)
    assert (out / "calibration" / "camchain-imucam.yaml").is_file()
    # The live image while the person was guided (the first instruction to "done"), decisions included: new frames of
    # the sensor, in order, and several while each pose was sought and held (from its instruction to the next one).
    first, done = log["words"][0][0], next(t for t, w in log["words"] if w.startswith("done"))
    images = np.array([(t, n) for t, n in log["images"] if first <= t <= done])
    assert np.all(np.diff(images[:, 1]) > 0), "the page showed a frame again or out of order"
    told = {line.removeprefix("next: ").strip() for _, line in output.stamped if line.startswith("next: ")}
    shown = [t for t, w in log["words"] if first <= t <= done and w in told]
    per_pose = [np.count_nonzero((images[:, 0] >= a) & (images[:, 0] < b)) for a, b in itertools.pairwise(shown)]
    assert len(per_pose) >= 5 and min(per_pose) >= 2, f"new images while each pose was held: {per_pose}"
    latencies = _instruction_latencies(output, log["words"])  # every instruction the guide showed reached the page
    assert len(latencies) >= 5, latencies
    assert len({text for _, text in log["bars"]}) >= 3  # the predicted errors moved as the data came
    rate, gap = len(images) / ((done - first) / 1e3), np.diff(images[:, 0]).max() / 1e3
    print(f"live image {rate:.1f} Hz (longest pause {gap:.2f} s), {min(per_pose)}-{max(per_pose)} images a pose; "
          f"instruction latency median {np.median(latencies):.2f} s, max {max(latencies):.2f} s over "
          f"{len(latencies)}")  # fmt: skip


def _close_tab(driver) -> None:
    """Close the page's tab (a blank tab keeps the browser open, as a person's other tabs do)."""
    page = driver.current_window_handle
    driver.switch_to.new_window("tab")
    blank = driver.current_window_handle
    driver.switch_to.window(page)
    driver.close()
    driver.switch_to.window(blank)


def test_a_closed_tab_stops_the_guide_with_one_line_and_a_calibratable_recording(tmp_path, browser):
    out = tmp_path / "out"
    proc, output = _guide(out)
    try:
        browser.get(output.url)
        browser.refresh()  # a reload is no close, nor is a visit elsewhere and back
        browser.get("data:text/html,<p>elsewhere</p>")
        browser.back()
        WebDriverWait(browser, 300, poll_frequency=0.2).until(lambda d: "step 4:" in output.text())
        _close_tab(browser)
        assert proc.wait(timeout=60) == 1, output.text()
    finally:
        kill_if_running(proc)
    (line,) = [line for line in output.lines if line.startswith("vical-guide: error")]
    assert line.startswith("vical-guide: error: stopped: the guide's page was closed;"), line
    assert f"the recording so far is in {out / 'recording'}" in line
    assert yaml.safe_load((out / "collect.yaml").read_text())["outcome"].startswith("stopped: the guide's page was")
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 80
    assert calibrate_joint(out, tmp_path / "cal") == 0


def test_a_lost_sensor_stops_the_guide_and_the_page_says_why(tmp_path, browser):
    """The IMU stops 12 s into the run (a pulled cable): the page's result says the guide stopped and why; its Close
    button ends the app with the fault's status 1; the recording so far is kept."""
    out = tmp_path / "out"
    proc, output = _guide(out, "limits.wait_timeout=1", "person.faults.imu_gap=[12.0,1000.0]")
    try:
        browser.get(output.url)
        wait = WebDriverWait(browser, 300, poll_frequency=0.2)
        wait.until(lambda d: d.find_element(By.ID, "result").is_displayed())
        outcome = browser.find_element(By.ID, "outcome").text
        assert "outcome: stopped: no IMU samples for 1 s while the camera streams" in outcome, outcome
        browser.find_element(By.ID, "close").click()
        assert proc.wait(timeout=60) == 1, output.text()
    finally:
        kill_if_running(proc)
    assert "the recording so far is in" in output.text()
    assert len(read_euroc(out / "recording", read_target_yaml(out / "target.yaml")).frames) >= 40
