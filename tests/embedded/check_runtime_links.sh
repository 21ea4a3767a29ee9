#!/usr/bin/env bash
# nao_rt is the runtime only: no runtime target links a toolchain library, and no
# runtime executable holds toolchain code (the synthesiser, k-means, the offline triangulation,
# the evaluation: everything in namespace nao::tools).
#   usage: check_runtime_links.sh LINK_REPORT EXECUTABLE...
# LINK_REPORT is written by tests/CMakeLists.txt at configure time: one line per runtime target
# (runtime/, codegen/), "<target>: <toolchain targets in its link closure>" (nothing after the
# colon when it is clean). Each executable's symbols are read with nm.
# Exit 0 when all is clean; 1 with one line per problem.
set -euo pipefail
[[ $# -ge 2 ]] || { echo "usage: $0 LINK_REPORT EXECUTABLE..." >&2; exit 2; }
report="$1"
shift
status=0
[[ -s "$report" ]] || { echo "FAIL: $report is missing or empty (re-run CMake)"; exit 1; }
n_targets=0
while IFS= read -r line; do
  n_targets=$((n_targets + 1))
  target="${line%%:*}" deps="${line#*:}"
  deps="${deps# }"
  if [[ -n "$deps" ]]; then
    echo "FAIL: runtime target $target links toolchain libraries: $deps"
    status=1
  fi
done <"$report"
echo "ok: link closures of $n_targets runtime targets read ($report)"
# Known entry points of the synthesiser, the offline triangulation and k-means, by name (the
# triangulation core with its subject choice is the runtime's: live cameras use it).
known='renderCamera|sampleMotion|kmeansPlusPlus|generateDemo|triangulateCapture|observeDemo|synthesise'
for exe in "$@"; do
  [[ -x "$exe" ]] || { echo "FAIL: $exe: not an executable (build it first)"; status=1; continue; }
  symbols=$(nm -C --defined-only "$exe" 2>/dev/null || true)
  [[ -n "$symbols" ]] || { echo "FAIL: $exe: no symbols read (stripped?)"; status=1; continue; }
  tools=$(grep -c 'nao::tools::' <<<"$symbols" || true)
  named=$(grep -E "$known" <<<"$symbols" | awk '{$1=$2=""; print}' | sed 's/^ *//' | head -n 5 || true)
  if [[ "$tools" -ne 0 || -n "$named" ]]; then
    echo "FAIL: $exe holds toolchain code: $tools symbols in nao::tools::$( [[ -n "$named" ]] && echo ", e.g. $(echo $named)")"
    status=1
  else
    echo "ok: $exe: $(wc -l <<<"$symbols") symbols, none in nao::tools:: and none of $known"
  fi
done
exit $status
