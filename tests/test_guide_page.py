"""vical-guide's page in a real browser (Debian's headless Chromium, driven by Selenium): a simulated person is guided
live while the page shows the instruction in words, the live image, a bar per parameter group and the instructions
so far; then the result with the calibration's plots; its Close button ends the app with status 0.

Integration tier: it needs Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs them)."""

import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

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
        pytest.fail(
            "the page's test needs Debian's chromium and chromium-driver (apt-get install chromium "
            "chromium-driver; .ci/run installs them)"
        )
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
    """A process's output lines, read as they come (so that its pipe never fills), and the page's address."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self.url: str | None = None
        self.found = threading.Event()
        self._thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self._thread.start()

    def _read(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            self.lines.append(line)
            match = re.search(r"the guide's page: (http://\S+)", line)
            if match:
                self.url = match.group(1)
                self.found.set()
        self.found.set()


def _live_width(driver) -> int:
    return driver.execute_script("return document.getElementById('live').naturalWidth")


def test_the_page_guides_a_simulated_person_live_and_shows_the_result(tmp_path, browser):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "vical.apps.guide", f"out={out}", "page.port=0", "page.linger=300",
           "limits.max_steps=6", "seed=3"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        output = Output(proc)
        assert output.found.wait(120) and output.url, "".join(output.lines)
        browser.get(output.url)
        wait = WebDriverWait(browser, 240, poll_frequency=0.2)
        # Live: an instruction in words, the image as the sensor sees it, a bar per parameter group.
        wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#history li"))
        assert browser.find_element(By.ID, "words").text
        wait.until(lambda d: _live_width(d) == 640)
        bars = wait.until(lambda d: d.find_elements(By.CSS_SELECTOR, "#bars .group"))
        assert all(re.fullmatch(r"\w+: \d+\.\d\dx tolerance", b.text.strip()) for b in bars), [b.text for b in bars]
        # The result: the outcome, the calibration's results and plots.
        wait.until(lambda d: d.find_element(By.ID, "result").is_displayed())
        outcome = browser.find_element(By.ID, "outcome").text
        assert "steps: 6" in outcome and "calibration: done" in outcome, outcome
        summary = browser.find_element(By.ID, "summary").text
        assert summary.startswith("vical calibration results: task joint") and "fx" in summary, summary
        plotted = "return [...document.querySelectorAll('#files img')].some(i => i.complete && i.naturalWidth > 0)"
        wait.until(lambda d: d.execute_script(plotted))
        browser.find_element(By.ID, "close").click()
        assert proc.wait(timeout=60) == 0, "".join(output.lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert (out / "calibration" / "camchain-imucam.yaml").is_file()
    assert any("next: " in line for line in output.lines)
