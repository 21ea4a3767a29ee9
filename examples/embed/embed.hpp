// The controller as a robot framework embeds it: nao_core runs the ticks, nao_io reads model.bin
// once at configure time. The framework reads the joints, the controller turns the angles into
// a command, the framework writes it (docs/embedding.md walks through it).
#pragma once

#include "nao/controller.hpp"
#include "nao/model_file.hpp"

#include <memory>
#include <string>
#include <vector>
namespace embed {

// The architecture compiled in: the small one (models/autonomous.bin); nao_codegen writes a
// model's own (nao_model_dims.hpp).
using Dims = nao::SmallPolicyDims;

// Built at configure time: everything that reads a file, allocates or may throw.
struct Controller {
  nao::ModelFile file;  // the weights the policy's views read
  nao::ModelSpec spec;  // starts, workspace, run codes, retargeting setting
  std::unique_ptr<nao::ControllerModel<Dims>> model;
  std::unique_ptr<nao::ControllerData<Dims>> data;
  nao::SteadyClock clock;
};

inline std::unique_ptr<Controller> configure(const std::string& model_path, const nao::ArmModel& arm) {
  auto c = std::make_unique<Controller>();
  c->file = nao::readModelFile(model_path);
  nao::checkJointsMatch(c->file, arm, model_path);
  c->spec = nao::readModelSpec(c->file.header, nao::RetargetParams{}, model_path);
  std::vector<const float*> tensors;
  for (std::size_t i = 0; i < c->file.tensors.size(); ++i) tensors.push_back(c->file.data(i));
  const nao::PolicyWeights<Dims> weights = nao::bindPolicyWeights<Dims>(
      tensors.data(), tensors.size(), c->file.header.arch, c->file.header.conditioning);
  nao::ControllerParams params;
  params.retarget = c->spec.retarget;
  c->model = std::make_unique<nao::ControllerModel<Dims>>(
      nao::configureController(arm, weights, params, c->spec.workspace, c->spec.run_codes));
  c->data = std::make_unique<nao::ControllerData<Dims>>();
  return c;
}

// One cycle on the framework's joint interface (read() -> angles, write(q_cmd)): read, update
// (no I/O inside), write the command for the next period.
template <class Joints>
const nao::TickRecord& cycle(Controller& c, Joints& joints, const nao::SkeletonFrame* human) {
  const nao::TickRecord& rec = nao::updateController(*c.model, *c.data, joints.read(), human);
  joints.write(rec.q_cmd);
  return rec;
}

}  // namespace embed
