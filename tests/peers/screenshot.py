"""Screenshot of a page in headless Chromium (software rendering), taken once the page has
settled: a capture every 2 s until two in a row are identical (and larger than the viewer's
loading screen), at most TIMEOUT seconds. Drives Chromium over the DevTools protocol.

    python screenshot.py URL OUT.png [TIMEOUT=120] [WIDTH=1600] [HEIGHT=900]
"""
import base64
import json
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

import websocket

url, out = sys.argv[1], sys.argv[2]
timeout = float(sys.argv[3]) if len(sys.argv) > 3 else 120.0
width = int(sys.argv[4]) if len(sys.argv) > 4 else 1600
height = int(sys.argv[5]) if len(sys.argv) > 5 else 900

with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
profile = tempfile.mkdtemp(prefix="dynaflow-chromium-")
chrome = subprocess.Popen(
    ["chromium", "--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
     "--ignore-gpu-blocklist", "--no-first-run", f"--user-data-dir={profile}", f"--window-size={width},{height}",
     f"--remote-debugging-port={port}", "about:blank"],
    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
try:
    tabs = None
    for _ in range(300):
        try:
            tabs = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json", timeout=2))
            break
        except Exception:
            time.sleep(0.1)
    if tabs is None:
        sys.exit("chromium did not start its DevTools endpoint")
    tab = [t for t in tabs if t["type"] == "page"][0]
    ws = websocket.create_connection(tab["webSocketDebuggerUrl"], timeout=60)
    counter = [0]

    def call(method, **params):
        counter[0] += 1
        ws.send(json.dumps({"id": counter[0], "method": method, "params": params}))
        while True:
            m = json.loads(ws.recv())
            if m.get("id") == counter[0]:
                if "error" in m:
                    sys.exit(f"{method}: {m['error']}")
                return m["result"]

    call("Page.enable")
    call("Page.navigate", url=url)
    start, last, png = time.time(), None, None
    while time.time() - start < timeout:
        time.sleep(2)
        png = base64.b64decode(call("Page.captureScreenshot", format="png")["data"])
        if last == png and len(png) > 100_000:
            break
        last = png
    open(out, "wb").write(png)
    print(f"screenshot after {time.time() - start:.0f} s: {len(png)} bytes")
finally:
    chrome.kill()
