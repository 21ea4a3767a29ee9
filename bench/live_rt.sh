#!/bin/bash
# nao_rt on live cameras (docs/cameras.md): held-out synthetic recordings of whole_arm, rendered
# as two cameras of OpenPose JSON at 30 Hz, are replayed one after the other by
# `nao_toolchain replay` into camera folders that do not exist when nao_rt starts, as OpenPose
# --write_json fills them; nao_rt --realtime runs the compiled-in reference-conditioned policy on
# the ODE arm for the whole replay. Prints the load average before and after, then per run:
# overruns, tick time, the latency from a frame's newest file appearing to the tick that used its
# skeleton, allocations on the control thread after activate and the camera counters.
# Usage: bench/live_rt.sh [BUILD_DIR] [RECORDINGS] > result.txt   (RECORDINGS default 4, ~14 s each)
set -euo pipefail
build="${1:-build}"
count="${2:-4}"
tc="$build/bin/nao_toolchain"
rt="$build/bin/nao_rt"
for exe in "$tc" "$rt"; do
  [[ -x "$exe" ]] || { echo "live_rt.sh: $exe not built (toolchain/nao build)" >&2; exit 1; }
done
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$tc" synth --movement whole_arm --per-movement "$count" --seed 1000001 --out "$tmp/rec" >/dev/null
frames=0
for rec in "$tmp"/rec/whole_arm_*/; do
  frames=$((frames + $(find "$rec/cam0" -name '*_keypoints.json' | wc -l)))
done
seconds=$(((frames + 29) / 30 + 3))
echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); host: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
echo "recordings: $count held-out whole_arm demonstrations (synth --seed 1000001), $frames frames per camera at 30 Hz, replayed back to back"
echo "uptime before: $(uptime)"
cmd=("$rt" --reference "openpose:$tmp/rig/cam0,$tmp/rig/cam1" --calibration "$tmp/rec/whole_arm_000/calibration.json"
  --movement whole_arm --realtime --seconds "$seconds" --log "$tmp/run")
echo "command: ${cmd[*]//$tmp/TMP}"
"${cmd[@]}" >"$tmp/rt.txt" 2>&1 &
rt_pid=$!
sleep 1
for rec in "$tmp"/rec/whole_arm_*/; do
  "$tc" replay --recording "$rec" --to "$tmp/rig/cam0,$tmp/rig/cam1" >>"$tmp/replay.txt" 2>&1
done
wait "$rt_pid" || { cat "$tmp/rt.txt" >&2; exit 1; }
echo "uptime after:  $(uptime)"
/usr/bin/python3 - "$tmp/run/summary.json" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
c, t = s["camera"], s["tick_us"]
print(f"ticks {s['ticks']}, overruns {s['overruns']}, allocations after activate {s['allocations_after_activate']} "
      f"(reader thread {c['reader_allocations']})")
print(f"tick_us p50 {t['p50']:.0f}  p99 {t['p99']:.0f}  max {t['max']:.0f}")
l = c["latency_ms"]
print(f"frame file -> tick that used it [ms]: p50 {l['p50']:.1f}  p99 {l['p99']:.1f}  max {l['max']:.1f}  (n {l['n']})")
skip = {"latency_ms", "human_scale_m", "reader_allocations"}
print("camera: " + ", ".join(f"{k} {v}" for k, v in c.items() if k not in skip))
print("faults (ticks): " + (", ".join(f"{k} {v}" for k, v in s["faults"].items() if v) or "none"))
EOF
