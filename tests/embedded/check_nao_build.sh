#!/usr/bin/env bash
# The robot build (preset nao, build-nao/; docs/embedded.md) is what the NAO V6
# can run:
#   1. static: no program interpreter, no NEEDED library, no glibc symbol version requirement
#      (so the robot's own glibc, whatever its version, is never asked for anything);
#   2. no AVX/AVX2/AVX-512/FMA instruction (any VEX/EVEX-encoded instruction: a ymm/zmm
#      register, a vfmadd..., or a v-prefixed xmm one) in any function of our code, ODE,
#      TinyXML or libstdc++. The only functions that have them are glibc's CPU-dispatched
#      variants (memcpy_avx_unaligned, strlen_evex, exp_fma, ...), which static glibc links in
#      beside their SSE2 versions and which its IFUNC resolvers pick only on CPUs that have the
#      extension - never on the Atom. Each such function must be defined by libc.a/libm.a and
#      carry the extension in its name; their number is printed;
#   3. it runs the three demo movements (the demo's recorded references: demonstration 0 of run
#      seed 1000001, synthesised and triangulated by NAO_TOOLCHAIN into WORK_DIR, --reference
#      file:PATH) with the closed-loop RMSE of the native build within +-0.1 mm (and with no heap
#      allocation after activate).
#   usage: check_nao_build.sh NAO_RT_ROBOT NAO_RT_NATIVE WORK_DIR NAO_TOOLCHAIN
# Exit 0 pass, 1 fail, 77 skipped (the robot build does not exist; toolchain/nao test builds it).
set -euo pipefail
[[ $# -eq 4 ]] || { echo "usage: $0 NAO_RT_ROBOT NAO_RT_NATIVE WORK_DIR NAO_TOOLCHAIN" >&2; exit 2; }
robot="$1" native="$2" work="$3" tc="$4"
if [[ ! -x "$robot" ]]; then
  echo "SKIP: $robot does not exist: build the robot build first (cmake --preset nao && cmake --build build-nao --target nao_rt, or toolchain/nao test, which does)"
  exit 77
fi
fail() { echo "FAIL: $*"; exit 1; }

# 1. Static.
readelf -l "$robot" | grep -q 'INTERP' && fail "$robot has a program interpreter: it is dynamically linked"
needed=$(readelf -d "$robot" 2>/dev/null | grep '(NEEDED)' || true)
[[ -z "$needed" ]] || fail "$robot needs shared libraries: $needed"
versions=$(readelf -V "$robot" | grep -o 'GLIBC_[0-9.]*' | sort -uV || true)
[[ -z "$versions" ]] || fail "$robot requires glibc symbol versions: $(echo $versions)"
echo "ok: $robot is static (no interpreter, no NEEDED, no GLIBC_ version requirement)"

# 2. No AVX/FMA outside glibc's CPU-dispatched variants.
# glibc's static archives: libc.a, and the ones libm.a (a linker script) groups.
glibc_archives=("$(gcc -print-file-name=libc.a)")
libm_a=$(gcc -print-file-name=libm.a)
if head -c 7 "$libm_a" | grep -q '!<arch>'; then
  glibc_archives+=("$libm_a")
else
  mapfile -t -O 1 glibc_archives < <(grep -o '/[^ )]*\.a' "$libm_a")
fi
glibc_symbols=$(nm --defined-only "${glibc_archives[@]}" 2>/dev/null | awk 'NF==3{print $3}' | sort -u)
[[ -n "$glibc_symbols" ]] || fail "no symbols read from glibc's archives (${glibc_archives[*]})"
# Functions with a VEX/EVEX instruction: a v-prefixed mnemonic, which covers every ymm/zmm use,
# every vfmadd/vfmsub/vfnmadd/vfnmsub and AVX-128 (VEX-encoded xmm) alike.
offenders=$(objdump -d --no-show-raw-insn "$robot" |
  awk '/^[0-9a-f]+ <.*>:$/{f=substr($2, 2, length($2)-3)} /^ +[0-9a-f]+:\t(\{[a-z0-9]+\} )?v[a-z]/{print f}' | sort -u)
n_avx=0 ours=()
while IFS= read -r f; do
  [[ -n "$f" ]] || continue
  if grep -qxF "$f" <<<"$glibc_symbols" && grep -qiE 'avx|evex|fma|xsave' <<<"$f"; then
    n_avx=$((n_avx + 1))
  else
    ours+=("$f")
  fi
done <<<"$offenders"
[[ ${#ours[@]} -eq 0 ]] || fail "AVX/FMA instructions outside glibc's CPU-dispatched variants, in: ${ours[*]}"
n_ymm=$(objdump -d --no-show-raw-insn "$robot" | grep -cE '%[yz]mm' || true)
echo "ok: no AVX/FMA instruction in our code, ODE, TinyXML or libstdc++; glibc's CPU-dispatched variants with them: $n_avx functions ($n_ymm ymm/zmm operands), never selected on the Atom (no AVX)"

# 3. The three demo movements, robot build against native build, on the same recorded references.
mkdir -p "$work"
rm -rf "$work/references"
"$tc" synth --movement all --per-movement 1 --seed 1000001 --out "$work/references" >"$work/synth.log" 2>&1 ||
  fail "$tc synth failed: $(tail -n 3 "$work/synth.log")"
status=0
for m in whole_arm elbow wrist; do
  skeleton="$work/references/${m}_000/skeleton.csv"
  "$tc" triangulate --demo "$work/references/${m}_000" --max-gap 0 --out "$skeleton" >"$work/triangulate-$m.log" 2>&1 ||
    fail "$tc triangulate failed on $m: $(tail -n 3 "$work/triangulate-$m.log")"
  for build in robot native; do
    exe="$robot"
    [[ $build == native ]] && exe="$native"
    rm -rf "$work/$build-$m"
    "$exe" --reference "file:$skeleton" --movement "$m" --zero-timing --log "$work/$build-$m" >"$work/$build-$m.log" 2>&1 ||
      fail "$exe --reference file:$skeleton failed: $(tail -n 3 "$work/$build-$m.log")"
  done
  python3 - "$work/robot-$m/summary.json" "$work/native-$m/summary.json" "$m" <<'PY' || status=1
import json, sys
robot, native, m = (json.load(open(sys.argv[1])), json.load(open(sys.argv[2])), sys.argv[3])
r, n = robot["ee_rmse_m"] * 1e3, native["ee_rmse_m"] * 1e3
alloc = robot["allocations_after_activate"]
ok = abs(r - n) <= 0.1 and robot["ticks"] == native["ticks"] and alloc == 0
print("%s %s: RMSE robot build %.4f mm, native %.4f mm (|diff| %.2e mm, tolerance 0.1), ticks %d/%d, allocations after activate %s"
      % ("ok:" if ok else "FAIL:", m, r, n, abs(r - n), robot["ticks"], native["ticks"], alloc))
sys.exit(0 if ok else 1)
PY
  if cmp -s "$work/robot-$m/ticks.csv" "$work/native-$m/ticks.csv"; then
    echo "     $m: ticks.csv byte-identical between the two builds"
  else
    echo "     $m: ticks.csv differs between the two builds (allowed: only the RMSE is compared)"
  fi
done
exit $status
