#!/usr/bin/env bash
# The lab mission as four processes on loopback (docs/nodes.md, "Running the nodes as separate
# processes"): two mock Avias replaying one `starc sim lab` run at its recorded time, the robot
# node and the rig node, each with its own peak RSS.
#
#   scripts/nodes_as_processes.sh [SIM_DIR [OUT_DIR]]
#   ROS2_CONNECT=tcp/127.0.0.1:7447 scripts/nodes_as_processes.sh ...   # both nodes' ROS 2 bridge on
#
# SIM_DIR (default /tmp/lab_proc) is simulated first when it has no avia.pcap. OUT_DIR (default
# SIM_DIR/processes) gets each process's log, each node's summary (robot.json, fpv.json) and
# recording (robot.mcap, fpv.mcap). Needs target/release/starc (or STARC=path). Loopback only:
# the mocks on 127.0.7.1/127.0.7.2 broadcast to 127.0.0.1 ports; every child is killed on exit.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
STARC=${STARC:-$ROOT/target/release/starc}
SIM=${1:-/tmp/lab_proc}
OUT=${2:-$SIM/processes}
PLAY_S=${PLAY_S:-30}     # the lab run's length
LEAD_S=${LEAD_S:-4}      # time for the nodes to come up and find their mocks
TAIL_S=${TAIL_S:-3}      # time for the last scans after the recording ends

pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
    sleep 1
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

[ -f "$SIM/avia.pcap" ] || "$STARC" sim lab --out "$SIM" --sensors-only
mkdir -p "$OUT"
# The node configs, recording next to their copies in OUT.
sed 's/^# record = /record = /' "$ROOT/config/loopback/robot.toml" > "$OUT/robot.toml"
sed 's/^# record = /record = /' "$ROOT/config/loopback/fpv.toml" > "$OUT/fpv.toml"
if [ -n "${ROS2_CONNECT:-}" ]; then
    for f in "$OUT/robot.toml" "$OUT/fpv.toml"; do
        printf '\n[ros2]\nenabled = true\nconnect = ["%s"]\n' "$ROS2_CONNECT" >> "$f"
    done
fi

LIMIT=$((LEAD_S + PLAY_S + TAIL_S + 30))
START=$(( $(date +%s%N) + LEAD_S * 1000000000 ))
timeout -k 5 -s INT "$LIMIT" "$STARC" robot --config "$OUT/robot.toml" > "$OUT/robot.json" 2> "$OUT/robot.log" &
robot=$!; pids+=("$robot")
timeout -k 5 -s INT "$LIMIT" "$STARC" fpv --config "$OUT/fpv.toml" > "$OUT/fpv.json" 2> "$OUT/fpv.log" &
rig=$!; pids+=("$rig")
for m in "127.0.7.1 55701 192.168.1.101 robot" "127.0.7.2 55702 192.168.2.102 rig"; do
    set -- $m
    timeout -k 5 -s INT "$LIMIT" "$STARC" mock avia --ip "$1" --broadcast-to "127.0.0.1:$2" \
        --source "$SIM/avia.pcap" --capture-device "$3" --recorded-time --start-at-unix-ns "$START" \
        > "$OUT/mock_$4.txt" 2> "$OUT/mock_$4.log" &
    pids+=("$!")
done

# The nodes' own processes (timeout's children), for VmHWM before they exit.
sleep $((LEAD_S + PLAY_S + TAIL_S))
hwm() {
    local pid
    pid=$(pgrep -P "$1" -x starc) || { echo "? (exited)"; return; }
    awk '/VmHWM/ {printf "%.1f", $2 / 1024}' "/proc/$pid/status" || echo "?"
}
# CPU seconds (user + system) the node's process has used.
cpu() {
    local pid
    pid=$(pgrep -P "$1" -x starc) || { echo "?"; return; }
    awk -v hz="$(getconf CLK_TCK)" '{printf "%.2f", ($14 + $15) / hz}' "/proc/$pid/stat" || echo "?"
}
robot_hwm=$(hwm "$robot"); rig_hwm=$(hwm "$rig")
robot_cpu=$(cpu "$robot"); rig_cpu=$(cpu "$rig")
for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done
wait "${pids[@]}" || true
pids=()

echo "VmHWM just before SIGINT: robot node ${robot_hwm} MiB, rig node ${rig_hwm} MiB"
echo "CPU just before SIGINT: robot node ${robot_cpu} s, rig node ${rig_cpu} s"
echo "robot node summary:"; cat "$OUT/robot.json"
echo "rig node summary:"; cat "$OUT/fpv.json"
echo "mocks:"; grep -h "sent" "$OUT"/mock_*.txt || true
