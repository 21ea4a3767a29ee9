#!/usr/bin/env python3
"""nao_core keeps no process-wide state and reads no environment (tests/CMakeLists.txt, layer_core_no_state).

usage: check_core_state.py LIBNAO_CORE_A RUNTIME_CORE_DIR

What the core computes depends only on its arguments: the policy's kernel is the bound weights'
(PolicyWeights::kernel), the CPU's features are asked of the compiler runtime each time. So:

1. no object of libnao_core.a (nm -C --format=sysv: class and section of every defined symbol) lies
   in a writable data section (.data*, .bss*, .tdata*, .tbss*, common), whatever its class (D, d,
   B, b, V, u: globals, statics, function-local statics, inline variables, their guards), except
   what the compiler adds for itself (ALLOWED below). .data.rel.ro* is read-only once relocated
   (vtables, typeinfo) and is not state;
2. no source under runtime/core names getenv, secure_getenv, setenv, putenv or environ, and the
   archive uses none of them from outside.

Exit 0 when both hold, 1 with one line per finding.
"""
import pathlib
import re
import subprocess
import sys

WRITABLE = re.compile(r"^(\.data|\.bss|\.tdata|\.tbss)(\.|$)|^\*COM\*$|^COMMON$")
READ_ONLY_AFTER_RELOCATION = re.compile(r"^\.data\.rel\.ro(\.|$)")
# What the toolchain itself puts in writable data:
#   DW.ref.__gxx_personality_v0  GCC's pointer to the C++ exception personality routine, one hidden
#                                copy per object that has unwind tables; in .data.rel.local because
#                                position-independent code needs it relocated. Written by the loader
#                                only, never by our code.
ALLOWED = {"DW.ref.__gxx_personality_v0"}
ENVIRONMENT = re.compile(r"\b(secure_getenv|getenv|setenv|unsetenv|putenv|clearenv|__environ|environ)\b")


def state_symbols(archive):
    out = subprocess.run(["nm", "-C", "--format=sysv", "--defined-only", archive], check=True,
                         capture_output=True, text=True).stdout
    found = []
    member = "?"
    for line in out.splitlines():
        m = re.match(r"^Symbols from .*\[(.*)\]:$", line)
        if m:
            member = m.group(1)
            continue
        # Name|Value|Class|Type|Size|Line|Section; a demangled name may hold '|' (operator|).
        parts = line.rsplit("|", 6)
        if len(parts) != 7:
            continue
        name, _value, cls, typ, _size, _line, section = (p.strip() for p in parts)
        if typ == "SECTION" or not section:
            continue
        if WRITABLE.search(section) and not READ_ONLY_AFTER_RELOCATION.search(section) and name not in ALLOWED:
            found.append(f"{member}: '{name}' (class {cls}, {typ or 'no type'}) in {section}")
    return found


def environment_uses(archive, core_dir):
    found = []
    undefined = subprocess.run(["nm", "--undefined-only", "--format=just-symbols", archive], check=True,
                               capture_output=True, text=True).stdout.split()
    found += [f"libnao_core.a uses '{s}'" for s in sorted(set(undefined)) if ENVIRONMENT.fullmatch(s)]
    for path in sorted(pathlib.Path(core_dir).rglob("*")):
        if path.suffix not in {".hpp", ".cpp", ".h", ".cc"}:
            continue
        for number, text in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if ENVIRONMENT.search(text):
                found.append(f"{path}:{number}: {text.strip()}")
    return found


def main():
    if len(sys.argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    archive, core_dir = sys.argv[1:]
    problems = [f"mutable global: {s}" for s in state_symbols(archive)]
    problems += [f"environment: {s}" for s in environment_uses(archive, core_dir)]
    for p in problems:
        print("FAIL: " + p)
    if not problems:
        print(f"ok: {archive} has no object in writable data (allowed: {', '.join(sorted(ALLOWED))}) and "
              f"{core_dir} reads no environment")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
