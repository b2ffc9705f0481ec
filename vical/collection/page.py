"""``vical-guide``'s local web page: the live image, where the board should appear next, the instruction in words, a
bar per parameter group, the time so far, "done", and the calibration's result at the end.

``GuidePage`` is a ``vical.robot.Person`` (the guide shows it each step's ``Guidance``) and the sensor stream's
viewer (``SensorStream.viewer``: every frame with its detections). It serves, on ``http://<host>:<port>`` (werkzeug's
threaded server, in a thread of its own; localhost only by default, nothing from the internet):

- ``/``: the page (HTML, CSS and a script that polls the two below; no external resources);
- ``/state.json?page=<id>``: the instruction, the groups' predicted error over tolerance, the time, the stage, the
  history of instructions, the result;
- ``/frame.jpg``: the latest frame (grey; a corner-level sensor's on a plain background) with the detected corners
  (green) and the board's outline where the next pose puts it (orange), projected with the guide's camera (the
  datasheet's, as the guide's PnP);
- ``/files/<name>``: the calibration's files (results, plots, report) once it is done;
- ``POST /close``: the person has read the result: the app stops serving (``wait_closed``);
- ``POST /left?page=<id>``: the tab is going away (its ``pagehide``): unless another load of the page polls within
  ``RELOAD_GRACE_S`` (a reload), the person has closed it and ``gone`` says so (the guide stops, keeping the recording).

Each load of the page polls with an id of its own: a poll that was in flight when its tab closed may reach the server
after the tab's ``/left``, and must not count as the page being back.

The script polls ``/state.json`` every ``POLL_MS`` and loads the next frame whenever there is a new one and the last
has loaded: the live image follows the sensor at up to 1000 / ``POLL_MS`` frames a second.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from werkzeug.exceptions import NotFound
from werkzeug.serving import BaseWSGIServer, WSGIRequestHandler, make_server, select_address_family
from werkzeug.utils import safe_join
from werkzeug.wrappers import Request, Response

from vical.config_checks import require, require_range
from vical.data import Target
from vical.geometry import T_CAM_BODY, CameraModel, invert_transform
from vical.robot import CameraDetections, CameraImage, Guidance, Person

HISTORY = 12  # instructions the page lists
JPEG_QUALITY = 80
BACKGROUND = 96  # grey level of a corner-level frame's image
DETECTED = (60, 200, 60)  # BGR
OUTLINE = (0, 140, 255)  # BGR
FILE_SUFFIXES = (".png", ".pdf", ".txt", ".yaml", ".csv")  # what /files serves
POLL_MS = 100  # [ms] between the script's polls: a 10 Hz live image at most, an instruction seen 50 ms late on average
RELOAD_GRACE_S = 3.0  # [s] a tab that left with no other load of the page polling since is closed, not reloading


@dataclass(frozen=True)
class PageSettings:
    """Where the page is served. ``port`` 0: any free port (the app prints the address); ``linger`` [s]: how long
    the page stays up after the calibration for the person to read it (or until its Close button)."""

    enabled: bool = True
    host: str = "127.0.0.1"
    port: int = 8765
    linger: float = 300.0

    def __post_init__(self) -> None:
        require(isinstance(self.host, str) and bool(self.host), "page.host", "a host name or address", self.host)
        require(isinstance(self.port, int) and 0 <= self.port <= 65535, "page.port", "a port 0-65535", self.port)
        require_range("page.linger", self.linger, 0.0)


class GuidePage(Person):
    """The page (module doc) for a camera ``camera`` (its size and projection) and board ``target``."""

    def __init__(self, camera: CameraModel, target: Target, settings: PageSettings) -> None:
        self.camera = camera
        self.target = target
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._polling: set[str] = set()  # the page's loads (their ids) that poll and have not left
        self._left: set[str] = set()  # the loads that left: polls of theirs still in flight do not bring them back
        self._left_at: float | None = None  # [s] monotonic: the last ``pagehide`` of a load
        self._frame: np.ndarray | None = None  # the latest image, grey (H, W)
        self._corners = np.zeros((0, 2))
        self._frames = 0
        self._guidance: Guidance | None = None
        self._outline: np.ndarray | None = None  # (4, 2) [px] the board's corners at the shown pose
        self._history: list[str] = []
        self._stage = "starting"
        self._result: dict | None = None
        self._files: Path | None = None
        self._file_list: list[str] = []  # the calibration's files the page links (FILE_SUFFIXES)
        self._results_text = ""
        self._server = _server(settings.host, settings.port, self._wsgi)
        self.url = f"http://{settings.host}:{self._server.socket.getsockname()[1]}"
        self._thread = threading.Thread(target=self._server.serve_forever, name="vical-guide-page", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ what the guide and the app tell it
    def show(self, guidance: Guidance) -> None:
        outline = None if guidance.T_board_body is None else self._outline_at(guidance.T_board_body)
        with self._lock:
            self._guidance, self._outline = guidance, outline
            self._history = ([guidance.words] + self._history)[:HISTORY]

    def view(self, frame: CameraImage | CameraDetections, corners: np.ndarray, ids: np.ndarray) -> None:
        """The stream's latest frame and its detections (``SensorStream.viewer``)."""
        image = frame.image if isinstance(frame, CameraImage) else None
        with self._lock:
            self._frame, self._corners, self._frames = image, np.asarray(corners, float), self._frames + 1

    def stage(self, line: str) -> None:
        """What the app is doing (its progress lines)."""
        with self._lock:
            self._stage = line

    def finish(self, result: dict, files: Path | None) -> None:
        """The run's outcome (``result``: what ``collect.yaml`` says, and the calibration's status) and the folder of
        the calibration's files, served under ``/files``."""
        found = sorted(files.rglob("*")) if files is not None and files.is_dir() else []
        names = sorted(str(p.relative_to(files)) for p in found if p.suffix in FILE_SUFFIXES)
        text = "\n".join(p.read_text() for p in found if p.name == "results.txt")
        with self._lock:  # the folder is complete: listed once, not at every poll
            self._result, self._files, self._file_list, self._results_text = result, files, names, text

    def gone(self) -> str | None:
        """Why the person no longer sees the page (its tab closed), or None (``vical.robot.Person.gone``)."""
        with self._lock:
            left, polling = self._left_at, bool(self._polling)
        if left is None or polling or time.monotonic() - left < RELOAD_GRACE_S:
            return None
        return "the guide's page was closed"

    def wait_closed(self, seconds: float) -> bool:
        """Serve until the page's Close button, its tab closed or ``seconds`` [s]; whether it was closed."""
        end = time.monotonic() + seconds
        while not self._closed.wait(min(0.2, max(0.0, end - time.monotonic()))):
            if self.gone() is not None:
                return True
            if time.monotonic() >= end:
                return False
        return True

    def close(self) -> None:
        """Stop serving (again: nothing)."""
        if self._thread.is_alive():
            self._server.shutdown()
            self._thread.join(timeout=5.0)
            self._server.server_close()

    # ------------------------------------------------------------------ drawing
    def _outline_at(self, T_board_body: np.ndarray) -> np.ndarray | None:
        """The board's four outer corners [px] seen from the body pose ``T_board_body`` (None: behind the camera)."""
        points = self.target.points
        lo, hi = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
        corners = np.array([[lo[0], lo[1], 0.0], [hi[0], lo[1], 0.0], [hi[0], hi[1], 0.0], [lo[0], hi[1], 0.0]])
        T_cam_board = invert_transform(T_board_body @ invert_transform(T_CAM_BODY))
        q = corners @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
        if np.any(q[:, 2] <= 1e-3):
            return None
        uv, ok = self.camera.project(q)
        return uv if np.all(ok) and np.all(np.isfinite(uv)) else None

    def _jpeg(self) -> bytes:
        with self._lock:
            frame, corners, outline = self._frame, self._corners.copy(), self._outline
        if frame is None:
            frame = np.full((self.camera.height, self.camera.width), BACKGROUND, np.uint8)
        image = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        for u, v in np.round(corners).astype(int):
            cv2.circle(image, (int(u), int(v)), 3, DETECTED, -1)
        if outline is not None:
            cv2.polylines(image, [np.round(outline).astype(np.int32)], True, OUTLINE, 3)
        _, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        return data.tobytes()

    def _state(self) -> dict:
        with self._lock:
            g = self._guidance
            return {
                "words": "" if g is None else g.words,
                "ratios": {} if g is None else {k: float(v) for k, v in g.ratios.items()},
                "elapsed_s": 0.0 if g is None else float(g.elapsed_s),
                "done": bool(g is not None and g.done),
                "stage": self._stage,
                "history": list(self._history),
                "frames": self._frames,
                "result": self._result,
                "results_text": self._results_text,
                "files": list(self._file_list),
            }

    # ------------------------------------------------------------------ serving
    @Request.application
    def _wsgi(self, request: Request) -> Response:
        path = request.path
        if path == "/":
            return Response(PAGE, mimetype="text/html")
        if path == "/state.json":
            load = request.args.get("page", "")
            with self._lock:
                if load not in self._left:
                    self._polling.add(load)
            return Response(json.dumps(self._state()), mimetype="application/json", headers=NO_CACHE)
        if path == "/frame.jpg":
            return Response(self._jpeg(), mimetype="image/jpeg", headers=NO_CACHE)
        if path == "/close" and request.method == "POST":
            self._closed.set()
            return Response("closed", mimetype="text/plain")
        if path == "/left" and request.method == "POST":
            load = request.args.get("page", "")
            with self._lock:
                self._polling.discard(load)
                self._left.add(load)
                self._left_at = time.monotonic()
            return Response("left", mimetype="text/plain")
        if path.startswith("/files/"):
            return self._file(path.removeprefix("/files/"))
        return NotFound()

    def _file(self, name: str) -> Response:
        with self._lock:
            root = self._files
        found = None if root is None else safe_join(str(root), name)
        if found is None or not Path(found).is_file() or Path(found).suffix not in FILE_SUFFIXES:
            return NotFound()
        mimetypes = {".png": "image/png", ".pdf": "application/pdf"}
        return Response(Path(found).read_bytes(), mimetype=mimetypes.get(Path(found).suffix, "text/plain"))


class _Quiet(WSGIRequestHandler):
    """Serves without a log line per request (the page polls ten times a second; the guide's lines would drown)."""

    def log_request(self, *args, **kwargs) -> None:
        pass


def _server(host: str, port: int, app) -> BaseWSGIServer:
    """werkzeug's threaded server of ``app`` on a socket bound here: a port in use raises ``OSError`` to the caller
    (werkzeug's own bind prints and exits)."""
    family = select_address_family(host, port)
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(64)
        return make_server(host, sock.getsockname()[1], app, threaded=True, fd=sock.fileno(),
                           request_handler=_Quiet)  # fmt: skip


NO_CACHE = {"Cache-Control": "no-store"}

PAGE = """<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>vical-guide</title>
<style>
body { font-family: sans-serif; margin: 1em; background: #fafafa; color: #222; }
#main { display: flex; gap: 1.5em; flex-wrap: wrap; }
#live { max-width: 100%; border: 1px solid #999; }
#words { font-size: 1.8em; font-weight: bold; margin: 0.3em 0; min-height: 1.3em; }
#words.done { color: #1a7f1a; }
.bar { width: 22em; height: 1.1em; background: #ddd; position: relative; margin: 0.2em 0 0.6em 0; }
.fill { height: 100%; background: #e08a00; }
.fill.ok { background: #2e9b2e; }
.tolerance { position: absolute; left: 25%; top: -2px; bottom: -2px; border-left: 2px solid #222; }
#history { color: #666; }
pre { background: #fff; border: 1px solid #ccc; padding: 0.5em; max-width: 60em; overflow: auto; }
</style></head>
<body>
<h1>vical-guide</h1>
<div id="words">starting</div>
<div>time <span id="elapsed">0.0</span> s &middot; <span id="stage"></span></div>
<div id="main">
  <div><img id="live" src="/frame.jpg" alt="the live image"></div>
  <div><h2>predicted error / tolerance</h2><div id="bars"></div>
       <h2>instructions</h2><ol id="history"></ol></div>
</div>
<div id="result" hidden><h2>result</h2><ul id="outcome"></ul><pre id="summary"></pre><div id="files"></div>
  <button id="close" type="button">Close</button></div>
<script>
const live = document.getElementById("live");
let frames = -1, loading = !live.complete;  // the first frame loads with the page
const newLoad = () => Date.now().toString(36) + Math.random().toString(36).slice(2);
let load = newLoad();  // this load's id (module doc); restored from the back-forward cache, it polls as a new one
live.onload = live.onerror = () => { loading = false; };
function bar(name, ratio) {
  const row = document.createElement("div");
  row.className = "group"; row.dataset.group = name;
  row.textContent = name + ": " + ratio.toFixed(2) + "x tolerance";
  const outer = document.createElement("div"); outer.className = "bar";
  const fill = document.createElement("div"); fill.className = ratio <= 1 ? "fill ok" : "fill";
  fill.style.width = Math.min(100, 25 * ratio) + "%";
  const mark = document.createElement("div"); mark.className = "tolerance";
  outer.append(fill, mark); row.append(outer); return row;
}
function files(names) {
  const box = document.getElementById("files"); box.replaceChildren();
  for (const name of names) {
    if (name.endsWith(".png")) {
      const img = document.createElement("img"); img.src = "/files/" + name; img.alt = name;
      img.style.maxWidth = "45em"; box.append(img);
    } else {
      const a = document.createElement("a"); a.href = "/files/" + name; a.textContent = name;
      box.append(a, document.createElement("br"));
    }
  }
}
async function poll() {
  try {
    const s = await (await fetch("/state.json?page=" + load, {cache: "no-store"})).json();
    const words = document.getElementById("words");
    words.textContent = s.words || s.stage; words.className = s.done ? "done" : "";
    document.getElementById("elapsed").textContent = s.elapsed_s.toFixed(1);
    document.getElementById("stage").textContent = s.stage;
    document.getElementById("bars").replaceChildren(
      ...Object.entries(s.ratios).map(([k, v]) => bar(k, v)));
    document.getElementById("history").replaceChildren(...s.history.map(h => {
      const li = document.createElement("li"); li.textContent = h; return li; }));
    if (s.frames !== frames && !loading) { frames = s.frames; loading = true; live.src = "/frame.jpg?n=" + frames; }
    if (s.result) {
      document.getElementById("result").hidden = false;
      document.getElementById("outcome").replaceChildren(...Object.entries(s.result).map(([k, v]) => {
        const li = document.createElement("li"); li.textContent = k + ": " + v; return li; }));
      document.getElementById("summary").textContent = s.results_text;
      if (document.getElementById("files").childElementCount !== s.files.length) files(s.files);
    }
  } catch (e) { document.getElementById("stage").textContent = "the guide has stopped serving"; return; }
  setTimeout(poll, __POLL_MS__);
}
addEventListener("pagehide", () => navigator.sendBeacon("/left?page=" + load));  // polls may follow it: same id
addEventListener("pageshow", e => { if (e.persisted) load = newLoad(); });
document.getElementById("close").onclick = async () => {
  await fetch("/close", {method: "POST"});
  document.getElementById("stage").textContent = "closed";
};
poll();
</script>
</body></html>
""".replace("__POLL_MS__", str(POLL_MS))

__all__ = ["GuidePage", "PageSettings"]
