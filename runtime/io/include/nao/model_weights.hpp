// A model.bin's tensors as the policy's weights: copied once into 64-byte aligned storage that
// the bound weights own (shared by every copy of them, a ControllerModel's included), so nothing
// built from a ModelFile depends on the file object staying alive. Configure-time code:
// allocates and may throw.
#pragma once

#include "nao/model_file.hpp"
#include "nao/policy.hpp"

#include <algorithm>
#include <cstddef>
#include <cstring>
#include <memory>
#include <new>
#include <stdexcept>
#include <vector>

namespace nao {

/// The aligned floats a model's tensors are copied into (bindPolicyWeights, nao_rt --weights).
struct WeightStorage {
  struct Free {
    void operator()(float* f) const noexcept { ::operator delete[](f, std::align_val_t{kModelAlignment}); }
  };
  std::unique_ptr<float[], Free> floats;
  std::size_t n_floats = 0;
};

/// Copies the tensors of `model` into `storage` (allocated here: every tensor of its table, each
/// padded to 64 bytes, 64-byte aligned, zero-filled, so the padding between tensors reads as
/// zeros) and returns where each one starts, in manifest order. Throws std::bad_alloc.
inline std::vector<const float*> copyWeightFile(const ModelFile& model, WeightStorage& storage) {
  std::vector<const float*> pointers;
  pointers.reserve(model.tensors.size());
  storage.n_floats = 0;
  for (const TensorEntry& t : model.tensors) storage.n_floats += (t.spec.count() + 15) / 16 * 16;
  storage.floats.reset(static_cast<float*>(
      ::operator new[](storage.n_floats * sizeof(float), std::align_val_t{kModelAlignment})));
  float* floats = storage.floats.get();
  std::fill(floats, floats + storage.n_floats, 0.0f);
  std::size_t used = 0;
  for (std::size_t i = 0; i < model.tensors.size(); ++i) {
    const std::size_t n = model.tensors[i].spec.count();
    if (used + n > storage.n_floats) throw std::logic_error("the weight storage is smaller than the model's manifest");
    std::memcpy(floats + used, model.data(i), n * sizeof(float));
    pointers.push_back(floats + used);
    used += (n + 15) / 16 * 16;
  }
  return pointers;
}

/// The policy's weights of a model.bin (readModelFile, or a mapped image): its tensors copied
/// into aligned storage the weights own (PolicyWeights::storage), the views bound by manifest
/// name, checked against the compiled Dims (checkPolicyArch: a model of another architecture is
/// refused, naming the difference). `kernel` as for the pointer form. The file may be destroyed
/// afterwards.
template <class Dims>
PolicyWeights<Dims> bindPolicyWeights(const ModelFile& file, PolicyKernel kernel = bestPolicyKernel()) {
  auto storage = std::make_shared<WeightStorage>();
  const std::vector<const float*> pointers = copyWeightFile(file, *storage);
  PolicyWeights<Dims> w =
      bindPolicyWeights<Dims>(pointers.data(), pointers.size(), file.header.arch, file.header.conditioning, kernel);
  w.storage = std::move(storage);
  return w;
}

}  // namespace nao
