// The controller as a robot framework embeds it: nao_core runs the ticks, nao_io reads model.bin
// once at configure time. The framework reads the joints, the controller turns the angles into
// a command, the framework writes it (docs/embedding.md walks through it).
#pragma once

#include "nao/controller.hpp"
#include "nao/model_weights.hpp"

#include <memory>
#include <string>
#include <utility>

namespace embed {

// Built at configure time (reads files, allocates, may throw). Dims: the model's architecture.
template <class Dims>
struct Controller {
  explicit Controller(nao::ControllerModel<Dims> m) : model(std::move(m)) {}
  nao::ControllerModel<Dims> model;  // owns its weights: the model file may go once this exists
  std::unique_ptr<nao::ControllerData<Dims>> data = std::make_unique<nao::ControllerData<Dims>>();
  nao::SteadyClock clock;
};

// The model (joints checked against the arm), its metadata and weights. `params`: timeouts, home
// pose, human kinematics (the retargeting setting is the model's).
template <class Dims>
std::unique_ptr<Controller<Dims>> configure(const nao::ModelFile& file, const std::string& origin,
                                            const nao::ArmModel& arm, const nao::ControllerParams& params = {}) {
  nao::checkJointsMatch(file, arm, origin);
  return std::make_unique<Controller<Dims>>(nao::configureController(
      arm, nao::readModelSpec(file.header, nao::RetargetParams{}, origin), nao::bindPolicyWeights<Dims>(file), params));
}

// One cycle on the framework's joint interface (read() -> angles, write(q_cmd)): read, update
// (no I/O inside), write the command for the next period.
template <class Dims, class Joints>
const nao::TickRecord& cycle(Controller<Dims>& c, Joints& joints, const nao::SkeletonFrame* human) {
  const nao::TickRecord& rec = nao::updateController(c.model, *c.data, joints.read(), human);
  joints.write(rec.q_cmd);
  return rec;
}

}  // namespace embed
