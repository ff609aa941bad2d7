#!/usr/bin/env bash
# Creates .venv at the repo root with Python 3.12 and installs this package (editable) with its test extra,
# unless .venv already has it. Sourced by scripts/main.sh and scripts/test.sh.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"

find_python312() {
  for c in python3.12 "$(command -v pyenv >/dev/null 2>&1 && pyenv root 2>/dev/null)/versions/"3.12*/bin/python3.12 \
           "$HOME"/.pyenv/versions/3.12*/bin/python3.12 /usr/bin/python3.12 /usr/local/bin/python3.12; do
    if [ -n "$c" ] && "$c" -c 'import sys; assert sys.version_info[:2] == (3, 12)' >/dev/null 2>&1; then
      echo "$c"; return 0
    fi
  done
  return 1
}

if [ ! -x "$VENV/bin/python" ]; then
  PY="$(find_python312)" || { echo "error: Python 3.12 not found (LeRobot 0.6.1 needs >= 3.12)" >&2; exit 1; }
  echo "creating $VENV with $PY" >&2
  "$PY" -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --upgrade pip
fi
# Re-install only when pyproject.toml changed since the last install (first install: ~5 min, a 4 GB torch).
# The test extra includes the gpu one: MuJoCo Warp (a 150 MB wheel) runs tests/sim/test_sim_warp.py on Warp's CPU
# device. Warp compiles its kernels on first use (about 2 min on 2 cores) into its kernel cache, ~/.cache/warp
# (WARP_CACHE_PATH moves it), and loads them from there in later runs.
EXTRAS="${BLINDGRASP_EXTRAS:-test}"
STAMP="$VENV/.blindgrasp-installed-${EXTRAS//,/-}"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
  echo "installing lerobot_blindgrasp[$EXTRAS] and its dependencies into $VENV" >&2
  "$VENV/bin/pip" install --quiet -e "$ROOT[$EXTRAS]"
  touch "$STAMP"
fi
export PATH="$VENV/bin:$PATH"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
export HF_HUB_OFFLINE="${HF_HUB_OFFLINE:-1}"
