"""The web pages in a real browser: headless Chromium (Debian's `chromium`, driven through
`chromedriver` by selenium) against a real `geocert serve` (embedded Redis, a real Celery worker).

Submit a job from the form and watch its bound chart move while it runs, cancel one, open a
finished triangulation's and an autocalibration's 3D view, page, filter and sort the items, verify
a certificate, use the pages at a phone's width and from the keyboard, and give an API key once.
The page tells the truth (TestTheResultAsItIs): what is not certified, not determined or warned
about is said first; a reconstruction's and an autocalibration's own figures, the answers in the
item tables, a finished job's status and bounds as they were, a failed job's error in words, and
templates that run as given. Every test ends by reading the browser's console log: any error there
fails it. Screenshots go to tests/service/screenshots/ (printed at the end of the run) for a
person to look at.

`scripts/test` installs chromium and chromium-driver when missing (scripts/bootstrap.sh), so these
tests run wherever the suite runs; they are not skipped for want of a browser."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By
from selenium.webdriver.common.keys import Keys
from selenium.webdriver.support.ui import Select, WebDriverWait

from geocert.solvers.autocalibration import scenes
from tests.servers import cluster, free_port, wait_ready
from tests.support import ROOT, service_job

pytestmark = pytest.mark.slow  # real servers and a browser: the full run only

SCREENSHOTS = Path(__file__).resolve().parent / "screenshots"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
KEY = "web-test-key"


def start_service(tmp: Path, **env: str) -> tuple[subprocess.Popen, str]:
    port = free_port()
    environment = {key: value for key, value in os.environ.items() if key != "GEOCERT_REDIS_URL"}
    environment.update(GEOCERT_DATA_DIR=str(tmp), GEOCERT_PROGRESS_INTERVAL_S="0.1",
                       GEOCERT_CHUNK_SIZES='{"triangulation": 20}', **env)
    workers = "0" if env.get("NO_WORKERS") else "1"
    process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port),
                                "--workers", workers, "--concurrency", "2"], env=environment)
    base = f"http://127.0.0.1:{port}"
    with httpx.Client(base_url=base, timeout=10) as client:
        wait_ready(client, process, workers=workers != "0")
    return process, base


def stop(process: subprocess.Popen) -> None:
    process.terminate()
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(timeout=10)


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    process, base = start_service(tmp_path_factory.mktemp("web"))
    with httpx.Client(base_url=base, timeout=30) as client:
        yield client
    stop(process)


@pytest.fixture(scope="module")
def browser(request):
    assert Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists(), (
        "chromium and chromedriver are needed: scripts/test installs them (apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1280,1000",
                     "--disable-gpu", "--no-first-run"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.set_script_timeout(30)
    SCREENSHOTS.mkdir(exist_ok=True)
    yield driver
    driver.quit()
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    with capture.global_and_fixture_disabled():  # printed whatever -s says: a person looks at them
        print(f"\nweb page screenshots: {SCREENSHOTS}", flush=True)


@pytest.fixture
def page(browser):
    """The browser, with its console checked after the test: an error there fails the test."""
    browser.set_window_size(1280, 1000)
    browser.get_log("browser")  # drop what an earlier test left
    yield browser
    errors = [entry for entry in browser.get_log("browser") if entry["level"] == "SEVERE"]
    assert not errors, f"console errors: {errors}"


def shot(driver, name: str) -> None:
    driver.save_screenshot(str(SCREENSHOTS / f"{name}.png"))


def state(driver) -> dict:
    return driver.execute_script(
        "const s = window.GC_STATE || {}; return {rendered: s.rendered, view: s.view, verify: s.verify, "
        "chart: (s.chart || []).map(p => [p.t, p.upper, p.lower, p.gap]), "
        "status: (document.getElementById('status') || {}).textContent};")


def wait(driver, condition, limit_s: float = 60, message: str = ""):
    return WebDriverWait(driver, limit_s, poll_frequency=0.05).until(lambda d: condition(d), message)


def wait_job(client: httpx.Client, job_id: str, limit_s: float = 120) -> dict:
    deadline = time.monotonic() + limit_s
    while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, f"job still {job['status']}"
        time.sleep(0.1)
    return job


def finished_page(driver, base: str, job_id: str) -> dict:
    driver.get(f"{base}/jobs/{job_id}")
    wait(driver, lambda d: state(d)["rendered"], 30, "the finished job's page did not render")
    return state(driver)


def example(name: str) -> dict:
    return json.loads((ROOT / "examples" / f"{name}.json").read_text())


def solved(client: httpx.Client, body: dict) -> tuple[str, dict]:
    job_id = client.post("/v1/jobs", json=body).json()["id"]
    job = wait_job(client, job_id, limit_s=600)
    assert job["status"] == "succeeded", job.get("error")
    return job_id, job


def verdict(driver) -> dict:
    return driver.execute_script("return window.GC_STATE.verdict;")


def text(driver, element_id: str) -> str:
    return driver.find_element(By.ID, element_id).text


class TestWebPages:
    def test_a_job_submitted_from_the_form_streams_its_bounds_then_shows_its_items(self, page, service):
        base = str(service.base_url).rstrip("/")
        body = service_job(np.random.default_rng(7), tracks=60, views=5, norm="L1L1", rel_gap=1e-5,
                           certificate="full")
        page.get(base + "/")
        wait(page, lambda d: len(Select(d.find_element(By.ID, "template-kind")).options) > 1, 20)
        page.execute_script("document.getElementById('job-json').value = arguments[0];", json.dumps(body))
        page.find_element(By.ID, "submit-button").click()
        wait(page, lambda d: "/jobs/" in d.current_url, 20, "the form did not lead to the job's page")
        job_id = page.current_url.rstrip("/").rsplit("/", 1)[1]

        seen_running: list = []  # distinct chart points seen while the page said the job was running
        while True:
            now = state(page)
            if now["status"] in ("succeeded", "failed", "cancelled"):
                break
            if now["status"] == "running":
                seen_running = max(seen_running, now["chart"], key=len)
                if len({tuple(p) for p in seen_running}) == 3:
                    shot(page, "job-running")
            time.sleep(0.05)
        distinct = {tuple(p) for p in seen_running}
        assert len(distinct) >= 2, f"the chart had {len(distinct)} distinct points while the job ran"
        assert len({p[0] for p in distinct}) >= 2 and len({p[2] for p in distinct}) >= 2  # time and lower bound moved
        assert now["status"] == "succeeded"

        done = wait(page, lambda d: state(d)["rendered"] and state(d), 30, "the result did not render")
        job = service.get(f"/v1/jobs/{job_id}").json()
        assert done["view"] == {"points": 60, "cameras": 5}  # a triangulation's points, its cameras from the request
        assert int(page.find_element(By.ID, "chart").get_attribute("data-points")) >= 2
        assert page.find_element(By.ID, "s-items").text == "60 / 60"
        note = page.find_element(By.ID, "page-note").text
        assert note == "60 of 60 items; page 1 of 2", note
        assert "residuals" in page.find_element(By.ID, "hist-note").text
        shot(page, "job-finished")

        # sort by cost, highest first: the table's first row is the costliest item
        page.find_element(By.CSS_SELECTOR, "#items thead button[data-sort='cost']").click()
        page.find_element(By.CSS_SELECTOR, "#items thead button[data-sort='cost']").click()
        costs = [track["cost"] for track in job["result"]["tracks"]]
        first = int(page.find_element(By.CSS_SELECTOR, "#items tbody tr").get_attribute("data-item"))
        assert first == int(np.argmax(costs))
        # pages of 25: three, the last with 10 rows
        Select(page.find_element(By.ID, "f-size")).select_by_visible_text("25")
        page.find_element(By.ID, "last").click()
        assert len(page.find_elements(By.CSS_SELECTOR, "#items tbody tr")) == 10
        assert page.find_element(By.ID, "page-note").text == "60 of 60 items; page 3 of 3"
        # a filter nothing meets
        Select(page.find_element(By.ID, "f-certified")).select_by_visible_text("no")
        assert page.find_element(By.ID, "page-note").text.startswith("0 of 60 items")

        # the job is listed on / with its certified fraction
        page.get(base + "/")
        row = wait(page, lambda d: d.find_elements(By.CSS_SELECTOR, f"tr[data-job='{job_id}']"), 20)[0]
        assert "succeeded" in row.text and "60 / 60" in row.text and "100 %" in row.text

    def test_the_form_says_what_is_not_json_and_takes_an_uploaded_file(self, page, service, tmp_path):
        base = str(service.base_url).rstrip("/")
        page.get(base + "/")
        wait(page, lambda d: len(Select(d.find_element(By.ID, "template-kind")).options) > 1, 20)
        assert page.find_element(By.ID, "source-images").is_enabled()  # the reconstruction kind takes images
        assert "sent as a reconstruction job" in page.find_element(By.ID, "images-note").text
        Select(page.find_element(By.ID, "template-kind")).select_by_value("triangulation")
        template = json.loads(page.find_element(By.ID, "job-json").get_attribute("value"))
        assert template["kind"] == "triangulation" and template["options"]["norm"] == "L2L2"
        page.execute_script("document.getElementById('job-json').value = '{\"kind\": ';")
        page.find_element(By.ID, "submit-button").click()  # refused before any request: nothing in the console
        error = wait(page, lambda d: d.find_element(By.ID, "error").is_displayed() and d.find_element(By.ID, "error"), 10)
        assert error.text.startswith("Not JSON")
        job_file = tmp_path / "job.json"
        job_file.write_text(json.dumps(service_job(np.random.default_rng(5), tracks=2, views=3)))
        page.find_element(By.CSS_SELECTOR, "input[name=source][value=upload]").click()
        page.find_element(By.ID, "job-file").send_keys(str(job_file))
        page.find_element(By.ID, "submit-button").click()
        wait(page, lambda d: "/jobs/" in d.current_url, 20, "the uploaded job was not submitted")
        wait(page, lambda d: state(d)["status"] == "succeeded" and state(d)["rendered"], 60)
        assert page.find_element(By.ID, "s-items").text == "2 / 2"

    def test_a_running_job_is_cancelled_from_its_page(self, page, service):
        base = str(service.base_url).rstrip("/")
        body = service_job(np.random.default_rng(24), tracks=1, views=6, norm="L1L1", rel_gap=0.0, abs_gap=0.0,
                           max_nodes=100_000, time_limit_s=60)
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        page.get(f"{base}/jobs/{job_id}")
        wait(page, lambda d: state(d)["status"] == "running" and len(state(d)["chart"]) >= 1, 30,
             "the job did not start")
        button = page.find_element(By.ID, "cancel")
        assert button.is_enabled()
        button.click()
        wait(page, lambda d: state(d)["status"] == "cancelled", 30, "the page never said cancelled")
        wait(page, lambda d: state(d)["rendered"], 20)
        assert not page.find_element(By.ID, "cancel").is_enabled()
        assert service.get(f"/v1/jobs/{job_id}").json()["status"] == "cancelled"
        shot(page, "job-cancelled")

    def test_an_autocalibration_in_3d_and_its_certificate_verified(self, page, service):
        base = str(service.base_url).rstrip("/")
        scene = scenes.make_scene(8, 0.1, seed=5)
        body = {"kind": "autocalibration", "data": scene.job_data(), "options": {"certificate": "full"}}
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        assert wait_job(service, job_id)["status"] == "succeeded"
        now = finished_page(page, base, job_id)
        assert now["view"] == {"points": 100, "cameras": 8}

        canvas = page.find_element(By.ID, "view3d")
        image = lambda: page.execute_script("return arguments[0].toDataURL();", canvas)  # noqa: E731
        before = image()
        ActionChains(page).move_to_element(canvas).click_and_hold().move_by_offset(80, 30).release().perform()
        dragged = image()
        assert dragged != before, "dragging did not rotate the view"
        canvas.send_keys("+++")  # zoom from the keyboard
        assert image() != dragged
        shot(page, "autocalibration-3d")

        page.find_element(By.ID, "verify").click()
        wait(page, lambda d: state(d)["verify"], 60, "no verification report")
        verdict = page.find_element(By.ID, "verify-verdict").text
        report = state(page)["verify"]
        assert verdict == "valid" and report["valid"] is True, report["first_failure"]
        rows = page.find_elements(By.CSS_SELECTOR, "#verify-report tr[data-check]")
        assert [row.get_attribute("data-check") for row in rows] == [check["name"] for check in report["checks"]]
        assert all("passed" in row.text for row in rows)
        page.execute_script("document.getElementById('verify-report').scrollIntoView();")
        shot(page, "autocalibration-verified")

    def test_phone_width_and_keyboard(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id = service.post("/v1/jobs", json=service_job(np.random.default_rng(3), tracks=120, views=4)).json()["id"]
        wait_job(service, job_id)
        page.set_window_size(390, 844)
        page.get(base + "/")
        wait(page, lambda d: d.find_elements(By.CSS_SELECTOR, f"tr[data-job='{job_id}']"), 20)
        overflow = "return document.documentElement.scrollWidth - window.innerWidth;"
        assert page.execute_script(overflow) <= 1, "the jobs page is wider than a phone"
        shot(page, "phone-jobs")

        # the keyboard reaches the form's submit button, and the job's link, by Tab alone
        page.find_element(By.TAG_NAME, "body").click()
        reached = set()
        for _ in range(40):
            ActionChains(page).send_keys(Keys.TAB).perform()
            active = page.switch_to.active_element
            reached.add(active.get_attribute("id") or active.get_attribute("href") or active.tag_name)
        assert "submit-button" in reached and f"{base}/jobs/{job_id}" in reached, reached

        now = finished_page(page, base, job_id)
        assert now["view"]["points"] == 120
        assert page.execute_script(overflow) <= 1, "the job's page is wider than a phone"
        page.find_element(By.ID, "view3d").send_keys(Keys.ARROW_LEFT)  # focusable: rotates from the keyboard
        shot(page, "phone-job")


# Records every text the status badge is given, from the document's first moment (before the
# page's own scripts run), so a test sees a flicker that ends before it could look: each text set
# is a mutation record of its own, even when several come in one task.
BADGE_OBSERVER = """
window.__badges = [];
document.addEventListener("DOMContentLoaded", () => {
  const badge = document.getElementById("status");
  if (badge) new MutationObserver((records) => {
    for (const record of records) for (const node of record.addedNodes) window.__badges.push(node.textContent);
  }).observe(badge, {childList: true});
});
"""


def progress_events(client: httpx.Client, job_id: str) -> list[dict]:
    """The job's progress events as its stream replays them (a finished job's stream ends)."""
    events, name = [], None
    with client.stream("GET", f"/v1/jobs/{job_id}/events", timeout=30) as response:
        for line in response.iter_lines():
            if line.startswith("event:"):
                name = line.split(":", 1)[1].strip()
            elif line.startswith("data:") and name == "progress":
                events.append(json.loads(line.split(":", 1)[1]))
    return events


def numbers(text_block: str) -> list[float]:
    return [float(x) for x in text_block.replace("[", " ").replace("]", " ").replace(",", " ").split()]


class TestTheResultAsItIs:
    """The page says first what is not certified, not determined or warned about, and shows the
    answer itself; each test fails on the page as it was before (issue 34, item 7)."""

    def test_a_reconstruction_reads_its_points_cameras_summary_and_exports(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id, job = solved(service, example("reconstruction-tracks"))
        result = job["result"]
        finished_page(page, base, job_id)
        points, cameras = result["points"], result["cameras"]
        certified = sum(point["certified"] for point in points)
        assert text(page, "summary").startswith(f"{len(points)} points, {certified} certified")  # was "1 points, 1 certified"
        registered = [camera for camera in cameras if camera["registered"]]
        figures = text(page, "answer")
        assert f"Views registered\n{len(registered)} of {len(cameras)}" in figures
        rms = page.execute_script("return GC.num(arguments[0], 4);", result["summary"]["rms_reprojection_px"])
        assert f"RMS reprojection\n{rms} px" in figures
        rows = page.find_elements(By.CSS_SELECTOR, "#cameras tbody tr")
        assert [row.find_elements(By.TAG_NAME, "td")[3].text for row in rows] == [
            "yes" if camera["certified"] else "no" for camera in cameras]
        # the K returned is the adjustment's, and the page says it is not a certified quantity
        assert "not certified" in text(page, "k-note")
        cameras_certified = sum(camera["certified"] for camera in cameras)
        lines = verdict(page)["lines"]
        assert f"{cameras_certified} of {len(cameras)} cameras certified" in " ".join(lines)
        if cameras_certified < len(cameras):
            assert verdict(page)["level"] != "yes"
        # the exports the API offers, linked and working
        links = {a.text: a.get_attribute("href") for a in page.find_elements(By.CSS_SELECTOR, "#links a")}
        colmap = links["Export: COLMAP model (zip)"]
        assert colmap.endswith(f"/v1/jobs/{job_id}/export?format=colmap")
        response = service.get(colmap)
        assert response.status_code == 200 and response.content[:2] == b"PK"
        assert service.get(links["Export: Points (PLY)"]).text.startswith("ply")
        shot(page, "reconstruction")
        page.get(base + "/")  # one job item stands for the whole reconstruction: the list sends you to its page
        row = wait(page, lambda d: d.find_elements(By.CSS_SELECTOR, f"tr[data-job='{job_id}']"), 20)[0]
        assert row.find_elements(By.TAG_NAME, "td")[4].text == "see job"  # was "100 %" with 0 of 8 cameras certified

    def test_an_autocalibration_shows_its_K_stages_and_what_the_data_do_not_fix(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id, job = solved(service, example("autocalibration-turntable"))
        result = job["result"]
        finished_page(page, base, job_id)
        stages = result["stages"]
        certified = sum(stage["certified"] for stage in stages)
        assert text(page, "summary").startswith(f"{len(stages)} stages, {certified} certified")  # was "1 stages"
        now = verdict(page)
        assert now["level"] != "yes"
        codes = {w["code"] for stage in stages for w in stage["determinacy"]["warnings"]}
        assert codes, "a turntable is a critical motion: the result warns"
        for code in codes:
            assert any(code in line for line in now["lines"]), (code, now["lines"])
        assert any(line.startswith("Not determined by the data") for line in now["lines"])
        note = text(page, "k-note")
        assert "NOT determined" in note and ("NOT certified" in note) == (not stages[-1]["certified"])
        K = page.find_element(By.CSS_SELECTOR, "#answer pre.matrix").text
        assert np.allclose(numbers(K), np.ravel(result["K"]), rtol=1e-4, atol=1e-4)
        shot(page, "autocalibration-turntable")

        # a well-posed scene: green only when every stage is certified, determined and unwarned
        job_id, job = solved(service, example("autocalibration-stratified"))
        finished_page(page, base, job_id)
        clean = all(stage["certified"] and stage["determinacy"]["determined"] and not stage["determinacy"]["warnings"]
                    for stage in job["result"]["stages"])
        assert (verdict(page)["level"] == "yes") == clean

    def test_a_finished_jobs_page_keeps_its_status_and_shows_its_bounds_history(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id, job = solved(service, example("triangulation"))
        script = page.execute_cdp_cmd("Page.addScriptToEvaluateOnNewDocument", {"source": BADGE_OBSERVER})
        try:
            finished_page(page, base, job_id)
            wait(page, lambda d: d.find_element(By.ID, "chart-note").text, 30, "the chart never said it was complete")
            badges = page.execute_script("return window.__badges;")
        finally:
            page.execute_cdp_cmd("Page.removeScriptToEvaluateOnNewDocument", {"identifier": script["identifier"]})
        assert badges and set(badges) == {"succeeded"}, badges  # was succeeded -> queued/running -> succeeded
        assert not page.find_element(By.ID, "cancel").is_displayed()  # nothing to cancel
        events = progress_events(service, job_id)
        distinct = {(e["elapsed_s"], e["upper_bound"], e["lower_bound"], e["gap_abs"]) for e in events}
        assert int(page.find_element(By.ID, "chart").get_attribute("data-points")) == len(distinct)
        drawable = {p for p in distinct if any(v is not None and v > 0 for v in p[1:])}
        assert text(page, "chart-note").startswith(f"{len(drawable)} progress report")
        # the table shows each track's point
        first = page.find_element(By.CSS_SELECTOR, "#items tbody tr[data-item='0'] td.answer").text
        assert np.allclose(numbers(first), job["result"]["tracks"][0]["point"], rtol=1e-4, atol=1e-4)

    def test_estimates_say_so_and_a_chart_without_bounds_says_why(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id, job = solved(service, example("stereo-lines-pair"))
        finished_page(page, base, job_id)
        wait(page, lambda d: d.find_element(By.ID, "chart-note").text, 30, "the chart still waits for progress")
        now = verdict(page)
        assert now["level"] == "estimate" and "not certified" in now["headline"]
        assert not page.find_element(By.ID, "chart").is_displayed()  # was "Waiting for progress…" for ever
        assert text(page, "chart-note").startswith("No bounds")
        assert not page.find_element(By.ID, "verify").is_displayed()  # was: "submit with certificate full", refused
        pair = job["result"]["pairs"][0]
        angle = np.degrees(np.arccos(np.clip((np.trace(pair["R"]) - 1) / 2, -1, 1)))
        cell = page.find_element(By.CSS_SELECTOR, "#items tbody tr[data-item='0'] td.answer").text
        assert abs(numbers(cell.split("°")[0].replace("R:", ""))[0] - angle) < 1e-3 * max(1, angle)
        shot(page, "stereo-lines")
        page.get(base + "/")  # the list says so too (was "0 %" certified)
        row = wait(page, lambda d: d.find_elements(By.CSS_SELECTOR, f"tr[data-job='{job_id}']"), 20)[0]
        assert row.find_elements(By.TAG_NAME, "td")[4].text == "estimates"

    def test_the_item_tables_show_the_matrices(self, page, service):
        base = str(service.base_url).rstrip("/")
        job_id, job = solved(service, example("homography-plane"))
        finished_page(page, base, job_id)
        headers = [th.text for th in page.find_elements(By.CSS_SELECTOR, "#items thead th")]
        assert "matrix" in headers
        for index, item in enumerate(job["result"]["maps"]):
            shown = page.find_element(By.CSS_SELECTOR, f"#items tbody tr[data-item='{index}'] td.answer pre.matrix").text
            assert np.allclose(numbers(shown), np.ravel(item["matrix"]), rtol=1e-4, atol=1e-5)

    def test_a_failed_job_says_what_failed_in_words(self, page, tmp_path):
        from geocert.app.core.security import PUBLIC_OWNER
        from geocert.jobs.store import JobStore

        with cluster(tmp_path, workers=0) as (running, client):
            store = JobStore.from_url(running.redis_url)
            body = service_job(np.random.default_rng(2), tracks=3)
            job_id = store.create("triangulation", body, 3, 3, PUBLIC_OWNER)["id"]
            assert store.mark_running(job_id) and store.claim_end(job_id)
            # the error as the worker records a solver's exception (workers/tasks.py, end_with_error)
            store.end(job_id, "failed", error={
                "type": "about:blank", "title": "Solver failure", "status": 500,
                "detail": "ValueError: matmul: Input operand 1 does not have enough dimensions"})
            assert client.get(f"/v1/jobs/{job_id}").json()["status"] == "failed"
            finished_page(page, running.base, job_id)
            now = verdict(page)
            assert now["level"] == "no" and now["headline"].startswith("Failed")
            assert text(page, "failure-title") == "Solver failure (500)"
            failure = text(page, "failure")
            assert "internal error" in failure and "not of your data" in failure
            assert "0 of 3 items" in failure
            assert "The error reported: ValueError: matmul" in failure  # after the words, for a bug report
            assert not page.find_element(By.ID, "error").is_displayed()  # was the raw exception in the page's error box
            assert not page.find_element(By.ID, "cancel").is_displayed()
            shot(page, "failed")

    def test_every_template_runs_as_given(self, page, service):
        base = str(service.base_url).rstrip("/")
        for info in service.get("/v1/problems").json():
            page.get(base + "/")
            wait(page, lambda d: len(Select(d.find_element(By.ID, "template-kind")).options) > 1, 20)
            Select(page.find_element(By.ID, "template-kind")).select_by_value(info["kind"])
            template = json.loads(page.find_element(By.ID, "job-json").get_attribute("value"))
            assert template == info["example"] and template["data"]  # was: every data field an empty list
            page.find_element(By.ID, "submit-button").click()
            wait(page, lambda d: "/jobs/" in d.current_url, 20, f"the {info['kind']} template was refused")
            wait(page, lambda d: state(d)["status"] in ("succeeded", "failed", "cancelled") and state(d)["rendered"], 300)
            assert state(page)["status"] == "succeeded", info["kind"]


class TestTheVerdictsWords:
    """What the page says of a reconstruction's cameras and K, in the browser, from truth.js as
    served (a page of its own: no service needed). A newcomer read "returned is: not certified",
    "6 of 14 cameras certified; not certified: ... (not_run)" for views never registered, and
    views_not_registered by index beside named photos."""

    RESULT = {
        "summary": {"calibration": {"K": [[800, 0, 320], [0, 800, 240], [0, 0, 1]], "source": "bundle_adjustment",
                                    "certified": True, "returned_is_certified": False, "determined": True},
                    "warnings": [{"code": "views_not_registered", "detail": (
                        "3 of 6 views not registered (no camera returned for them): views 3, 4: too few "
                        "3D-2D inliers; views 5: not started")}]},
        "cameras": [{"view": 0, "name": "box0.jpg", "registered": True, "certified": True, "status": "optimal"},
                    {"view": 1, "name": "box1.jpg", "registered": True, "certified": True, "status": "optimal"},
                    {"view": 2, "name": "box2.jpg", "registered": True, "certified": False, "status": "not_run"},
                    {"view": 3, "name": "box3.jpg", "registered": False, "certified": False, "status": "not_run",
                     "reason": "too few 3D-2D inliers"},
                    {"view": 4, "name": "box4.jpg", "registered": False, "certified": False, "status": "not_run",
                     "reason": "too few 3D-2D inliers"},
                    {"view": 5, "name": "box5.jpg", "registered": False, "certified": False, "status": "not_run",
                     "reason": "not started"}],
        "points": [{"certified": True}, {"certified": True}],
    }

    def verdict_of(self, page, tmp_path, result) -> list[str]:
        truth = ROOT / "geocert" / "app" / "web" / "truth.js"
        html = tmp_path / "truth.html"
        html.write_text(f'<!doctype html><html><head><script src="{truth.as_uri()}"></script></head><body></body></html>')
        page.get(html.as_uri())
        lines = page.execute_script(
            "return Truth.verdict({status: 'succeeded'}, arguments[0], 'points', true).lines.map(l => l.text);", result)
        return lines

    def test_not_determined_sends_the_reader_to_warnings_only_when_there_are_some(self, page, tmp_path):
        """A stereo pair's translation comes back undetermined with an empty warnings list: the
        page said "see the warnings" of warnings that were not there."""
        pair = {"certified": False, "status": "estimate", "translation_determined": False,
                "determinacy": {"determined": False, "warnings": []}}
        warned = dict(pair, determinacy={"determined": False, "warnings": [{"code": "orbital_motion", "detail": "a ring"}]})
        self.verdict_of(page, tmp_path, {})
        said = lambda result: page.execute_script(  # noqa: E731
            "return Truth.verdict({status: 'succeeded'}, arguments[0], 'pairs', false).lines"
            ".filter(l => l.kind === 'determined').map(l => l.text);", result)
        quiet, loud = said({"pairs": [pair]}), said({"pairs": [warned]})
        assert quiet and not any("see the warnings" in line for line in quiet), quiet
        assert loud and all("see the warnings" in line for line in loud), loud
        # a certified stage not determined, no warning (the stratified example's metric stage):
        # the headline said "read the warnings" too
        stage = {"name": "metric", "certified": True, "status": "optimal", "determinacy": {"determined": False, "warnings": []}}
        headline = lambda result: page.execute_script(  # noqa: E731
            "return Truth.verdict({status: 'succeeded'}, arguments[0], 'stages', true).headline;", result)
        assert "warnings" not in headline({"stages": [stage]}), headline({"stages": [stage]})
        warned_stage = dict(stage, determinacy=warned["determinacy"])
        assert "read the warnings" in headline({"stages": [warned_stage]})

    def test_the_cameras_line_says_which_views_were_not_registered_and_what_not_run_means(self, page, tmp_path):
        lines = self.verdict_of(page, tmp_path, self.RESULT)
        cameras = next(line for line in lines if "cameras certified" in line)
        assert cameras.startswith("2 of 6 cameras certified; 3 not registered (no camera was returned for them, "
                                  "so none is certified): box3.jpg, box4.jpg, box5.jpg"), cameras
        assert "box2.jpg (not judged: no bound was computed for it, status not_run)" in cameras, cameras
        assert "box3.jpg (not_run)" not in cameras  # was: every view not registered listed as not_run

    def test_the_returned_K_is_said_plainly(self, page, tmp_path):
        lines = self.verdict_of(page, tmp_path, self.RESULT)
        assert not any("returned is" in line for line in lines), lines  # was "returned is: not certified"
        assert ("The K the cameras use is not certified: it is the bundle adjustment's estimate; the "
                "autocalibration's certified K is shown apart") in lines, lines

    def test_views_not_registered_are_named_by_their_photos(self, page, tmp_path):
        lines = self.verdict_of(page, tmp_path, self.RESULT)
        warning = next(line for line in lines if line.startswith("Warning views_not_registered"))
        assert warning.endswith("3 of 6 views not registered (no camera returned for them): box3.jpg, box4.jpg: "
                                "too few 3D-2D inliers; box5.jpg: not started"), warning  # was "views 3, 4: ..."
        unnamed = json.loads(json.dumps(self.RESULT))
        for camera in unnamed["cameras"]:
            camera["name"] = None
        lines = self.verdict_of(page, tmp_path, unnamed)
        assert any(line.endswith("views 3, 4: too few 3D-2D inliers; views 5: not started") for line in lines)


    def test_a_large_jobs_views_not_registered_are_named_ten_then_counted(self, page, tmp_path):
        """500 photos, 480 not registered: the line named every one (a wall of names); now the
        first 10, as the warning does, and "and 470 more", every view still in the cameras."""
        cameras = [{"view": v, "name": f"IMG_{v:04d}.jpg", "registered": v < 20, "certified": v < 20,
                    "status": "optimal" if v < 20 else "not_run",
                    "reason": None if v < 20 else ("not started" if v % 2 else "too few 3D-2D inliers")}
                   for v in range(500)]
        result = {"summary": {"warnings": [{"code": "views_not_registered", "detail": (
                      "480 of 500 views not registered (no camera returned for them): views 20 (IMG_0020.jpg), "
                      "22 (IMG_0022.jpg), ...: too few 3D-2D inliers; and 470 more")}]},
                  "cameras": cameras, "points": [{"certified": True}]}
        lines = self.verdict_of(page, tmp_path, result)
        warning = next(line for line in lines if line.startswith("Warning views_not_registered"))
        named = [f"IMG_{v:04d}.jpg" for v in range(20, 30)]
        assert all(name in warning for name in named), warning
        assert "IMG_0030.jpg" not in warning and "IMG_0499.jpg" not in warning, warning
        assert "480 of 500 views not registered" in warning and "and 470 more" in warning, warning
        assert "cameras table" in warning, warning
        assert len(warning) < 1000, len(warning)  # was every one of the 480 names


class TestApiKeys:
    def test_the_page_asks_for_the_key_once_and_keeps_it_for_the_tab(self, page, tmp_path):
        process, base = start_service(tmp_path, GEOCERT_API_KEYS=KEY, NO_WORKERS="1")
        try:
            with httpx.Client(base_url=base, timeout=10, headers={"X-API-Key": KEY}) as client:
                job_id = client.post("/v1/jobs", json=service_job(np.random.default_rng(1), tracks=1)).json()["id"]
            page.get(base + "/")
            dialog = wait(page, lambda d: d.find_element(By.ID, "key-dialog").is_displayed()
                          and d.find_element(By.ID, "key-dialog"), 20, "the page did not ask for a key")
            dialog.find_element(By.ID, "key-input").send_keys(KEY + Keys.ENTER)
            wait(page, lambda d: d.find_elements(By.CSS_SELECTOR, f"tr[data-job='{job_id}']"), 20)
            assert page.execute_script("return sessionStorage.getItem('geocert.apiKey');") == KEY
            page.get(f"{base}/jobs/{job_id}")  # the same tab: no second question
            wait(page, lambda d: state(d)["status"] == "queued", 20)
            assert not page.find_element(By.ID, "key-dialog").is_displayed()
            assert page.find_element(By.ID, "cancel").is_enabled()
            page.execute_script("sessionStorage.clear();")  # a new tab's state: the job's page asks, once
            page.get(f"{base}/jobs/{job_id}")
            dialog = wait(page, lambda d: d.find_element(By.ID, "key-dialog").is_displayed()
                          and d.find_element(By.ID, "key-dialog"), 20, "the job's page did not ask for a key")
            dialog.find_element(By.ID, "key-input").send_keys(KEY + Keys.ENTER)
            wait(page, lambda d: state(d)["status"] == "queued", 20)
            assert not page.find_element(By.ID, "key-dialog").is_displayed()
            page.execute_script("sessionStorage.clear();")
        finally:
            stop(process)


class TestRoutesThePageUses:
    def test_a_finished_job_is_sent_as_the_job_model_writes_it_and_its_request_is_kept(self, service):
        from geocert.app.schemas import Job

        body = service_job(np.random.default_rng(11), tracks=3, views=3, certificate="full")
        job_id = service.post("/v1/jobs", json=body).json()["id"]
        wait_job(service, job_id)
        response = service.get(f"/v1/jobs/{job_id}")  # the stored result, sent as stored
        document = response.json()
        assert response.headers["content-type"] == "application/json"
        assert document == json.loads(Job.model_validate(document).model_dump_json(by_alias=True))
        assert document["progress"]["items_certified"] == document["result"]["stats"]["certified"] == 3
        assert service.get(f"/v1/jobs/{job_id}/certificate").json() == document["result"]["certificate"]
        request = service.get(f"/v1/jobs/{job_id}/request").json()
        assert request["data"] == body["data"] and request["options"]["certificate"] == "full"
        assert request["options"]["rel_gap"] == 1e-3  # defaults filled in
        assert service.get("/v1/jobs/0123456789abcdef0123456789abcdef/request").status_code == 404
