// libccd entry points for a static link against Debian's libode.a (NAO_STATIC, preset nao).
//
// Debian builds ODE against the system libccd, but libccd-dev ships only a shared library, so a
// static nao_rt cannot link the real ones. ODE's collider table (collision_kernel.cpp) names its
// convex-geometry colliders, which call these three; the simulated arm has no collision geometry
// (sim_arm.cpp creates bodies and joints only), so they are never called. If one ever is, the
// program stops with a message rather than computing a wrong contact.
#include <cstdio>
#include <cstdlib>

namespace {
[[noreturn]] void noLibccd(const char* name) {
  std::fprintf(stderr, "nao: %s: ODE's libccd collision is not in this static build (docs/embedded.md)\n", name);
  std::abort();
}
}  // namespace

extern "C" {
void ccdFirstDirDefault(const void*, const void*, void*) { noLibccd("ccdFirstDirDefault"); }
int ccdMPRIntersect(const void*, const void*, const void*) { noLibccd("ccdMPRIntersect"); }
int ccdMPRPenetration(const void*, const void*, const void*, double*, void*, void*) { noLibccd("ccdMPRPenetration"); }
}
