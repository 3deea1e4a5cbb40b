#!/usr/bin/env bash
# Set up, then run every benchmark; each prints a markdown table. Not part of the tests:
# numbers from a shared machine are for comparison side by side, not for pass/fail.
#   scripts/bench.sh             # all of them (a few minutes; the casadi solves dominate)
#   scripts/bench.sh planner     # one: sim, planner, trajectory, controller, frc_bridge, sysid
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/setup.sh" >/dev/null
cd "$ROOT"
for name in ${1:-sim planner trajectory controller frc_bridge sysid}; do
  echo "== bench_$name"
  if [ "$name" = controller ]; then
    python "bench/bench_$name.py" --minimum
  elif [ "$name" = trajectory ]; then
    python bench/bench_trajectory.py
    python bench/bench_trajectory.py --what-if
    python bench/bench_trajectory.py --planning
  else
    python "bench/bench_$name.py"
  fi
done
