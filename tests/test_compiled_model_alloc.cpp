// The compiled-in model (codegen/compiled): the generated code is assembled and
// linked into this test (nao_compiled_model: models/default.bin through nao_codegen), its views
// are bound at the generated offsets with no allocation, and it computes bit for bit what the
// --weights path computes from the same file. Built three times: test_compiled_model_alloc over
// the build's NAO_MODEL_PRECISION, and test_compiled_model_alloc_<fp32|int8|packed> over the
// other two nao_codegen precisions: int8 (the int8 blob in .rodata, bound in place, the same
// bytes and bits as nao_rt --precision int8) and fp32-packed (the packed copy in .rodata, the
// same bytes as nao_rt --precision fp32-packed makes and the same bits as fp32).
#include "nao/compiled_model.hpp"
#include "nao/model_file.hpp"
#include "nao/policy.hpp"
#include "nao/quantize.hpp"
#include "nao_model_config.hpp"
#include "support/alloc_counter.hpp"

#include <doctest/doctest.h>

#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

using namespace nao;
using nao::test::CountAllocations;

namespace {

// The views' names in visiting order, and whether each came with an int8 / packed companion.
template <class Dims>
std::vector<std::pair<std::string, bool>> visitedViews() {
  PolicyWeights<Dims> w;
  std::vector<std::pair<std::string, bool>> views;
  detail::visitWeightViews(w, [&](const detail::ViewName& n, auto&, auto&... quant) {
    views.emplace_back(n.str(), sizeof...(quant) == 1);
  });
  return views;
}

template <class Dims>
void checkVisitOrder() {
  const std::vector<TensorSpec> manifest = policyManifest(Dims::arch());
  const std::vector<std::pair<std::string, bool>> views = visitedViews<Dims>();
  REQUIRE(views.size() == manifest.size());
  CHECK(views.size() == detail::policyViewCount<Dims>(Dims::arch().chunk));
  for (std::size_t i = 0; i < views.size(); ++i) {
    CHECK_MESSAGE(views[i].first == manifest[i].name, "entry ", i, ": expected ", manifest[i].name, ", got ",
                  views[i].first);
    CHECK_MESSAGE(views[i].second == (manifest[i].role == TensorRole::kMatrix), manifest[i].name,
                  ": an int8 / packed companion exactly for the manifest's matrices");
  }
}

// The tensor's first float lies in [lo, hi).
bool inside(const void* p, const std::uint8_t* lo, const std::uint8_t* hi) {
  const auto* b = reinterpret_cast<const std::uint8_t*>(p);
  return b >= lo && b < hi;
}

}  // namespace

TEST_CASE("the runtime visits the policy's views in manifest order, the order the offsets follow, with int8 copies exactly for the manifest's matrices") {
  checkVisitOrder<PaperPolicyDims>();
  checkVisitOrder<SmallPolicyDims>();
}

TEST_CASE("the generated constants describe the file they were generated from") {
  const ModelFile file = readModelFile(NAO_COMPILED_MODEL_SOURCE);
  const compiled::ModelBytes blob = compiled::modelBytes();
  REQUIRE(blob.size == file.bytes.size());
  CHECK(std::memcmp(blob.data, file.bytes.data(), blob.size) == 0);
  CHECK(reinterpret_cast<std::uintptr_t>(blob.data) % kModelAlignment == 0);

  const ModelFile mapped = mappedModelFile(compiled::modelImage(), "compiled-in model");
  CHECK(mapped.bytes.empty());
  CHECK(mapped.mapped == blob.data);
  CHECK(mapped.size() == file.size());
  CHECK(mapped.checksum == file.checksum);
  CHECK(mapped.header.arch == file.header.arch);
  CHECK(mapped.header.conditioning == file.header.conditioning);
  CHECK(mapped.header.metadata_json == file.header.metadata_json);
  CHECK(mapped.header.movement_names == file.header.movement_names);
  REQUIRE(mapped.header.joints.size() == file.header.joints.size());
  for (std::size_t j = 0; j < file.header.joints.size(); ++j) {
    CHECK(mapped.header.joints[j].name == file.header.joints[j].name);
    CHECK(mapped.header.joints[j].lower == file.header.joints[j].lower);
    CHECK(mapped.header.joints[j].upper == file.header.joints[j].upper);
    CHECK(mapped.header.joints[j].velocity == file.header.joints[j].velocity);
  }
  REQUIRE(mapped.tensors.size() == file.tensors.size());
  for (std::size_t i = 0; i < file.tensors.size(); ++i) {
    CHECK(mapped.tensors[i].offset == file.tensors[i].offset);
    CHECK(mapped.tensors[i].spec.name == file.tensors[i].spec.name);
    CHECK(mapped.tensors[i].spec.shape == file.tensors[i].spec.shape);
  }
}

TEST_CASE("binding the compiled-in model allocates nothing and points into .rodata") {
  // Built before counting: the header's strings (once per process) and the origin's name.
  const ModelImage image = compiled::modelImage();
  const std::string origin = "compiled-in model";
  CountAllocations counter;
  checkModelImage(image.bytes, image.size, image.checksum, origin);
  const std::int64_t after_check = counter.count();
  const PolicyWeights<compiled::Dims> w = compiled::policyWeights();
  const std::int64_t n_alloc = counter.count();
  CHECK_MESSAGE(after_check == 0, "checking the image allocated ", after_check, " times");
  CHECK_MESSAGE(n_alloc == 0, "binding allocated ", n_alloc, " times");
  const std::uint8_t* lo = image.bytes;
  const std::uint8_t* hi = image.bytes + image.size;
  CHECK(inside(w.embed_in_weight.data(), lo, hi));
  CHECK(inside(w.enc[0].attn.wq.data(), lo, hi));
  CHECK(inside(w.dec.back().ffn.w3.data(), lo, hi));
  CHECK(inside(w.centroids.data(), lo, hi));
  CHECK(w.conditioning == compiled::kConditioning);
  // nao_codegen --precision int8: the int8 views point into the compiled-in int8 blob.
  CHECK(usesInt8(w) == compiled::kInt8Weights);
  if constexpr (compiled::kInt8Weights) {
    CountAllocations check_counter;
    checkInt8Image(image, image.header->arch, origin);
    CHECK(check_counter.count() == 0);
    const std::uint8_t* lo8 = image.int8_bytes;
    const std::uint8_t* hi8 = image.int8_bytes + image.int8_size;
    CHECK(inside(w.enc[0].attn.wq8.w, lo8, hi8));
    CHECK(inside(w.dec.back().ffn.w3q.scale, lo8, hi8));
  } else {
    CHECK(image.int8_bytes == nullptr);
  }
  // nao_codegen --precision fp32-packed: the packed views point into the compiled-in packed blob.
  CHECK(usesPacked(w) == compiled::kPackedWeights);
  if constexpr (compiled::kPackedWeights) {
    CountAllocations check_counter;
    checkPackedImage(image, image.header->arch, origin);
    CHECK(check_counter.count() == 0);
    CHECK(runPrecision("", true, image) == WeightPrecision::kFp32Packed);
    CHECK(inside(w.enc[0].attn.wq8.packed, image.packed_bytes, image.packed_bytes + image.packed_size));
    CHECK(inside(w.dec.back().ffn.w3q.packed, image.packed_bytes, image.packed_bytes + image.packed_size));
  } else {
    CHECK(image.packed_bytes == nullptr);
  }
}

TEST_CASE("a run's copy of a compiled-in blob holds the blob's bytes outside the image, whose released pages read back the same") {
  // nao_rt reads the int8 or packed blob from this copy (anonymous memory), not from .rodata.
  const ModelImage image = compiled::modelImage();
  // An fp32 build has no blob: its model bytes stand in (copied and released the same way).
  const std::uint8_t* blob = image.packed_bytes != nullptr ? image.packed_bytes
                             : image.int8_bytes != nullptr ? image.int8_bytes
                                                           : image.bytes;
  const std::size_t n = image.packed_bytes != nullptr ? image.packed_size
                        : image.int8_bytes != nullptr ? image.int8_size
                                                      : image.size;
  const std::vector<std::uint8_t> before(blob, blob + n);
  const AlignedBytes copy = anonymousCopy(blob, n);
  REQUIRE(copy.size == n);
  CHECK_FALSE(inside(copy.data.get(), image.bytes, image.bytes + image.size));
  if (image.packed_bytes != nullptr)
    CHECK_FALSE(inside(copy.data.get(), image.packed_bytes, image.packed_bytes + image.packed_size));
  if (image.int8_bytes != nullptr)
    CHECK_FALSE(inside(copy.data.get(), image.int8_bytes, image.int8_bytes + image.int8_size));
  CHECK(reinterpret_cast<std::uintptr_t>(copy.data.get()) % 64 == 0);
  CHECK(std::memcmp(copy.data.get(), before.data(), n) == 0);
  // The image's pages were handed back; reading them faults the file's bytes in again.
  CHECK(std::memcmp(blob, before.data(), n) == 0);
}

TEST_CASE("the compiled-in binding and the --weights path compute the same bits over a long rollout") {
  using Dims = compiled::Dims;
  const ModelFile file = readModelFile(NAO_COMPILED_MODEL_SOURCE);
  std::vector<const float*> ptrs;
  for (std::size_t i = 0; i < file.tensors.size(); ++i) ptrs.push_back(file.data(i));
  PolicyWeights<Dims> by_name = bindPolicyWeights<Dims>(ptrs.data(), ptrs.size(), file.header.arch, file.header.conditioning);
  // int8 generated code: the --weights path quantises the same file at start-up (nao_rt
  // --precision int8); both must be the same bytes and compute the same bits.
  AlignedBytes blob;
  if constexpr (compiled::kInt8Weights) {
    blob = quantizeModelInt8(file);
    const ModelImage image = compiled::modelImage();
    REQUIRE(blob.size == image.int8_size);
    CHECK(std::memcmp(blob.data.get(), image.int8_bytes, blob.size) == 0);
    bindQuantizedWeights<Dims>(by_name, blob.data.get());
  }
  // Packed generated code: the same bytes as packing the file at start-up; the --weights path
  // stays plain fp32, so the rollout below also checks that the packed copy gives fp32's bits.
  if constexpr (compiled::kPackedWeights) {
    const AlignedBytes packed = packModelFp32(file);
    const ModelImage image = compiled::modelImage();
    REQUIRE(packed.size == image.packed_size);
    CHECK(std::memcmp(packed.data.get(), image.packed_bytes, packed.size) == 0);
  }
  const PolicyWeights<Dims> at_offsets = compiled::policyWeights();
  auto ws_a = makePolicyWorkspace<Dims>();
  auto ws_b = makePolicyWorkspace<Dims>();
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<float> angle(-1.2f, 1.2f), delta(-0.05f, 0.05f);
  const int ticks = 3 * Dims::kWindow + 7;  // the rings wrap
  int differing = 0;
  for (int t = 0; t < ticks; ++t) {
    PolicyInput in;
    for (int j = 0; j < 5; ++j) {
      in.q[j] = angle(rng);
      in.a_prev[j] = delta(rng);
      in.r[j] = angle(rng);
    }
    in.movement = t % compiled::kMovements;
    in.step = t;
    const Eigen::Matrix<float, 5, 1> a = stepPolicy(by_name, *ws_a, in);
    const Eigen::Matrix<float, 5, 1> b = stepPolicy(at_offsets, *ws_b, in);
    REQUIRE(a.allFinite());
    if (std::memcmp(a.data(), b.data(), sizeof(float) * 5) != 0) ++differing;
    if (std::memcmp(&ws_a->score, &ws_b->score, sizeof ws_a->score) != 0) ++differing;
    if (std::memcmp(&ws_a->cross, &ws_b->cross, sizeof ws_a->cross) != 0) ++differing;
  }
  CHECK(differing == 0);
}

namespace {

/// A copy of the image's int8 or packed blob (`bytes`, `size`) passes `check`; one flipped byte
/// fails it on the checksum, and 64 bytes fewer on the size.
using BlobCheck = void (*)(const ModelImage&, const PolicyArch&, const std::string&);
void checkDamagedBlob(const ModelImage& image, const std::uint8_t* ModelImage::*bytes,
                      std::size_t ModelImage::*size, BlobCheck check, const std::string& what) {
  std::vector<std::uint8_t> q(image.*bytes, image.*bytes + image.*size);
  ModelImage bad = image;
  bad.*bytes = q.data();
  CHECK_NOTHROW(check(bad, image.header->arch, "compiled-in model"));
  q[q.size() / 3] ^= 0x01;
  CHECK_THROWS_WITH_AS(check(bad, image.header->arch, "compiled-in model"),
                       doctest::Contains((what + " weights checksum mismatch").c_str()), ModelFileError);
  bad.*size -= 64;
  CHECK_THROWS_WITH_AS(check(bad, image.header->arch, "compiled-in model"), doctest::Contains("the architecture needs"),
                       ModelFileError);
}

}  // namespace

TEST_CASE("a damaged or mismatched image is refused with the checksum, and generated extents that are not the manifest's by name") {
  const ModelImage image = compiled::modelImage();
  std::vector<std::uint8_t> copy(image.bytes, image.bytes + image.size);
  ModelImage damaged = image;
  damaged.bytes = copy.data();
  copy[copy.size() / 2] ^= 0x10;
  CHECK_THROWS_WITH_AS(mappedModelFile(damaged, "compiled-in model"),
                       doctest::Contains("compiled-in model: checksum mismatch"), ModelFileError);
  copy[copy.size() / 2] ^= 0x10;
  ModelImage other = damaged;
  other.checksum ^= 1;
  CHECK_THROWS_WITH_AS(mappedModelFile(other, "compiled-in model"), doctest::Contains("its generated code describes"),
                       ModelFileError);
  CHECK_NOTHROW(mappedModelFile(damaged, "compiled-in model"));
  // Generated view extents that are not the manifest's: refused, naming the tensor.
  std::vector<TensorExtent> extents(image.extents, image.extents + image.tensors);
  std::swap(extents[0].rows, extents[0].cols);
  ModelImage reshaped = image;
  reshaped.extents = extents.data();
  CHECK_THROWS_WITH_AS(mappedModelFile(reshaped, "compiled-in model"),
                       doctest::Contains("tensor 'embed.in.weight' has the generated extent"), ModelFileError);
  if constexpr (compiled::kInt8Weights)
    checkDamagedBlob(image, &ModelImage::int8_bytes, &ModelImage::int8_size, checkInt8Image, "int8");
  if constexpr (compiled::kPackedWeights)
    checkDamagedBlob(image, &ModelImage::packed_bytes, &ModelImage::packed_size, checkPackedImage, "packed");
}

namespace {

/// Resident pages of this process (/proc/self/statm, second field); -1 if unreadable.
long residentPages() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (f == nullptr) return -1;
  long size = 0, resident = -1;
  if (std::fscanf(f, "%ld %ld", &size, &resident) != 2) resident = -1;
  std::fclose(f);
  return resident;
}

}  // namespace

TEST_CASE("releaseImagePages takes the image out of the resident set; the next read gets the same bytes") {
#if defined(__linux__)
  const ModelImage image = compiled::modelImage();
  const long page = sysconf(_SC_PAGESIZE);
  REQUIRE(page > 0);
  checkModelImage(image.bytes, image.size, image.checksum, "compiled-in model");  // every page resident
  const long before = residentPages();
  REQUIRE(before > 0);
  const std::size_t released = releaseImagePages(image.bytes, image.size);
  const long after = residentPages();
  // All whole pages inside the image, and the resident set down by (nearly) as many: a page
  // or two may come back for this process's own stack or heap meanwhile.
  CHECK(released + 2 * static_cast<std::size_t>(page) >= image.size);
  CHECK(static_cast<double>(before - after) * static_cast<double>(page) >= 0.95 * static_cast<double>(released));
  // Read again from the file: the checksum still holds, and the pages are back.
  CHECK_NOTHROW(checkModelImage(image.bytes, image.size, image.checksum, "compiled-in model"));
  CHECK(static_cast<double>(residentPages() - after) * static_cast<double>(page) >= 0.95 * static_cast<double>(released));
  CHECK(releaseImagePages(nullptr, 4096) == 0);
  CHECK(releaseImagePages(image.bytes, 16) == 0);  // no whole page inside
#else
  MESSAGE("releaseImagePages does nothing off Linux: not checked");
#endif
}
