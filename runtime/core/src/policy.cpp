// Configure-time parts of the policy runtime: binding the weight views to manifest tensors and
// the architecture check (nao/policy.hpp).
#include "nao/policy.hpp"

#include <stdexcept>
#include <string>
#include <unordered_map>

namespace nao::detail {

namespace {

std::string shapeText(const std::vector<int>& shape) {
  std::string s = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? "," : "") + std::to_string(shape[i]);
  return s + "]";
}

// The dimensions a compiled runtime fixes (PolicyDims): the computation's, not the tables'.
std::string computeText(const PolicyArch& a) {
  std::string ffn;
  for (std::size_t i = 0; i < a.ffn_hidden.size(); ++i) ffn += (i ? "-" : "") + std::to_string(a.ffn_hidden[i]);
  return "d_model " + std::to_string(a.d_model) + ", heads " + std::to_string(a.heads) + ", encoder layers " +
         std::to_string(a.encoder_layers) + ", decoder layers " + std::to_string(a.decoder_layers) + ", ffn " + ffn +
         ", tokens " + std::to_string(a.tokens) + ", features " + std::to_string(a.features) + ", window " +
         std::to_string(a.window);
}

}  // namespace

void bindWeightSlots(const std::vector<WeightSlot>& slots, const std::vector<TensorSpec>& manifest,
                     const float* const* tensors, std::size_t count) {
  if (count != manifest.size())
    throw std::invalid_argument("policy weights: " + std::to_string(count) + " tensors given, the manifest has " +
                                std::to_string(manifest.size()));
  if (count > 0 && tensors == nullptr) throw std::invalid_argument("policy weights: null tensor table");

  std::unordered_map<std::string, std::size_t> by_name;
  for (std::size_t i = 0; i < slots.size(); ++i)
    if (!by_name.emplace(slots[i].name, i).second)
      throw std::invalid_argument("policy weights: two views named '" + slots[i].name + "'");

  std::vector<bool> bound(slots.size(), false);
  for (std::size_t i = 0; i < manifest.size(); ++i) {
    const TensorSpec& spec = manifest[i];
    const auto it = by_name.find(spec.name);
    if (it == by_name.end())
      throw std::invalid_argument("policy weights: manifest tensor '" + spec.name + "' (entry " + std::to_string(i) +
                                  ") has no view in PolicyWeights");
    const WeightSlot& slot = slots[it->second];
    const TensorExtent extent = viewExtent(spec);
    long rows = static_cast<long>(extent.rows), cols = static_cast<long>(extent.cols);
    // A flat view (one dynamic column) takes the tensor whole.
    if (slot.rows == Eigen::Dynamic && slot.cols == 1) {
      rows *= cols;
      cols = 1;
    }
    if ((slot.rows != Eigen::Dynamic && rows != slot.rows) || (slot.cols != Eigen::Dynamic && cols != slot.cols))
      throw std::invalid_argument("policy weights: tensor '" + spec.name + "' has shape " + shapeText(spec.shape) +
                                  " (Eigen [" + std::to_string(rows) + "," + std::to_string(cols) +
                                  "]), its view is Eigen [" + std::to_string(slot.rows) + "," +
                                  std::to_string(slot.cols) + "]");
    if (slot.matrix != (spec.role == TensorRole::kMatrix))
      throw std::invalid_argument("policy weights: tensor '" + spec.name + "' is " +
                                  (spec.role == TensorRole::kMatrix ? "" : "not ") +
                                  "a matrix with int8 and packed copies in the manifest, its view " +
                                  (slot.matrix ? "has" : "has no") + " such copies");
    if (bound[it->second]) throw std::invalid_argument("policy weights: tensor '" + spec.name + "' listed twice");
    if (tensors[i] == nullptr)
      throw std::invalid_argument("policy weights: tensor '" + spec.name + "' (entry " + std::to_string(i) +
                                  ") has no data");
    slot.rebind(slot.view, tensors[i], rows, cols);
    bound[it->second] = true;
  }
  for (std::size_t i = 0; i < slots.size(); ++i)
    if (!bound[i]) throw std::invalid_argument("policy weights: view '" + slots[i].name + "' is not in the manifest");
}

void requireArch(const PolicyArch& compiled, const PolicyArch& given) {
  if (computeText(compiled) != computeText(given) || compiled.ffn_hidden != given.ffn_hidden)
    throw std::invalid_argument("policy architecture (" + computeText(given) + ") differs from the compiled one (" +
                                computeText(compiled) + ")");
  const std::string problem = archProblem(given);
  if (!problem.empty()) throw std::invalid_argument("policy architecture: " + problem);
  if (given.chunk > kPolicyMaxChunk)
    throw std::invalid_argument("policy architecture: chunk " + std::to_string(given.chunk) + " is above the runtime's " +
                                std::to_string(kPolicyMaxChunk));
}

}  // namespace nao::detail
