"""Screenshots of a page in a headless Chromium (tests only), with software WebGL (SwiftShader), so
they run on a machine without a GPU or a display.

Chromium's own ``--screenshot`` flag takes its picture when a budget of the page's virtual time is
spent, and virtual time runs ahead while the page waits on its websocket: on a loaded machine the
picture came before viser had drawn every Gaussian. Here the page runs on the wall clock, driven
over Chromium's DevTools protocol (a websocket; ``websockets`` comes with viser), and the picture is
the first of two, taken a few seconds apart, that agree.
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_browser() -> str | None:
    """The path of a Chromium-family browser on PATH, or None."""
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


def url_in(line: str) -> str | None:
    """The first ``http://...`` address in ``line`` (up to a space or parenthesis), or None."""
    m = re.search(r"http://[^\s()]+", line)
    return m.group(0) if m else None


class Browser:
    """A headless Chromium showing one page ``width`` x ``height`` CSS px at device scale 1; a
    context manager that ends the browser it started."""

    def __init__(self, width: int, height: int, exe: str | None = None):
        self.width, self.height, self.exe = width, height, exe or find_browser()
        self.profile = tempfile.TemporaryDirectory(prefix="fusiongs-browser-")
        self.proc: subprocess.Popen | None = None
        self.ws = None
        self.last_id = 0

    def __enter__(self) -> Browser:
        import websockets.sync.client

        self.proc = subprocess.Popen(
            [self.exe, "--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--hide-scrollbars", "--force-device-scale-factor=1", "--no-first-run", "--mute-audio",
             f"--window-size={self.width},{self.height}", f"--user-data-dir={self.profile.name}",
             "--remote-debugging-port=0", "about:blank"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = Path(self.profile.name) / "DevToolsActivePort"  # Chromium writes its port here
        deadline = time.monotonic() + 60
        pages: list[dict] = []
        while not pages:
            if time.monotonic() > deadline or self.proc.poll() is not None:
                raise RuntimeError(f"{self.exe} did not open its DevTools port")
            time.sleep(0.2)
            if port_file.is_file() and port_file.read_text().strip():
                port = int(port_file.read_text().split()[0])
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
                    pages = [t for t in json.load(r) if t.get("type") == "page"]
        self.ws = websockets.sync.client.connect(pages[0]["webSocketDebuggerUrl"], max_size=None,
                                                 open_timeout=30)
        self.call("Emulation.setDeviceMetricsOverride", width=self.width, height=self.height,
                  deviceScaleFactor=1, mobile=False)
        return self

    def call(self, method: str, **params) -> dict:
        """One DevTools command and its result (the events that arrive meanwhile are dropped)."""
        self.last_id += 1
        self.ws.send(json.dumps({"id": self.last_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=120))
            if msg.get("id") == self.last_id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg.get("result", {})

    def screenshot(self) -> np.ndarray:
        """The page as it is now: ``[H, W, 3]`` float64 sRGB in [0, 1]."""
        import cv2

        data = base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)[..., ::-1] / 255.0

    def settled(self, url: str, wait: float = 4.0, every: float = 3.0, timeout: float = 120.0,
                tol: float = 0.5 / 255) -> np.ndarray:
        """Open ``url`` and return its screenshot once two taken ``every`` s apart differ by less than
        ``tol`` on average (the first after ``wait`` s); the last one at ``timeout`` s."""
        self.call("Page.navigate", url=url)
        time.sleep(wait)
        last, deadline = self.screenshot(), time.monotonic() + timeout
        while time.monotonic() < deadline:
            time.sleep(every)
            now = self.screenshot()
            if np.abs(now - last).mean() < tol:
                return now
            last = now
        return last

    def __exit__(self, *exc) -> None:
        if self.ws is not None:
            self.ws.close()
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.profile.cleanup()


def screenshot(url: str, width: int, height: int, exe: str | None = None) -> np.ndarray:
    """The page at ``url`` in a ``width`` x ``height`` window once it has settled
    (:meth:`Browser.settled`): ``[H, W, 3]`` float64 sRGB in [0, 1]."""
    with Browser(width, height, exe) as browser:
        return browser.settled(url)
