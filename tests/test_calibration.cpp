// Calibration files: our JSON and the OpenCV/Anipose TOML give the same cameras; Rodrigues
// vectors become R_CW; every malformed case gives one line naming the camera and field.
#include "nao/tools/calibration.hpp"
#include "nao/tools/command.hpp"

#include <doctest/doctest.h>

#include <Eigen/Geometry>

#include <filesystem>
#include <fstream>
#include <string>

namespace {

using namespace nao::tools;
namespace fs = std::filesystem;

const std::string kDataDir = std::string(NAO_TEST_DATA_DIR) + "/triangulate";

const std::string kGoodCamera = R"({"name": "c", "size": [640, 480],
  "matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]], "distortions": [0, 0, 0, 0, 0],
  "rotation": [0, 0, 0], "translation": [0, 0, 2]})";

std::string withCamera(const std::string& camera) { return "{\"cameras\": [" + camera + "]}"; }

// kGoodCamera with one field's value replaced (or the field removed when value is empty).
std::string replaceField(const std::string& field, const std::string& value) {
  std::string cam = kGoodCamera;
  const auto key = cam.find("\"" + field + "\"");
  REQUIRE(key != std::string::npos);
  auto end = cam.find(field == "matrix" ? "]]" : "]", key);
  end += field == "matrix" ? 2 : 1;
  if (value.empty()) {
    const auto comma = cam.find(',', end);
    cam.erase(key, comma + 1 - key);
  } else {
    cam.replace(key, end - key, "\"" + field + "\": " + value);
  }
  return withCamera(cam);
}

void expectJsonError(const std::string& text, const std::string& expected) {
  try {
    parseCalibrationJson(text, "calib.json");
    FAIL("expected an error containing \"" << expected << "\", the calibration was accepted");
  } catch (const UserError& e) {
    const std::string message = e.what();
    CHECK_MESSAGE(message.find(expected) != std::string::npos, "message \"" << message << "\" lacks \"" << expected << "\"");
    CHECK_MESSAGE(message.find("calib.json") != std::string::npos, "message \"" << message << "\" does not name the file");
  }
}

}  // namespace

TEST_CASE("Rodrigues vectors give the rotation about their axis by their norm, and back") {
  const Eigen::Vector3d r(0.3, -0.8, 0.5);
  const Eigen::Matrix3d expected = Eigen::AngleAxisd(r.norm(), r.normalized()).toRotationMatrix();
  CHECK((rotationFromRodrigues(r) - expected).norm() < 1e-14);
  CHECK((rodriguesFromRotation(expected) - r).norm() < 1e-12);
  CHECK((rotationFromRodrigues(Eigen::Vector3d::Zero()) - Eigen::Matrix3d::Identity()).norm() == 0.0);
  // Rodrigues' formula written out, as an independent check: R = I + sin t K + (1 - cos t) K^2.
  const double t = r.norm();
  const Eigen::Vector3d k = r / t;
  Eigen::Matrix3d K;
  K << 0, -k.z(), k.y(), k.z(), 0, -k.x(), -k.y(), k.x(), 0;
  const Eigen::Matrix3d formula = Eigen::Matrix3d::Identity() + std::sin(t) * K + (1 - std::cos(t)) * K * K;
  CHECK((rotationFromRodrigues(r) - formula).norm() < 1e-14);
}

TEST_CASE("our calibration JSON is read field by field") {
  const CameraSet cams = readCalibration(kDataDir + "/calibration.json");
  REQUIRE(cams.size() == 2);
  CHECK(cams[0].name == "left");
  CHECK(cams[0].width == 1920);
  CHECK(cams[0].height == 1080);
  CHECK(cams[0].K(0, 0) == 1000.0);
  CHECK(cams[0].K(1, 1) == 1002.0);
  CHECK(cams[0].K(0, 2) == 955.5);
  CHECK(cams[0].K(1, 2) == 538.25);
  CHECK(cams[0].dist[4] == 0.001);
  CHECK(cams[1].K(0, 1) == 0.5);
  CHECK((cams[0].R_CW - rotationFromRodrigues(Eigen::Vector3d(1.2, -1.1, 1.3))).norm() == 0.0);
  CHECK(cams[0].p_CW == Eigen::Vector3d(0.1, 1.2, 3.1));
  // World -> camera: the camera centre C satisfies R C + t = 0, so it projects nowhere, while
  // a point in front of the camera lands where K puts it.
  const Eigen::Vector3d C_W = -cams[0].R_CW.transpose() * cams[0].p_CW;
  CHECK(toCamera(cams[0], C_W).norm() < 1e-12);
  const Eigen::Vector3d on_axis_W = cams[0].R_CW.transpose() * (Eigen::Vector3d(0, 0, 3) - cams[0].p_CW);
  CHECK((project(cams[0], on_axis_W) - Eigen::Vector2d(955.5, 538.25)).norm() < 1e-9);
}

TEST_CASE("the Anipose TOML gives exactly the cameras of the equivalent JSON, metadata skipped") {
  const CameraSet json = readCalibration(kDataDir + "/calibration.json");
  const CameraSet toml = readCalibration(kDataDir + "/calibration.toml");
  REQUIRE(toml.size() == json.size());
  for (std::size_t c = 0; c < json.size(); ++c) {
    CAPTURE(c);
    CHECK(toml[c].name == json[c].name);
    CHECK(toml[c].width == json[c].width);
    CHECK(toml[c].height == json[c].height);
    CHECK(toml[c].K == json[c].K);
    CHECK(toml[c].dist == json[c].dist);  // 4 TOML coefficients: k3 = 0
    CHECK(toml[c].R_CW == json[c].R_CW);
    CHECK(toml[c].p_CW == json[c].p_CW);
  }
}

TEST_CASE("TOML cameras keep file order, not key order, and accept a rotation matrix") {
  const std::string text = R"(
[cam_10]
size = [640, 480]
matrix = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
rotation = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
translation = [0.0, 0.0, 2.0]
[metadata]
note = "skipped"
[cam_2]
size = [320, 240]
matrix = [[250, 0, 160], [0, 250, 120], [0, 0, 1]]
distortions = [0.0, 0.0, 0.0, 0.0]
rotation = [0.0, 0.0, 0.0]
translation = [0.0, 0.0, 1.0]
)";
  const CameraSet cams = parseCalibrationToml(text, "order.toml");
  REQUIRE(cams.size() == 2);
  CHECK(cams[0].name == "cam_10");
  CHECK(cams[1].name == "cam_2");
  CHECK(cams[0].R_CW(0, 1) == -1.0);
  CHECK(cams[1].K(0, 0) == 250.0);  // integers are numbers too
}

TEST_CASE("a calibration JSON written by formatCalibrationJson reads back to the same cameras") {
  const CameraSet cams = readCalibration(kDataDir + "/calibration.json");
  const CameraSet back = parseCalibrationJson(formatCalibrationJson(cams), "written.json");
  REQUIRE(back.size() == cams.size());
  for (std::size_t c = 0; c < cams.size(); ++c) {
    CHECK(back[c].K == cams[c].K);
    CHECK(back[c].dist == cams[c].dist);
    CHECK((back[c].R_CW - cams[c].R_CW).norm() < 1e-14);
    CHECK(back[c].p_CW == cams[c].p_CW);
  }
}

TEST_CASE("malformed calibrations give one clear line each") {
  CHECK_NOTHROW(parseCalibrationJson(withCamera(kGoodCamera), "calib.json"));
  SUBCASE("JSON that does not parse") { expectJsonError("{\"cameras\": [", "calibration JSON does not parse"); }
  SUBCASE("no cameras array") { expectJsonError("{\"camera\": []}", "no 'cameras' array"); }
  SUBCASE("empty cameras array") { expectJsonError("{\"cameras\": []}", "'cameras' is empty"); }
  SUBCASE("missing field") { expectJsonError(replaceField("rotation", ""), "missing field 'rotation'"); }
  SUBCASE("matrix of the wrong shape") {
    expectJsonError(replaceField("matrix", "[[500, 0, 320], [0, 500, 240]]"), "field 'matrix' is an array of 2");
  }
  SUBCASE("non-positive focal length") {
    expectJsonError(replaceField("matrix", "[[0, 0, 320], [0, 500, 240], [0, 0, 1]]"), "focal lengths must be positive");
  }
  SUBCASE("K without 0 0 1 last row") {
    expectJsonError(replaceField("matrix", "[[500, 0, 320], [0, 500, 240], [0, 0, 2]]"), "must have the form");
  }
  SUBCASE("distortion of unsupported length") {
    expectJsonError(replaceField("distortions", "[0.1, 0.2, 0.3]"), "field 'distortions' is an array of 3");
  }
  SUBCASE("rotation that is not a rotation") {
    expectJsonError(replaceField("rotation", "[[1, 0, 0], [0, 2, 0], [0, 0, 1]]"), "'rotation' matrix is not a rotation");
  }
  SUBCASE("reflection is not a rotation") {
    expectJsonError(replaceField("rotation", "[[-1, 0, 0], [0, 1, 0], [0, 0, 1]]"), "det = -1");
  }
  SUBCASE("non-number value") { expectJsonError(replaceField("translation", "[0, \"x\", 2]"), "not all numbers"); }
  SUBCASE("bad image size") { expectJsonError(replaceField("size", "[640.5, 480]"), "'size' must be two positive integers"); }
  SUBCASE("TOML that does not parse") {
    CHECK_THROWS_WITH_AS(parseCalibrationToml("[cam_0\nsize = [1, 2]", "calib.toml"),
                         doctest::Contains("calib.toml:1:"), UserError);
    CHECK_THROWS_WITH_AS(parseCalibrationToml("[cam_0\nsize = [1, 2]", "calib.toml"),
                         doctest::Contains("calibration TOML does not parse"), UserError);
  }
  SUBCASE("TOML with a non-finite value") {
    const std::string text = "[cam_0]\nsize = [640, 480]\nmatrix = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]\n"
                             "distortions = [0.0, 0.0, 0.0, 0.0]\nrotation = [0.0, nan, 0.0]\ntranslation = [0.0, 0.0, 1.0]\n";
    CHECK_THROWS_WITH_AS(parseCalibrationToml(text, "calib.toml"),
                         doctest::Contains("camera [cam_0]: field 'rotation' holds a non-finite value"), UserError);
  }
  SUBCASE("TOML without camera sections") {
    CHECK_THROWS_WITH_AS(parseCalibrationToml("[metadata]\nerror = 1.0\n", "calib.toml"),
                         doctest::Contains("no camera sections"), UserError);
  }
  SUBCASE("unknown extension and missing file") {
    CHECK_THROWS_WITH_AS(readCalibration("cameras.yaml"), doctest::Contains("expected a .json or .toml file"), UserError);
    CHECK_THROWS_WITH_AS(readCalibration(kDataDir + "/absent.json"), doctest::Contains("cannot open calibration file"),
                         UserError);
  }
}

TEST_CASE("calibrations that parse but mean nothing are refused, naming the file") {
  SUBCASE("a number that overflows a double (json out_of_range, not parse_error)") {
    expectJsonError(replaceField("translation", "[1e400, 0, 2]"), "calibration JSON does not parse");
  }
  SUBCASE("JSON nested deeper than any calibration") {
    expectJsonError("{\"cameras\": " + std::string(100000, '[') + std::string(100000, ']') + "}", "nests deeper than");
  }
  SUBCASE("a Rodrigues vector whose norm overflows") {
    expectJsonError(replaceField("rotation", "[1e200, 0, 0]"), "'rotation' [1e+200, 0, 0] is not a rotation");
  }
  SUBCASE("focal lengths of 1e-300 px") {
    expectJsonError(replaceField("matrix", "[[1e-300, 0, 320], [0, 1e-300, 240], [0, 0, 1]]"),
                    "focal lengths fx=1e-300, fy=1e-300 px are not plausible");
  }
  SUBCASE("a camera kilometres away") {
    expectJsonError(replaceField("translation", "[0, 0, 2e3]"), "more than 1000 m away");
  }
  SUBCASE("two identical cameras") {
    std::string second = kGoodCamera;
    second.replace(second.find("\"c\""), 3, "\"d\"");
    expectJsonError("{\"cameras\": [" + kGoodCamera + ", " + second + "]}", "cameras 'c' and 'd' sit at the same place");
  }
  SUBCASE("two identical cameras in TOML") {
    const std::string cam = "size = [640, 480]\nmatrix = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]\n"
                            "distortions = [0.0, 0.0, 0.0, 0.0]\nrotation = [0.0, 0.0, 0.0]\ntranslation = [0.0, 0.0, 1.0]\n";
    CHECK_THROWS_WITH_AS(parseCalibrationToml("[cam_0]\n" + cam + "[cam_1]\n" + cam, "calib.toml"),
                         doctest::Contains("calib.toml: cameras 'cam_0' and 'cam_1' sit at the same place"), UserError);
  }
  SUBCASE("the project's own calibrations pass every check") {
    CHECK(readCalibration(kDataDir + "/calibration.json").size() == 2);
    CHECK(readCalibration(kDataDir + "/calibration.toml").size() == 2);
  }
}
