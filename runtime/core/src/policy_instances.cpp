// The policy step of the paper and the small configuration, compiled once (nao/policy.hpp says why).
#include "nao/policy.hpp"

namespace nao {

NAO_POLICY_STEP_INSTANCES(, PaperPolicyDims)
NAO_POLICY_STEP_INSTANCES(, SmallPolicyDims)

}  // namespace nao
