#!/usr/bin/env bash
# Creates .venv beside the checkout and installs geocert into it (with test extras when asked),
# every package at the version constraints.txt pins (the versions the tests were run with).
# Idempotent: re-installs only when pyproject.toml or constraints.txt changed since the last install.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
extras="${1:-}"
python="${PYTHON:-python3}"
venv="$root/.venv"
stamp="$venv/.installed${extras:+-$extras}"
if [ ! -x "$venv/bin/python" ]; then
  "$python" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip
fi
if [ ! -f "$stamp" ] || [ "$root/pyproject.toml" -nt "$stamp" ] || [ "$root/constraints.txt" -nt "$stamp" ]; then
  target="$root"
  [ -n "$extras" ] && target="$root[$extras]"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -c "$root/constraints.txt" -e "$target"
  touch "$stamp"
fi
# geocert's own modules compiled to bytecode, as a wheel's install compiles them: the editable
# install leaves them to each process, and where PYTHONDONTWRITEBYTECODE is set (as on this project's
# machines) every `geocert solve` compiled some 120 modules again (about 0.4 s of its CPU). Up-to-date
# files are skipped; a module edited since is compiled again in memory, never read stale.
"$venv/bin/python" -m compileall -q "$root/geocert" >/dev/null || true
# System packages, for the test extras only: the web page's browser tests (tests/service/test_web.py)
# need Debian's chromium and chromium-driver, the TLS proxy tests (tests/service/test_proxy.py)
# nginx and openssl. When any is missing they are installed with apt-get (sudo unless root), so
# the test command and CI run those tests rather than skip them. apt-get waits for the package
# lock another process holds (an unattended upgrade, another install) for up to
# GEOCERT_APT_LOCK_TIMEOUT_S seconds (default 600) instead of failing at once. When the install
# still fails, the other tests run anyway, and the browser tests fail naming what is missing.
if [ "$extras" = "test" ]; then
  missing=""
  for tool in chromium chromedriver nginx openssl; do
    command -v "$tool" >/dev/null 2>&1 || [ -x "/usr/sbin/$tool" ] || missing="$missing $tool"
  done
  if [ -n "$missing" ]; then
    packages="chromium chromium-driver nginx openssl"
    wait_s="${GEOCERT_APT_LOCK_TIMEOUT_S:-600}"
    sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    echo "scripts/bootstrap.sh: missing$missing; installing Debian packages $packages with ${sudo:+sudo }apt-get" >&2
    echo "  (the browser tests drive chromium through chromedriver; the TLS proxy tests run nginx with" >&2
    echo "  an openssl certificate), waiting up to ${wait_s} s for the package lock if another process holds it" >&2
    apt=($sudo env DEBIAN_FRONTEND=noninteractive apt-get -qq -o "DPkg::Lock::Timeout=$wait_s")
    if ! { "${apt[@]}" update && "${apt[@]}" install -y $packages >/dev/null; }; then
      echo "scripts/bootstrap.sh: apt-get could not install $packages (output above); running the tests" >&2
      echo "  anyway: tests/service/test_web.py will fail and tests/service/test_proxy.py skip until they are installed" >&2
    fi
  fi
fi
