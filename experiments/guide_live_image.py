"""vical-guide's live image and instructions through the guide's own loop, while its planner decides.

A simulated person (rendered images, the guide's default planner with its 48 candidates) is guided with the page
on, and a client reads the page as its script does (``vical.collection.page.POLL_MS``: ``/state.json``, then the
frame when there is a new one). Two ways of waiting for the planner, side by side in the same run on the same
sensors (tuning seeds, not the held-out ones):

- **reading**: the planner decides in a worker thread while the loop keeps reading the sensor and feeding the page
  (``vical.collection.runner.decide``; what ``vical-guide`` does with a page or a live sensor);
- **paused** (the peer): the planner decides in the loop, which reads nothing meanwhile (what a simulated sensor
  without a page gets, and what every run got before): the live image stands still for each decision.

Per way: the live image's rate at the client [1/s] and its longest pause [s] from the first instruction to the
stop, the share of the guided time in pauses over 0.5 s (a freeze a person sees), each instruction's latency from the
guide's ``show`` to the client reading it [ms], and the planner's wall time per decision [ms] (a worker thread
shares the interpreter with the reading loop).

    python experiments/guide_live_image.py              # 3 sensors, 8 poses each: ~6 min on 2 cores
    python experiments/guide_live_image.py --sensors 1 --steps 3
"""

from __future__ import annotations

import argparse
import json
import threading
import time
import urllib.request
from dataclasses import dataclass

import numpy as np
from hydra import compose, initialize_config_dir

from vical.apps.collect import board, build_robot, configured_policy, nominal_sensor
from vical.apps.guide import CONF_DIR, build_guide, check_settings, guided_mdp
from vical.collection.page import POLL_MS, GuidePage
from vical.robot import Guidance, Person

FIRST_SEED = 40000  # the guide's tuning sensors (held-out comparisons use 60000 on)
PAUSE_S = 0.5  # [s] a gap in the live image a person sees as a freeze


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.read()


class Client:
    """Reads the page as its script does, in a thread: each image it loaded and each instruction it first saw."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.images: list[float] = []  # time.perf_counter() of each frame loaded
        self.words: dict[str, float] = {}  # instruction -> when first read
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()

    def _poll(self) -> None:
        frames = -1
        while not self._stop.is_set():
            state = json.loads(_get(self.url + "/state.json"))
            self.words.setdefault(state["words"], time.perf_counter())
            if state["frames"] != frames:
                frames = state["frames"]
                _get(self.url + f"/frame.jpg?n={frames}")
                self.images.append(time.perf_counter())
            time.sleep(POLL_MS / 1e3)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


class Stamped(Person):
    """When the guide showed each instruction (``time.perf_counter()``)."""

    def __init__(self) -> None:
        self.shown: list[tuple[float, str]] = []

    def show(self, guidance: Guidance) -> None:
        self.shown.append((time.perf_counter(), guidance.words))


@dataclass(frozen=True)
class Run:
    rate_hz: float
    longest_pause_s: float
    paused_share: float
    latencies_ms: list[float]
    decision_ms: float


def guided(seed: int, steps: int, reading: bool) -> Run:
    """One guided run of the tuning sensor ``seed`` for ``steps`` poses with the page and a client reading it."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="guide", overrides=[f"seed={seed}", f"limits.max_steps={steps}", "progress=false",
                                                      "page.port=0", "out=unused"])  # fmt: skip
    s = check_settings(cfg)
    policy = configured_policy(cfg, s.task, "planner")
    mdp = guided_mdp(cfg, policy)
    rig = build_robot(cfg.person, "person")
    nominal = nominal_sensor(s, rig)
    page = GuidePage(nominal.camera, board(cfg, rig), s.page)
    stamped = Stamped()
    try:
        guide = build_guide(cfg, s, rig, policy, mdp, nominal, page, None, lambda line: None)
        guide.person.people.append(stamped)
        if not reading:
            guide._decision_wait = lambda: None  # the peer: decide in the loop, reading nothing meanwhile
        client = Client(page.url)
        try:
            result = guide.run(seed)
        finally:
            client.stop()
    finally:
        page.close()
        rig.close()
    first, end = stamped.shown[0][0], client.images[-1]
    images = np.array([t for t in client.images if first <= t <= end])
    gaps = np.diff(images)
    latencies = [1e3 * (client.words[w] - t) for t, w in stamped.shown[1:] if w in client.words]
    return Run(len(images) / (end - first), float(gaps.max()), float(gaps[gaps > PAUSE_S].sum() / (end - first)),
               latencies, 1e3 * result.decision_s / max(result.steps, 1))  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sensors", type=int, default=3, help="tuning sensors from seed 40000")
    parser.add_argument("--steps", type=int, default=8, help="poses per run")
    args = parser.parse_args(argv)
    runs: dict[bool, list[Run]] = {True: [], False: []}
    for seed in range(FIRST_SEED, FIRST_SEED + args.sensors):
        for reading in (True, False):
            runs[reading].append(guided(seed, args.steps, reading))
            r = runs[reading][-1]
            print(f"seed {seed} {'reading' if reading else 'paused'}: {r.rate_hz:.1f} Hz, longest pause "
                  f"{r.longest_pause_s:.2f} s, decisions {r.decision_ms:.0f} ms", flush=True)  # fmt: skip
    print(f"\n{args.sensors} sensors x {args.steps} poses, the page read every {POLL_MS} ms\n")
    print("| measure | reading while deciding | paused (peer) | ratio |")
    print("|---|---|---|---|")
    rows = [
        ("live image, mean rate [1/s]", lambda r: r.rate_hz, "{:.1f}"),
        ("live image, longest pause [s]", lambda r: r.longest_pause_s, "{:.2f}"),
        (f"guided time in pauses > {PAUSE_S} s [%]", lambda r: 100 * r.paused_share, "{:.1f}"),
        ("instruction latency, median [ms]", lambda r: np.median(r.latencies_ms), "{:.0f}"),
        ("instruction latency, worst [ms]", lambda r: np.max(r.latencies_ms), "{:.0f}"),
        ("planner's decision, mean [ms]", lambda r: r.decision_ms, "{:.0f}"),
    ]
    for name, measure, fmt in rows:
        worst = "longest" in name or "worst" in name
        pick = max if worst else np.mean
        a, b = (float(pick([measure(r) for r in runs[k]])) for k in (True, False))
        ratio = f"{a / b:.2f}" if b else "-"
        print(f"| {name} | {fmt.format(a)} | {fmt.format(b)} | {ratio} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
