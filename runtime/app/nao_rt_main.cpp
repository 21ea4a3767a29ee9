// nao_rt: the NAO V6 right-arm imitation controller runtime (docs/nao_rt.md).
//
// The policy is compiled in (models/default.bin through nao_codegen at build time); --weights
// loads another model.bin of the same architecture. This file only binds nao_rt's main
// (rt_main.hpp) to the compiled dimensions and the compiled-in model.
#include "rt_main.hpp"

#if NAO_HAVE_COMPILED_MODEL
#include "nao/compiled_model.hpp"
#include "nao_model_dims.hpp"
#endif

int main(int argc, char** argv) {
#if NAO_HAVE_COMPILED_MODEL
  return nao::rt::naoRtMain<nao::compiled::Dims>(argc, argv, nao::compiled::modelImage());
#else
  // Without a compiled-in model, --weights must be of the paper architecture.
  return nao::rt::naoRtMain<nao::PaperPolicyDims>(argc, argv, nao::ModelImage{});
#endif
}
