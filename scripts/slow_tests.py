"""Write tests/slow_tests.txt from a run's durations, so that the quick tier (-m "not slow") stays
quick: a file whose tests take more than FILE_S in all is slow as a whole (its module fixtures
included), and any other test taking more than TEST_S; a test whose setup takes that long is a
shared fixture's first user, so its class (or file) is marked, or the next test would pay it. The
entries of the list already there are kept: run it again on the quick tier's durations to add
what was hidden behind them.

    GEOCERT_CPU_DURATIONS=durations.txt scripts/test -m "not slow" -p no:randomly
    .venv/bin/python scripts/slow_tests.py durations.txt

GEOCERT_CPU_DURATIONS has the conftest write each test's setup, call and teardown in CPU seconds
(the test process's and the children's it waited for), in the form --durations=0 prints wall
seconds (which the script reads too: `--durations=0 --durations-min=0.2 > durations.txt`). CPU
seconds are the measure on a machine other work loads: wall seconds there mark nearly every test
slow. The list is a measurement, kept in the repository beside the tests, and the conftest marks
what it names (tests/conftest.py)."""

from __future__ import annotations

import re
import sys
from collections import defaultdict
from pathlib import Path

FILE_S = 8.0
TEST_S = 0.5
LIST = Path(__file__).resolve().parents[1] / "tests" / "slow_tests.txt"
LINE = re.compile(r"^\s*([0-9.]+)s (setup|call|teardown)\s+(.+?)\s*$")  # a test id may hold spaces (its parameters)


def main(path: str) -> None:
    by_test: dict[str, float] = defaultdict(float)
    owners = set()  # the class or file of a test whose setup (a shared fixture) is slow
    for line in Path(path).read_text().splitlines():
        match = LINE.match(line)
        if match:
            by_test[match.group(3)] += float(match.group(1))
            if match.group(2) == "setup" and float(match.group(1)) > TEST_S:
                owners.add(match.group(3).split("[")[0].rsplit("::", 1)[0])
    by_file: dict[str, float] = defaultdict(float)
    for test, seconds in by_test.items():
        by_file[test.split("::")[0]] += seconds
    files = sorted(name for name, seconds in by_file.items() if seconds > FILE_S)
    tests = sorted(test for test, seconds in by_test.items()
                   if seconds > TEST_S and test.split("::")[0] not in files)
    before = {line.strip() for line in LIST.read_text().splitlines()
              if line.strip() and not line.startswith("#")} if LIST.exists() else set()
    entries = sorted(before | set(files) | set(tests) | owners)
    header = [f"# Measured slow (scripts/slow_tests.py): files over {FILE_S:g} s in all, tests over {TEST_S:g} s,",
              "# and the class or file of a test whose setup (a shared fixture) took that long."]
    LIST.write_text("\n".join(header + entries) + "\n")
    print(f"{len(entries) - len(before)} entries added, {len(entries)} in all")


if __name__ == "__main__":
    main(sys.argv[1])
