// The toolchain's CSV files: what is written reads back, and a broken file names its problem.
#include "nao/tools/command.hpp"
#include "nao/tools/skeleton_csv.hpp"
#include "support/test_util.hpp"

#include <doctest/doctest.h>

#include <sstream>

using namespace nao;
using namespace nao::tools;

namespace {

Skeleton twoFrames() {
  Skeleton s(2);
  for (int f = 0; f < 2; ++f) {
    s[f].t_s = 0.1 * f;
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      s[f].p_W[i] = Eigen::Vector3d(0.01 * i, -0.02 * i + f, 1.0 + 0.001 * i);
      s[f].ok[i] = (i + f) % 5 != 0;  // some points missing
    }
  }
  return s;
}

std::string readError(const std::string& name, const std::string& text) {
  const std::string path = nao::test::writeTempFile(name, text);
  try {
    readSkeletonCsv(path);
  } catch (const UserError& e) {
    return e.what();
  }
  FAIL("reading " << name << " should have thrown UserError");
  return {};
}

// A valid one-frame file whose first data value is replaced by `t_value`, and `tail` appended.
std::string oneFrame(const std::string& t_value, const std::string& tail = "") {
  std::ostringstream row;
  row.precision(10);
  writeSkeletonColumns(row, twoFrames()[0]);
  std::string r = row.str();
  r = t_value + r.substr(r.find(','));
  return skeletonCsvHeader() + "\n" + r + "\n" + tail;
}

}  // namespace

TEST_CASE("a skeleton CSV reads back what was written, missing points stay missing") {
  const Skeleton s = twoFrames();
  const std::string path = nao::test::writeTempFile("roundtrip_skeleton.csv", "");
  writeSkeletonCsv(path, s);
  const Skeleton back = readSkeletonCsv(path);
  REQUIRE(back.size() == s.size());
  for (std::size_t f = 0; f < s.size(); ++f) {
    CHECK(back[f].t_s == doctest::Approx(s[f].t_s));
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      CHECK(back[f].ok[i] == s[f].ok[i]);
      if (s[f].ok[i]) CHECK((back[f].p_W[i] - s[f].p_W[i]).norm() < 1e-9);
    }
  }
}

TEST_CASE("a broken skeleton CSV is refused with the file, line and column") {
  const std::string header = skeletonCsvHeader();
  CHECK_THROWS_WITH_AS(readSkeletonCsv("/nonexistent/skeleton.csv"), doctest::Contains("cannot open skeleton CSV"),
                       UserError);
  CHECK(readError("empty.csv", "").find("empty file") != std::string::npos);
  const std::string no_column = header.substr(0, header.rfind(','));  // drops RHand17_ok
  CHECK(readError("no_column.csv", no_column + "\n").find("missing column 'RHand17_ok'") != std::string::npos);
  const std::string nan = readError("nan.csv", oneFrame("nan"));
  CHECK_MESSAGE(nan.find("nan.csv:2: column 't_s' holds 'nan'") != std::string::npos, nan);
  const std::string text = readError("text.csv", oneFrame("zero"));
  CHECK_MESSAGE(text.find("expected a finite number") != std::string::npos, text);
  const std::string short_row = readError("short.csv", header + "\n0.0,1,2\n");
  CHECK_MESSAGE(short_row.find("short.csv:2: 3 values") != std::string::npos, short_row);
  const std::string back_in_time = readError("time.csv", oneFrame("0.5") + oneFrame("0.2").substr(header.size() + 1));
  CHECK_MESSAGE(back_in_time.find("does not increase") != std::string::npos, back_in_time);
}
