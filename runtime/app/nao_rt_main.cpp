// nao_rt: the NAO V6 right-arm imitation controller runtime (docs/nao_rt.md).
//
// The policy is compiled in (models/default.bin through nao_codegen at build time); --weights
// loads another model.bin of the same architecture, or of the paper's or the small
// configuration's (models/autonomous.bin), which are compiled beside it. This file only binds
// nao_rt's main (rt_main.hpp) to those dimensions and the compiled-in model. The robot build
// (NAO_RT_ONE_ARCHITECTURE) holds the compiled-in model's alone.
#include "rt_main.hpp"

#if NAO_HAVE_COMPILED_MODEL
#include "nao/compiled_model.hpp"
#include "nao_model_dims.hpp"
#endif

int main(int argc, char** argv) {
#if NAO_HAVE_COMPILED_MODEL
#if NAO_RT_ONE_ARCHITECTURE
  return nao::rt::naoRtMain<nao::compiled::Dims>(argc, argv, nao::compiled::modelImage());
#else
  return nao::rt::naoRtMain<nao::compiled::Dims, nao::PaperPolicyDims, nao::SmallPolicyDims>(
      argc, argv, nao::compiled::modelImage());
#endif
#else
  // Without a compiled-in model, --weights must be of the paper or the small architecture.
  return nao::rt::naoRtMain<nao::PaperPolicyDims, nao::SmallPolicyDims>(argc, argv, nao::ModelImage{});
#endif
}
