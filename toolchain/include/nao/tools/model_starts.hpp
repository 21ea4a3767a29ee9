// The autonomous starts of a model (model.bin metadata "starts", nao/model_file.hpp) from the
// data set it was trained on: its held-out demonstrations' start states. The trainer writes them
// into a new model itself; nao_toolchain model-starts adds them to a model.bin that has none.
// Offline code: reads files, allocates, throws UserError.
#pragma once

#include "nao/model_file.hpp"

#include <string>

namespace nao::tools {

/// The starts of the model with header `header`, from the clustered data set `data_dir`
/// (out/train/data layout: <movement>_<index>/retarget.csv and features.csv): for every
/// demonstration of the model's split.val, in that order and by movement (movement_names order),
/// its name, its length (the rows of its features.csv, the 10 Hz grid) and its start pose (the
/// first row's qr_0..4 of its retarget.csv: the retargeted first pose, rad). Throws UserError for
/// a model without split.val, a name that is not <movement>_<index> of one of its movements, or a
/// demonstration missing from the data set.
ModelStarts heldOutStarts(const ModelHeader& header, const std::string& data_dir);

/// Writes `model` to `out` with the starts of heldOutStarts(data_dir) in its metadata (every other
/// key, the header and the tensors as they were). When the metadata records the fingerprint of the
/// data the model was trained on (data.fingerprint), the data set's must be the same. Throws
/// UserError or ModelFileError. Returns the starts written.
ModelStarts addModelStarts(const ModelFile& model, const std::string& data_dir, const std::string& out);

}  // namespace nao::tools
