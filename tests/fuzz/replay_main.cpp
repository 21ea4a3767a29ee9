// The fuzz target as a plain regression test (normal build, CTest): runs
// LLVMFuzzerTestOneInput once on every file of the corpus directories given on the command line
// (seeds and the crashes fuzzing found). A crash, an abort or an exception the target does not
// expect fails the test; so does an empty corpus, which would test nothing.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::vector<fs::path> files;
  for (int a = 1; a < argc; ++a) {
    std::error_code ec;
    if (fs::is_directory(argv[a], ec)) {
      for (const fs::directory_entry& e : fs::directory_iterator(argv[a]))
        if (e.is_regular_file()) files.push_back(e.path());
    } else {
      files.emplace_back(argv[a]);
    }
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) {
    std::fprintf(stderr, "replay: no corpus files given (usage: %s CORPUS_DIR|FILE...)\n", argv[0]);
    return 1;
  }
  for (const fs::path& f : files) {
    std::ifstream in(f, std::ios::binary);
    if (!in) {
      std::fprintf(stderr, "replay: cannot read %s\n", f.c_str());
      return 1;
    }
    const std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    // A copy of exactly `size` bytes, like libFuzzer's: a read past the end is an ASan error.
    const std::vector<std::uint8_t> input(bytes.begin(), bytes.end());
    static const std::uint8_t kNone = 0;  // libFuzzer never passes a null pointer, even for 0 bytes
    LLVMFuzzerTestOneInput(input.empty() ? &kNone : input.data(), input.size());
  }
  std::printf("replayed %zu corpus input(s) without a failure\n", files.size());
  return 0;
}
