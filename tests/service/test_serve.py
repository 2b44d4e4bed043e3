"""`geocert serve` and `scripts/serve` as a user starts them: the address printed once the
service answers, a second serve in the same checkout refused without harming the first, and
the default worker running a short job beside a long one."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

from geocert.solvers.autocalibration import scenes
from tests.servers import free_port
from tests.support import ROOT

pytestmark = pytest.mark.slow  # real servers: the full run only

ONE_TRACK = {"kind": "triangulation",
             "data": {"cameras": [[[800, 0, 320, 0], [0, 800, 240, 0], [0, 0, 1, 0]],
                                  [[800, 0, 320, -800], [0, 800, 240, 0], [0, 0, 1, 0]]],
                      "tracks": [{"views": [0, 1], "points": [[330, 250], [250, 251]]}]}}


def serve_env(data_dir: Path) -> dict[str, str]:
    env = {key: value for key, value in os.environ.items() if not key.startswith("GEOCERT_")}
    return {**env, "GEOCERT_DATA_DIR": str(data_dir)}


@contextmanager
def serving(data_dir: Path, port: int, *arguments: str):
    """`geocert serve` with its defaults (but the port and data directory), its standard error in
    a file; yields the process and a function reading that file. Stops its whole process group."""
    log_path = data_dir.parent / f"serve-{port}.log"
    with open(log_path, "w") as log:
        process = subprocess.Popen([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port), *arguments],
                                   env=serve_env(data_dir), stdout=log, stderr=log, start_new_session=True)
        try:
            yield process, log_path.read_text
        finally:
            for sig, wait_s in ((signal.SIGTERM, 30), (signal.SIGKILL, 10)):
                try:
                    os.killpg(process.pid, sig)
                    process.wait(timeout=wait_s)
                    break
                except subprocess.TimeoutExpired:
                    continue
                except ProcessLookupError:
                    break


def wait_for_line(read, process, text: str, limit_s: float = 120) -> str:
    deadline = time.monotonic() + limit_s
    while text not in (output := read()):
        assert process.poll() is None, f"geocert serve exited ({process.returncode}):\n{output[-3000:]}"
        assert time.monotonic() < deadline, f"no {text!r} within {limit_s} s:\n{output[-3000:]}"
        time.sleep(0.3)
    return output


def finished(client: httpx.Client, job_id: str, limit_s: float = 120) -> dict:
    deadline = time.monotonic() + limit_s
    while (job := client.get(f"/v1/jobs/{job_id}").json())["status"] not in ("succeeded", "failed", "cancelled"):
        assert time.monotonic() < deadline, f"job still {job['status']}"
        time.sleep(0.2)
    return job


def test_serve_prints_its_address_and_a_second_serve_leaves_the_first_alone(tmp_path):
    data = tmp_path / "var"
    port = free_port()
    with serving(data, port) as (first, read):
        output = wait_for_line(read, first, "ready at")
        assert f"ready at http://127.0.0.1:{port}/" in output
        socket = data / "redis.sock"
        assert socket.exists()

        # The same data directory, another port: refused before anything of the first is touched.
        second = subprocess.run([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(free_port())],
                                env=serve_env(data), capture_output=True, text=True, timeout=60)
        assert second.returncode == 2
        assert "another geocert serve" in second.stderr and str(data.resolve()) in second.stderr
        assert f"pid {first.pid}" in second.stderr
        # The same port, another data directory: refused before its Redis starts.
        other = tmp_path / "other"
        third = subprocess.run([sys.executable, "-m", "geocert.app.cli", "serve", "--port", str(port)],
                               env=serve_env(other), capture_output=True, text=True, timeout=60)
        assert third.returncode == 2 and f"127.0.0.1:{port} is in use" in third.stderr
        assert not (other / "redis.sock").exists()

        assert socket.exists()  # the first's Redis socket is still there, and the first still serves
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:
            assert client.get("/readyz").status_code == 200
            job = finished(client, client.post("/v1/jobs", json=ONE_TRACK).json()["id"])
            assert job["status"] == "succeeded"


def test_the_default_worker_runs_a_short_job_beside_a_long_one(tmp_path):
    """With the defaults (`geocert serve` without --workers or --concurrency), a job that runs to its
    time limits (four cameras without points: the affine stage never closes its gap in its 60 s)
    does not hold the only solver: a one-track job submitted after it ends while it still runs."""
    port = free_port()
    with serving(tmp_path / "var", port) as (process, read):
        wait_for_line(read, process, "ready at")
        data = scenes.make_scene(4, 0.1, seed=5).job_data()
        data.pop("points")
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) as client:
            long_id = client.post("/v1/jobs", json={"kind": "autocalibration", "data": data}).json()["id"]  # 60 s a stage
            deadline = time.monotonic() + 60
            while client.get(f"/v1/jobs/{long_id}").json()["status"] != "running":
                assert time.monotonic() < deadline, "the long job did not start"
                time.sleep(0.2)
            short = finished(client, client.post("/v1/jobs", json=ONE_TRACK).json()["id"], limit_s=300)
            assert short["status"] == "succeeded"
            assert client.get(f"/v1/jobs/{long_id}").json()["status"] == "running"
            assert client.post(f"/v1/jobs/{long_id}/cancel").status_code == 202
            assert finished(client, long_id)["status"] == "cancelled"


def test_scripts_serve_says_what_it_does(tmp_path):
    """scripts/serve in a checkout without .venv says it installs (first run), else that it checks,
    then that it starts: its own lines, with bootstrap.sh and geocert replaced by stand-ins."""
    scripts = tmp_path / "scripts"
    scripts.mkdir()
    shutil.copy2(ROOT / "scripts" / "serve", scripts / "serve")
    (scripts / "bootstrap.sh").write_text("mkdir -p \"$(dirname \"$0\")/../.venv/bin\"\n"
                                          "printf '#!/bin/sh\\necho serve \"$@\"\\n' > \"$(dirname \"$0\")/../.venv/bin/geocert\"\n"
                                          "chmod +x \"$(dirname \"$0\")/../.venv/bin/geocert\"\n")
    first = subprocess.run(["bash", str(scripts / "serve"), "--port", "9"], capture_output=True, text=True, timeout=60)
    assert first.returncode == 0, first.stderr
    assert "installing geocert" in first.stderr and "first run" in first.stderr
    assert "starting" in first.stderr and first.stdout.strip() == "serve serve --port 9"
    again = subprocess.run(["bash", str(scripts / "serve")], capture_output=True, text=True, timeout=60)
    assert "checking the installation" in again.stderr and "installing" not in again.stderr
