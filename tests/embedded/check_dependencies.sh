#!/usr/bin/env bash
# nao_rt depends only on what the loop needs (docs/embedded.md): its ELF names
# none of the offline toolchain's libraries, neither directly (NEEDED entries, readelf -d) nor
# through another library (the loader's closure, ldd).
#   usage: check_dependencies.sh EXECUTABLE...
# Exit 0 when every executable is clean; 1 with one line per forbidden library found.
set -euo pipefail
[[ $# -ge 1 ]] || { echo "usage: $0 EXECUTABLE..." >&2; exit 2; }

# Ceres and what it brings (glog, gflags, SuiteSparse, BLAS/LAPACK/ATLAS/OpenBLAS, gfortran and
# its quadmath, OpenMP), and toml++.
forbidden='libceres|libglog|libgflags|libcholmod|libcxsparse|libsuitesparse|libamd\.|libcamd|libcolamd|libccolamd|libmetis|libblas|liblapack|libf77blas|libcblas|libatlas|libopenblas|libgfortran|libquadmath|libgomp|libtomlplusplus|libtorch|libc10'
status=0
for exe in "$@"; do
  [[ -x "$exe" ]] || { echo "FAIL: $exe: not an executable (build it first)"; status=1; continue; }
  needed=$(readelf -d "$exe" | sed -n 's/.*(NEEDED).*\[\(.*\)\]/\1/p')
  closure=$(ldd "$exe" 2>&1 | awk '{print $1}' || true)
  echo "$exe NEEDED: $(echo $needed)"
  echo "$exe closure ($(echo "$closure" | grep -c .) entries): $(echo $closure)"
  bad=$(printf '%s\n%s\n' "$needed" "$closure" | grep -E "$forbidden" | sort -u || true)
  if [[ -n "$bad" ]]; then
    echo "FAIL: $exe depends on offline-toolchain libraries: $(echo $bad)"
    status=1
  fi
done
[[ $status -eq 0 ]] && echo "ok: no Ceres, glog, gflags, SuiteSparse, BLAS/LAPACK, gfortran or toml++"
exit $status
