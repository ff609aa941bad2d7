#!/usr/bin/env bash
# README command 2: run the test suite (creates .venv first if it is missing).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$ROOT/scripts/bootstrap.sh"
cd "$ROOT"
# The force board's firmware tests (tests/hardware/test_force_board_sim.py) compile it and run it in simavr. As root with
# apt-get (CI) the Debian packages are installed when missing; elsewhere those tests skip, and this says which.
FIRMWARE_PACKAGES="gcc-avr avr-libc simavr libsimavr-dev make gcc"
if ! { command -v avr-gcc && command -v make && command -v cc && [ -e /usr/include/simavr/sim_avr.h ]; } >/dev/null; then
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null; then
    echo "installing the force-board firmware toolchain: $FIRMWARE_PACKAGES"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $FIRMWARE_PACKAGES; } >/dev/null 2>&1 \
      || echo "warning: could not install $FIRMWARE_PACKAGES; the force-board firmware tests will skip" >&2
  else
    echo "note: apt-get install $FIRMWARE_PACKAGES enables the force-board firmware tests (they skip without)" >&2
  fi
fi
set +e
# The project's lint rules and format (pyproject.toml [tool.ruff]; .pre-commit-config.yaml runs the same).
ruff check . && ruff format --check .
lint=$?
# Idle OpenMP threads sleep instead of spinning (libgomp reads this once, when torch loads): the suite runs torch in
# its own process and in the lerobot-train / lerobot-eval subprocesses it starts, and on 2 cores spinning threads
# of one process starve the others. The package itself sets nothing on import; a user's own setting wins.
export OMP_WAIT_POLICY="${OMP_WAIT_POLICY:-PASSIVE}"
# Two worker processes, each running whole test files (--dist loadfile keeps a file's module fixtures in one
# process): most tests wait on a subprocess or a serial port, which leaves a core idle in one process.
# BLINDGRASP_TEST_WORKERS=0 runs it in one process; a later -n on the command line wins.
python -m pytest -q --durations=15 -n "${BLINDGRASP_TEST_WORKERS:-2}" --dist loadfile "$@"
code=$?
set -e
if [ "$code" -eq 5 ]; then
  echo "error: pytest collected no tests (exit 5); the suite must not be empty" >&2
fi
if [ "$code" -eq 0 ] && [ "$lint" -ne 0 ]; then
  echo "error: ruff check / ruff format --check failed (see above); run: ruff check --fix . && ruff format ." >&2
  code=$lint
fi
exit "$code"
