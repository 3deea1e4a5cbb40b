#!/usr/bin/env bash
# Set everything up, then run the main job: sim, planner and controller working together on
# the default arm, a tour of preset goals with each move's time and error reported, and the
# viewer (a window when there is a display, else a picture rewritten in arm_view.png).
#
#   scripts/run.sh                         # the default arm, one tour, then stop
#   scripts/run.sh config/frc_robot.yaml   # another parameter file
#   TOUR_LOOPS=0 scripts/run.sh            # keep touring until Ctrl-C
#   STAY=1 scripts/run.sh                  # after the tour, keep the arm up for scripts/arm
#
# It ends with one line: how many goals the tour reached, where the picture is, what next.
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

# scripts/arm finds this run's domain here.
echo "$ROS_DOMAIN_ID" > "$ROOT/.run_domain"

pids=()
stop() {
  # The controller first: once idle it asks the planner for the paths between presets.
  for pid in "${pids[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -f "$OVERRIDES" "$ROOT/.run_domain"
}
trap stop EXIT INT TERM

for node in controller sim planner viewer; do
  "$BIN/$node" "${ros_args[@]}" &
  pids+=($!)
done
missed=0
"$BIN/tour" "${ros_args[@]}" || missed=$?

if [ "$missed" -eq 0 ]; then
  outcome="every goal of the tour reached"
else
  outcome="$missed goal(s) of the tour NOT reached (the reasons are above)"
fi
if $headless; then
  picture="the last move: $HERE/arm_view.png"
else
  picture="the viewer window shows the last move"
fi
if [ -n "${STAY:-}" ]; then
  echo "== $outcome; $picture. The arm stays up on ROS domain $ROS_DOMAIN_ID: in another" \
    "terminal try scripts/arm goal 1.1 0.9 (or preset high_score, estop, state); Ctrl-C stops it."
  wait
else
  stop
  trap - EXIT
  echo "== $outcome; $picture. Next: STAY=1 scripts/run.sh, then scripts/arm goal 1.1 0.9" \
    "in another terminal."
fi
[ "$missed" -eq 0 ]
