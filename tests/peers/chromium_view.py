#!/usr/bin/env python3
"""Opens the rig's browser view in headless Chromium, waits, takes a screenshot and reads the
page's status line, over the DevTools protocol (PyPI websockets).

usage: chromium_view.py URL SCREENSHOT.png WAIT_S [WIDTH HEIGHT]

Two phases: WAIT_S after the page was opened it takes FIRST.png (SCREENSHOT with "first"
before its suffix) and prints {"phase": "first"}; then it waits for one line on stdin (the
caller changing what is published), WAIT_S more, and takes SCREENSHOT. Prints a last JSON line:
{"status": <status line text>, "class": <its class>, "width": .., "height": ..}. Chromium reaches nothing but loopback: other hosts go to a proxy at a closed
loopback port, host names do not resolve, background services are off. It runs in a session
(process group) of its own with a throwaway profile, killed as a group at the end whatever
happens.
"""

import base64
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

from websockets.sync.client import connect

CHROMIUM = os.environ.get("CHROMIUM", "chromium")
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--hide-scrollbars",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--disable-extensions",
    "--disable-domain-reliability",
    "--disable-breakpad",
    "--metrics-recording-only",
    "--no-pings",
    "--proxy-server=http://127.0.0.1:9",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
    "--remote-debugging-address=127.0.0.1",
    "--remote-debugging-port=0",
]


def devtools_port(profile: str, proc: subprocess.Popen, timeout_s: float = 20.0) -> int:
    """Chromium writes the port it chose to DevToolsActivePort in its profile."""
    path = os.path.join(profile, "DevToolsActivePort")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"chromium exited with {proc.returncode}")
        try:
            with open(path) as f:
                return int(f.readline().strip())
        except (FileNotFoundError, ValueError):
            time.sleep(0.05)
    raise SystemExit("chromium opened no DevTools port")


class Page:
    def __init__(self, ws):
        self.ws = ws
        self.next_id = 0

    def call(self, method: str, **params):
        self.next_id += 1
        self.ws.send(json.dumps({"id": self.next_id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv(timeout=30))
            if msg.get("id") == self.next_id:
                if "error" in msg:
                    raise SystemExit(f"{method}: {msg['error']}")
                return msg["result"]


def drive(port: int, url: str, shot: str, wait_s: float, width: int, height: int) -> dict:
    direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))
    targets = json.load(direct.open(f"http://127.0.0.1:{port}/json/list", timeout=10))
    page_ws = next(t["webSocketDebuggerUrl"] for t in targets if t["type"] == "page")
    with connect(page_ws, max_size=64 << 20, proxy=None) as ws:
        page = Page(ws)
        page.call("Emulation.setDeviceMetricsOverride", width=width, height=height, deviceScaleFactor=1, mobile=False)
        page.call("Page.navigate", url=url)

        def capture(path: str) -> None:
            png = base64.b64decode(page.call("Page.captureScreenshot", format="png")["data"])
            with open(path, "wb") as f:
                f.write(png)

        time.sleep(wait_s)
        root, ext = os.path.splitext(shot)
        capture(root + ".first" + ext)
        print(json.dumps({"phase": "first"}), flush=True)
        sys.stdin.readline()
        time.sleep(wait_s)
        capture(shot)
        expr = "JSON.stringify([document.getElementById('status').textContent, document.getElementById('status').className])"
        value = page.call("Runtime.evaluate", expression=expr, returnByValue=True)["result"]["value"]
        text, cls = json.loads(value)
        return {"status": text, "class": cls, "width": width, "height": height}


def main() -> int:
    url, shot, wait_s = sys.argv[1], sys.argv[2], float(sys.argv[3])
    width, height = (int(sys.argv[4]), int(sys.argv[5])) if len(sys.argv) > 5 else (480, 320)
    profile = tempfile.mkdtemp(prefix="starc-chromium-")
    env = dict(os.environ, HOME=profile)
    for k in ("http_proxy", "https_proxy", "HTTP_PROXY", "HTTPS_PROXY", "all_proxy", "ALL_PROXY"):
        env.pop(k, None)
    proc = subprocess.Popen(
        [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", "about:blank"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
        start_new_session=True,
    )
    try:
        result = drive(devtools_port(profile, proc), url, shot, wait_s, width, height)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
        # Its children die with the group; wait until none is left (at most 5 s).
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            try:
                os.killpg(proc.pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.05)
        shutil.rmtree(profile, ignore_errors=True)
    print(json.dumps(result), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
