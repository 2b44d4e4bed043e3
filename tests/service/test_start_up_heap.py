"""An API process's start-up heap leaves the cyclic collector's generations once it serves
(app.lifecycle.Server, jobs.collection.start_up_heap_frozen): its collections then scan only
what requests make. A solver process's: tests/workers/test_solvers_loaded.py."""

from __future__ import annotations

import json
import os
import subprocess
import sys

_SERVE = """
import asyncio, gc, json
import uvicorn
from geocert.app import lifecycle

async def app(scope, receive, send):
    pass

config = uvicorn.Config(app, host="127.0.0.1", port=0, lifespan="off", log_level="warning")
config.load()
server = lifecycle.Server(config)
server.lifespan = config.lifespan_class(config)

async def main():
    before = gc.get_freeze_count()
    await server.startup()
    after = gc.get_freeze_count()
    await server.shutdown()
    return {"before": before, "after": after, "enabled": gc.isenabled()}

print(json.dumps(asyncio.run(main())))
"""


def test_an_api_process_freezes_its_start_up_heap_once_it_serves(tmp_path):
    out = subprocess.run([sys.executable, "-c", _SERVE], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                         env={"PATH": "/usr/bin:/bin", "PYTHONPATH": os.environ.get("PYTHONPATH", ""),
                              "GEOCERT_DATA_DIR": str(tmp_path)})
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["before"] == 0
    assert seen["after"] > 10_000  # uvicorn's, the app's and their modules' objects, not a handful
    assert seen["enabled"]  # the collector stays on, for the cycles requests make
