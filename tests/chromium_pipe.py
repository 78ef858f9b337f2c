"""One headless Chromium for many pages, driven over the DevTools protocol on a pipe (stdlib only).

``chromium --remote-debugging-pipe`` reads commands on its fd 3 and writes answers and events on its fd 4, each
message one JSON object ended by a NUL byte.  :class:`Browser` starts it once (in its own process group, with a
throw-away profile) and :meth:`Browser.load` opens a page as the command line's ``--dump-dom``,
``--print-to-pdf`` and ``--screenshot`` do (Chromium's own headless command handler, ``headless_command.js``): a
new target of the window size asked (``--window-size``), navigate, wait for the frame's ``load`` lifecycle event,
then the virtual-time budget (``--virtual-time-budget``, policy ``pauseIfNetworkFetchesPending``); the
:class:`Page` then dumps the DOM (doctype + ``outerHTML``), prints a PDF (``printBackground`` and
``preferCSSPageSize``, tagged, no header or footer as ``--no-pdf-header-footer``) or takes a PNG screenshot.

Each start costs about a second of CPU and three to five of wall time on a 2-core machine; a test module starts
one.  Every wait is bounded (:class:`TimeoutError`, never a hang), and :meth:`Browser.close` kills the whole
process group (the fixtures call it at tear-down, also after a failure).
"""

from __future__ import annotations

import base64
import fcntl
import json
import os
import select
import signal
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync", "--hide-scrollbars")
"""The flags the one-page-per-start way (``testdata.run_chromium`` until the pipe) gave."""
VIRTUAL_TIME_BUDGET_MS = 10_000
WINDOW_BARS_PX = 143
"""The height a ``--window-size`` window lost to the page the one-page-per-start way (headless Chromium 150 run
as root: its emulated toolbar, 87 px, and the ``--no-sandbox`` warning bar, 56 px): a 1000 × 800 window showed a
1000 × 657 page (``innerHeight``).  On a pipe no warning bar shows."""


def window_viewport(width: int, height: int) -> tuple[int, int]:
    """The page's (width, height) [CSS px] that ``--window-size=width,height`` gave: the same checks, same numbers."""
    return width, height - WINDOW_BARS_PX


class Browser:
    """A headless Chromium on a DevTools pipe; ``timeout_s`` bounds each command and each wait."""

    def __init__(self, executable: str, profile: Path, *, timeout_s: float = 120) -> None:
        self.timeout_s = timeout_s
        self.log = profile.with_name(profile.name + ".log")
        to_chrome, self._to_chrome = os.pipe()
        self._from_chrome, from_chrome = os.pipe()

        def fds_3_and_4() -> None:  # in the child, before exec: its fd 3 reads our commands, fd 4 writes answers
            read, write = (fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in (to_chrome, from_chrome))
            os.dup2(read, 3)
            os.dup2(write, 4)

        with self.log.open("wb") as log:
            self._proc = subprocess.Popen(  # noqa: S603 - a fixed command of the test's own chromium
                [executable, *FLAGS, f"--user-data-dir={profile}", "--remote-debugging-pipe", "about:blank"],
                stdin=subprocess.DEVNULL, stdout=log, stderr=log, pass_fds=(3, 4), preexec_fn=fds_3_and_4,  # noqa: PLW1509
                start_new_session=True)
        os.close(to_chrome)
        os.close(from_chrome)
        self._buffer = b""
        self._events: list[dict[str, Any]] = []
        self._next_id = 0

    def close(self) -> None:
        """Close Chromium (``Browser.close``, so that it reaps its own processes and their CPU counts as the
        test's, as a command line start's does), then kill whatever is left of its process group (idempotent)."""
        if self._proc.poll() is None and self._to_chrome >= 0:
            try:
                self.timeout_s = min(self.timeout_s, 30)
                self.send("Browser.close")
            except (OSError, RuntimeError, TimeoutError):
                pass
            try:
                self._proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                pass
        try:
            os.killpg(self._proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            self._proc.wait(timeout=30)
        finally:
            for fd in (self._to_chrome, self._from_chrome):
                if fd >= 0:
                    os.close(fd)
            self._to_chrome = self._from_chrome = -1

    def stderr(self) -> str:
        """The end of Chromium's own output, for an assertion's message."""
        return self.log.read_text(errors="replace")[-2000:] if self.log.exists() else ""

    def send(self, method: str, params: dict[str, Any] | None = None, session: str | None = None) -> dict[str, Any]:
        """Send a command and wait for its answer (its ``result``); an ``error`` answer raises RuntimeError."""
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session is not None:
            message["sessionId"] = session
        data = json.dumps(message).encode() + b"\0"
        while data:
            data = data[os.write(self._to_chrome, data):]
        answer = self._wait(lambda m: m.get("id") == self._next_id, method)
        if "error" in answer:
            raise RuntimeError(f"{method}: {answer['error']}")
        return answer.get("result", {})

    def wait_event(self, method: str, session: str, match: dict[str, Any] | None = None) -> dict[str, Any]:
        """The first event ``method`` of ``session`` whose params hold ``match`` (events already read count)."""
        def wanted(m: dict[str, Any]) -> bool:
            params = m.get("params", {})
            return (m.get("method") == method and m.get("sessionId") == session
                    and all(params.get(k) == v for k, v in (match or {}).items()))
        for i, event in enumerate(self._events):
            if wanted(event):
                return self._events.pop(i)
        return self._wait(wanted, method)

    def _wait(self, wanted: Any, what: str) -> dict[str, Any]:
        deadline = time.monotonic() + self.timeout_s
        while True:
            while b"\0" in self._buffer:
                raw, self._buffer = self._buffer.split(b"\0", 1)
                message = json.loads(raw)
                if wanted(message):
                    return message
                if "method" in message:
                    self._events.append(message)
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"chromium gave no {what} within {self.timeout_s} s\n{self.stderr()}")
            if select.select([self._from_chrome], [], [], left)[0]:
                chunk = os.read(self._from_chrome, 1 << 20)
                if not chunk:
                    raise RuntimeError(f"chromium closed its DevTools pipe (exit {self._proc.poll()})\n"
                                       f"{self.stderr()}")
                self._buffer += chunk

    @contextmanager
    def load(self, url: str, viewport: tuple[int, int] | None = None) -> Iterator[Page]:
        """A new page showing ``url`` loaded as the command line loads it, closed after; ``viewport``: its
        (width, height) [CSS px] (``Emulation.setDeviceMetricsOverride``, scale 1, not mobile), else the
        window's."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        try:
            session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
            if viewport is not None:
                self.send("Emulation.setDeviceMetricsOverride", {"width": viewport[0], "height": viewport[1],
                                                                 "deviceScaleFactor": 1, "mobile": False},
                          session=session)
            self.send("Page.enable", session=session)
            self.send("Page.setLifecycleEventsEnabled", {"enabled": True}, session=session)
            loader = self.send("Page.navigate", {"url": url}, session=session)["loaderId"]
            self.wait_event("Page.lifecycleEvent", session, {"name": "load", "loaderId": loader})
            self.send("Emulation.setVirtualTimePolicy", {"budget": VIRTUAL_TIME_BUDGET_MS,
                                                         "maxVirtualTimeTaskStarvationCount": 9999,
                                                         "policy": "pauseIfNetworkFetchesPending"}, session=session)
            self.wait_event("Emulation.virtualTimeBudgetExpired", session)
            yield Page(self, session)
        finally:
            if self._proc.poll() is None:
                self.send("Target.closeTarget", {"targetId": target})
            self._events.clear()


class Page:
    """A loaded page of a :class:`Browser`, read as ``--dump-dom``, ``--print-to-pdf``, ``--screenshot`` do."""

    def __init__(self, browser: Browser, session: str) -> None:
        self.browser, self.session = browser, session

    def dom(self) -> str:
        """The serialized DOM: doctype (if any), a newline, ``document.documentElement.outerHTML``."""
        script = ("(document.doctype ? new XMLSerializer().serializeToString(document.doctype) + '\\n' : '')"
                  " + document.documentElement.outerHTML")
        return str(self.browser.send("Runtime.evaluate", {"expression": script, "returnByValue": True},
                                     session=self.session)["result"]["value"])

    def print_pdf(self, path: Path) -> None:
        """Write the page printed to PDF to ``path``, as ``--print-to-pdf --no-pdf-header-footer``."""
        params = {"displayHeaderFooter": False, "generateTaggedPDF": True, "printBackground": True,
                  "preferCSSPageSize": True}
        data = self.browser.send("Page.printToPDF", params, session=self.session)["data"]
        path.write_bytes(base64.b64decode(data))

    def screenshot(self, path: Path) -> None:
        """Write a PNG of the window to ``path``, as ``--screenshot``."""
        data = self.browser.send("Page.captureScreenshot", {"format": "png"}, session=self.session)["data"]
        path.write_bytes(base64.b64decode(data))
