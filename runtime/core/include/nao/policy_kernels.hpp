// The policy's kernels, one header per family under nao/policy_kernels/ (each family's kernels
// give the same bits whichever of kSse, kAvx2 and kAvx512 runs them):
//
//   dispatch.hpp  PolicyKernel, what this CPU runs (policyKernelSupported, bestPolicyKernel); the
//                 kernel is the bound weights' (PolicyWeights::kernel), passed to every call
//   lanes.hpp     the vector registers the families share (Eigen's packet, AVX-512 lane helpers)
//   affine.hpp    affineTokens: Y = W X + b over J token columns, W column-major (fp32)
//   packed.hpp    "Packed fp32": affineTokensPacked over W in the kernels' block order
//   int8.hpp      "Reduced precision": affineTokensInt8, int8 weights and quantised tokens
//   window.hpp    "Window attention": windowScores, windowValues over a ring of keys and values
//   softmax.hpp   the softmax's exponential (expShifted) and the window softmax (windowSoftmax)
//   norm.hpp      headSumNorm, the norm-based attention score's vector norm
#pragma once

#include "nao/policy_kernels/affine.hpp"    // IWYU pragma: export
#include "nao/policy_kernels/dispatch.hpp"  // IWYU pragma: export
#include "nao/policy_kernels/int8.hpp"      // IWYU pragma: export
#include "nao/policy_kernels/lanes.hpp"     // IWYU pragma: export
#include "nao/policy_kernels/norm.hpp"      // IWYU pragma: export
#include "nao/policy_kernels/packed.hpp"    // IWYU pragma: export
#include "nao/policy_kernels/softmax.hpp"   // IWYU pragma: export
#include "nao/policy_kernels/window.hpp"    // IWYU pragma: export
