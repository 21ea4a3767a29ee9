#!/usr/bin/env python3
"""Link test of one runtime layer (tests/layers/CMakeLists.txt).

usage: check_layer.py LAYER CLOSURE_FILE LINK_PROGRAM STATIC_LIBRARY

Checks that the layer's link closure holds only what the layer may use, that a program linking the
layer alone needs no other shared library, and for core, that no symbol of the archive (nm) names
a parser, a simulator, a thread, a socket or a file, and that no source of runtime/core names a
robot backend (the controller's tick takes the measured angles and returns the command; the
caller talks to the robot). Exit 0 when all holds, 1 with one line per
problem (what was allowed, what was found).
"""
import pathlib
import re
import subprocess
import sys

CORE_SOURCES = pathlib.Path(__file__).resolve().parents[2] / "runtime" / "core"

CORE = {"nao_core", "Eigen3::Eigen", "nao_flags"}
# The URDF reader: urdfdom (and its console_bridge) or TinyXML, as libraries or their targets.
URDF = [r"PkgConfig::URDFDOM", r".*/liburdfdom_\w+\.(so|a)", r".*/libconsole_bridge\.(so|a)", r".*tinyxml.*"]
# Per layer: the targets and libraries its closure may reach (regular expressions, whole name).
ALLOWED_CLOSURE = {
    "core": [re.escape(t) for t in CORE],
    "io": [re.escape(t) for t in CORE | {"nao_io", "nlohmann_json::nlohmann_json"}]
          + URDF,
    "backends": [re.escape(t) for t in CORE | {"nao_backends", "Threads::Threads", "nao_ode_ccd_stubs"}]
                + [r"PkgConfig::ODE", r".*/libode\.(so|a)", r"-pthread"],
    "live": [re.escape(t) for t in CORE | {"nao_live", "nao_io", "Threads::Threads", "nlohmann_json::nlohmann_json"}]
            + URDF + [r"-pthread"],
}
# Shared libraries a program linking the layer may need (readelf -d NEEDED).
BASE_SO = [r"libstdc\+\+\.so.*", r"libm\.so.*", r"libgcc_s\.so.*", r"libc\.so.*", r"ld-linux.*"]
ALLOWED_SO = {
    "core": BASE_SO,
    "io": BASE_SO + [r"liburdfdom.*", r"libconsole_bridge.*", r"libtinyxml.*"],
    "backends": BASE_SO + [r"libode\.so.*"],
    "live": BASE_SO + [r"liburdfdom.*", r"libconsole_bridge.*", r"libtinyxml.*"],
}
# nao_core's symbols: what the C++ runtime and libm give (undefined ones), never a parser,
# simulator, thread, socket or file (any symbol).
CORE_UNDEFINED_OK = re.compile(
    r"^(std::|operator new|operator delete|__cxa_|__gxx_personality|_Unwind_|__dso_handle|__stack_chk_fail|"
    r"typeinfo for (std::|__cxxabiv1::)|vtable for (std::|__cxxabiv1::)|_GLOBAL_OFFSET_TABLE_|"
    r"__cpu_(model|features2|indicator_init)|"  # libgcc's CPU detection (the policy kernel's dispatch)
    r"(mem(cpy|move|set|cmp)|strlen|strcmp|getenv|abort|__assert_fail|clock_gettime|snprintf|aligned_alloc|malloc|free|"
    r"posix_memalign|__cxa_atexit|"
    r"(sqrt|exp|expm1|log|log1p|log2|pow|sin|cos|sincos|tan|asin|acos|atan|atan2|sinh|cosh|tanh|fabs|fmod|hypot|"
    r"floor|ceil|round|lround|nearbyint|rint|lrint|trunc|fmin|fmax|cbrt|remainder)f?)$)")
CORE_FORBIDDEN = re.compile(
    r"nlohmann|msgpack|urdf|TiXml|tinyxml|console_bridge|\bd(World|Body|Joint|Init|Close|Space)[A-Z]|"
    r"RobotBackend|pthread_|std::thread|std::(__cxx11::)?basic_(i|o)?fstream|std::filesystem|\b(f?open|fopen64|mmap|munmap|"
    r"shm_open|shm_unlink|inotify_\w+|socket|connect|poll|read|write|fread|fwrite|fclose)$")


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def whole(patterns, name):
    return any(re.fullmatch(p, name) for p in patterns)


def main():
    if len(sys.argv) != 5:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    layer, closure_file, program, archive = sys.argv[1:]
    problems = []
    closure = [line.strip() for line in open(closure_file) if line.strip()]
    print(f"nao_{layer} link closure: {' '.join(closure)}")
    for name in closure:
        if not whole(ALLOWED_CLOSURE[layer], name):
            problems.append(f"nao_{layer} links {name}; expected only {ALLOWED_CLOSURE[layer]}")
    needed = re.findall(r"\(NEEDED\).*\[(.*)\]", run(["readelf", "-d", program]))
    print(f"{program} NEEDED: {' '.join(needed)}")
    for so in needed:
        if not whole(ALLOWED_SO[layer], so):
            problems.append(f"a program linking nao_{layer} alone needs {so}; expected only {ALLOWED_SO[layer]}")
    if layer == "core":
        defined = set(run(["nm", "-C", "--defined-only", "--format=just-symbols", archive]).split("\n"))
        undefined = set(run(["nm", "-C", "--undefined-only", "--format=just-symbols", archive]).split("\n"))
        symbols = {s for s in defined | undefined if s and not s.endswith(":")}
        external = sorted(s for s in undefined - defined if s and not s.endswith(":"))
        print(f"{archive}: {len(symbols)} symbols, {len(external)} from outside the archive")
        for s in sorted(symbols):
            if CORE_FORBIDDEN.search(s):
                problems.append(f"libnao_core.a has symbol '{s}'; expected no parser, simulator, thread, socket or file")
        for s in external:
            if not CORE_UNDEFINED_OK.match(s) or CORE_FORBIDDEN.search(s):
                problems.append(f"libnao_core.a uses '{s}' from outside; expected only the C++ runtime and libm")
        for path in sorted(CORE_SOURCES.rglob("*.[ch]pp")):
            if re.search(r"\bRobotBackend\b", path.read_text(errors="replace")):
                problems.append(f"{path} names RobotBackend; expected the robot only outside nao_core")
    for p in problems:
        print("FAIL: " + p)
    if not problems:
        print(f"ok: nao_{layer} links only what the layer may use")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
