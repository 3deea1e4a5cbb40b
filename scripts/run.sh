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
# shellcheck disable=SC1091
source "$ROOT/scripts/setup.sh"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 1 ))}"
echo "== running on ROS domain $ROS_DOMAIN_ID with $PARAMS"

pids=()
stop() {
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap stop EXIT INT TERM

for node in sim planner controller; do
  ros2_run_args=(--ros-args --params-file "$PARAMS")
  "$ROOT/install/lib/arm_control/$node" "${ros2_run_args[@]}" &
  pids+=($!)
done
viewer_args=(--ros-args --params-file "$PARAMS")
if [ -z "${DISPLAY:-}" ]; then
  viewer_args+=(-p headless:=true -p "png_path:=$PWD/arm_view.png")
  echo "== no display: the viewer draws to $PWD/arm_view.png"
fi
"$ROOT/install/lib/arm_control/viewer" "${viewer_args[@]}" &
pids+=($!)

"$ROOT/install/lib/arm_control/tour" --ros-args --params-file "$PARAMS" \
  -p "loops:=${TOUR_LOOPS:-1}"
