#!/usr/bin/env python3
"""The runtime takes nothing from codegen/ but the compiled-in model generated there
(tests/CMakeLists.txt, runtime_takes_nothing_from_codegen).

usage: check_runtime_codegen.py REPORT EXECUTABLE...

REPORT is written by tests/CMakeLists.txt when the build system is generated: one line per target
defined under runtime/, "<target>: <codegen/ targets in its link closure>", the compiled-in model
(nao_compiled_model*) in brackets: that one is allowed, anything else is an arrow from the runtime
up into the code generator. Each executable's symbols are read with nm: none may be in namespace
nao::codegen. Exit 0 when all is clean, 1 with one line per problem.
"""
import subprocess
import sys


def main():
    if len(sys.argv) < 3:
        print(__doc__.strip().splitlines()[3], file=sys.stderr)
        return 2
    report, executables = sys.argv[1], sys.argv[2:]
    problems = []
    try:
        lines = [line.rstrip("\n") for line in open(report) if line.strip()]
    except OSError as e:
        print(f"FAIL: {report}: {e} (re-run CMake)")
        return 1
    if not lines:
        print(f"FAIL: {report} is empty (re-run CMake)")
        return 1
    model_users = []
    for line in lines:
        target, _, deps = line.partition(":")
        names = deps.split()
        bad = [n for n in names if not (n.startswith("[") and n.endswith("]"))]
        if bad:
            problems.append(f"runtime target {target} links codegen/ targets {' '.join(bad)}; "
                            "expected only the compiled-in model (nao_compiled_model*)")
        if len(bad) < len(names):
            model_users.append(target)
    print(f"ok: link closures of {len(lines)} runtime targets read ({report}); the compiled-in model in "
          f"{', '.join(model_users) or 'none'}")
    for exe in executables:
        out = subprocess.run(["nm", "-C", "--defined-only", exe], capture_output=True, text=True)
        if out.returncode != 0 or not out.stdout:
            problems.append(f"{exe}: no symbols read (missing or stripped?)")
            continue
        codegen = [line.split(" ", 2)[-1] for line in out.stdout.splitlines() if "nao::codegen::" in line]
        if codegen:
            problems.append(f"{exe} holds {len(codegen)} symbols of nao::codegen, e.g. {codegen[0]}")
        else:
            print(f"ok: {exe}: no symbol of nao::codegen")
    for p in problems:
        print("FAIL: " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
