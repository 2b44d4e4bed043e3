"""An API process `geocert serve` started ends when `geocert serve` is gone, even if its own
shutdown never finishes: the process below plays one whose server ignores the request to stop."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

STUCK_API_PROCESS = textwrap.dedent("""
    import os, sys, time, types
    from geocert.app import lifecycle
    server = types.SimpleNamespace(should_exit=False)  # a server whose shutdown never ends
    lifecycle._end_when_orphaned(server, os.getppid(), grace_s=1.0, poll_s=0.1)
    print(os.getpid(), flush=True)
    while True:
        time.sleep(1)
""")

PARENT = textwrap.dedent("""
    import subprocess, sys, time
    child = subprocess.Popen([sys.executable, "-c", sys.argv[1]], stdout=sys.stdout)
    time.sleep(600)
""")


def test_an_api_process_whose_shutdown_hangs_still_ends_when_its_parent_dies():
    parent = subprocess.Popen([sys.executable, "-c", PARENT, STUCK_API_PROCESS], stdout=subprocess.PIPE,
                              start_new_session=True)
    try:
        child = int(parent.stdout.readline())
        time.sleep(0.5)
        assert _alive(child)  # it waits while its parent lives
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait(timeout=10)
        deadline = time.monotonic() + 30
        while _alive(child):
            assert time.monotonic() < deadline, "the orphaned process still runs 30 s after its parent died"
            time.sleep(0.1)
    finally:
        try:
            os.killpg(parent.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False
