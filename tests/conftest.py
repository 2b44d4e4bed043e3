"""Test-wide settings: property tests draw the same examples on every run (CI must not depend on
luck); set HYPOTHESIS_PROFILE=explore locally to draw new ones. The run's header names the BLAS
kernels loaded (the numerical tests must pass under any: CI runs them under two), and its summary
counts the tests skipped for want of the shared data and says where they looked."""

import os
import time
from pathlib import Path

import pytest
from hypothesis import settings

from tests.support import SHARED_DATA, SHARED_DATA_MISSING, SHARED_DATA_REQUIRED, shared_data

settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# Every certified result the suites produce, in this process and in the workers it starts, is
# checked by the independent verifier before it is returned (geocert/verify/checks.py): a result its own
# certificate does not prove raises SelfCheckFailed. The verifier installs that check when it is
# imported (core.self_check): here, for tests that call a solver directly.
os.environ.setdefault("GEOCERT_SELF_VERIFY", "1")
import geocert.verify.checks  # noqa: E402,F401


def pytest_configure(config):
    config.addinivalue_line("markers", "shared_data(*names): needs these data sets of ../shared/data "
                                       "(skipped without them, failed when GEOCERT_REQUIRE_SHARED_DATA=1)")
    if os.environ.get("GEOCERT_CPU_DURATIONS"):
        config.pluginmanager.register(CpuDurations(Path(os.environ["GEOCERT_CPU_DURATIONS"])))


class CpuDurations:
    """GEOCERT_CPU_DURATIONS=<file>: each test's setup, call and teardown in CPU seconds (this
    process's, and its children's it waited for), appended to <file> as --durations=0 writes
    wall seconds, for scripts/slow_tests.py: with other work on the machine, CPU time measures a
    test where wall time does not."""

    def __init__(self, path: Path):
        self.path = path

    @staticmethod
    def _cpu_seconds() -> float:
        children = os.times()
        return time.process_time() + children.children_user + children.children_system

    def _timed(self, phase: str, item):
        before = self._cpu_seconds()
        yield
        seconds = self._cpu_seconds() - before
        with self.path.open("a") as out:
            out.write(f"{seconds:.3f}s {phase} {item.nodeid}\n")

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_setup(self, item):
        yield from self._timed("setup", item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_call(self, item):
        yield from self._timed("call", item)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_teardown(self, item):
        yield from self._timed("teardown", item)


def blas_kernels() -> list[str]:
    """What each loaded OpenBLAS (numpy's, scipy's, OpenCV's) runs: library, version, kernel."""
    import cv2  # noqa: F401  (OpenCV brings its own OpenBLAS)
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info

    return sorted(f"{os.path.basename(i['filepath'])} {i.get('version')} {i.get('architecture', '?')} "
                  f"{i.get('num_threads')} threads" for i in threadpool_info() if i.get("internal_api") == "openblas")


def numpy_simd() -> str:
    """The SIMD extensions numpy's own loops dispatch to (NPY_DISABLE_CPU_FEATURES removes some)."""
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # numpy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return " ".join(name for name in __cpu_dispatch__ if __cpu_features__.get(name)) or "baseline only"


def pytest_report_header(config):
    found = "found" if SHARED_DATA.is_dir() else "MISSING: the tests that need it skip"
    return [f"BLAS: {'; '.join(blas_kernels())} (OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '')})",
            f"numpy SIMD: {numpy_simd()}",
            f"shared data: {SHARED_DATA} ({found}{', required' if SHARED_DATA_REQUIRED else ''})"]


SLOW_TESTS = Path(__file__).with_name("slow_tests.txt")


def pytest_collection_modifyitems(config, items):
    """Tests and files measured slow (slow_tests.txt, written by scripts/slow_tests.py from a
    run's durations) are marked slow as well as those marked in their files, so that the quick
    tier (-m "not slow") stays quick."""
    measured = {line.strip() for line in SLOW_TESTS.read_text().splitlines()
                if line.strip() and not line.startswith("#")} if SLOW_TESTS.exists() else set()
    for item in items:
        owners = item.nodeid.split("[")[0].split("::")  # its file, class and function
        if item.nodeid in measured or any("::".join(owners[:n]) in measured for n in range(1, len(owners) + 1)):
            item.add_marker(pytest.mark.slow)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    for mark in item.iter_markers("shared_data"):
        for name in mark.args:
            shared_data(name)


def pytest_terminal_summary(terminalreporter):
    skipped = [r for r in terminalreporter.stats.get("skipped", [])
               if isinstance(r.longrepr, tuple) and SHARED_DATA_MISSING in r.longrepr[2]]
    if skipped:
        terminalreporter.write_sep("=", f"{len(skipped)} tests skipped for want of the shared data", yellow=True)
        terminalreporter.write_line(f"They looked in {SHARED_DATA}: put Oxford Dinosaur, Oxford Model House and "
                                    f"Middlebury dinoSparseRing there (../shared/data beside the checkout), or set "
                                    f"GEOCERT_SHARED_DATA to their folder. CI sets GEOCERT_REQUIRE_SHARED_DATA=1, "
                                    f"which fails these tests instead.")
