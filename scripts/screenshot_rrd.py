#!/usr/bin/env python3
"""Render a Rerun recording to PNG screenshots of the real web viewer, headless.

Usage::

    .venv/bin/python scripts/screenshot_rrd.py RECORDING.rrd OUT_PREFIX [options]

What it does:

1. starts ``rerun --serve-web --bind 127.0.0.1`` (the ``rerun`` next to this Python, e.g.
   ``.venv/bin/rerun``) on free local ports, serving RECORDING.rrd to the web viewer, with
   the viewer's analytics switched off (config and data dirs in a temporary folder);
2. opens the viewer page in Debian's headless ``chromium`` (software WebGL through
   SwiftShader; every host name but 127.0.0.1 resolves to nothing, so nothing leaves the
   machine), driven over the DevTools protocol on a pipe (no debugging port);
3. takes a screenshot every ``--every`` seconds; once at least ``--min-wait`` seconds have
   passed and two screenshots in a row are identical (the viewer has finished loading
   and drawing) -- or at ``--timeout`` -- it writes ``OUT_PREFIX.png`` (and, with
   ``--keep-all``, every intermediate one as ``OUT_PREFIX-<seconds>s.png``), downscaled
   with Pillow to at most ``--max-kb`` KB.

Loading takes a minute or more with software rendering. Needs ``chromium``
(``apt-get install -y chromium``) and, for the downscale, Pillow.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

HOST = "127.0.0.1"


def _private_env(workdir: Path) -> dict[str, str]:
    """The environment with home, config, data and cache folders in ``workdir``: nothing
    of the viewer's or the browser's state is read from or left in the user's home."""
    env = dict(os.environ)
    env.update(
        HOME=str(workdir),
        XDG_CONFIG_HOME=str(workdir / "config"),
        XDG_DATA_HOME=str(workdir / "data"),
        XDG_CACHE_HOME=str(workdir / "cache"),
    )
    return env


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


def rerun_binary() -> str:
    local = Path(sys.executable).with_name("rerun")
    if local.exists():
        return str(local)
    found = shutil.which("rerun")
    if found is None:
        raise SystemExit("no `rerun` next to this Python nor on PATH")
    return found


def wait_for_http(url: str, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=5) as response:
                if response.status == 200:
                    return
        except OSError:
            pass
        if time.monotonic() > deadline:
            raise SystemExit(f"the web viewer did not answer at {url} within {timeout:.0f} s")
        time.sleep(0.5)


@contextlib.contextmanager
def serve(recording: Path, workdir: Path, log: Path) -> Iterator[str]:
    """Serve ``recording`` with ``rerun --serve-web`` on 127.0.0.1; yield the viewer URL."""
    web_port, grpc_port = free_port(), free_port()
    env = _private_env(workdir)
    binary = rerun_binary()
    subprocess.run(
        [binary, "analytics", "disable"], env=env, check=False, capture_output=True, timeout=60
    )
    command = [
        binary,
        "--serve-web",
        "--bind",
        HOST,
        "--web-viewer-port",
        str(web_port),
        "--port",
        str(grpc_port),
        str(recording),
    ]
    with log.open("w") as out:
        process = subprocess.Popen(
            command, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )
    try:
        wait_for_http(f"http://{HOST}:{web_port}/", 120)
        proxy = f"rerun+http://{HOST}:{grpc_port}/proxy"
        yield f"http://{HOST}:{web_port}/?url={urllib.parse.quote(proxy, safe='')}"
    finally:
        # `.venv/bin/rerun` is a Python wrapper around the real binary: end the whole
        # process group this script started (its own session), not just the wrapper.
        _end_group(process)


class DevTools:
    """A minimal Chrome DevTools Protocol client over ``--remote-debugging-pipe``."""

    def __init__(self, chromium: str, width: int, height: int, workdir: Path) -> None:
        to_browser_r, to_browser_w = os.pipe()
        from_browser_r, from_browser_w = os.pipe()
        profile = tempfile.mkdtemp(prefix="profile-", dir=workdir)
        args = [
            chromium,
            "--headless",
            "--no-sandbox",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-default-apps",
            "--disable-extensions",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-quic",
            "--disable-renderer-backgrounding",
            "--disable-background-timer-throttling",
            "--disable-backgrounding-occluded-windows",
            f"--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE {HOST}",
            f"--user-data-dir={profile}",
            f"--window-size={width},{height}",
            "--remote-debugging-pipe",
            "about:blank",
        ]
        # Chromium reads commands from fd 3 and writes replies to fd 4.
        self.process = subprocess.Popen(
            args,
            env=_private_env(workdir),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=(workdir / "chromium.log").open("w"),
            pass_fds=(3, 4),
            preexec_fn=lambda: _dup_pipes(to_browser_r, from_browser_w),
            start_new_session=True,
        )
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._out = os.fdopen(to_browser_w, "wb", buffering=0)
        self._in = os.fdopen(from_browser_r, "rb", buffering=0)
        self._next_id = 0
        self._replies: dict[int, dict[str, Any]] = {}
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        buffer = b""
        while True:
            chunk = self._in.read(1 << 16)
            if not chunk:
                with self._cond:
                    self._cond.notify_all()
                return
            buffer += chunk
            while b"\0" in buffer:
                raw, buffer = buffer.split(b"\0", 1)
                message = json.loads(raw)
                if "id" in message:
                    with self._cond:
                        self._replies[message["id"]] = message
                        self._cond.notify_all()

    def call(
        self, method: str, session: str | None = None, timeout: float = 120, **params: Any
    ) -> dict[str, Any]:
        self._next_id += 1
        ident = self._next_id
        message: dict[str, Any] = {"id": ident, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self._out.write(json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + timeout
        with self._cond:
            while ident not in self._replies:
                left = deadline - time.monotonic()
                if left <= 0 or self.process.poll() is not None:
                    raise RuntimeError(f"no reply to {method} (chromium exited or timed out)")
                self._cond.wait(min(left, 1.0))
            reply = self._replies.pop(ident)
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return dict(reply.get("result", {}))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.call("Browser.close", timeout=10)
        _end_group(self.process)


def _end_group(process: subprocess.Popen[Any]) -> None:
    """Terminate (then kill) the process group led by ``process`` (started with
    ``start_new_session=True``), and reap ``process``."""
    for sig, wait in ((signal.SIGTERM, 10.0), (signal.SIGKILL, 10.0)):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, sig)
        try:
            process.wait(wait)
        except subprocess.TimeoutExpired:
            continue
        # The leader is gone; give the rest of its group a moment, then make sure.
        time.sleep(0.5)
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        return


def _dup_pipes(read_fd: int, write_fd: int) -> None:
    # Copy both out of the way first: either may already be fd 3 or 4.
    read_copy, write_copy = os.dup(read_fd), os.dup(write_fd)
    os.dup2(read_copy, 3)
    os.dup2(write_copy, 4)


def shrink(png: bytes, max_kb: int) -> bytes:
    """Downscale a PNG (keeping its aspect) until it fits in ``max_kb`` KB."""
    if len(png) <= max_kb * 1024:
        return png
    from PIL import Image

    image = Image.open(io.BytesIO(png)).convert("RGB")
    scale = 1.0
    while True:
        scale *= 0.85
        size = (max(1, int(image.width * scale)), max(1, int(image.height * scale)))
        buffer = io.BytesIO()
        image.resize(size, Image.Resampling.LANCZOS).save(buffer, "PNG", optimize=True)
        data = buffer.getvalue()
        if len(data) <= max_kb * 1024 or scale < 0.2:
            return data


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("recording", type=Path, help="the .rrd file")
    parser.add_argument("out_prefix", help="write OUT_PREFIX.png")
    parser.add_argument("--size", default="1600x1000", help="window size WxH (default 1600x1000)")
    parser.add_argument("--min-wait", type=float, default=60.0, help="seconds before done")
    parser.add_argument("--timeout", type=float, default=600.0, help="give up waiting after")
    parser.add_argument("--every", type=float, default=15.0, help="seconds between shots")
    parser.add_argument("--max-kb", type=int, default=400, help="downscale above this size")
    parser.add_argument("--keep-all", action="store_true", help="keep intermediate shots")
    parser.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = parser.parse_args(argv)
    recording = args.recording.resolve()
    if not recording.is_file():
        parser.error(f"no such recording: {recording}")
    if not Path(args.chromium).exists():
        parser.error(f"no chromium at {args.chromium} (apt-get install -y chromium)")
    width, height = (int(v) for v in args.size.lower().split("x"))
    out = Path(args.out_prefix + ".png")
    out.parent.mkdir(parents=True, exist_ok=True)

    with tempfile.TemporaryDirectory(prefix="screenshot-rrd-") as tmp:
        workdir = Path(tmp)
        with serve(recording, workdir, workdir / "rerun.log") as url:
            print(f"viewer: {url}", flush=True)
            browser = DevTools(args.chromium, width, height, workdir)
            try:
                target = browser.call("Target.createTarget", url="about:blank")["targetId"]
                session = browser.call("Target.attachToTarget", targetId=target, flatten=True)[
                    "sessionId"
                ]
                browser.call(
                    "Emulation.setDeviceMetricsOverride",
                    session,
                    width=width,
                    height=height,
                    deviceScaleFactor=1,
                    mobile=False,
                )
                browser.call("Page.enable", session)
                browser.call("Page.navigate", session, url=url)
                started = time.monotonic()
                previous: bytes | None = None
                shot = b""
                while True:
                    time.sleep(args.every)
                    elapsed = time.monotonic() - started
                    shot = base64.b64decode(
                        browser.call("Page.captureScreenshot", session, format="png")["data"]
                    )
                    print(f"{elapsed:5.0f} s: screenshot {len(shot) // 1024} KB", flush=True)
                    if args.keep_all:
                        Path(f"{args.out_prefix}-{elapsed:04.0f}s.png").write_bytes(shot)
                    if elapsed >= args.min_wait and shot == previous:
                        break
                    if elapsed >= args.timeout:
                        print("timed out waiting for a steady picture", flush=True)
                        break
                    previous = shot
            finally:
                browser.close()
    out.write_bytes(shrink(shot, args.max_kb))
    print(f"wrote {out} ({out.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
