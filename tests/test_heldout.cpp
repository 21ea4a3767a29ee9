// The held-out demonstrations an evaluation regenerates (nao/tools/heldout.hpp): the model's
// split.val of one movement, or a test set of synthesiser seeds training never used.
#include "nao/tools/heldout.hpp"
#include "nao/tools/reference_source.hpp"

#include <doctest/doctest.h>

#include <stdexcept>
#include <string>
#include <vector>

using namespace nao::tools;

TEST_CASE("validationDemos keeps the movement's split.val entries in order, with the synthesiser seed the metadata gives or 1") {
  const std::string meta = R"({"split":{"train":["elbow_000"],"val":["elbow_003","whole_arm_001","elbow_010","wrist_003","elbow_x"]}})";
  const ValidationSet v = validationDemos(meta, "elbow", "m.bin");
  CHECK(v.names == std::vector<std::string>{"elbow_003", "elbow_010"});
  CHECK(v.indices == std::vector<int>{3, 10});
  CHECK(v.seed == 1);
  CHECK(v.seed_assumed);
  const ValidationSet w = validationDemos(R"({"split":{"val":["whole_arm_007"]},"data":{"synth_seed":42}})", "whole_arm",
                                          "m.bin");
  CHECK(w.names == std::vector<std::string>{"whole_arm_007"});
  CHECK(w.seed == 42);
  CHECK_FALSE(w.seed_assumed);
  CHECK_THROWS_WITH_AS(validationDemos("{}", "elbow", "m.bin"), doctest::Contains("m.bin: the model's metadata names no validation demonstrations (split.val)"),
                       std::runtime_error);
  CHECK_THROWS_WITH_AS(validationDemos(meta, "wave", "m.bin"), doctest::Contains("movement 'wave'"), std::runtime_error);
}

TEST_CASE("testDemos names demonstrations 0..N-1 of run seed 1000000 + S, never a training seed") {
  const ValidationSet t = testDemos("wrist", 7, 3);
  CHECK(t.seed == kReferenceSeedBase + 7);
  CHECK_FALSE(t.seed_assumed);
  CHECK(t.names == std::vector<std::string>{"wrist_test7_000", "wrist_test7_001", "wrist_test7_002"});
  CHECK(t.indices == std::vector<int>{0, 1, 2});
  CHECK_THROWS_AS(testDemos("wrist", 7, 0), std::invalid_argument);
}
