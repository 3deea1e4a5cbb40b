#!/usr/bin/env bash
# Set everything up, then run the main job: sim, planner and controller working together on
# the default arm, a tour of preset goals with each move's time and error reported, and the
# viewer (a window when there is a display, else a picture rewritten in arm_view.png).
#
#   scripts/run.sh                         # the default arm, one tour, then stop
#   scripts/run.sh config/frc_robot.yaml   # another parameter file
#   TOUR_LOOPS=0 scripts/run.sh            # keep touring until Ctrl-C
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PARAMS="$(realpath "${1:-$ROOT/config/arm.yaml}")"
HERE="$PWD"
# shellcheck disable=SC1091
source "$ROOT/scripts/setup.sh"
# Where `ros2 run arm_control <name>` looks: <prefix>/lib/arm_control/<name>.
BIN="$(python -c 'from ament_index_python.packages import get_package_prefix as p
print(p("arm_control"))')/lib/arm_control"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 1 ))}"
echo "== running on ROS domain $ROS_DOMAIN_ID with $PARAMS"

# Run-time overrides as a second parameter file: a `-p` override applies to `/**`, which the
# node sections of $PARAMS (`/viewer:`, `/tour:`) would outrank.
OVERRIDES="$(mktemp --suffix=.yaml)"
headless=false
if [ -z "${DISPLAY:-}" ]; then
  headless=true
  echo "== no display: the viewer draws to $HERE/arm_view.png"
fi
cat > "$OVERRIDES" <<YAML
/viewer:
  ros__parameters: {headless: $headless, png_path: "$HERE/arm_view.png"}
/tour:
  ros__parameters: {loops: ${TOUR_LOOPS:-1}}
YAML
ros_args=(--ros-args --params-file "$PARAMS" --params-file "$OVERRIDES")

pids=()
stop() {
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -f "$OVERRIDES"
}
trap stop EXIT INT TERM

for node in sim planner controller viewer; do
  "$BIN/$node" "${ros_args[@]}" &
  pids+=($!)
done
"$BIN/tour" "${ros_args[@]}"
sleep 1                               # one more picture of where the tour ended
