// nao_codegen model.bin --out DIR: checks a model file and writes the sources that compile
// it into nao_rt (docs/policy.md "codegen"). Exit 0 on success, 1 on a bad model or an
// output that cannot be written, 2 on a bad command line; every error is one stderr line.
//
// The command line is parsed by hand: nao_codegen sits on the build's critical path to nao_rt
// when a model is compiled in, and CLI11 alone takes ~20 s to compile here.
#include "nao/codegen.hpp"

#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

namespace {

constexpr const char* kUsage =
    "Usage: nao_codegen MODEL --out DIR [--precision fp32|fp32-packed|int8] [--quiet]\n"
    "\n"
    "Checks MODEL (a model.bin: magic, version, checksum, architecture, tensor table, finite weights)\n"
    "and writes into DIR (created if missing):\n"
    "  nao_model_config.hpp  every dimension constexpr, checksum, tensor names/offsets, joints, movements\n"
    "  nao_model_dims.hpp    using Dims = nao::PolicyDims<...>\n"
    "  nao_model_weights.S   .incbin of DIR/model.bin into .rodata, 64-byte aligned\n"
    "  model.bin             a copy of MODEL\n"
    "  model.int8            --precision int8: the int8 weights (attention and FFN matrices, one\n"
    "                        scale per row, docs/policy.md), compiled in beside model.bin; nao_rt then\n"
    "                        runs int8 by default. Empty otherwise\n"
    "  model.packed          --precision fp32-packed: the attention and FFN matrices again, in the\n"
    "                        kernels' block order (the same bits as fp32, read in address order);\n"
    "                        nao_rt then runs fp32-packed by default. Empty otherwise\n"
    "Files whose content would not change are left untouched, so rebuilds stay cheap.\n"
    "\n"
    "Options:\n"
    "  --out DIR    output directory (required)\n"
    "  --precision P  fp32 (default, the reference), fp32-packed or int8\n"
    "  -q, --quiet  print nothing on success\n"
    "  -h, --help   print this help and exit\n";

int usageError(const std::string& what) {
  std::fprintf(stderr, "nao_codegen: %s (see nao_codegen --help)\n", what.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string model_path, out_dir;
  bool quiet = false;
  nao::WeightPrecision precision = nao::WeightPrecision::kFp32;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "-h" || arg == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (arg == "-q" || arg == "--quiet") {
      quiet = true;
    } else if (arg == "--out" || arg.rfind("--out=", 0) == 0) {
      if (arg == "--out" && i + 1 >= argc) return usageError("--out needs a directory");
      out_dir = arg == "--out" ? argv[++i] : arg.substr(6);
      if (out_dir.empty()) return usageError("--out needs a directory");
    } else if (arg == "--precision" || arg.rfind("--precision=", 0) == 0) {
      if (arg == "--precision" && i + 1 >= argc) return usageError("--precision needs fp32, fp32-packed or int8");
      const std::string value = arg == "--precision" ? argv[++i] : arg.substr(12);
      try {
        precision = nao::parseWeightPrecision(value);
      } catch (const std::invalid_argument& e) {
        return usageError(e.what());
      }
    } else if (arg.size() > 1 && arg[0] == '-') {
      return usageError("unknown option " + arg);
    } else if (model_path.empty()) {
      model_path = arg;
    } else {
      return usageError("one model file expected, got " + model_path + " and " + arg);
    }
  }
  if (model_path.empty()) return usageError("no model file given");
  if (out_dir.empty()) return usageError("--out DIR is required");

  try {
    const nao::codegen::Result r = nao::codegen::generate(model_path, out_dir, precision);
    if (!quiet)
      std::printf("nao_codegen: %s (%zu parameters, checksum 0x%016llx, %s) -> %s: %zu written, %zu unchanged\n",
                  model_path.c_str(), nao::parameterCount(r.model.header.arch),
                  static_cast<unsigned long long>(r.model.checksum), nao::weightPrecisionName(precision), out_dir.c_str(), r.written.size(),
                  r.unchanged.size());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "nao_codegen: %s\n", e.what());
    return 1;
  }
  return 0;
}
