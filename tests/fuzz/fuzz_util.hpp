// Shared by the fuzz targets (tests/fuzz/fuzz_*.cpp): a check that survives release builds and
// a scratch file for the readers that take a path.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

/// A property every accepted input must have. Fails (abort: libFuzzer saves the input, the
/// corpus replay fails) in every build type, unlike assert.
#define NAO_FUZZ_CHECK(cond)                                                                  \
  do {                                                                                        \
    if (!(cond)) {                                                                            \
      std::fprintf(stderr, "%s:%d: fuzz check failed: %s\n", __FILE__, __LINE__, #cond);     \
      std::abort();                                                                           \
    }                                                                                         \
  } while (0)

namespace nao::fuzz {

/// A per-process scratch directory (removed at exit) for readers that open a path.
inline const std::filesystem::path& scratchDir() {
  // Never destroyed: the atexit handler runs after static destructors registered later.
  static const std::filesystem::path* const dir = [] {
    const auto* d = new std::filesystem::path(std::filesystem::temp_directory_path() /
                                              ("nao_fuzz_" + std::to_string(::getpid())));
    std::filesystem::create_directories(*d);
    std::atexit([] {
      std::error_code ec;
      std::filesystem::remove_all(scratchDir(), ec);
    });
    return d;
  }();
  return *dir;
}

/// Writes the input to `relative` inside scratchDir() and returns its path.
inline std::string writeScratch(const std::string& relative, const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path path = scratchDir() / relative;
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  out.close();
  NAO_FUZZ_CHECK(out.good());
  return path.string();
}

}  // namespace nao::fuzz
