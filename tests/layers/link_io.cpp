// Links nao_io alone (layer_io_links): the files need nao_core, the JSON and URDF readers, no
// robot backend and no live input.
#include "nao/arm_model_io.hpp"
#include "nao/attention_shm.hpp"
#include "nao/model_file.hpp"
#include "nao/skeleton_csv.hpp"

int main(int argc, char** argv) {
  if (argc < 4) return 0;  // linking is the test; run with files to read them
  const nao::ArmModel arm = nao::loadArmModel(argv[1]);
  const nao::ModelFile model = nao::readModelFile(argv[2]);
  nao::checkJointsMatch(model, arm, argv[2]);
  return nao::readSkeletonCsv(argv[3]).empty() ? 1 : 0;
}
