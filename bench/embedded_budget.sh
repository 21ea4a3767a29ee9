#!/usr/bin/env bash
# embedded_budget.sh: the budgets of nao_rt, measured in one command (docs/embedded.md).
# Re-run it whenever the policy or the loop changes; it rewrites bench/results/embedded.txt.
#
#   bench/embedded_budget.sh [--ticks N] [--out FILE] [--native DIR]
#
# Measures, on the robot build (build-nao/bin/nao_rt; toolchain/nao build --preset nao) and the
# native build (DIR/bin/nao_rt, DIR = build unless --native):
#   1. binary sizes: file, stripped, the compiled-in weights, stripped without the weights;
#   2. peak resident set (VmHWM, getrusage of the child) over a 600-tick run, compiled-in model
#      and --weights models/default.bin;
# every run on the same recorded reference: demonstration 0 of whole_arm, run seed 1000001 (the
# demo's), synthesised and triangulated into a skeleton CSV by DIR/bin/nao_toolchain;
#   3. per tick of the robot build (valgrind callgrind, collecting inside runControllerTick only,
#      caches simulated with the Atom E3845's geometry): instructions, data reads/writes, L1
#      and last-level (the Atom's L2) misses, and the executed instruction mix; once with the
#      fp32 weights and once with --precision int8 (docs/policy.md "int8 weights"), each with the
#      in-process simulated arm and without it (as on the robot, where LoLA replaces it);
#   4. the tick time estimated on the NAO V6's Atom E3845 from those counts, for both (the
#      arithmetic is printed and explained in docs/embedded.md).
# Needs valgrind (apt-get install valgrind; not in toolchain/nao's package list: only this
# measurement uses it). Takes about two minutes. Exit status 0, or 1 with a message.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ARGS="$*"
TICKS=20
OUT="$ROOT/bench/results/embedded.txt"
NATIVE_DIR="$ROOT/build"
while [[ $# -gt 0 ]]; do
  case "$1" in
    --ticks) TICKS="$2"; shift 2 ;;
    --out) OUT="$2"; shift 2 ;;
    --native) NATIVE_DIR="$(cd "$2" && pwd)"; shift 2 ;;
    -h | --help) sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "embedded_budget.sh: unknown argument '$1' (--help)" >&2; exit 2 ;;
  esac
done
[[ "$TICKS" =~ ^[1-9][0-9]*$ ]] || { echo "embedded_budget.sh: --ticks must be a positive integer" >&2; exit 2; }
die() { echo "embedded_budget.sh: $*" >&2; exit 1; }
ROBOT="$ROOT/build-nao/bin/nao_rt" NATIVE="$NATIVE_DIR/bin/nao_rt" MODEL="$ROOT/models/default.bin"
TC="$NATIVE_DIR/bin/nao_toolchain"
[[ -x "$ROBOT" ]] || die "no robot build: run 'toolchain/nao build --preset nao' first"
[[ -x "$NATIVE" && -x "$TC" ]] || die "no native build: run 'toolchain/nao build' first"
[[ -f "$MODEL" ]] || die "no $MODEL (toolchain/nao train default)"
command -v valgrind >/dev/null || die "valgrind not found: apt-get install valgrind"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

"$TC" synth --movement whole_arm --per-movement 1 --seed 1000001 --out "$work/references" >/dev/null ||
  die "nao_toolchain synth failed"
SKELETON="$work/references/whole_arm_000/skeleton.csv"
"$TC" triangulate --demo "$work/references/whole_arm_000" --max-gap 0 --out "$SKELETON" >/dev/null ||
  die "nao_toolchain triangulate failed"
REFERENCE=(--reference "file:$SKELETON" --movement whole_arm)

load_before="$(cut -d' ' -f1-3 /proc/loadavg)"
# One tick under callgrind: only runControllerTick (the whole cycle: read, updateController's
# retarget, snap, policy and command, the robot's 100 physics steps, finishTick) is collected. Atom E3845 caches (docs/embedded.md): L1i 32 KiB
# 8-way, L1d 24 KiB 6-way, L2 1 MiB 16-way per two-core module; 64-byte lines.
# Each precision twice: the whole tick here (the in-process ODE arm included), and the tick as
# the robot runs it, where LoLA replaces the simulated arm: stepSim toggles collection off
# while it runs (nested toggles: on entering runControllerTick, off inside stepSim).
for precision in fp32 int8; do
  for variant in sim robot; do
    toggles=('--toggle-collect=*runControllerTick*')
    [[ "$variant" == robot ]] && toggles+=('--toggle-collect=*stepSim*')
    nice -n 19 valgrind --tool=callgrind --callgrind-out-file="$work/callgrind_${precision}_$variant.out" --dump-instr=yes \
      --compress-pos=no --compress-strings=no --cache-sim=yes \
      --I1=32768,8,64 --D1=24576,6,64 --LL=1048576,16,64 \
      --collect-atstart=no "${toggles[@]}" \
      "$ROBOT" "${REFERENCE[@]}" --ticks "$TICKS" --zero-timing --precision "$precision" \
      >"$work/callgrind.log" 2>&1 || { cat "$work/callgrind.log" >&2; die "valgrind failed ($precision, $variant)"; }
  done
done
objdump -d --no-show-raw-insn "$ROBOT" >"$work/robot.dis"
load_after="$(cut -d' ' -f1-3 /proc/loadavg)"

python3 - "$ROOT" "$ROBOT" "$NATIVE" "$MODEL" "$TICKS" "$work" "$load_before" "$load_after" "$OUT" "$ARGS" "$SKELETON" <<'PY'
import collections, datetime, json, os, re, resource, subprocess, sys

root, robot, native, model, ticks, work, load_before, load_after, out_path, args, skeleton = sys.argv[1:]
ticks = int(ticks)
lines = []
def say(s=""):
    lines.append(s)

def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout

def git(*a):
    try:
        return run(["git", "-C", root, *a]).strip()
    except Exception:
        return "?"

def cpu_model():
    for l in open("/proc/cpuinfo"):
        if l.startswith("model name"):
            return l.split(":", 1)[1].strip()
    return "?"

say("# nao_rt budgets (docs/embedded.md explains every number)")
say("command:  bench/embedded_budget.sh" + (" " + args if args else ""))
say("date:     " + datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"))
say("commit:   %s%s" % (git("rev-parse", "--short", "HEAD"), " (with uncommitted changes)" if git("status", "--porcelain", "--untracked-files=no") else ""))
say("host:     %s, %d cores; load average before %s, after the valgrind run %s" % (cpu_model(), os.cpu_count(), load_before, load_after))
say()

# 1. Sizes.
def blob_size(exe):
    # model.bin and the copies nao_codegen compiles in beside it (int8 or packed; empty otherwise)
    total = 0
    for l in run(["nm", "-S", exe]).splitlines():
        f = l.split()
        if len(f) == 4 and f[3] in ("nao_model_blob", "nao_model_int8", "nao_model_packed"):
            total += int(f[1], 16)
    return total
def sections(exe):
    s = {}
    for l in run(["size", "-A", exe]).splitlines():
        f = l.split()
        if len(f) >= 2 and f[0].startswith(".") and f[1].isdigit():
            s[f[0]] = int(f[1])
    return s
say("## 1. Binary sizes (bytes)")
say("%-34s %12s %12s %12s %14s %10s %10s" % ("", "file", "stripped", "weights", "stripped-w/o", ".text", ".bss"))
for name, exe in (("robot build-nao/bin/nao_rt", robot), ("native %s" % os.path.relpath(native, root), native)):
    stripped = os.path.join(work, "stripped")
    subprocess.run(["strip", "-o", stripped, exe], check=True)
    w = blob_size(exe)
    sec = sections(exe)
    say("%-34s %12d %12d %12d %14d %10d %10d" % (name, os.path.getsize(exe), os.path.getsize(stripped), w,
        os.path.getsize(stripped) - w, sec.get(".text", 0), sec.get(".bss", 0)))
say("(weights = the compiled-in model.bin and its int8 or packed copy, .rodata symbols nao_model_blob,")
say(" nao_model_int8, nao_model_packed; the robot build is static (fp32):")
say(" glibc, libstdc++, ODE and TinyXML are inside it, the native one links them as shared libraries)")
say()

# 2. Peak RSS.
def precision_of(exe):
    return json.loads(run([exe, "--info"]))["precision"]
def peak_rss_kib(cmd):
    pid = os.fork()
    if pid == 0:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        os.execv(cmd[0], cmd)
    _, status, usage = os.wait4(pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit("embedded_budget.sh: %s failed (exit %d)" % (" ".join(cmd), os.waitstatus_to_exitcode(status)))
    return usage.ru_maxrss
say("## 2. Peak resident set over a 600-tick run (--reference file:<whole_arm skeleton> --ticks 600)")
for name, exe, extra in (("robot, compiled-in model", robot, []),
                         ("robot, --weights models/default.bin", robot, ["--weights", model]),
                         ("native, compiled-in model (%s)" % precision_of(native), native, []),
                         ("native, compiled-in model as fp32", native, ["--precision", "fp32"]),
                         ("native, --weights models/default.bin", native, ["--weights", model])):
    kib = peak_rss_kib([exe, "--reference", "file:" + skeleton, "--movement", "whole_arm", "--ticks", "600",
                        "--zero-timing"] + extra)
    say("%-46s %7.1f MiB  (target <= 64 MB)" % (name, kib / 1024.0))
say()

# 3. and 4.: counts per tick (callgrind) and the Atom estimate, for each precision.
mnemonic = {}
for l in open(os.path.join(work, "robot.dis")):
    m = re.match(r"^\s+([0-9a-f]+):\t(\S+)", l)
    if m:
        mnemonic[int(m.group(1), 16)] = m.group(2)

def tick_budget(precision, variant, tag):
    events, cost_by_addr, summary = None, collections.Counter(), None
    skip_next = False
    with open(os.path.join(work, "callgrind_%s_%s.out" % (precision, variant))) as f:
        for l in f:
            if l.startswith("events:"):
                events = l.split()[1:]
            elif l.startswith("summary:"):
                summary = [int(x) for x in l.split()[1:]]
            elif l.startswith("calls="):
                skip_next = True          # the next line is the call's inclusive cost
            elif l.startswith("0x"):
                if skip_next:
                    skip_next = False
                    continue
                f_ = l.split()
                cost_by_addr[int(f_[0], 16)] += int(f_[2]) if len(f_) > 2 else 0   # Ir (fields: addr line Ir ...)
            else:
                skip_next = False
    if not summary or sum(summary) == 0:
        raise SystemExit("embedded_budget.sh: callgrind collected nothing (did runControllerTick get inlined?)")
    per = {e: v / ticks for e, v in zip(events, summary)}
    what = ("the whole tick, the in-process ODE arm (100 physics steps) included" if variant == "sim" else
            "the tick as on the robot: without the simulated arm (stepSim not collected), which LoLA replaces")
    say("## 3%s. One tick of the robot build, %s weights, %s; valgrind callgrind (mean of %d ticks, policy on)" % (
        tag, precision, what, ticks))
    say("caches simulated as the Atom E3845's: L1i 32 KiB 8-way, L1d 24 KiB 6-way, L2 (last level) 1 MiB 16-way, 64 B lines")
    say("instructions (Ir)            %12.0f" % per["Ir"])
    say("data reads / writes          %12.0f / %.0f" % (per["Dr"], per["Dw"]))
    say("L1i misses                   %12.0f" % per["I1mr"])
    say("L1d read / write misses      %12.0f / %.0f" % (per["D1mr"], per["D1mw"]))
    say("L2 misses (instr/read/write) %12.0f / %.0f / %.0f  = %.2f MB from DRAM per tick" % (
        per["ILmr"], per["DLmr"], per["DLmw"], (per["ILmr"] + per["DLmr"] + per["DLmw"]) * 64 / 1e6))
    # Executed instruction mix: address -> mnemonic from the disassembly.
    mix = collections.Counter()
    for a, ir in cost_by_addr.items():
        mix[mnemonic.get(a, "?")] += ir
    total = sum(mix.values())
    say("executed mix (top 10 of %d mnemonics, %% of Ir): %s" % (len(mix), ", ".join(
        "%s %.1f" % (k, 100.0 * v / total) for k, v in mix.most_common(10))))
    mulps = (mix["mulps"]) / ticks
    pmaddwd = mix["pmaddwd"] / ticks
    pmaddubsw = mix["pmaddubsw"] / ticks
    fp_other_mul = sum(v for k, v in mix.items() if k.startswith("mul") and k[3:] in ("ss", "sd", "pd")) / ticks
    say("packed-single multiplies per tick (mulps): %.0f; pmaddwd: %.0f; pmaddubsw: %.0f; other FP multiplies: %.0f" % (
        mulps, pmaddwd, pmaddubsw, fp_other_mul))
    say()

    # 4. The Atom estimate (docs/embedded.md, "Tick time on the Atom").
    f_hz = 1.91e9
    bw = 1333e6 * 8            # DDR3L-1333, one 64-bit channel: 10.66 GB/s theoretical
    dram_bytes = (per["ILmr"] + per["DLmr"] + per["DLmw"]) * 64
    t_issue = per["Ir"] / 2 / f_hz               # 2 instructions per cycle, Silvermont's width
    t_load = per["Dr"] / f_hz                    # one load per cycle
    # MULPS: one per 2 cycles on Silvermont; PMADDWD and PMADDUBSW counted the same way (their
    # Silvermont throughput is not in our reference facts: docs/embedded.md).
    t_mul = (2 * mulps + 2 * pmaddwd + 2 * pmaddubsw + 1 * fp_other_mul) / f_hz
    t_mem = dram_bytes / bw
    t_low = max(t_issue, t_load, t_mul, t_mem)
    t_ipc1 = per["Ir"] / 1 / f_hz
    t_high = t_ipc1 + dram_bytes / (0.5 * bw)
    say("## 4%s. Estimated tick on the NAO V6's Atom E3845 (1.91 GHz, DDR3L-1333 single channel), %s weights, %s" % (
        tag, precision, "with the simulated arm" if variant == "sim" else "as on the robot (no simulated arm)"))
    say("issue bound   Ir / (2 per cycle x 1.91 GHz)          = %.0f / 3.82e9   = %6.2f ms" % (per["Ir"], t_issue * 1e3))
    say("load bound    Dr / (1 per cycle x 1.91 GHz)          = %.0f / 1.91e9   = %6.2f ms" % (per["Dr"], t_load * 1e3))
    say("mul bound     (2 x (mulps + pmaddwd + pmaddubsw) + other muls) / 1.91 GHz = %.0f / 1.91e9 = %6.2f ms" % (
        2 * mulps + 2 * pmaddwd + 2 * pmaddubsw + fp_other_mul, t_mul * 1e3))
    say("DRAM bound    %.2f MB / 10.66 GB/s                       = %6.2f ms" % (dram_bytes / 1e6, t_mem * 1e3))
    say("optimistic    max of the four (all overlapped)                 = %6.2f ms" % (t_low * 1e3))
    say("pessimistic   Ir at 1 per cycle + DRAM at half bandwidth, serial = %.2f + %.2f = %6.2f ms" % (
        t_ipc1 * 1e3, dram_bytes / (0.5 * bw) * 1e3, t_high * 1e3))
    say("budget        20 ms per tick: %s" % (
        "met even pessimistically" if t_high <= 0.020 else
        "met optimistically, NOT pessimistically: measure on the robot" if t_low <= 0.020 else "NOT met"))
    say()

tick_budget("fp32", "sim", "a")
tick_budget("int8", "sim", "b")
tick_budget("fp32", "robot", "c")
tick_budget("int8", "robot", "d")
os.makedirs(os.path.dirname(out_path), exist_ok=True)
with open(out_path, "w") as f:
    f.write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
