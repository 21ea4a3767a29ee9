// A robot framework's view of nao-rt: configure, activate, 100 ticks of update, deactivate, and
// each tick's attention, against a kinematic arm written here (your framework's joint interface
// goes where KinematicArm is). Links nao_core and nao_io only.
//   usage: nao_embed_example MODEL.bin URDF [MOVEMENT [START]]
#include "embed.hpp"

#include "nao/arm_model_io.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

// An arm that reaches each command within the period: what a position-controlled joint
// interface does when its servos are fast enough.
struct KinematicArm final : nao::RobotBackend {
  nao::JointVector q = nao::JointVector::Zero();
  const nao::JointVector& activate(const nao::JointVector& q0) override { return q = q0; }
  const nao::JointVector& measured() const override { return q; }
  const nao::JointVector& command(const nao::JointVector& q_cmd) override { return q = q_cmd; }
  std::uint32_t faults() const override { return 0; }
  std::int64_t waitNs() const override { return 0; }
  nao::RobotStop stopReason() const override { return nao::RobotStop::kNone; }
  void deactivate() override {}
};

int main(int argc, char** argv) {
  if (argc < 3) return std::fprintf(stderr, "usage: %s MODEL.bin URDF [MOVEMENT [START]]\n", argv[0]), 2;
  try {
    const nao::ArmModel arm = nao::loadArmModel(argv[2]);
    KinematicArm robot;
    const auto c = embed::configure(argv[1], arm, robot);
    const std::vector<std::string>& names = c->file.header.movement_names;
    const auto m = static_cast<std::size_t>(std::find(names.begin(), names.end(), argc > 3 ? argv[3] : names[0]) - names.begin());
    const std::size_t start = argc > 4 ? std::stoul(argv[4]) : 0;
    if (m == names.size() || start >= c->spec.starts[m].size()) throw std::runtime_error("no such movement or start");

    // The real-time part: nothing below allocates, throws or does I/O until deactivate.
    nao::activateController(*c->model, *c->data, c->spec.starts[m][start].q, static_cast<int>(m), c->clock);
    for (int tick = 0; tick < 100; ++tick) {
      // An autonomous model takes no human frame; a reference model takes this tick's skeleton.
      const nao::TickRecord& rec = nao::updateController(*c->model, *c->data, nullptr);
      const int focus = static_cast<int>(std::max_element(rec.att.begin(), rec.att.end()) - rec.att.begin());
      std::printf("%3d  q %+.4f %+.4f %+.4f %+.4f %+.4f  attends %s  faults %u\n", tick, rec.q[0], rec.q[1],
                  rec.q[2], rec.q[3], rec.q[4], nao::kJointNames[static_cast<std::size_t>(focus)], rec.fault);
    }
    nao::deactivateController(*c->model, *c->data);
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nao_embed_example: %s\n", e.what());
    return 1;
  }
}
