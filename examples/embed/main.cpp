// A robot framework's view of nao-rt: configure, activate, 100 cycles of read -> update ->
// write, deactivate, and each tick's attention, against a joint interface written here (your
// framework's goes where KinematicJoints is). Links nao_core and nao_io only.
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

int main(int argc, char** argv) {
  if (argc < 3) return std::fprintf(stderr, "usage: %s MODEL.bin URDF [MOVEMENT [START]]\n", argv[0]), 2;
  try {
    const nao::ArmModel arm = nao::loadArmModel(argv[2]);
    const auto c = embed::configure(argv[1], arm);
    const std::vector<std::string>& names = c->file.header.movement_names;
    const auto m = static_cast<std::size_t>(std::find(names.begin(), names.end(), argc > 3 ? argv[3] : names[0]) - names.begin());
    const std::size_t start = argc > 4 ? std::stoul(argv[4]) : 0;
    if (m == names.size() || start >= c->spec.starts[m].size()) throw std::runtime_error("no such movement or start");
    // Activate: the framework brings the arm to the start pose; the run starts from what it reads.
    KinematicJoints joints{nao::clampToLimits(arm, c->spec.starts[m][start].q)};
    // The real-time part: nothing below allocates, throws or does I/O until deactivate.
    nao::activateController(*c->model, *c->data, joints.read(), static_cast<int>(m), c->clock);
    for (int tick = 0; tick < 100; ++tick) {
      // An autonomous model takes no human frame; a reference model takes this tick's skeleton.
      const nao::TickRecord& rec = embed::cycle(*c, joints, nullptr);
      const int focus = static_cast<int>(std::max_element(rec.att.begin(), rec.att.end()) - rec.att.begin());
      const nao::JointVector& q = joints.read();  // where the write took the arm
      std::printf("%3d  q %+.4f %+.4f %+.4f %+.4f %+.4f  attends %s  faults %u\n", tick, q[0], q[1], q[2], q[3], q[4],
                  nao::kJointNames[static_cast<std::size_t>(focus)], rec.fault);
    }
    nao::deactivateController(*c->model, *c->data);  // then the framework holds the arm
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nao_embed_example: %s\n", e.what());
    return 1;
  }
}
