#!/usr/bin/env bash
# Set up, build and run every test with `colcon test`. Fails when a test fails or none ran.
# Each run gets its own ROS domain with discovery kept on this machine.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# shellcheck disable=SC1091
source "$ROOT/scripts/setup.sh"
cd "$ROOT"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# Text files are UTF-8 (the docs and parameter files have degrees and Greek letters), whatever
# locale a library sets in some thread of the test process.
export PYTHONUTF8=1
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 100) + 1 ))}"

status=0
colcon test --event-handlers console_direct+ \
  --pytest-args -p no:cacheprovider --timeout=300 "$@" || status=$?
summary=$(colcon test-result --all 2>/dev/null | tail -n 1 || true)
echo "colcon: $summary"
# "Summary: 12 tests, 0 errors, 1 failure, 2 skipped"
read -r tests errors failures skipped < <(
  echo "$summary" | sed -E 's/[^0-9]+/ /g' | awk '{print $1+0, $2+0, $3+0, $4+0}')
failed=$(( errors + failures ))
passed=$(( tests - failed - skipped ))
echo "$passed passed, $failed failed, $skipped skipped"
if [ "$tests" -eq 0 ]; then
  echo "no test ran" >&2
  exit 1
fi
[ "$failed" -eq 0 ] && [ "$status" -eq 0 ]
