// A robot framework's view of nao-rt: configure, activate, 100 cycles of read -> update -> write,
// deactivate, and each tick's attention, on a joint interface written here (your framework's goes
// where KinematicJoints is). Links nao_core and nao_io only. Runs both committed models.
//   usage: nao_embed_example MODEL.bin URDF [MOVEMENT [START]]
#include "embed.hpp"

#include "nao/arm_model_io.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

// A position-controlled joint interface whose servos reach each command within the period.
struct KinematicJoints {
  nao::JointVector q = nao::JointVector::Zero();
  const nao::JointVector& read() const { return q; }
  void write(const nao::JointVector& q_cmd) { q = q_cmd; }
};

template <class Dims>
int run(const nao::ModelFile& file, const nao::ArmModel& arm, int argc, char** argv) {
  const auto c = embed::configure<Dims>(file, argv[1], arm);
  const std::vector<std::string>& names = c->model.spec.movement_names;
  const auto m = static_cast<std::size_t>(std::find(names.begin(), names.end(), argc > 3 ? argv[3] : names[0]) - names.begin());
  const std::size_t start = argc > 4 ? std::stoul(argv[4]) : 0;
  if (m == names.size() || (start > 0 && start >= c->model.spec.starts[m].size()))
    throw std::runtime_error("no such movement or start");
  // Activate where the framework brought the arm: a model start (a reference model has none: home).
  const std::vector<nao::ModelStart>& starts = c->model.spec.starts[m];
  KinematicJoints joints{nao::clampToLimits(arm, start < starts.size() ? starts[start].q : c->model.home)};
  // The real-time part: nothing below allocates, throws or does I/O until deactivate.
  nao::activateController(c->model, *c->data, joints.read(), static_cast<int>(m), c->clock);
  for (int tick = 0; tick < 100; ++tick) {
    // An autonomous model takes no human frame; a reference model takes this tick's skeleton.
    const nao::TickRecord& rec = embed::cycle(*c, joints, nullptr);
    const int focus = static_cast<int>(std::max_element(rec.att.begin(), rec.att.end()) - rec.att.begin());
    const nao::JointVector& q = joints.read();  // where the write took the arm
    std::printf("%3d  q %+.4f %+.4f %+.4f %+.4f %+.4f  attends %s  faults %u\n", tick, q[0], q[1], q[2], q[3], q[4],
                nao::kJointNames[static_cast<std::size_t>(focus)], rec.fault);
  }
  nao::deactivateController(c->model, *c->data);  // then the framework holds the arm
  return 0;
}

int main(int argc, char** argv) {
  if (argc < 3) return std::fprintf(stderr, "usage: %s MODEL.bin URDF [MOVEMENT [START]]\n", argv[0]), 2;
  try {
    const nao::ArmModel arm = nao::loadArmModel(argv[2]);
    const nao::ModelFile file = nao::readModelFile(argv[1]);
    // The architectures compiled in (nao_codegen MODEL --out DIR writes another's, nao_model_dims.hpp).
    return nao::withPolicyDims<nao::PaperPolicyDims, nao::SmallPolicyDims>(
        file.header.arch, [&](auto dims) { return run<decltype(dims)>(file, arm, argc, argv); });
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nao_embed_example: %s\n", e.what());
    return 1;
  }
}
