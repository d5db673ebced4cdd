"""A headless Chromium driven through the DevTools protocol over a pipe
(``--remote-debugging-pipe``: JSON messages, each ended by a NUL byte, on file descriptors 3
and 4 of the browser), enough to load a page and evaluate JavaScript in it (no third-party
package: the standard library's ``subprocess`` and ``json``); and the viewer run in it: the
page opened from ``file://`` as a user opens it, its errors, and the shader's float framebuffer
read back.

The browser is Debian's ``chromium-headless-shell`` (``scripts/setup.sh`` installs it). The flags
``--use-angle=swiftshader --enable-unsafe-swiftshader`` give WebGL 2 on the CPU (SwiftShader),
with float textures, float render targets and exact read-back, on a machine without a GPU.
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

BROWSERS = ("chromium-headless-shell", "chromium", "google-chrome")
# WebGL 2 on SwiftShader (software): no GPU needed, the same results on every machine
SOFTWARE_GL = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")
# a page opened from file:// may import ES modules and read files beside it (the three.js page)
FILE_ACCESS = ("--allow-file-access-from-files",)


class BrowserError(RuntimeError):
    """The browser could not be found or started, a command failed, or a page threw."""


def find_browser() -> str | None:
    """Path of the first of ``BROWSERS`` on ``PATH`` (``$STUDY_CHROMIUM`` first when set), or
    None."""
    env = os.environ.get("STUDY_CHROMIUM")
    if env:
        return env if Path(env).is_file() else shutil.which(env)
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


class Chromium:
    """One headless Chromium process and one page (a tab) in it.

    ``with Chromium() as b: b.open(url); b.evaluate("1 + 1")``. ``timeout`` (seconds) bounds
    every command; a command that takes longer raises BrowserError (never a hang).
    """

    def __init__(self, executable: str | None = None, flags=SOFTWARE_GL, timeout: float = 120.0):
        exe = executable or find_browser()
        if exe is None:
            raise BrowserError(
                "no Chromium found (looked for " + ", ".join(BROWSERS) + "); install it with "
                "`apt-get install chromium-headless-shell` (scripts/setup.sh does) or set "
                "$STUDY_CHROMIUM to its path"
            )
        self.timeout = timeout
        self._profile = tempfile.mkdtemp(prefix="study_chromium_")
        to_browser_r, self._w = os.pipe()
        self._r, from_browser_w = os.pipe()

        # the browser reads commands on fd 3 and writes replies on fd 4: a shell moves the pipes
        # there (bash: dash takes no fd number over 9; no preexec_fn: no fork of this possibly
        # multithreaded process)
        # (both ends first moved to 10 and above, clear of 3 and 4)
        r, w = (fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_browser_r, from_browser_w))
        for fd in (to_browser_r, from_browser_w):
            os.close(fd)
        move = f'exec 3<&{r} 4>&{w} {r}<&- {w}>&- "$@"'
        args = [
            "/bin/bash",
            "-c",
            move,
            "sh",
            exe,
            "--headless",
            "--remote-debugging-pipe",
            f"--user-data-dir={self._profile}",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-timer-throttling",
            "--disable-renderer-backgrounding",
            "--no-sandbox",
            *flags,
            "about:blank",
        ]
        try:
            self.proc = subprocess.Popen(
                args,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                pass_fds=(r, w),
            )
        except OSError as exc:
            raise BrowserError(f"could not start {exe}: {exc}") from exc
        finally:
            os.close(r)
            os.close(w)
        self._next_id, self._buf, self.session = 0, b"", None
        self.events: list[dict] = []

    # -- the protocol -----------------------------------------------------------------------
    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        """Send one command and wait for its reply; returns its ``result``."""
        self._next_id += 1
        msg = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        data = json.dumps(msg).encode() + b"\0"
        try:
            while data:
                data = data[os.write(self._w, data) :]
        except OSError as exc:
            raise BrowserError(f"the browser closed its pipe ({exc}){self._stderr()}") from exc
        deadline = time.monotonic() + self.timeout
        while True:
            reply = self._receive(deadline, method)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})
            self.events.append(reply)

    def _receive(self, deadline: float, method: str) -> dict:
        while b"\0" not in self._buf:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BrowserError(f"{method}: no reply from the browser in {self.timeout:.0f} s")
            ready, _, _ = select.select([self._r], [], [], min(left, 1.0))
            if not ready:
                if self.proc.poll() is not None:
                    raise BrowserError(
                        f"the browser exited ({self.proc.returncode}){self._stderr()}"
                    )
                continue
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise BrowserError(f"the browser closed its pipe{self._stderr()}")
            self._buf += chunk
        msg, _, self._buf = self._buf.partition(b"\0")
        return json.loads(msg)

    def _stderr(self) -> str:
        if self.proc.poll() is None or self.proc.stderr is None:
            return ""
        tail = self.proc.stderr.read().decode(errors="replace").strip().splitlines()[-5:]
        return (": " + " | ".join(tail)) if tail else ""

    # -- a page -----------------------------------------------------------------------------
    def open(self, url: str, width: int = 800, height: int = 600) -> None:
        """Open ``url`` in a new tab of ``width`` x ``height`` CSS pixels and wait for its load
        event."""
        target = self.send(
            "Target.createTarget", {"url": "about:blank", "width": width, "height": height}
        )["targetId"]
        self.session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        self.send("Page.enable", session=self.session)
        self.send("Page.navigate", {"url": url}, session=self.session)
        deadline = time.monotonic() + self.timeout
        while not any(
            e.get("method") == "Page.loadEventFired" and e.get("sessionId") == self.session
            for e in self.events
        ):
            self.events.append(self._receive(deadline, f"loading {url}"))

    def evaluate(self, expression: str):
        """The value of a JavaScript ``expression`` in the page (a promise is awaited); a
        thrown exception raises BrowserError with its message."""
        res = self.send(
            "Runtime.evaluate",
            {"expression": expression, "awaitPromise": True, "returnByValue": True},
            session=self.session,
        )
        if "exceptionDetails" in res:
            d = res["exceptionDetails"]
            text = d.get("exception", {}).get("description") or d.get("text")
            raise BrowserError(f"the page threw: {text}")
        return res["result"].get("value")

    def close(self) -> None:
        """End the browser (idempotent) and remove its profile folder."""
        if getattr(self, "proc", None) is not None and self.proc.poll() is None:
            try:
                self.send("Browser.close")
            except BrowserError:
                pass
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for fd in ("_w", "_r"):
            if getattr(self, fd, None) is not None:
                try:
                    os.close(getattr(self, fd))
                except OSError:
                    pass
                setattr(self, fd, None)
        if getattr(self, "proc", None) is not None and self.proc.stderr is not None:
            self.proc.stderr.close()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> "Chromium":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_viewer(browser: Chromium, index_html: Path, *, expect_errors: bool = False) -> list[str]:
    """Open ``index_html`` from the file system (``file://``) and wait until the page has set
    itself up. Returns the errors the page reports (``waterViewer.errors``, shown in its text);
    BrowserError when it reports any and ``expect_errors`` is False."""
    browser.open(Path(index_html).resolve().as_uri())
    state = browser.evaluate(
        "JSON.stringify(window.waterViewer ? {ready: waterViewer.ready, errors: "
        "waterViewer.errors} : {ready: false, errors: ['viewer.js did not run']})"
    )
    state = json.loads(state)
    if state["errors"] and not expect_errors:
        raise BrowserError("the viewer reports: " + " | ".join(state["errors"]))
    return state["errors"]


def open_three_example(browser: Chromium, example_html: Path, *, expect_errors=False) -> list:
    """Open a calibration's ``threejs/example.html`` from the file system, still (no animation
    loop), in a browser started with ``FILE_ACCESS``, and wait until it has loaded its textures
    and built its inputs. Returns the errors the page reports (``waterThree.errors``);
    BrowserError when it reports any and ``expect_errors`` is False."""
    browser.open(Path(example_html).resolve().as_uri() + "?still")
    state = json.loads(browser.evaluate(
        "window.waterThree ? waterThree.loaded.then((s) => JSON.stringify(s)) : "
        "JSON.stringify({ready: false, errors: ['the page did not run']})"
    ))  # fmt: skip
    if state["errors"] and not expect_errors:
        raise BrowserError("the three.js page reports: " + " | ".join(state["errors"]))
    return state["errors"]


def render_float(browser: Chromium, api: str = "waterViewer", **opts) -> tuple:
    """One frame of the opened page's shader (``<api>.renderFloat(opts)``; the viewer's
    ``waterViewer``: ``time`` seconds, ``constants`` 'fitted' | 'default', ``yaw`` / ``pitch``
    degrees, ``distance`` factor; the three.js page's ``waterThree``: ``time``, ``constants``,
    ``inputs`` 'scene' | 'study'; none: the study's camera at time 0): (rgba (H, W, 4) float32
    as the shader wrote it, mask (H, W) bool, the water's coverage), row 0 at the top as the
    port's images."""
    r = browser.evaluate(f"{api}.renderFloat({json.dumps(opts)})")
    w, h = r["width"], r["height"]
    rgba = np.frombuffer(base64.b64decode(r["rgba"]), "<f4").reshape(h, w, 4)[::-1].copy()
    mask = np.frombuffer(base64.b64decode(r["mask"]), "<f4").reshape(h, w, 4)[::-1, :, 0] > 0.5
    return rgba, mask


class BrowserRenderer:
    """The renderer ``shaders_port.gl.compare.compare_port_gl`` takes, drawing with the page
    open in ``browser`` (the viewer, or ``api="waterThree"``: the three.js page, ``opts`` its
    ``inputs``) with its own constants (``which`` 'fitted' or 'default'; the constants passed
    to ``render`` are those the port renders with)."""

    def __init__(self, browser: Chromium, which: str = "fitted", time: float = 0.0,
                 api: str = "waterViewer", **opts):  # fmt: skip
        self.browser, self.which, self.time, self.api, self.opts = browser, which, time, api, opts

    def render(self, constants=None):
        return render_float(self.browser, self.api, constants=self.which, time=self.time,
                            **self.opts)  # fmt: skip
