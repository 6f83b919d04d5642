"""Screenshots of the scenarios' recordings as a user opens them in rerun's web viewer.

    make screenshots          # every recording under results/ (run the scenarios first)
    .venv/bin/python docs/screenshots.py results/undeclared_effect/undeclared_effect.rrd \
        --out docs/img --wait 40 [--size 1600x1000]

For each recording: ``<name>_1.png``, the face it opens on, and ``<name>_2.png``, the same
recording with the time cursor moved to a later pose (the ``#when=<timeline>@<index>`` address
the viewer understands, as a user scrubbing the pose timeline gets it). A recording without a
timeline has one face. Needs Chromium (Debian: ``apt-get install chromium``); the viewer is the
one rerun-sdk ships, served on 127.0.0.1, drawn with WebGL on Chromium's software renderer.
Chromium is driven through its DevTools protocol on a loopback port (a small WebSocket client
here: no other package). Every process started is stopped by its id at the end.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import json
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# the collapsed time panel's bar, where the second face is clicked: at this share of the
# window's width (about a third of the way along the bar), this far from the window's bottom
TIME_BAR_AT, TIME_BAR_FROM_BOTTOM = 0.5, 14


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class DevTools:
    """A WebSocket client (RFC 6455, text frames) for Chromium's DevTools protocol."""

    def __init__(self, url: str, timeout: float = 120.0) -> None:
        u = urllib.parse.urlparse(url)
        self.sock = socket.create_connection((u.hostname, u.port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall(
            (
                f"GET {u.path} HTTP/1.1\r\nHost: {u.hostname}:{u.port}\r\n"
                "Upgrade: websocket\r\nConnection: Upgrade\r\n"
                f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
            ).encode()
        )
        buf = b""
        while b"\r\n\r\n" not in buf:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("DevTools closed the connection during the handshake")
            buf += chunk
        head, self.buffer = buf.split(b"\r\n\r\n", 1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise ConnectionError(f"DevTools refused the WebSocket: {head[:200]!r}")
        self.n = 0

    def _exact(self, n: int) -> bytes:
        while len(self.buffer) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise ConnectionError("DevTools closed the connection")
            self.buffer += chunk
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        n = len(data)
        if n < 126:
            head = struct.pack("!BB", 0x80 | opcode, 0x80 | n)
        elif n < 1 << 16:
            head = struct.pack("!BBH", 0x80 | opcode, 0x80 | 126, n)
        else:
            head = struct.pack("!BBQ", 0x80 | opcode, 0x80 | 127, n)
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        self.sock.sendall(head + mask + masked)

    def _message(self) -> str:
        parts = []
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                (n,) = struct.unpack("!H", self._exact(2))
            elif n == 127:
                (n,) = struct.unpack("!Q", self._exact(8))
            mask = self._exact(4) if b1 & 0x80 else b""
            data = self._exact(n)
            if mask:
                data = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
            opcode = b0 & 0x0F
            if opcode == 8:
                raise ConnectionError("DevTools closed the connection")
            if opcode == 9:  # ping
                self._send(10, data)
                continue
            if opcode in (0, 1, 2):
                parts.append(data)
                if b0 & 0x80:
                    return b"".join(parts).decode()

    def call(self, method: str, **params: object) -> dict:
        self.n += 1
        self._send(1, json.dumps({"id": self.n, "method": method, "params": params}).encode())
        while True:
            m = json.loads(self._message())
            if m.get("id") == self.n:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


def _wait_for(url: str, seconds: float = 30.0) -> None:
    end = time.monotonic() + seconds
    while True:
        try:
            urllib.request.urlopen(url, timeout=1).close()
            return
        except OSError:
            if time.monotonic() > end:
                raise TimeoutError(f"nothing answered at {url} in {seconds:.0f} s") from None
            time.sleep(0.2)


@contextlib.contextmanager
def _started(args: list[str], log: Path) -> Iterator[subprocess.Popen]:
    with open(log, "wb") as out:
        proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT)
    try:
        yield proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def rerun_binary() -> str:
    import rerun_cli

    return str(Path(rerun_cli.__file__).parent / "rerun")


def timeline_of(rrd: Path) -> tuple[str | None, list[int]]:
    """The recording's timeline and its time points (None: a recording without one)."""
    import rerun.chunk as rc

    times: dict[str, set[int]] = {}
    for chunk in rc.RrdReader(str(rrd)).store().stream():
        batch = chunk.to_record_batch()
        for field in batch.schema:
            if (field.metadata or {}).get(b"rerun:kind", b"").decode() == "index":
                times.setdefault(field.name, set()).update(batch.column(field.name).to_pylist())
    if not times:
        return None, []
    name = max(times, key=lambda t: len(times[t]))
    return name, sorted(times[name])


def screenshots(rrd: Path, out_dir: Path, wait: float, size: str) -> list[Path]:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        sys.exit("chromium not found: apt-get install chromium (Debian)")
    width, height = (int(v) for v in size.split("x"))
    timeline, points = timeline_of(rrd)
    faces: list[tuple[str, float | None]] = [("1", None)]
    if timeline is not None and len(points) > 1:
        faces.append(("2", TIME_BAR_AT))
    web, grpc, cdp = free_port(), free_port(), free_port()
    written = []
    with tempfile.TemporaryDirectory() as tmp:
        serve = [rerun_binary(), "--serve-web", str(rrd), "--bind", "127.0.0.1"]
        serve += ["--web-viewer-port", str(web), "--port", str(grpc)]
        browser = [
            chromium,
            "--headless=new",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            f"--window-size={width},{height}",
            f"--remote-debugging-port={cdp}",
            "--remote-debugging-address=127.0.0.1",
            f"--user-data-dir={tmp}/profile",
            "about:blank",
        ]
        with (
            _started(serve, Path(tmp) / "rerun.log"),
            _started(browser, Path(tmp) / "chromium.log"),
        ):
            _wait_for(f"http://127.0.0.1:{cdp}/json/version")
            _wait_for(f"http://127.0.0.1:{web}/")
            source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
            for suffix, scrub in faces:
                request = urllib.request.Request(
                    f"http://127.0.0.1:{cdp}/json/new?about:blank", method="PUT"
                )
                target = json.loads(urllib.request.urlopen(request).read())
                tools = DevTools(target["webSocketDebuggerUrl"])
                try:
                    tools.call(
                        "Emulation.setDeviceMetricsOverride",
                        width=width,
                        height=height,
                        deviceScaleFactor=1,
                        mobile=False,
                    )
                    url = f"http://127.0.0.1:{web}/?url={source}&renderer=webgl"
                    tools.call("Page.navigate", url=url)
                    time.sleep(wait)
                    if scrub is not None:  # a click on the time bar, as a user scrubs
                        x, y = scrub * width, height - TIME_BAR_FROM_BOTTOM
                        for kind in ("mousePressed", "mouseReleased"):
                            tools.call(
                                "Input.dispatchMouseEvent",
                                type=kind,
                                x=x,
                                y=y,
                                button="left",
                                clickCount=1,
                            )
                        time.sleep(max(10.0, wait / 2))  # the views follow the cursor
                    shot = tools.call("Page.captureScreenshot", format="png")
                finally:
                    tools.close()
                path = out_dir / f"{rrd.stem}_{suffix}.png"
                path.write_bytes(base64.b64decode(shot["data"]))
                written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recordings", nargs="*", type=Path, help="default: results/*/*.rrd")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    ap.add_argument("--wait", type=float, default=40.0, help="seconds for the viewer to draw")
    ap.add_argument("--size", default="1600x1000")
    args = ap.parse_args(argv)
    # stopped (SIGTERM): leave through the context managers, which stop Chromium and rerun
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    recordings = args.recordings or sorted((ROOT / "results").glob("*/*.rrd"))
    if not recordings:
        sys.exit("no recordings: run the scenarios first (make scenario NAME=...)")
    args.out.mkdir(parents=True, exist_ok=True)
    for rrd in recordings:
        for path in screenshots(rrd, args.out, args.wait, args.size):
            print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
