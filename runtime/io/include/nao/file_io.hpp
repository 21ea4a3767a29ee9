// Whole-file writes that readers never see half done (model.bin, attention.bin).
#pragma once

#include <cstddef>
#include <string>

namespace nao {

/// Writes `size` bytes to a temporary file next to `path` (mode 0644, fsync'ed) and renames it
/// over `path`: a reader sees the old file or the new one, never part of one. Returns an empty
/// string on success, else what failed (with the system's reason, without `path`); the
/// temporary file is removed on failure. Not for the real-time path.
std::string writeFileAtomically(const std::string& path, const void* data, std::size_t size);

}  // namespace nao
