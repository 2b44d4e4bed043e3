"""Checks the web pages in Firefox, which the CI's browser tests (Chromium, tests/service/test_web.py)
do not cover: geckodriver is not packaged in Debian, so this drives Firefox over Marionette.

Needs Debian's firefox-esr and, in a Python of its own, `pip install marionette_driver` (not a
project dependency; the project's .venv gives the example job). Against a running service
(`scripts/serve`, or `.venv/bin/geocert serve --port 8766`):

    python -m venv /tmp/ff && /tmp/ff/bin/pip install marionette_driver
    /tmp/ff/bin/python scripts/firefox_check.py http://127.0.0.1:8766

It submits a 20-track triangulation and an 8-view autocalibration through the API, then in headless
Firefox opens the jobs list, the triangulation's items and histogram, the autocalibration's 3D view
and verifies its certificate, and narrows the window to a phone's width. It prints what it saw and
the console errors of the page (Firefox's own, from resource:// URLs, are listed apart), and exits
1 if a check failed or the page logged an error."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.request

from marionette_driver.by import By
from marionette_driver.marionette import Marionette

CAMERAS = [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]], [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]]


def call(base: str, path: str, body: dict | None = None) -> dict:
    request = urllib.request.Request(base + path, data=None if body is None else json.dumps(body).encode(),
                                     headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(request, timeout=30) as answer:
        return json.loads(answer.read())


def submitted(base: str, job: dict) -> str:
    job_id = call(base, "/v1/jobs", job)["id"]
    while call(base, f"/v1/jobs/{job_id}")["status"] not in ("succeeded", "failed", "cancelled"):
        time.sleep(0.5)
    return job_id


def wait(check, seconds: float = 30.0):
    end = time.time() + seconds
    while time.time() < end:
        try:
            value = check()
            if value:
                return value
        except Exception:  # not there yet
            pass
        time.sleep(0.3)
    raise TimeoutError("the page did not show what was expected")


def main() -> int:
    base = sys.argv[1].rstrip("/")
    tracks = [{"views": [0, 1], "points": [[320 + 10 * k, 240 + 3 * k], [240 + 10 * k, 240 + 3 * k + 0.7]]}
              for k in range(20)]
    triangulation = submitted(base, {"kind": "triangulation", "data": {"cameras": CAMERAS, "tracks": tracks},
                                     "options": {"certificate": "full"}})
    project_python = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".venv", "bin", "python")
    example = json.loads(subprocess.run([project_python, "-c", "import json; from geocert.kinds import KINDS; "
                                         "print(json.dumps(KINDS.get('autocalibration').example))"],
                                        capture_output=True, text=True, check=True).stdout)
    autocalibration = submitted(base, {**example, "options": {"certificate": "full"}})
    profile = tempfile.mkdtemp()
    with open(os.path.join(profile, "user.js"), "w") as prefs:
        prefs.write('user_pref("devtools.console.stdout.content", true);\nuser_pref("marionette.port", 2829);\n')
    log_path = os.path.join(profile, "firefox.log")
    with open(log_path, "w") as log:
        firefox = subprocess.Popen(["firefox-esr", "--headless", "--marionette", "--no-remote", "--profile", profile,
                                    "--width", "1280", "--height", "900"], stdout=log, stderr=subprocess.STDOUT)
    failed = []
    try:
        time.sleep(5)
        browser = Marionette(host="127.0.0.1", port=2829)
        browser.start_session()
        caps = browser.session_capabilities
        print("browser:", caps.get("browserName"), caps.get("browserVersion"))
        browser.navigate(base + "/")
        wait(lambda: browser.find_elements(By.CSS_SELECTOR, f"tr[data-job='{triangulation}']"))
        print("jobs list: both jobs listed")
        browser.navigate(f"{base}/jobs/{triangulation}")
        items = wait(lambda: browser.find_element(By.ID, "s-items").text.strip() == "20 / 20"
                     and browser.find_elements(By.CSS_SELECTOR, "#items tbody tr"))
        print("triangulation: 20 / 20 items,", len(items), "rows;", browser.find_element(By.ID, "hist-note").text[:50])
        browser.navigate(f"{base}/jobs/{autocalibration}")
        size = wait(lambda: browser.execute_script(  # laid out (a canvas starts at 300 x 150)
            "var c = document.getElementById('view3d'); return c && c.width != 300 ? [c.width, c.height] : null"))
        wait(lambda: browser.find_element(By.ID, "verify").is_displayed())
        browser.find_element(By.ID, "verify").click()
        verdict = wait(lambda: browser.find_element(By.ID, "verify-verdict").text)
        checks = len(browser.find_elements(By.CSS_SELECTOR, "#verify-report tr[data-check]"))
        print("autocalibration: 3D canvas", size, "| verify:", verdict, "with", checks, "checks")
        if verdict != "valid" or checks == 0:
            failed.append("verify")
        browser.set_window_rect(width=390, height=844)
        browser.navigate(base + "/")
        wait(lambda: browser.find_elements(By.CSS_SELECTOR, "tr[data-job]"))
        scroll, client = browser.execute_script(
            "return [document.documentElement.scrollWidth, document.documentElement.clientWidth]")
        print(f"narrow window: page {scroll} px wide in a {client} px viewport")
        if scroll > client:
            failed.append("narrow width scrolls sideways")
        browser.delete_session()
    finally:
        firefox.terminate()
        firefox.wait(10)
    lines = [line for line in open(log_path) if "JavaScript error" in line or "console.error" in line]
    own = [line for line in lines if "resource://" in line or "RSLoader" in line]
    page = [line for line in lines if line not in own]
    print(f"console errors of the page: {len(page)} (Firefox's own, ignored: {len(own)})")
    for line in page[:10]:
        print("  ", line.strip()[:200])
    return 1 if failed or page else 0


if __name__ == "__main__":
    sys.exit(main())
