#!/usr/bin/env bash
# Set up ./.venv and run the test suite (extra arguments go to pytest).
#   bash scripts/test.sh          the quick suite: every test but those marked slow (a few minutes)
#   bash scripts/test.sh --all    every test; CI (CI=true) always runs every test
#   bash scripts/test.sh -n 1     in one process: by default the tests run in one process per core,
#                                 four at most (pytest-xdist; each builds its own session fixtures and
#                                 computes on its share of the cores, tests/conftest.py; the longest
#                                 tests start first, and an idle process takes half of the other's
#                                 queue: --dist worksteal): on two cores the quick suite takes about
#                                 3 minutes that way (3:07 with other work on the machine), 6 in one process
# Real-data tests read ../shared/mocap (or $TORCHSPLICE_MOCAP) and skip, saying why, without it.
# The viewer's browser tests need Debian's chromium and chromium-driver: installed here with
# apt-get when missing and running as root (set TORCHSPLICE_NO_APT=1 not to); without them those
# tests skip, saying why. Under CI=true, missing real data or browser fail those tests instead.
# The docs extra (mkdocs) lets tests/project/test_docs.py build the documentation site strictly.
set -euo pipefail
cd "$(dirname "$0")/.."
all=0
if [ "${1:-}" = "--all" ]; then all=1; shift; fi
case "${CI:-}" in true|1|yes) all=1 ;; esac
if ! { command -v chromium >/dev/null && command -v chromedriver >/dev/null; } \
    && [ "$(id -u)" = 0 ] && [ -z "${TORCHSPLICE_NO_APT:-}" ] && command -v apt-get >/dev/null; then
  echo "setup: installing chromium and chromium-driver for the browser tests" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null
  apt-get install -y -qq --no-install-recommends chromium chromium-driver >/dev/null
fi
TORCHSPLICE_EXTRAS="test,ray,docs" . scripts/setup_env.sh
# every kernel compiled once here (no-ops once the cache records them: a cache the set-up left
# half-compiled is finished), float64 too, which the known-answer tests splice in, rather than on
# first use in each test process
python -m torchsplice.warmup
python -m torchsplice.warmup --float64
# bytecode kept: where the machine sets PYTHONDONTWRITEBYTECODE, pytest would rewrite every test
# module's asserts again in each process (12 s of each one's start on two cores, 4 s with the cache)
unset PYTHONDONTWRITEBYTECODE
if [ "$all" = 0 ]; then
  echo "test: the quick suite (tests marked slow left out; --all runs them too)" >&2
  set -- -m "not slow" "$@"
fi
case " $* " in
  *" -p no:xdist "*) ;;
  *" -n "*|*" -n"[0-9]*|*" --numprocesses"*)
     case " $* " in *" --dist"*) ;; *) set -- --dist worksteal "$@" ;; esac ;;
  *) _procs="$(nproc 2>/dev/null || echo 1)"
     if [ "$_procs" -gt 4 ]; then _procs=4; fi
     if [ "$_procs" -ge 2 ]; then set -- -n "$_procs" --dist worksteal "$@"; fi ;;
esac
exec python -m pytest "$@"
