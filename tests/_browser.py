"""A headless Chromium driven through the DevTools protocol over a pipe (no downloads, no ports).

Chromium from the system (Debian's ``chromium`` package) is started with
``--remote-debugging-pipe``: it reads JSON commands from file descriptor 3 and writes replies and
events to descriptor 4, each message ending with a NUL byte. Every wait is bounded.

>>> with Browser(800, 600) as b:                       # doctest: +SKIP
...     b.open("file:///tmp/page.html#t=1")
...     png = b.screenshot()                           # (600, 800, 3) uint8
"""

from __future__ import annotations

import base64
import fcntl
import io
import json
import os
import queue
import shutil
import subprocess
import tempfile
import threading
import time

import numpy as np

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "chrome")


def find_chromium() -> str | None:
    """Path of a Chromium on PATH (or ``SE3DYN_CHROMIUM``), None when there is none."""
    env = os.environ.get("SE3DYN_CHROMIUM")
    if env:
        return env if shutil.which(env) else None
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


class BrowserError(RuntimeError):
    pass


class Browser:
    """One headless Chromium with one page (viewport ``width`` x ``height`` CSS pixels)."""

    def __init__(self, width: int = 1000, height: int = 700, timeout: float = 60.0):
        exe = find_chromium()
        if exe is None:
            raise BrowserError("no chromium on PATH")
        self.width, self.height, self.timeout = width, height, timeout
        self.profile = tempfile.mkdtemp(prefix="se3dyn-chromium-")
        r, self._cmd_w = os.pipe()
        self._out_r, w = os.pipe()
        # the child's ends on descriptors >= 20, so that they are neither 3 nor 4
        cmd_r, out_w = fcntl.fcntl(r, fcntl.F_DUPFD, 20), fcntl.fcntl(w, fcntl.F_DUPFD, 20)
        os.close(r)
        os.close(w)
        args = ["--headless", "--no-sandbox", "--remote-debugging-pipe",
                "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
                "--disable-gpu-sandbox", "--no-first-run", "--no-default-browser-check",
                "--disable-extensions", "--disable-background-networking", "--mute-audio",
                "--hide-scrollbars", "--force-device-scale-factor=1",
                f"--user-data-dir={self.profile}", f"--window-size={width},{height}",
                "about:blank"]
        # bash puts the pipe ends on descriptors 3 (commands in) and 4 (replies out) and becomes
        # Chromium (no preexec_fn: safe beside the reader threads of other browsers; dash, the
        # usual /bin/sh, cannot redirect descriptors above 9)
        shell = f'exec "$0" "$@" 3<&{cmd_r} 4>&{out_w} {cmd_r}<&- {out_w}>&-'
        self.proc = subprocess.Popen([shutil.which("bash") or "/bin/bash", "-c", shell, exe,
                                      *args],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, pass_fds=(cmd_r, out_w))
        os.close(cmd_r)
        os.close(out_w)
        self._id = 0
        self._replies: dict[int, dict] = {}
        self._cv = threading.Condition()
        self.events: queue.Queue = queue.Queue()
        self.log: list[dict] = []
        self.requests: list[str] = []  # URLs the page asked for (Network.requestWillBeSent)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        try:
            targets = self.call("Target.getTargets")["targetInfos"]
            page = next(t for t in targets if t["type"] == "page")
            self.session = self.call("Target.attachToTarget", targetId=page["targetId"],
                                     flatten=True)["sessionId"]
            for domain in ("Page", "Runtime", "Log", "Network"):
                self.call(f"{domain}.enable", session=True)
            self.call("Emulation.setDeviceMetricsOverride", session=True, width=width,
                      height=height, deviceScaleFactor=1, mobile=False)
        except BaseException:
            self.close()
            raise

    # -----------------------------------------------------------------------------------------
    def _read(self) -> None:
        buf = b""
        while True:
            try:
                chunk = os.read(self._out_r, 1 << 20)
            except OSError:
                chunk = b""
            if not chunk:
                with self._cv:
                    self._replies[-1] = {"error": {"message": "browser closed the pipe"}}
                    self._cv.notify_all()
                return
            buf += chunk
            while b"\0" in buf:
                raw, buf = buf.split(b"\0", 1)
                msg = json.loads(raw)
                if "id" in msg:
                    with self._cv:
                        self._replies[msg["id"]] = msg
                        self._cv.notify_all()
                else:
                    self._event(msg)

    def _event(self, msg: dict) -> None:
        m, p = msg.get("method", ""), msg.get("params", {})
        if m == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            self.log.append({"level": "error", "text": str(
                d.get("exception", {}).get("description") or d.get("text"))})
        elif m == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", "")))
                            for a in p.get("args", []))
            self.log.append({"level": p.get("type", "log"), "text": text})
        elif m == "Network.requestWillBeSent":
            self.requests.append(p.get("request", {}).get("url", ""))
        elif m == "Log.entryAdded":
            e = p.get("entry", {})
            self.log.append({"level": e.get("level", "info"), "text": e.get("text", ""),
                             "source": e.get("source", "")})
        self.events.put(msg)

    def call(self, method: str, session: bool = False, timeout: float | None = None,
             **params) -> dict:
        """Send one DevTools command and wait (bounded) for its reply."""
        self._id += 1
        msg: dict = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = self.session
        os.write(self._cmd_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + (timeout or self.timeout)
        with self._cv:
            while self._id not in self._replies:
                if -1 in self._replies:
                    raise BrowserError(self._replies[-1]["error"]["message"])
                left = deadline - time.monotonic()
                if left <= 0:
                    raise BrowserError(f"no reply to {method} within {timeout or self.timeout} s")
                self._cv.wait(left)
            reply = self._replies.pop(self._id)
        if "error" in reply:
            raise BrowserError(f"{method}: {reply['error'].get('message')}")
        return reply.get("result", {})

    # -----------------------------------------------------------------------------------------
    def evaluate(self, expression: str, timeout: float | None = None):
        """The value of a JavaScript expression in the page (promises awaited)."""
        r = self.call("Runtime.evaluate", session=True, timeout=timeout, expression=expression,
                      returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            d = r["exceptionDetails"]
            raise BrowserError(f"{expression!r}: " + str(
                d.get("exception", {}).get("description") or d.get("text")))
        return r.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float = 60.0, poll: float = 0.05):
        """Poll until the expression is truthy; return its value (bounded wait)."""
        deadline = time.monotonic() + timeout
        while True:
            v = self.evaluate(expression)
            if v:
                return v
            if time.monotonic() > deadline:
                raise BrowserError(f"{expression!r} still false after {timeout} s; page log: "
                                   f"{self.log[-5:]}")
            time.sleep(poll)

    def open(self, url: str, ready: str = "document.documentElement.dataset.ready === '1'",
             timeout: float = 90.0) -> None:
        """Load ``url`` afresh (through about:blank, so a new hash reloads) and wait until
        ``ready`` holds and two more frames are drawn."""
        self.call("Page.navigate", session=True, url="about:blank")
        self.wait_for("document.readyState === 'complete' && location.href === 'about:blank'",
                      timeout=30)
        self.call("Page.navigate", session=True, url=url)
        self.wait_for(f"document.readyState === 'complete' && ({ready})", timeout=timeout)
        self.frames()

    def frames(self, count: int = 2) -> None:
        """Wait for ``count`` animation frames (the page has drawn its last change)."""
        self.evaluate(f"new Promise(r => {{ let k = {int(count)}; const f = () => --k > 0 ? "
                      "requestAnimationFrame(f) : r(true); requestAnimationFrame(f); })")

    def screenshot(self) -> np.ndarray:
        """The viewport as an RGB array, shape (height, width, 3), uint8."""
        from PIL import Image

        r = self.call("Page.captureScreenshot", session=True, format="png")
        img = Image.open(io.BytesIO(base64.b64decode(r["data"]))).convert("RGB")
        return np.asarray(img)

    def click(self, x: float, y: float) -> None:
        """A left click at viewport coordinates (CSS pixels)."""
        for kind in ("mouseMoved", "mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", session=True, type=kind, x=x, y=y,
                      button="left" if kind != "mouseMoved" else "none",
                      clickCount=0 if kind == "mouseMoved" else 1)

    def errors(self) -> list[dict]:
        """Console errors, uncaught exceptions and error log entries so far."""
        return [e for e in self.log if e["level"] in ("error", "assert")]

    def close(self) -> None:
        try:
            if self.proc.poll() is None:
                try:
                    self.call("Browser.close", timeout=5)
                except BrowserError:
                    pass
                try:
                    self.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=10)
        finally:
            for fd in (self._cmd_w, self._out_r):
                try:
                    os.close(fd)
                except OSError:
                    pass
            shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
