"""Write tests/slow_tests.txt from a run's durations, so that the quick tier (-m "not slow") stays
quick: a file whose tests take more than FILE_S in all is slow as a whole (its module fixtures
included), and any other test taking more than TEST_S.

    scripts/test -m "not slow" -p no:randomly --durations=0 --durations-min=0.2 > durations.txt
    .venv/bin/python scripts/slow_tests.py durations.txt

Durations are wall clock on the machine measured; the list is a measurement, kept in the
repository beside the tests, and the conftest marks what it names (tests/conftest.py)."""

from __future__ import annotations

import re
import sys
from collections import defaultdict
from pathlib import Path

FILE_S = 8.0
TEST_S = 1.0
LIST = Path(__file__).resolve().parents[1] / "tests" / "slow_tests.txt"
LINE = re.compile(r"^\s*([0-9.]+)s (setup|call|teardown)\s+(\S+)")


def main(path: str) -> None:
    by_test: dict[str, float] = defaultdict(float)
    for line in Path(path).read_text().splitlines():
        match = LINE.match(line)
        if match:
            by_test[match.group(3)] += float(match.group(1))
    by_file: dict[str, float] = defaultdict(float)
    for test, seconds in by_test.items():
        by_file[test.split("::")[0]] += seconds
    files = sorted(name for name, seconds in by_file.items() if seconds > FILE_S)
    tests = sorted(test for test, seconds in by_test.items()
                   if seconds > TEST_S and test.split("::")[0] not in files)
    kept = sum(seconds for test, seconds in by_test.items() if test.split("::")[0] not in files and test not in tests)
    header = [f"# Measured slow (scripts/slow_tests.py): files over {FILE_S:g} s in all, then tests over {TEST_S:g} s.",
              f"# The quick tier's measured tests left: {kept:.0f} s of those over the run's --durations-min."]
    LIST.write_text("\n".join(header + files + tests) + "\n")
    print(f"{len(files)} files, {len(tests)} tests marked slow; {kept:.0f} s measured left in the quick tier")


if __name__ == "__main__":
    main(sys.argv[1])
