#!/bin/bash
# LoLA round trip per cycle (docs/lola.md): nao_lola_sim + nao_rt --robot lola for >= 10,000
# cycles of 12 ms (1200 ticks, about 2 min 10 s of real time per mode), once in the default
# mode (the packet that ends a tick is answered after the tick) and once with
# --lola-answer-first. Prints p50/p99/max of
#   - nao_rt's side: sensor packet complete -> actuator packet sent (summary.json lola.round_trip_us),
#   - the robot's side: sensor packet sent -> actuator packet complete (nao_lola_sim --summary),
# with the load average before and after. Usage: bench/lola_roundtrip.sh [BUILD_DIR] > result.txt
# The autonomous-mode model runs its policy on every tick (a synthetic reference ends after
# ~13 s, after which the controller bypasses the policy and the ticks get cheap).
# MODEL (default models/autonomous.bin) and NAO_RT (default BUILD_DIR/bin/nao_rt) choose the model
# and the nao_rt of its dimensions: models/autonomous.bin is of the small configuration, so
# NAO_RT=$(toolchain/nao build --model models/autonomous.bin | tail -n 1); the committed results
# ran the paper configuration's autonomous model of their date.
# Environment: PRECISION=fp32|int8 (nao_rt --precision, default fp32); NAO_POLICY_KERNEL=sse|avx2|avx512
# (nao_rt --policy-kernel, default the best this CPU runs); MODES="default no-warm
# answer-first io-thread" (any subset, in that order; default: default and answer-first).
# no-warm: the default without warming the cache before the tick's packet (--lola-no-warm).
set -euo pipefail
build="${1:-build}"
precision="${PRECISION:-fp32}"
modes="${MODES:-default answer-first}"
model="${MODEL:-models/autonomous.bin}"
nao_rt="${NAO_RT:-$build/bin/nao_rt}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); host: $(nproc) cores; precision $precision"
for mode in $modes; do
  flags=(--precision "$precision")
  [[ -n "${NAO_POLICY_KERNEL:-}" ]] && flags+=(--policy-kernel "$NAO_POLICY_KERNEL")
  case "$mode" in
    default) ;;
    no-warm) flags+=(--lola-no-warm) ;;
    answer-first) flags+=(--lola-answer-first) ;;
    io-thread) flags+=(--lola-io-thread) ;;
    *) echo "lola_roundtrip.sh: unknown mode '$mode'" >&2; exit 2 ;;
  esac
  echo
  echo "## mode: $mode"
  echo "uptime before: $(uptime)"
  "$build/bin/nao_lola_sim" --socket "$tmp/lola.sock" --seconds 200 --summary "$tmp/sim.json" 2>/dev/null &
  sim=$!
  sleep 0.5
  cmd=("$nao_rt" --robot "lola:$tmp/lola.sock" --weights "$model" --reference none --movement whole_arm --ticks 1200 --log "$tmp/run" "${flags[@]}")
  echo "command: ${cmd[*]/$tmp/TMP}"
  "${cmd[@]}" > "$tmp/out.txt"
  kill -TERM "$sim"
  wait "$sim" || true
  echo "uptime after:  $(uptime)"
  /usr/bin/python3 - "$tmp/run/summary.json" "$tmp/sim.json" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1])); sim = json.load(open(sys.argv[2]))
l, r = s["lola"], sim["round_trip_us"]
print(f"cycles answered: {l['cycles']} (late by nao_rt's count: {l['late']}; malformed {l['malformed']})")
print(f"nao_rt side, packet in -> answer out [us]: p50 {l['round_trip_us']['p50']:.1f}  p99 {l['round_trip_us']['p99']:.1f}  max {l['round_trip_us']['max']:.1f}")
print(f"robot side, packet sent -> answer in [us]: p50 {r['p50']:.1f}  p99 {r['p99']:.1f}  max {r['max']:.1f}  (n {r['n']})")
print(f"answered within the 12 ms cycle (robot side): {sim['answered_in_cycle']} of {sim['sent']} sent "
      f"({100.0 * sim['answered_in_cycle'] / max(1, sim['sent']):.2f} %)")
print(f"ticks {s['ticks']}, tick_us p50 {s['tick_us']['p50']:.0f} p99 {s['tick_us']['p99']:.0f} max {s['tick_us']['max']:.0f}, "
      f"allocations after activate {s['allocations_after_activate']}")
if l.get("warm"):
    print(f"cache warmed before each tick's packet: {l['warm_us_mean']:.0f} us per tick (mean)")
EOF
done
