#!/usr/bin/env bash
# A ground station sees the vehicle through the executive: MAVProxy 1.8.75 on `lrauv exec --gcs`.
#
# Runs the simulator (`lrauv sim`, ArduSub-like, at 10x), the executive with a ground-station
# link, and MAVProxy as the ground station, fed commands on its standard input, then checks what
# MAVProxy printed: the vehicle's position (the autopilot's GLOBAL_POSITION_INT, forwarded),
# ArduSub's mode list (`mode` with no argument), the executive's goals (`wp list`), its file
# store (`ftp list`) and its parameters (`param fetch` / `param show EXEC*`). Not part of
# `make test`; MAVProxy is not a dependency of this project: it is installed into a venv of its
# own (MAVPROXY_VENV, default /tmp/lrauv-mavproxy-venv). docs/ground-station.md shows a run.
#
#   bench/gcs_mavproxy_check.sh [WORK_DIR]        (default out/gcs-check)
#
# Ports: the simulator listens on 127.0.0.1:$SIM_PORT (14560), the executive's ground-station
# link on 127.0.0.1:$GCS_PORT (14551). Exit status 0 when every check passed.
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-out/gcs-check}
VENV=${MAVPROXY_VENV:-/tmp/lrauv-mavproxy-venv}
SIM_PORT=${SIM_PORT:-14560}
GCS_PORT=${GCS_PORT:-14551}
START=-117.96,33.34
LRAUV=.venv/bin/lrauv
mkdir -p "$WORK"

if [ ! -x "$VENV/bin/mavproxy.py" ]; then
  echo "installing MAVProxy 1.8.75 into $VENV"
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet MAVProxy==1.8.75
fi
if [ ! -f "$WORK/demo.lrpt" ]; then
  "$LRAUV" forecast synth "$WORK/forecast.nc" --issue 0
  "$LRAUV" plan missions/demo.yaml --forecast "$WORK/forecast.nc" --out "$WORK/demo.lrpt" --start "$START,0,0"
fi

# The simulator's GCS failsafe watches the executive (MAV_GCS_SYSID 1, as docs/executive.md advises for an
# AUV): MAVProxy's heartbeats, forwarded to it, come once a wall second, ten vehicle seconds apart at 10x.
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT
"$LRAUV" sim --forecast "$WORK/forecast.nc" --start "$START" --speedup 10 --listen "127.0.0.1:$SIM_PORT" --gcs-sysid 1 \
  --quiet > "$WORK/sim.txt" 2>&1 &
pids+=($!)
"$LRAUV" exec --table "$WORK/demo.lrpt" --mission missions/demo.yaml --link "udpout:127.0.0.1:$SIM_PORT" \
  --gcs "udpin:127.0.0.1:$GCS_PORT" --log "$WORK/exec.mcap" > "$WORK/exec.txt" 2>&1 &
pids+=($!)

# MAVProxy reads its commands from standard input and ends at its end. `mode` lists the modes of
# the vehicle it picked from the heartbeats; `wp`, `ftp` and `param` go to target_component 191.
{
  sleep 8
  echo "mode"
  sleep 1
  echo "status GLOBAL_POSITION_INT"
  echo "status HEARTBEAT"
  sleep 1
  echo "set target_component 191"
  echo "wp list"
  sleep 3
  echo "ftp list /"
  sleep 3
  echo "param fetch"
  sleep 3
  echo "param show EXEC*"
  sleep 1
} | "$VENV/bin/mavproxy.py" --master="udpout:127.0.0.1:$GCS_PORT" --no-state --state-basedir="$WORK" \
      > "$WORK/mavproxy.txt" 2>&1 || true

out="$WORK/mavproxy.txt"
status=0
check() {  # check WHAT PATTERN: one line of $out matches PATTERN (extended regular expression)
  if grep -Eq "$2" "$out"; then echo "ok      $1: $(grep -Em1 "$2" "$out" | cut -c1-110)"
  else echo "FAILED  $1 (no line matching /$2/ in $out)"; status=1; fi
}
check "vehicle picked from the autopilot's heartbeat" "Detected vehicle 1:1 on"
check "ArduSub's modes listed" "Available modes: .*SURFACE"
check "position forwarded" "GLOBAL_POSITION_INT .*lat ?: ?33"
check "the executive's goals (wp list)" "Requesting [0-9]+ waypoints"
check "the executive's file store (ftp list)" " D tables"
check "the executive's parameters" "EXEC_MAX_DEPTH_M"
exit $status
