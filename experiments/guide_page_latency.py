"""vical-guide's page: how fast it serves the live image, and how soon a browser sees a new instruction.

Measured against what it must keep up with, side by side in the same run:

- **frame rate**: ``/frame.jpg`` requests served per second (640 x 480, the corners and outline drawn, JPEG) while
  the guide hands it frames at a camera's 30 Hz, against that camera rate (a ratio >= 1: the page can show every
  frame of the sensor);
- **instruction latency**: from the guide's ``show`` to a client polling ``/state.json`` as the page's script does
  (every ``POLL_MS``) reading the new words, against the poll interval itself (what the script's polling costs
  unavoidably: half of it on average);
- **state size**: the bytes of ``/state.json``.

    python experiments/guide_page_latency.py          # ~20 s
"""

from __future__ import annotations

import json
import threading
import time
import urllib.request

import numpy as np

from vical.calib.synthetic import default_camera
from vical.collection.page import POLL_MS, GuidePage, PageSettings
from vical.data import Target
from vical.geometry import T_CAM_BODY, make_transform
from vical.robot import CameraImage, Guidance

CAMERA_HZ = 30.0
POLL_S = POLL_MS / 1e3  # the page script's interval
INSTRUCTIONS = 40


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=5) as response:
        return response.read()


def _feed(page: GuidePage, camera, stop: threading.Event) -> None:
    """Frames at the camera rate: a moving grey pattern with 100 detected corners."""
    rng = np.random.default_rng(0)
    k = 0
    while not stop.is_set():
        image = ((np.indices((camera.height, camera.width)).sum(axis=0) + 7 * k) % 256).astype(np.uint8)
        page.view(CameraImage(k, image), rng.uniform([0, 0], [camera.width, camera.height], (100, 2)), np.arange(100))
        k += 1
        time.sleep(1.0 / CAMERA_HZ)


def frame_rate(page: GuidePage, seconds: float = 5.0) -> float:
    served, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _get(page.url + "/frame.jpg")
        served += 1
    return served / (time.perf_counter() - start)


def instruction_latency(page: GuidePage, pose: np.ndarray) -> tuple[list[float], int]:
    """Seconds from each ``show`` (at random phases) to the first read of it by a client that polls ``/state.json``
    every ``POLL_S`` as the page's script does; the state's size."""
    seen: list[tuple[float, str, int]] = []
    stop = threading.Event()

    def poll() -> None:
        while not stop.is_set():
            body = _get(page.url + "/state.json")
            seen.append((time.perf_counter(), json.loads(body)["words"], len(body)))
            time.sleep(POLL_S)

    poller = threading.Thread(target=poll, daemon=True)
    poller.start()
    shown = {}
    rng = np.random.default_rng(1)
    for n in range(INSTRUCTIONS):
        time.sleep(float(rng.uniform(POLL_S, 3 * POLL_S)))
        words = f"instruction {n}"
        shown[words] = time.perf_counter()
        page.show(Guidance(pose, words, {"intrinsics": 1.5, "extrinsics": 2.0, "time_offset": 0.8}, float(n)))
    time.sleep(2 * POLL_S)
    stop.set()
    poller.join()
    first = {}
    for at, words, _ in seen:
        first.setdefault(words, at)
    return [first[w] - t for w, t in shown.items() if w in first], seen[-1][2]


def main() -> int:
    camera, target = default_camera(), Target.aprilgrid()
    page = GuidePage(camera, target, PageSettings(port=0))
    stop = threading.Event()
    feeder = threading.Thread(target=_feed, args=(page, camera, stop), daemon=True)
    feeder.start()
    try:
        pose = make_transform(np.diag([1.0, -1.0, -1.0]), target.center + [0.0, 0.0, 1.0]) @ T_CAM_BODY
        page.show(Guidance(pose, "start", {}, 0.0))
        rate = frame_rate(page)
        latencies, size = instruction_latency(page, pose)
    finally:
        stop.set()
        feeder.join()
        page.close()
    print("| measure | page | peer | ratio |")
    print("|---|---|---|---|")
    print(f"| frames served [1/s] vs the camera's rate | {rate:.1f} | {CAMERA_HZ:.0f} | {rate / CAMERA_HZ:.2f} |")
    mean, worst = float(np.mean(latencies)), float(np.max(latencies))
    print(f"| instruction latency, mean [ms] vs half the poll interval | {mean * 1e3:.0f} | {POLL_S / 2 * 1e3:.0f} | "
          f"{mean / (POLL_S / 2):.2f} |")  # fmt: skip
    print(f"| instruction latency, worst [ms] vs the poll interval | {worst * 1e3:.0f} | {POLL_S * 1e3:.0f} | "
          f"{worst / POLL_S:.2f} |")  # fmt: skip
    print(f"| /state.json [bytes] | {size} | - | - |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
