"""scripts/bootstrap.sh's system packages (what scripts/test installs beyond the virtual
environment): it says what it installs and why, waits a bounded time for the package lock another
process holds instead of failing at once, and runs the tests even when apt-get still fails.

Run on a copy of the script in a throw-away checkout whose virtual environment is already
installed, with chromium missing from PATH and an apt-get stand-in that records its arguments and,
like the real one, exits 100 at once on a held lock unless given DPkg::Lock::Timeout."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.support import ROOT

FAKE_APT = """#!/bin/sh
echo "$@" >> "{log}"
case "$*" in
  *DPkg::Lock::Timeout=*) exit {status} ;;
  *) echo "E: Could not get lock /var/lib/dpkg/lock-frontend" >&2; exit 100 ;;
esac
"""


def installed_checkout(tmp_path: Path) -> Path:
    """A copy of the script in a checkout whose .venv is installed and current (no pip run)."""
    checkout = tmp_path / "checkout"
    (checkout / "scripts").mkdir(parents=True)
    shutil.copy(ROOT / "scripts" / "bootstrap.sh", checkout / "scripts")
    (checkout / ".venv" / "bin").mkdir(parents=True)
    (checkout / ".venv" / "bin" / "python").symlink_to("/bin/true")
    for name in ("pyproject.toml", "constraints.txt"):
        (checkout / name).write_text("")
        os.utime(checkout / name, (0, 0))
    (checkout / ".venv" / ".installed-test").touch()
    return checkout


def bootstrap(tmp_path: Path, apt_status: int, env: dict | None = None) -> tuple[subprocess.CompletedProcess, list[str]]:
    checkout = installed_checkout(tmp_path)
    bin_dir, log = tmp_path / "bin", tmp_path / "apt.log"
    bin_dir.mkdir()
    for tool in ("dirname", "id", "env", "touch", "sh"):  # what the script runs; no chromium
        (bin_dir / tool).symlink_to(shutil.which(tool))
    (bin_dir / "apt-get").write_text(FAKE_APT.format(log=log, status=apt_status))
    (bin_dir / "sudo").write_text('#!/bin/sh\nexec "$@"\n')
    for tool in ("apt-get", "sudo"):
        (bin_dir / tool).chmod(0o755)
    run = subprocess.run([shutil.which("bash"), str(checkout / "scripts" / "bootstrap.sh"), "test"],
                         env={"PATH": str(bin_dir), **(env or {})}, capture_output=True, text=True, timeout=60)
    return run, log.read_text().splitlines() if log.exists() else []


class TestSystemPackages:
    def test_says_what_it_installs_and_why_and_waits_for_the_lock(self, tmp_path):
        run, calls = bootstrap(tmp_path, apt_status=0)
        assert run.returncode == 0, run.stderr
        assert "chromium chromium-driver nginx openssl" in run.stderr
        assert "browser tests" in run.stderr and "proxy tests" in run.stderr
        assert [call.split()[-1] for call in calls] == ["update", "openssl"], calls
        assert all("DPkg::Lock::Timeout=600" in call for call in calls), calls

    def test_the_wait_is_configurable(self, tmp_path):
        run, calls = bootstrap(tmp_path, apt_status=0, env={"GEOCERT_APT_LOCK_TIMEOUT_S": "30"})
        assert run.returncode == 0, run.stderr
        assert calls and all("DPkg::Lock::Timeout=30" in call for call in calls), calls

    def test_a_failed_install_says_so_and_lets_the_tests_run(self, tmp_path):
        run, calls = bootstrap(tmp_path, apt_status=100)
        assert run.returncode == 0, run.stderr
        assert len(calls) == 1  # the update failed: no install attempted
        assert "could not install" in run.stderr and "test_web.py will fail" in run.stderr

    @pytest.mark.skipif(not all(shutil.which(t) or Path("/usr/sbin", t).exists()
                                for t in ("chromium", "chromedriver", "nginx", "openssl")),
                        reason="checks a machine with the four tools installed")
    def test_nothing_is_installed_when_the_tools_are_there(self, tmp_path):
        checkout = installed_checkout(tmp_path)
        run = subprocess.run(["bash", str(checkout / "scripts" / "bootstrap.sh"), "test"], capture_output=True,
                             text=True, timeout=60)
        assert run.returncode == 0 and "apt-get" not in run.stderr, run.stderr
