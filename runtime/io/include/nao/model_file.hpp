// model.bin: one versioned little-endian file holding a trained policy (docs/policy.md).
// Written by `nao_toolchain train`, read by nao_rt, nao_codegen and the tests.
// Configure-time code: reading and writing allocate and may throw.
#pragma once

#include "nao/arm_model_io.hpp"
#include "nao/model_spec.hpp"
#include "nao/policy_config.hpp"

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace nao {

inline constexpr char kModelMagic[8] = {'N', 'A', 'O', 'P', 'O', 'L', 'C', 'Y'};
inline constexpr std::uint32_t kModelFormatVersion = 3;  ///< 3: action chunks, the bins field (always 0), law tensors
inline constexpr std::size_t kModelAlignment = 64;  ///< tensor data offsets are multiples of this

/// A model.bin that cannot be used: the message names the file and the problem.
class ModelFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct TrainedJoint {
  std::string name;       ///< URDF joint name
  double lower = 0.0;     ///< rad
  double upper = 0.0;     ///< rad
  double velocity = 0.0;  ///< rad/s
};

/// Everything in model.bin but the tensor data.
struct ModelHeader {
  PolicyArch arch;
  Conditioning conditioning = Conditioning::kReference;
  std::vector<TrainedJoint> joints;          ///< arch.tokens entries, joint order
  std::vector<std::string> movement_names;   ///< arch.movements entries, index order
  std::string metadata_json;                 ///< training config, seed, fingerprint, losses
};

/// Tensor table entry as stored: manifest name and shape, where its floats start.
struct TensorEntry {
  TensorSpec spec;
  std::uint64_t offset = 0;  ///< bytes from the start of the file
};

struct ModelFile {
  ModelHeader header;
  std::vector<TensorEntry> tensors;  ///< manifest order
  std::vector<std::uint8_t> bytes;   ///< the whole file as read (tensor data at the offsets)
  std::uint64_t checksum = 0;        ///< FNV-1a 64 stored at the end (verified)
  /// The file's bytes where they already are, not copied (the compiled-in model in .rodata);
  /// when set, `bytes` is empty and data() reads from here.
  const std::uint8_t* mapped = nullptr;
  std::size_t mapped_size = 0;

  /// Bytes of the file (read or mapped).
  std::size_t size() const { return mapped != nullptr ? mapped_size : bytes.size(); }

  /// Pointer to tensor `index`'s floats inside `bytes` or `mapped` (unaligned access is fine
  /// for Eigen::Map).
  const float* data(std::size_t index) const;
  /// Index of the tensor named `name`; throws ModelFileError if absent.
  std::size_t find(const std::string& name) const;
};

/// FNV-1a 64 over a byte range (the model checksum).
std::uint64_t fnv1a64(const std::uint8_t* data, std::size_t size, std::uint64_t seed = 0xcbf29ce484222325ull);

/// Builds the file bytes: `tensors` holds one float vector per manifest entry, in manifest order,
/// each of the manifest's element count. Throws ModelFileError on a size mismatch or an
/// unusable architecture.
std::vector<std::uint8_t> encodeModel(const ModelHeader& header, const std::vector<std::vector<float>>& tensors);

/// Checks a model.bin image that is used in place (the compiled-in bytes): the magic, then the
/// FNV-1a 64 over everything before the stored checksum, once over the mapped bytes, against the
/// stored value and against `expected` (what the generated code says it was built from). Throws
/// ModelFileError "<origin>: <problem>". No allocation unless it throws.
void checkModelImage(const std::uint8_t* data, std::size_t size, std::uint64_t expected, const std::string& origin);

/// A model.bin image used where it lies (the compiled-in model in .rodata, codegen/compiled),
/// with what the generated code states about it as constants.
struct ModelImage {
  const std::uint8_t* bytes = nullptr;     ///< nullptr: there is none
  std::size_t size = 0;
  std::uint64_t checksum = 0;              ///< the generated kChecksum
  const ModelHeader* header = nullptr;     ///< built from the generated constants
  const std::uint64_t* offsets = nullptr;  ///< the generated kTensorOffsets, manifest order
  const TensorExtent* extents = nullptr;   ///< the generated kTensorExtents (the views' extents)
  std::size_t tensors = 0;                 ///< entries of `offsets` and `extents`
  /// nao_codegen --precision int8: the int8 blob (nao/quantize.hpp) compiled in beside the
  /// model, and its generated FNV-1a 64; nullptr: the model was generated in fp32.
  const std::uint8_t* int8_bytes = nullptr;
  std::size_t int8_size = 0;
  std::uint64_t int8_checksum = 0;
  /// nao_codegen --precision fp32-packed: the packed fp32 blob (nao/quantize.hpp) compiled in
  /// beside the model; nullptr: none.
  const std::uint8_t* packed_bytes = nullptr;
  std::size_t packed_size = 0;
  std::uint64_t packed_checksum = 0;
};

/// `image` as a ModelFile that reads its tensors in place (`mapped`; `bytes` stays empty):
/// checkModelImage, then the header and the tensor table from the image's constants (shapes from
/// policyManifest(header->arch), the offsets, each range inside the image, each extent the
/// manifest's viewExtent). Nothing is decoded
/// and no tensor byte is copied. Throws ModelFileError "<origin>: <problem>".
ModelFile mappedModelFile(const ModelImage& image, const std::string& origin);

/// Hands the whole pages inside [data, data + size) of a read-only file-backed mapping (the
/// compiled-in image in .rodata) back to the OS: they leave the resident set and are read again
/// from the file (page cache) when next touched, with the same bytes. For an image whose
/// matrices a run reads from another copy (int8, packed) once its checksum has been verified
/// over it. Linux: madvise(MADV_DONTNEED); elsewhere it does nothing. Returns the bytes
/// released. Configure time only (the pages are faulted back in on the next read).
std::size_t releaseImagePages(const std::uint8_t* data, std::size_t size) noexcept;

/// encodeModel + write to `path` (whole file, then rename, so a crash leaves no half file).
/// Returns the checksum.
std::uint64_t writeModelFile(const std::string& path, const ModelHeader& header,
                             const std::vector<std::vector<float>>& tensors);

/// Parses and validates file bytes; `origin` names the source in messages. Rejects: wrong
/// magic, unknown version, truncation, checksum mismatch, an unusable architecture, a tensor
/// table that differs from the manifest (name, shape, order, offset), NaN/Inf weights.
/// Checked in that order; each ModelFileError reads "<origin>: <problem>". The checksum is
/// verified before any header field is believed: a file whose checksum fails is reported as
/// truncated only if its header is consistent with itself and describes a longer file, and
/// as a checksum mismatch otherwise (so one flipped byte after the version always reads
/// "checksum mismatch"). Every header read is bounded; counts are capped before use.
ModelFile decodeModel(std::vector<std::uint8_t> bytes, const std::string& origin);

/// Reads and validates `path` (decodeModel); an unreadable file throws ModelFileError too.
ModelFile readModelFile(const std::string& path);

/// Throws ModelFileError unless the joints the model was trained for are the arm's (names in
/// kJointNames order, limits within 1e-9 rad or rad/s).
void checkJointsMatch(const ModelFile& model, const ArmModel& arm, const std::string& origin);

/// Key poses of movement `m` (0..M-1) from the model's centroids tensor [M, K, J], rad.
std::vector<JointVector> modelKeyPoses(const ModelFile& model, int m);

/// The joints of `arm` as model.bin stores them.
std::vector<TrainedJoint> trainedJoints(const ArmModel& arm);

/// The model's header and metadata decoded once into their typed form (nao/model_spec.hpp): the
/// movement names, the starts, the workspace, the run codes, the retargeting setting (`defaults`
/// where the model records none), the split and the data fingerprint.
/// The one reader of model.bin's metadata. Throws ModelFileError, or std::runtime_error for an
/// unusable retargeting setting, naming `origin`. The sections:
///  - "starts" (the start states an autonomous run begins from, so that the
///    runtime never regenerates a demonstration):
///      "starts": {"<movement>": [{"name": "<demo>", "ticks": N, "q": [q0, q1, q2, q3, q4]}, ...], ...}
///    one key per movement in movement-index order, each list the held-out demonstrations (the
///    model's split.val of that movement, in that order): their names, lengths in 10 Hz ticks and
///    start poses (rad, joint order); empty lists when absent. Refused: not an object, a key that
///    is not one of the movements or a movement without a key, an entry that is not {"name":
///    non-empty string, "ticks": integer in 1..kMaxStartTicks, "q": 5 finite numbers}.
///    Code: model_starts.cpp.
///  - "workspace": {movement: {"lo": [5], "hi": [5]}}, one entry per movement, widened to the
///    movement's starts (a demonstration begins at its start); empty when absent. Refused: a
///    movement missing or unknown, not 5 finite numbers, lo above hi.
///  - "run_codes" (docs/autonomous.md "How a run commits to a variant": a model trained with a per-run
///    latent carries, per movement, its training demonstrations' start poses, the code of each -
///    the latent encoder's mean for the demonstration's clean rollout, projected to d_model: what
///    is added to every encoder token - and the hand-path DTW between every two of them):
///      "run_codes": {"<movement>": {"names": [...], "q": [[5]...], "code": [[d]...], "dtw_m": [[n]...]}, ...}
///    empty when absent (the zero code). A run from q0 takes the code of the medoid of the
///    kRunCodeNearest starts nearest q0 (the demonstration the evaluator's medoid replay tracks).
///    Refused: a movement missing or unknown, lists of different lengths, a q that is not 5 finite
///    numbers, a code that is not d_model finite numbers, a DTW table that is not n × n finite,
///    non-negative and symmetric. Code: model_run_codes.cpp.
///  - "data.retarget": {"priority": "hand"|"joints", "lambda_q": x, "posture_weights": [5]}, the
///    retargeting setting the training data were made with; `defaults` when absent.
///  - "split": {"train": [names], "val": [names]}, the demonstrations trained on and held out
///    (ModelSplit; entries that are not strings are left out, empty when absent), and
///    "data.fingerprint", the training data set's (empty when absent or not a string): what an
///    evaluation checks its data set and held-out demonstrations against.
ModelSpec readModelSpec(const ModelHeader& header, const RetargetParams& defaults, const std::string& origin);

/// `metadata_json` with "workspace" set (one entry per movement, in that order). Throws
/// ModelFileError when the metadata is not a JSON object or the lists do not match.
std::string withModelWorkspace(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                               const std::vector<ModelWorkspace>& workspace);

/// `metadata_json` with "run_codes" set (one entry per movement, in that order). Throws
/// ModelFileError when the metadata is not a JSON object or the lists do not match.
std::string withModelRunCodes(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                              const std::vector<ModelRunCodes>& codes);

/// `metadata_json` (an object, or empty for {}) with "starts" set to `starts` (one list per
/// movement of `movement_names`, keys in that order); every other key kept in place. The
/// serialiser the trainer and nao_toolchain model-starts write with. Throws ModelFileError when
/// the metadata is not a JSON object or the lists do not match the movements.
std::string withModelStarts(const std::string& metadata_json, const std::vector<std::string>& movement_names,
                            const ModelStarts& starts);

}  // namespace nao
