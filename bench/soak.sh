#!/bin/bash
# Soak test of the whole robot stack (docs/lola.md, docs/cameras.md, docs/attention_bin.md):
#   nao_lola_sim (the simulated NAO, LoLA's 12 ms clock)  <-- Unix socket -->  nao_rt --robot lola
#   nao_toolchain replay (two OpenPose camera folders at 30 fps)  -->  nao_rt --reference openpose:
#   nao_rt --attention-shm NAME  -->  nao_attn_tail NAME (every record, all the while)
# for an hour by default, with faults every few minutes: a packet gap (--drop, 6 or 40 cycles),
# a garbage packet (--garbage), malformed packets (--bad-length, 3 cycles) and a camera folder
# moved away for a second while its replayer writes (its writer fails and is restarted at the
# frame due once the folder is back, like an OpenPose that lost its output folder; the move waits
# until it falls >= 3 s from a replay loop's start and end). The run ends
# with SIGINT (the safe stop). nao_rt cannot reconnect to LoLA (a lost link ends the run, exit 3),
# so the hang-up is tested after the soak: a robot that closes the socket, then a restarted nao_rt
# on a new LoLA connection (what a supervisor would do), timed.
#
# nao_rt runs as on the robot: --realtime (SCHED_FIFO 50 + mlockall) and --lola-io-thread (the
# robot build's default); nao_lola_sim runs SCHED_FIFO 50 as LoLA does on the robot (when the
# machine permits it). The replayer and nao_attn_tail stay ordinary processes.
#
# The recording: held-out synthetic demonstration whole_arm_000 (synth --seed 1000001), looped
# back to back. A live rig has one calibration and synth samples a camera rig per recording,
# so the loop replays one recording (the others would be triangulated with a wrong calibration).
#
# Writes the report (default bench/results/soak.txt): the commands, load average before/after,
# faults injected against counted, each fault's recovery in ticks (ticks.csv and the attention
# stream), the run directory's size per hour, the attention reader's record check, nao_rt's RSS
# and open fds every 5 s, allocations after activate, overruns, the SIGINT stop, the hang-up and
# restart, and the acceptance items met or not. Exit 0 when all are met, 1 when one is not, 2 on
# a usage or set-up problem. Every process it starts is stopped on any exit (trap); no shared
# memory is left behind.
#
# Usage: bench/soak.sh [--minutes N (1-60, default 60)] [--build DIR (default build)]
#                      [--out FILE (default bench/results/soak.txt)] [--keep DIR (copy the run's files)]
#        bench/soak.sh --report DIR [--out FILE]   (the report again from a --keep folder)
# Environment: NAO_TOOLCHAIN (default BUILD/bin/nao_toolchain) for synth and replay.
set -uo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
minutes=60
build="$root/build"
out="$root/bench/results/soak.txt"
keep=""
report_dir=""
die() { echo "soak.sh: $2" >&2; exit "$1"; }
while (($#)); do
  case "$1" in
    --minutes) minutes="${2:-}"; shift 2 || die 2 "--minutes needs a value" ;;
    --build) build="${2:-}"; shift 2 || die 2 "--build needs a value" ;;
    --out) out="${2:-}"; shift 2 || die 2 "--out needs a value" ;;
    --keep) keep="${2:-}"; shift 2 || die 2 "--keep needs a value" ;;
    --report) report_dir="${2:-}"; shift 2 || die 2 "--report needs a value" ;;
    -h | --help) sed -n '2,/^set -uo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die 2 "unknown argument '$1' (see --help)" ;;
  esac
done
[[ "$minutes" =~ ^[0-9]+$ ]] && ((minutes >= 1 && minutes <= 60)) ||
  die 2 "--minutes takes a whole number from 1 to 60 (nao_rt runs at most 36,000 ticks)"
# The report from a run's files (the temporary folder, or a --keep copy): DIR OUT.
report() {
  /usr/bin/python3 - "$1" "$2" <<'EOF'
import collections, csv, json, os, sys

tmp, out = sys.argv[1], sys.argv[2]
P = collections.defaultdict(lambda: "?", (l.rstrip("\n").split("=", 1) for l in open(os.path.join(tmp, "params.txt")) if "=" in l))
lines, acc = [], []
def say(s=""):
    lines.append(s)
def accept(ok, what):
    acc.append((bool(ok), what))

def load(path):
    try:
        with open(os.path.join(tmp, path)) as f:
            return json.load(f)
    except Exception as e:  # a missing or cut summary is itself a finding
        return {"_error": str(e)}

s = load("run/summary.json")
sim = load("sim.json")
minutes = int(P["minutes"])
say(f"# bench/soak.sh --minutes {minutes} (repository root, release build): the whole stack on LoLA, live cameras and the shared-memory attention ring")
say(f"date: {P['date_before']} to {P['date_after']}; host: {P['host']}; commit {P['commit']}")
say(f"binaries (copied at the start): {P['binaries']}")
say(f"load average before: {P['load_before']}")
say(f"load average after:  {P['load_after']}")
say("commands:")
for k in ("cmd_synth", "cmd_sim", "cmd_rt", "cmd_replay", "cmd_tail"):
    say("  " + P[k])
say(f"faults: {P['n_faults']}, {P['schedule']}, after nao_rt connected to LoLA; kinds in turn: packet gap, garbage "
    "packet, malformed packets, camera folder gone")
say(f"scheduling: nao_rt {s.get('realtime_scheduling')} (I/O thread {(s.get('lola') or {}).get('io_thread_scheduling')}); "
    f"nao_lola_sim {P['sim_scheduling']}; replayers and nao_attn_tail SCHED_OTHER")
say()

# --- the run
ticks = s.get("ticks", 0) or 0
lola = s.get("lola") or {}
cam = s.get("camera") or {}
dur = s.get("duration_s") or ticks * 0.1
say("## The run")
say(f"ticks {ticks} ({dur / 60:.1f} min of LoLA time; loop wall {s.get('wall_s', 0) / 60:.1f} min), stop: {lola.get('stop')}, "
    f"nao_rt exit {P['rt_rc']}; the recording ({P['n_frames']} frames a camera) replayed {P['replay_loops']} times")
tu = s.get("tick_us") or {}
say(f"tick_us p50 {tu.get('p50', 0):.0f}  p99 {tu.get('p99', 0):.0f}  max {tu.get('max', 0):.0f}; slow_ticks {s.get('slow_ticks')}")
rtt = lola.get("round_trip_us") or {}
say(f"LoLA: cycles {lola.get('cycles')}, late answers {lola.get('late')} ({lola.get('late_descheduled')} waiting for a CPU), "
    f"round trip on nao_rt's side p50 {rtt.get('p50', 0):.0f} p99 {rtt.get('p99', 0):.0f} max {rtt.get('max', 0):.0f} us; "
    f"sim: {sim.get('sent')} packets sent, {sim.get('answered')} answers (its answered_in_cycle and round trip pair each answer "
    f"with the oldest unanswered packet, so they mean nothing after the first packet nao_rt rightly leaves unanswered)")
lat = cam.get("latency_ms") or {}
say(f"camera: frame file -> tick p50 {lat.get('p50', 0):.1f} p99 {lat.get('p99', 0):.1f} max {lat.get('max', 0):.1f} ms; "
    + ", ".join(f"{k} {v}" for k, v in cam.items() if k not in ("latency_ms", "human_scale_m", "reader_allocations")))
say("fault ticks: " + (", ".join(f"{k} {v}" for k, v in (s.get("faults") or {}).items() if v) or "none"))
say()

# --- ticks.csv and the attention stream
fault = []
try:
    with open(os.path.join(tmp, "run", "ticks.csv")) as f:
        r = csv.reader(f)
        hdr = next(r)
        ti, fi = hdr.index("tick"), hdr.index("fault")
        for row in r:
            fault.append(int(float(row[fi])))
except Exception as e:
    say(f"ticks.csv: unreadable ({e})")
n = len(fault)

attn_ticks, attn_fault, bad = [], {}, 0
with open(os.path.join(tmp, "attn.txt")) as f:
    for line in f:
        parts = line.split()
        if not parts or not parts[0].isdigit():
            continue
        attn_ticks.append(int(parts[0]))
        attn_fault[int(parts[0])] = int(parts[1])
        if "BAD-CHECKSUM" in line:
            bad += 1
try:
    attn_err = open(os.path.join(tmp, "attn.err")).read()
except OSError:
    attn_err = "(attn.err missing)"
skipped = sum(1 for l in attn_err.splitlines() if "skipped" in l)
closed = "closed the ring" in attn_err
in_order = attn_ticks == list(range(len(attn_ticks)))
same_bits = sum(1 for t in range(min(n, len(attn_ticks))) if attn_fault.get(t) != fault[t])
att = s.get("attention") or {}

# --- faults: injected, counted, recovered
HUMAN = 1 | 2 | 16384
BITS = {"drop": 512, "garbage": 1024, "bad_length": 1024, "camera": HUMAN}
events = [l.rstrip("\n").split("\t") for l in open(os.path.join(tmp, "events.tsv")) if l.strip()]
injected = [e for e in events if e[1] in BITS]

def episodes(mask):
    eps, t = [], 0
    while t < n:
        if fault[t] & mask:
            a = t
            while t < n and fault[t] & mask:
                t += 1
            eps.append((a, t))
        else:
            t += 1
    return eps

eps = {m: episodes(m) for m in set(BITS.values())}
used = {m: set() for m in eps}
say("## Faults and recovery")
say("Recovery: ticks from the first tick with the fault's bits to the first tick without them (ticks.csv; the")
say("attention stream carries the same bits).")
say("A LoLA fault is matched with the episode of its bits nearest the tick its cycle falls in (safe start ~75 cycles,")
say("then 100/12 cycles a tick, less the cycles lost to earlier faults); a camera fault with the first after the move.")
say(f"{'t [s]':>7}  {'fault':<11} {'expected tick':>14} {'bits from':>9} {'recovery [ticks]':>16}  detail")
SAFE_START_CYCLES = 75
recoveries = {k: [] for k in BITS}
unrecovered = 0
lost_cycles = 0  # sensor cycles that were no packet nao_rt counts: dropped or malformed
expected = {}
for e in injected:
    t_ms, kind, detail, tick = int(e[0]), e[1], e[2], int(e[3])
    m = BITS[kind]
    if kind == "camera":
        lo, hi, want = tick - 2, tick + 40, tick
    else:
        cycle = int(detail.split()[1].split("-")[0].rstrip(":"))
        want = int((cycle - SAFE_START_CYCLES - lost_cycles) * 12 / 100)
        lo, hi = want - 12, want + 12
        lost_cycles += {"drop": int(detail.split(": ")[1].split()[0]) if kind == "drop" else 0,
                        "garbage": 1, "bad_length": 3}[kind]
    expected[id(e)] = (lo, hi)
    cands = [(abs(a - want), i) for i, (a, b) in enumerate(eps[m]) if i not in used[m] and lo <= a <= hi]
    hit = min(cands)[1] if cands else None
    if hit is None:
        unrecovered += 1
        say(f"{t_ms / 1000:7.1f}  {kind:<11} {want:>14} {'-':>9} {'not seen':>16}  {detail}")
        continue
    used[m].add(hit)
    a, b = eps[m][hit]
    done = b < n
    if not done:
        unrecovered += 1
    rec_t = b - a
    recoveries[kind].append(rec_t)
    other = 0
    for t in range(a, b):
        other |= fault[t]
    say(f"{t_ms / 1000:7.1f}  {kind:<11} {want:>14} {a:>9} {rec_t if done else 'never':>16}  {detail}"
        + (f"; bits seen {other}" if other != m else ""))
# Three malformed packets in a row are also 48 ms without a good packet: a packet gap, part of the fault.
for e in injected:
    if e[1] != "bad_length":
        continue
    lo, hi = expected[id(e)]
    for i, (a, b) in enumerate(eps[512]):
        if i not in used[512] and lo <= a <= hi:
            used[512].add(i)
            break
spont = {m: [eps[m][i] for i in range(len(eps[m])) if i not in used[m]] for m in eps}
# Between two loops each replayer reads its frames before writing again: a short pause of the feed.
loop_ticks = [int(e[3]) for e in events if e[1] == "loop"]
at_loop = [ab for ab in spont[HUMAN] if any(t - 3 <= ab[0] <= t + 10 for t in loop_ticks)]
spont[HUMAN] = [ab for ab in spont[HUMAN] if ab not in at_loop]
for kind, r in recoveries.items():
    if r:
        say(f"  {kind}: recovery {min(r)}-{max(r)} ticks (mean {sum(r) / len(r):.1f}) over {len(r)} faults")
names = {512: "robot_packet_gap", 1024: "robot_malformed_packet", HUMAN: "no_human/human_timeout/human_bridged"}
say(f"  episodes of {names[HUMAN]} at a replay loop's start (the replayers reload, the feed pauses): {len(at_loop)} of "
    f"{len(loop_ticks)} loop starts, {sum(b - a for a, b in at_loop)} ticks in all")
for m, lst in spont.items():
    say(f"  episodes of {names[m]} with no fault injected near them: {len(lst)}"
        + (f" (ticks {', '.join(f'{a}+{b - a}' for a, b in lst[:12])}{' ...' if len(lst) > 12 else ''})" if lst else ""))
say()
nk = {k: sum(1 for e in injected if e[1] == k) for k in BITS}
drop_cycles = sum(int(e[2].split(": ")[1].split()[0]) for e in injected if e[1] == "drop")
say("## Injected against counted")
say(f"packet gaps:      {nk['drop']} injected ({drop_cycles} packets not sent; sim dropped {sim.get('dropped')}) + "
    f"{nk['bad_length']} from the bad-length faults (3 skipped packets: 48 ms without a good one) -> "
    f"lola.gaps {lola.get('gaps')}, robot_packet_gap on {(s.get('faults') or {}).get('robot_packet_gap')} ticks")
bad_packets = 3 * nk["bad_length"]
say(f"malformed:        {nk['garbage']} garbage + {bad_packets} bad-length packets injected (sim: garbage {sim.get('garbage')}, "
    f"bad_length {sim.get('bad_length')}) -> lola.malformed {lola.get('malformed')}, robot_malformed_packet on "
    f"{(s.get('faults') or {}).get('robot_malformed_packet')} ticks")
say(f"camera folder:    {nk['camera']} moves away and back -> folder_gone {cam.get('folder_gone')}, folder_back "
    f"{cam.get('folder_back')}; the writer restarted {P['replay_restarts']} times")
say(f"other robot faults: tracking_error {(s.get('faults') or {}).get('tracking_error')}, joint_hot "
    f"{(s.get('faults') or {}).get('joint_hot')}, robot_link_lost {(s.get('faults') or {}).get('robot_link_lost')}")
# Counted: the sim did what was asked, nao_rt's counters hold at least the injected faults (more when
# faults nobody injected came too, listed above) and each injected fault put its bits on a tick.
counted = (nk["drop"] > 0 and (lola.get("gaps") or 0) >= nk["drop"] + nk["bad_length"] and sim.get("dropped") == drop_cycles
           and nk["garbage"] + nk["bad_length"] > 0 and (lola.get("malformed") or 0) >= nk["garbage"] + bad_packets
           and sim.get("garbage") == nk["garbage"] and sim.get("bad_length") == bad_packets
           and cam.get("folder_gone") == nk["camera"] and cam.get("folder_back") == nk["camera"] and unrecovered == 0)
extra_gaps = (lola.get("gaps") or 0) - nk["drop"] - nk["bad_length"]
say()

# --- the attention reader
say("## Attention reader (nao_attn_tail --from-oldest on the shared-memory ring)")
say(f"records pushed {att.get('records_written')}, printed {len(attn_ticks)} (ticks 0..{attn_ticks[-1] if attn_ticks else '-'}, "
    f"consecutive: {in_order}), bad checksums {bad}, skipped-record reports {skipped}, ticks whose fault bits differ from "
    f"ticks.csv {same_bits}; the reader saw the ring closed: {closed}, exit {P['tail_rc']}; shared memory left: "
    f"{'yes' if P['shm_left'] == '1' else 'no'}")
attn_ok = (att.get("records_written") == ticks == len(attn_ticks) == n and in_order and bad == 0 and skipped == 0
           and same_bits == 0 and closed and P["tail_rc"] == "0" and P["shm_left"] == "0")
say()

# --- RSS and fds
samp = [l.split("\t") for l in open(os.path.join(tmp, "samples.tsv")).read().splitlines()[1:] if l]
samp = [(int(a) / 1000, int(b), int(c), int(d), int(e), float(f)) for a, b, c, d, e, f in samp]
say("## nao_rt's memory and file descriptors (/proc/PID/status VmRSS, /proc/PID/fd, every 5 s)")
warm = min(60.0, 0.1 * minutes * 60)
steady = [x for x in samp if x[0] >= warm]
rss_ok = fd_ok = False
if len(steady) >= 4:
    q = max(1, len(steady) // 4)
    first_q, last_q = steady[:q], steady[-q:]
    r0, r1 = max(x[1] for x in first_q), max(x[1] for x in last_q)
    xs = [x[0] for x in steady]
    ys = [x[1] for x in steady]
    mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx * 3600 if sxx else 0.0
    fds = sorted(set(x[3] for x in steady))
    thr = sorted(set(x[4] for x in steady if x[4] > 0))  # 0: a read of /proc cut short
    # The reader thread opens each frame file to read it: a sample may catch one more fd. Growth is
    # a count above the usual one in two samples in a row, or at the end.
    base = max(set(x[3] for x in steady), key=lambda v: sum(1 for x in steady if x[3] == v))
    above = [x for x in steady if x[3] > base]
    fd_grew = steady[-1][3] > base or any(a[3] > base and b[3] > base for a, b in zip(steady, steady[1:]))
    say(f"{len(samp)} samples; from {warm:.0f} s on ({len(steady)}): VmRSS first quarter max {r0} kB, last quarter max "
        f"{r1} kB, min {min(ys)}, max {max(ys)} kB, least-squares slope {slope:+.0f} kB/h; VmHWM at the end {samp[-1][2]} kB")
    say(f"open fds: {base} in {len(steady) - len(above)} of {len(steady)} samples"
        + (f", {len(above)} single samples with {', '.join(str(x[3]) for x in above[:5])} (a frame file open at that instant)" if above else "")
        + f" (first {steady[0][3]}, last {steady[-1][3]}); threads {', '.join(map(str, thr))}; "
        f"load1 over the run {min(x[5] for x in samp):.2f}-{max(x[5] for x in samp):.2f}")
    say("VmRSS by minute [kB]: " + " ".join(str(x[1]) for x in samp if int(x[0]) % 60 < 5))
    steps = []
    for prev, cur in zip(samp, samp[1:]):
        if cur[1] != prev[1]:
            near = [e for e in events if e[1] not in ("loop", "camera_back", "camera_writer")
                    and prev[0] - 5 <= int(e[0]) / 1000 <= cur[0]]
            steps.append(f"{cur[0]:.0f} s {cur[1] - prev[1]:+d} kB" + (f" ({near[0][1]} at {int(near[0][0]) / 1000:.0f} s)" if near else ""))
    say("VmRSS changes: " + ("; ".join(steps) if steps else "none"))
    rss_ok = r1 <= r0
    fd_ok = not fd_grew
else:
    say(f"too few samples ({len(samp)})")
say()

# --- run directory
run_bytes = int(P["run_bytes"])
say("## Run directory")
files = sorted(os.listdir(os.path.join(tmp, "run")))
sizes = ", ".join(f"{f} {os.path.getsize(os.path.join(tmp, 'run', f)) / 1e6:.2f} MB" for f in files)
grow = os.path.getsize(os.path.join(tmp, "run", "ticks.csv"))
say(f"{run_bytes / 1e6:.1f} MB after {dur / 60:.1f} min ({sizes}); ticks.csv grows with the run, attention.bin is the "
    f"last 1,024 records: {((run_bytes - grow) + grow * 3600 / max(dur, 1)) / 1e6:.1f} MB per hour of run")
cam_b = int(P["cam_bytes"])
say(f"the camera folders (OpenPose's output, never pruned here): {cam_b / 1e6:.0f} MB, {cam_b / 1e6 * 3600 / max(dur, 1):.0f} MB "
    "per hour at 2 cameras x 30 fps")
say()

# --- allocations, overruns, the stop
say("## Allocations, overruns, the SIGINT stop")
alloc = s.get("allocations_after_activate")
say(f"allocations after activate: control thread {alloc}, LoLA I/O thread {lola.get('io_allocations')}; camera reader "
    f"thread {cam.get('reader_allocations')} (not real-time, allowed to allocate)")
say(f"overruns {s.get('overruns')} (on LoLA the robot's packets are the clock: nao_rt counts no 100 ms-grid overrun there), "
    f"lola.overrun_ticks {lola.get('overrun_ticks')} (a tick's command published after its packet's answer was due), "
    f"slow_ticks {s.get('slow_ticks')}")
keys = ["ticks", "period_s", "duration_s", "overruns", "faults", "allocations_after_activate", "tick_us", "retarget_us",
        "policy_us", "sim_us", "slow_ticks", "ee_rmse_m", "network_share", "policy_ticks", "start_q", "model", "reference",
        "retarget", "movement", "realtime", "realtime_scheduling", "skipped_periods", "zero_timing", "robot", "wall_s",
        "lola", "camera", "attention"]
lola_keys = ["socket", "cycles", "late", "late_descheduled", "malformed", "gaps", "hot_cycles", "tracking_cycles",
             "io_thread", "io_thread_scheduling", "overrun_ticks", "io_allocations", "round_trip_us", "stop"]
missing = [k for k in keys if k not in s] + ["lola." + k for k in lola_keys if k not in lola]
run_files = all(os.path.exists(os.path.join(tmp, "run", f)) for f in ("ticks.csv", "attention.bin", "summary.json"))
say(f"SIGINT after {dur / 60:.1f} min: nao_rt exit {P['rt_rc']} (4 = safe stop on a signal) {int(P['sigint_to_exit_ms']) / 1000:.1f} s "
    f"later, lola.stop {lola.get('stop')}; summary.json keys missing: {', '.join(missing) or 'none'}; ticks.csv rows {n} "
    f"(summary ticks {ticks}); ticks.csv, attention.bin, summary.json written: {run_files}")
stop_ok = (P["rt_rc"] == "4" and lola.get("stop") == "signal" and not missing and n == ticks and run_files
           and P["rt_ended_early"] == "0")
say()

# --- hang-up
s2 = load("run_hangup/summary.json")
sim2 = load("sim_hangup.json")
s3 = load("run_restart/summary.json")
l2 = s2.get("lola") or {}
say("## Hang-up (nao_rt cannot reconnect: a lost LoLA link ends the run) and restart")
say("  " + P["cmd_sim_hangup"])
say("  " + P["cmd_rt_hangup"])
say("  " + P["cmd_rt_restart"])
say(f"robot closed the socket at cycle {P['hang_cycle']} (sim closed_by_injection {sim2.get('closed_by_injection')}): nao_rt "
    f"exit {P['rt2_rc']} (3 = link lost) {int(P['hangup_to_exit_ms']) / 1000:.2f} s later, lola.stop {l2.get('stop')}, "
    f"robot_link_lost on {(s2.get('faults') or {}).get('robot_link_lost')} tick(s), {s2.get('ticks')} ticks, run directory written: "
    f"{'_error' not in s2}")
say(f"restart: a new nao_rt on a new LoLA connection had its first tick {int(P['restart_first_tick_ms']) / 1000:.2f} s after "
    f"the old one exited; it ran {s3.get('ticks')} ticks, exit {P['rt3_rc']}, stop {(s3.get('lola') or {}).get('stop')}, "
    f"allocations after activate {s3.get('allocations_after_activate')}; shared memory left: "
    f"{'yes' if P['shm_left_restart'] == '1' else 'no'}")
hang_ok = (P["rt2_rc"] == "3" and l2.get("stop") == "link_lost" and (s2.get("faults") or {}).get("robot_link_lost", 0) >= 1
           and P["rt3_rc"] == "0" and int(P["restart_first_tick_ms"]) >= 0 and P["shm_left_restart"] == "0")
say()

accept(alloc == 0 and lola.get("io_allocations") == 0, f"0 allocations after activate (control {alloc}, I/O thread {lola.get('io_allocations')})")
accept(s.get("overruns") == 0 and lola.get("overrun_ticks") == 0,
       f"0 overruns (overruns {s.get('overruns')}, lola.overrun_ticks {lola.get('overrun_ticks')})")
accept(rss_ok, "no RSS growth (last quarter's max <= first quarter's max after warm-up)")
accept(fd_ok, "no fd growth (the open-fd count stays at its usual value)")
accept(counted, "every injected fault counted (gaps, malformed packets, folder gone/back)")
accept(unrecovered == 0 and len(injected) == int(P["n_faults"]),
       f"every injected fault recovered ({len(injected) - unrecovered} of {len(injected)})")
accept(attn_ok, "no lost or torn attention record (every tick read once, checksums good, bits as ticks.csv)")
accept(stop_ok, "clean stop on SIGINT, summary.json complete")
accept(hang_ok, "hang-up: link lost counted, exit 3; restart runs again")
extra = extra_gaps + len(spont[1024]) + len(spont[HUMAN])
say("## Acceptance")
for ok, what in acc:
    say(f"{'met    ' if ok else 'NOT MET'}  {what}")
say(f"(not an acceptance item) faults nobody injected: {extra_gaps} packet gaps, {len(spont[1024])} malformed, "
    f"{len(spont[HUMAN])} human-lost episodes away from faults and loop starts")
text = "\n".join(lines) + "\n"
with open(out, "w") as f:
    f.write(text)
sys.stdout.write(text)
sys.exit(0 if all(ok for ok, _ in acc) else 1)
EOF
}
if [[ -n "$report_dir" ]]; then
  [[ -f "$report_dir/params.txt" ]] || die 2 "$report_dir: not a --keep folder of a soak (no params.txt)"
  report "$report_dir" "$out"
  exit $?
fi
rt="$build/bin/nao_rt"
sim="$build/bin/nao_lola_sim"
tail_bin="$build/bin/nao_attn_tail"
tc="${NAO_TOOLCHAIN:-$build/bin/nao_toolchain}"
for exe in "$rt" "$sim" "$tail_bin" "$tc"; do
  [[ -x "$exe" ]] || die 2 "$exe not built (toolchain/nao build)"
done
[[ -x /usr/bin/python3 ]] || die 2 "/usr/bin/python3 is needed for the report"
mkdir -p "$(dirname "$out")" || die 2 "cannot create the folder of $out"

tmp="$(mktemp -d /tmp/nao_soak.XXXXXX)" || die 2 "mktemp failed"
shm="nao_soak_$$"
pids=()
rep0=0 rep1=0
cleanup() {
  local status=$?
  trap - EXIT INT TERM
  local p i alive_any
  pids+=("$rep0" "$rep1")
  for p in "${pids[@]}"; do alive "$p" && kill -TERM "$p" 2>/dev/null; done
  for ((i = 0; i < 50; i++)); do
    alive_any=0
    for p in "${pids[@]}"; do alive "$p" && alive_any=1; done
    ((alive_any)) || break
    sleep 0.1
  done
  for p in "${pids[@]}"; do alive "$p" && kill -KILL "$p" 2>/dev/null; done
  wait 2>/dev/null
  rm -f "/dev/shm/$shm" "/dev/shm/${shm}_restart"
  if [[ -n "$keep" ]]; then
    mkdir -p "$keep" && cp -r "$tmp"/run "$tmp"/run_hangup "$tmp"/run_restart "$tmp"/*.txt "$tmp"/*.json \
      "$tmp"/*.tsv "$tmp"/*.log "$tmp"/*.err "$tmp"/*.out "$keep"/ 2>/dev/null
  fi
  rm -rf "$tmp"
  exit "$status"
}
trap cleanup EXIT
trap 'echo "soak.sh: interrupted" >&2; exit 130' INT TERM

# A running child of this script: not a pid the system has since given to someone else, not a zombie.
alive() {
  [[ "$1" -gt 0 ]] || return 1
  local st state ppid
  { read -r st <"/proc/$1/stat"; } 2>/dev/null || return 1
  st=${st##*) }
  state=${st%% *}
  st=${st#* }
  ppid=${st%% *}
  [[ "$state" != Z && "$ppid" == "$$" ]]
}
now() { NOW=${EPOCHREALTIME/./}; }  # microseconds, no fork
log_event() { printf '%s\t%s\t%s\t%s\n' "$1" "$2" "$3" "$4" >>"$tmp/events.tsv"; }
# The newest tick the attention reader printed (-1 before the first).
last_tick() {
  local line
  line="$(tail -n 1 "$tmp/attn.txt" 2>/dev/null)"
  line="${line#"${line%%[![:space:]]*}"}"
  line="${line%% *}"
  [[ "$line" =~ ^[0-9]+$ ]] && echo "$line" || echo -1
}
wait_for() {  # PATH TENTHS: wait until PATH exists, at most TENTHS/10 s
  local i
  for ((i = 0; i < $2; i++)); do [[ -e "$1" ]] && return 0; sleep 0.1; done
  return 1
}
wait_exit() {  # PID TENTHS: wait until PID ends (at most TENTHS/10 s, then SIGKILL); its status in RC
  local i
  for ((i = 0; i < $2; i++)); do alive "$1" || break; sleep 0.1; done
  alive "$1" && kill -KILL "$1" 2>/dev/null
  wait "$1" 2>/dev/null
  RC=$?
}
rel() { sed "s|$tmp/bin/|$build/bin/|g; s|$tmp|TMP|g; s|$root/||g"; }

# The binaries as they are now: a rebuild of build/ during the soak cannot swap them.
mkdir -p "$tmp/bin"
binaries=""
for exe in "$rt" "$sim" "$tail_bin"; do
  cp -p "$exe" "$tmp/bin/" || die 2 "cannot copy $exe"
  binaries+="${exe##*/} $(date -u -r "$exe" '+%Y-%m-%d %H:%M UTC') md5 $(md5sum "$exe" | cut -c1-12); "
done
rt="$tmp/bin/nao_rt"
sim="$tmp/bin/nao_lola_sim"
tail_bin="$tmp/bin/nao_attn_tail"

sim_rt=(chrt -f 50)
chrt -f 50 true 2>/dev/null || sim_rt=()

# --- the recording, its per-camera views ---------------------------------------------------------
"$tc" synth --movement whole_arm --per-movement 1 --seed 1000001 --out "$tmp/rec" >"$tmp/synth.log" 2>&1 ||
  die 2 "nao_toolchain synth failed: $(tail -n 3 "$tmp/synth.log")"
rec="$tmp/rec/whole_arm_000"
rig="$tmp/rig"
# Each camera has a replayer of its own (a view holding only that camera as cam0/), so a camera's
# writer can fail and restart while the other camera goes on. Loop L's views name the frames
# with indices continued from loop L-1 (L x frames + i): the folders see one capture whose frame
# index only grows, as from one OpenPose session (recorded names repeated every loop would be a
# capture restart every loop, and a folder moved back would hold the last loop's "newer" frames).
frames0=("$rec"/cam0/*_keypoints.json)
n_frames=${#frames0[@]}
demo_prefix="${frames0[0]##*/}"
demo_prefix="${demo_prefix%_*_keypoints.json}"
make_views() {  # LOOP
  [[ -d "$tmp/view/$1" ]] && return 0
  /usr/bin/python3 - "$rec" "$tmp/view/$1" "$(($1 * n_frames))" <<'PY'
import os, re, sys
rec, view, offset = sys.argv[1], sys.argv[2], int(sys.argv[3])
for c in (0, 1):
    d = os.path.join(view, "c%d" % c, "cam0")
    os.makedirs(d)
    src = os.path.join(rec, "cam%d" % c)
    for f in os.listdir(src):
        m = re.match(r"(.*)_(\d{12})_keypoints\.json$", f)
        if m:
            os.symlink(os.path.join(src, f), os.path.join(d, "%s_%012d_keypoints.json" % (m.group(1), int(m.group(2)) + offset)))
PY
}
((n_frames > 30)) || die 2 "the recording has $n_frames frames"

# --- the fault schedule (seconds after nao_rt connected) -----------------------------------------
T=$((minutes * 60))
run_s=$((T + 30 > 3600 ? 3600 : T + 30))  # nao_rt's own limit: SIGINT comes first
stop_s=$((T < run_s - 5 ? T : run_s - 5))
spacing=$(((T - 40) / 4))
((spacing > 180)) && spacing=180
first=$((spacing < 60 ? spacing : 60))
kinds=(drop garbage bad_length camera)
sim_faults=()
f_ms=() f_kind=() f_detail=()
n=0
for ((t = first; t <= T - 20; t += spacing)); do
  kind=${kinds[n % 4]}
  c=$((t * 1000 / 12))
  case "$kind" in
    drop)
      len=$(((n / 4) % 2 ? 40 : 6))
      sim_faults+=(--drop "$c:$len")
      detail="cycle $c: $len packets not sent ($((len * 12)) ms)" ;;
    garbage)
      sim_faults+=(--garbage "$c:300")
      detail="cycle $c: 300 random bytes instead of the packet" ;;
    bad_length)
      sim_faults+=(--bad-length "$c:3")
      detail="cycles $c-$((c + 2)): Position with 24 entries" ;;
    camera) detail="cam0 folder moved away for 1 s while written" ;;
  esac
  f_ms+=($((t * 1000)))
  f_kind+=("$kind")
  f_detail+=("$detail")
  n=$((n + 1))
done
n_faults=$n

# --- the camera replay (polled from the main loop) -----------------------------------------------
rep_loop=-1 rep_loops=0 rep_restarts=0 cam_away=0 cam_back_at=0 loop_t=0
start_replayer() {  # VIEW FOLDER: one camera's replayer, its pid in REPLAY_PID
  "$tc" replay --recording "$1" --to "$2" >>"$tmp/replay.log" 2>&1 &
  REPLAY_PID=$!
}
replay_poll() {
  now
  if ((cam_away)) && ((NOW >= cam_back_at)); then
    mv "$rig/cam0.away" "$rig/cam0"
    cam_away=0
    log_event "$(((NOW - t0) / 1000))" camera_back "cam0 folder moved back" "$(last_tick)"
    # The writer failed while its folder was away: it starts again at the frame after cam1's
    # newest (cam1's writer goes on), as an OpenPose whose writes failed for a second.
    if ! alive "$rep0" && alive "$rep1"; then
      local i name
      for ((i = n_frames - 1; i >= 0; i--)); do
        printf -v name '%s_%012d_keypoints.json' "$demo_prefix" $((rep_loop * n_frames + i))
        [[ -e "$rig/cam1/$name" ]] && break
      done
      local k=$((i + 1))
      if ((k < n_frames)); then
        rep_restarts=$((rep_restarts + 1))
        local view="$tmp/view/r$rep_restarts"
        local loop_files=("$tmp/view/$rep_loop/c0/cam0"/*_keypoints.json)
        mkdir -p "$view/cam0"
        ln -s -t "$view/cam0" "${loop_files[@]:k}"
        start_replayer "$view" "$rig/cam0"
        rep0=$REPLAY_PID
        log_event "$(((NOW - t0) / 1000))" camera_writer "cam0 writer restarted at frame $k of loop $rep_loop" "$(last_tick)"
      fi
    fi
  fi
  if ((!cam_away)) && ! alive "$rep0" && ! alive "$rep1"; then
    rep_loop=$((rep_loop + 1))
    make_views "$rep_loop"
    start_replayer "$tmp/view/$rep_loop/c0" "$rig/cam0"
    rep0=$REPLAY_PID
    start_replayer "$tmp/view/$rep_loop/c1" "$rig/cam1"
    rep1=$REPLAY_PID
    rep_loops=$((rep_loops + 1))
    loop_t=$NOW
    [[ -n "${t0:-}" ]] && log_event "$(((NOW - t0) / 1000))" loop "replay loop $rep_loop starts" "$(last_tick)"
    # The next loop's views now, while this one plays; the last-but-one's are done with.
    make_views $((rep_loop + 1))
    rm -rf "$tmp/view/$((rep_loop - 2))"
  fi
}
# A camera fault waits until its 1 s move falls inside a replay loop, >= 3 s from the loop's
# start and end: a loop start pauses the feed by itself (the replayers reload), and the report
# could not tell that pause from the fault's. A loop running late takes the fault at once.
camera_window() {
  local e=$((NOW - loop_t)) len=$((n_frames * 1000000 / 30))
  ((e >= 3000000 && (e <= len - 4000000 || e > len + 3000000)))
}
camera_fault() {
  now
  if [[ -d "$rig/cam0" ]]; then
    mv "$rig/cam0" "$rig/cam0.away"
    cam_away=1
    cam_back_at=$((NOW + 1000000))
    return 0
  fi
  return 1
}

# --- RSS and open fds of nao_rt, every 5 s ----------------------------------------------------------
sample() {  # PID REL_MS
  local key val unit rss=0 hwm=0 threads=0 fds load
  while read -r key val unit; do
    case "$key" in
      VmRSS:) rss=$val ;;
      VmHWM:) hwm=$val ;;
      Threads:) threads=$val ;;
    esac
  done <"/proc/$1/status" 2>/dev/null || return 0
  local fdl=("/proc/$1/fd/"*)
  fds=${#fdl[@]}
  read -r load _ </proc/loadavg
  printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$2" "$rss" "$hwm" "$fds" "$threads" "$load" >>"$tmp/samples.tsv"
}

# --- the soak ----------------------------------------------------------------------------------
: >"$tmp/events.tsv"
printf 'rel_ms\trss_kB\thwm_kB\tfds\tthreads\tload1\n' >"$tmp/samples.tsv"
echo "$(date -u '+%Y-%m-%d %H:%M:%S UTC')" >"$tmp/date_before.txt"
cat /proc/loadavg >"$tmp/load_before.txt"
sock="$tmp/lola.sock"
sim_cmd=("${sim_rt[@]}" "$sim" --socket "$sock" --seconds "$((run_s + 120))" --summary "$tmp/sim.json" "${sim_faults[@]}")
"${sim_cmd[@]}" >"$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=("$sim_pid")
wait_for "$sock" 100 || die 2 "nao_lola_sim did not create its socket: $(cat "$tmp/sim.log")"
rt_args=(--reference "openpose:$rig/cam0,$rig/cam1" --calibration "$rec/calibration.json" --movement whole_arm
  --realtime --lola-io-thread)
rt_cmd=("$rt" --robot "lola:$sock" "${rt_args[@]}" --seconds "$run_s" --log "$tmp/run" --attention-shm "$shm")
now
t_launch=$NOW
"${rt_cmd[@]}" >"$tmp/rt.out" 2>"$tmp/rt.err" &
rt_pid=$!
pids+=("$rt_pid")
# The ring appears once nao_rt is connected to LoLA: the fault times count from there.
wait_for "/dev/shm/$shm" 300 || die 2 "nao_rt made no attention ring: $(cat "$tmp/rt.err")"
now
t0=$NOW
tail_cmd=("$tail_bin" "$shm" --from-oldest --interval-ms 20)
tail_pid=0
for ((i = 0; i < 50; i++)); do  # the ring's magic is stored last: retry until it opens
  "${tail_cmd[@]}" >"$tmp/attn.txt" 2>"$tmp/attn.err" &
  tail_pid=$!
  sleep 0.2
  alive "$tail_pid" && break
  wait "$tail_pid" 2>/dev/null
  tail_pid=0
done
((tail_pid > 0)) || die 2 "nao_attn_tail cannot read the ring: $(cat "$tmp/attn.err")"
pids+=("$tail_pid")
echo "soak.sh: $minutes min from $(date -u '+%H:%M:%S UTC'); $n_faults faults; temporary files in $tmp" >&2

stop_ms=$((stop_s * 1000))
next_sample=0
fi_idx=0
rt_ended_early=0
while :; do
  now
  r=$(((NOW - t0) / 1000))
  if ! alive "$rt_pid"; then
    rt_ended_early=1
    break
  fi
  ((r >= stop_ms)) && break
  while ((fi_idx < n_faults)) && ((r >= f_ms[fi_idx])); do
    if [[ "${f_kind[fi_idx]}" == camera ]]; then
      camera_window || break
      camera_fault || f_detail[fi_idx]+=" (not done: the folder was not there)"
    fi
    log_event "$r" "${f_kind[fi_idx]}" "${f_detail[fi_idx]}" "$(last_tick)"
    fi_idx=$((fi_idx + 1))
  done
  replay_poll
  if ((r >= next_sample)); then
    sample "$rt_pid" "$r"
    next_sample=$((next_sample + 5000))
  fi
  sleep 0.05
done
now
t_sigint=$NOW
log_event "$(((NOW - t0) / 1000))" sigint "SIGINT to nao_rt" "$(last_tick)"
kill -INT "$rt_pid" 2>/dev/null
# The safe stop: the current tick ends, the stiffness ramps down over 0.6 s; the camera keeps
# running meanwhile.
for ((i = 0; i < 300; i++)); do
  alive "$rt_pid" || break
  replay_poll
  sleep 0.1
done
now
t_rt_end=$NOW
wait_exit "$rt_pid" 1
rt_rc=$RC
wait_exit "$tail_pid" 100
tail_rc=$RC
shm_left=0
[[ -e "/dev/shm/$shm" ]] && shm_left=1
cat /proc/loadavg >"$tmp/load_after.txt"
echo "$(date -u '+%Y-%m-%d %H:%M:%S UTC')" >"$tmp/date_after.txt"
kill -TERM "$sim_pid" 2>/dev/null
wait_exit "$sim_pid" 200
du -sb "$tmp/run" | cut -f1 >"$tmp/run_bytes.txt"
((cam_away)) && mv "$rig/cam0.away" "$rig/cam0"
cam_away=0

# --- the hang-up, then a restart on a new connection ------------------------------------------------
echo "soak.sh: the hang-up and the restart" >&2
sock2="$tmp/lola_hangup.sock"
hang_c=$((15000 / 12))
sim2_cmd=("${sim_rt[@]}" "$sim" --socket "$sock2" --seconds 120 --summary "$tmp/sim_hangup.json" --close-at "$hang_c")
"${sim2_cmd[@]}" >"$tmp/sim_hangup.log" 2>&1 &
sim2_pid=$!
pids+=("$sim2_pid")
wait_for "$sock2" 100 || die 2 "nao_lola_sim (hang-up) did not start"
rt2_cmd=("$rt" --robot "lola:$sock2" "${rt_args[@]}" --seconds 60 --log "$tmp/run_hangup")
"${rt2_cmd[@]}" >"$tmp/rt_hangup.out" 2>"$tmp/rt_hangup.err" &
rt2_pid=$!
pids+=("$rt2_pid")
t_hang=0
for ((i = 0; i < 4500; i++)); do
  replay_poll
  if ((t_hang == 0)) && ! alive "$sim2_pid"; then t_hang=$NOW; fi
  alive "$rt2_pid" || break
  sleep 0.02
done
now
t_rt2_end=$NOW
wait_exit "$rt2_pid" 1
rt2_rc=$RC
((t_hang == 0)) && t_hang=$NOW
wait_exit "$sim2_pid" 50
# The restart: a new LoLA (the robot's, restarted) and a new nao_rt, as a supervisor would start it.
sock3="$tmp/lola_restart.sock"
sim3_cmd=("${sim_rt[@]}" "$sim" --socket "$sock3" --seconds 60 --summary "$tmp/sim_restart.json")
"${sim3_cmd[@]}" >"$tmp/sim_restart.log" 2>&1 &
sim3_pid=$!
pids+=("$sim3_pid")
wait_for "$sock3" 100 || die 2 "nao_lola_sim (restart) did not start"
rt3_cmd=("$rt" --robot "lola:$sock3" "${rt_args[@]}" --seconds 5 --log "$tmp/run_restart" --attention-shm "${shm}_restart")
"${rt3_cmd[@]}" >"$tmp/rt_restart.out" 2>"$tmp/rt_restart.err" &
rt3_pid=$!
pids+=("$rt3_pid")
t_first3=0
tail3_pid=0
for ((i = 0; i < 300; i++)); do
  replay_poll
  if ((tail3_pid == 0)) && [[ -e "/dev/shm/${shm}_restart" ]]; then
    "$tail_bin" "${shm}_restart" --from-oldest --count 1 --interval-ms 1 >"$tmp/attn_restart.txt" 2>/dev/null &
    tail3_pid=$!
    pids+=("$tail3_pid")
  fi
  if ((tail3_pid > 0 && t_first3 == 0)) && ! alive "$tail3_pid"; then
    wait "$tail3_pid"
    if [[ $? -eq 0 ]]; then
      t_first3=$NOW
    else
      tail3_pid=0  # opened before the magic: try again
    fi
  fi
  alive "$rt3_pid" || break
  sleep 0.05
done
wait_exit "$rt3_pid" 200
rt3_rc=$RC
kill -TERM "$sim3_pid" 2>/dev/null
wait_exit "$sim3_pid" 50
for p in "$rep0" "$rep1"; do alive "$p" && kill -TERM "$p" 2>/dev/null; done
shm_left3=0
[[ -e "/dev/shm/${shm}_restart" ]] && shm_left3=1

# --- the report --------------------------------------------------------------------------------------
{
  echo "minutes=$minutes"
  echo "binaries=$binaries"
  echo "n_faults=$n_faults"
  echo "schedule=every $spacing s from $first s, SIGINT at $stop_s s (nao_rt --seconds $run_s)"
  echo "rt_rc=$rt_rc"
  echo "tail_rc=$tail_rc"
  echo "rt_ended_early=$rt_ended_early"
  echo "shm_left=$shm_left"
  echo "shm_left_restart=$shm_left3"
  echo "sigint_to_exit_ms=$(((t_rt_end - t_sigint) / 1000))"
  echo "launch_to_ring_ms=$(((t0 - t_launch) / 1000))"
  echo "rt2_rc=$rt2_rc"
  echo "hangup_to_exit_ms=$(((t_rt2_end - t_hang) / 1000))"
  echo "rt3_rc=$rt3_rc"
  echo "restart_first_tick_ms=$((t_first3 > 0 ? (t_first3 - t_rt2_end) / 1000 : -1))"
  echo "hang_cycle=$hang_c"
  echo "replay_loops=$rep_loops"
  echo "replay_restarts=$rep_restarts"
  echo "n_frames=$n_frames"
  echo "sim_scheduling=${sim_rt[*]:-SCHED_OTHER (chrt not permitted)}"
  echo "commit=$(git -C "$root" rev-parse --short HEAD 2>/dev/null || echo unknown)"
  echo "host=$(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "date_before=$(cat "$tmp/date_before.txt")"
  echo "date_after=$(cat "$tmp/date_after.txt")"
  echo "load_before=$(cat "$tmp/load_before.txt")"
  echo "load_after=$(cat "$tmp/load_after.txt")"
  echo "run_bytes=$(cat "$tmp/run_bytes.txt")"
  echo "cmd_sim=$(echo "${sim_cmd[*]}" | rel)"
  echo "cmd_rt=$(echo "${rt_cmd[*]}" | rel)"
  echo "cmd_replay=$(echo "$tc replay --recording $tmp/view/<loop>/c<k> --to $rig/cam<k>  (one per camera; loop L's frame indices continue loop L-1's)" | rel)"
  echo "cam_bytes=$(du -sb "$rig" | cut -f1)"
  echo "cmd_tail=$(echo "${tail_cmd[*]}" | rel)"
  echo "cmd_synth=$(echo "$tc synth --movement whole_arm --per-movement 1 --seed 1000001 --out $tmp/rec" | rel)"
  echo "cmd_sim_hangup=$(echo "${sim2_cmd[*]}" | rel)"
  echo "cmd_rt_hangup=$(echo "${rt2_cmd[*]}" | rel)"
  echo "cmd_rt_restart=$(echo "${rt3_cmd[*]}" | rel)"
} >"$tmp/params.txt"
status=0
report "$tmp" "$out" || status=$?
exit "$status"
