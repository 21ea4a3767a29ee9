// OpenPose JSON reader: file naming, layouts (BODY_25, BODY_25B), multi-person frames,
// undetected points, and malformed files with the message each one gives.
#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {

using namespace nao;
using namespace nao::tools;
namespace fs = std::filesystem;

fs::path freshDir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / "nao_rt_tests" / "openpose" / name;
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void writeText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

// 25 triples: point k at (100 + k, 200 + k) with confidence 0.5 + k / 100.
nlohmann::json poseArray(int offset = 0) {
  nlohmann::json a = nlohmann::json::array();
  for (int k = 0; k < 25; ++k) {
    a.push_back(100.0 + k + offset);
    a.push_back(200.0 + k + offset);
    a.push_back(0.5 + k / 100.0);
  }
  return a;
}

std::string documentOf(const nlohmann::json& people_array) {
  nlohmann::json doc = nlohmann::json::object();
  doc["version"] = 1.3;
  doc["people"] = people_array;
  return doc.dump();
}
nlohmann::json personWith(const std::string& key, const nlohmann::json& value) {
  nlohmann::json p = nlohmann::json::object();
  p[key] = value;
  return p;
}
std::string document(const std::vector<nlohmann::json>& people) {
  nlohmann::json array = nlohmann::json::array();
  for (const nlohmann::json& p : people) array.push_back(p);
  return documentOf(array);
}

// Expects parseOpenPoseJson to throw a UserError whose message contains `expected`.
void expectError(const std::string& text, const std::string& expected) {
  try {
    parseOpenPoseJson(text, PoseFormat::kBody25, "frame.json");
    FAIL("expected an error containing \"" << expected << "\", the file was accepted");
  } catch (const UserError& e) {
    const std::string message = e.what();
    CHECK_MESSAGE(message.find(expected) != std::string::npos, "message \"" << message << "\" lacks \"" << expected << "\"");
    CHECK_MESSAGE(message.find("frame.json") != std::string::npos, "message \"" << message << "\" does not name the file");
  }
}

}  // namespace

TEST_CASE("frame index is parsed from both OpenPose namings and nothing else") {
  CHECK(openPoseFrameIndex("video_000000000042_keypoints.json") == 42);
  CHECK(openPoseFrameIndex("cam_left_000000001234_keypoints.json") == 1234);
  CHECK(openPoseFrameIndex("000000000042_keypoints.json") == 42);  // a camera's frames have no name part
  CHECK_FALSE(openPoseFrameIndex("x000000000042_keypoints.json"));
  CHECK(openPoseFrameIndex("demo.17.json") == 17);
  CHECK(openPoseFrameIndex("a.b.0007.json") == 7);
  CHECK_FALSE(openPoseFrameIndex("video_42_keypoints.json"));  // not 12 digits
  CHECK_FALSE(openPoseFrameIndex("calibration.json"));
  CHECK_FALSE(openPoseFrameIndex("notes.txt"));
  CHECK_FALSE(openPoseFrameIndex("demo.17.json.bak"));
}

TEST_CASE("a camera folder is read in numeric frame order and other files are ignored") {
  const fs::path dir = freshDir("order");
  const nlohmann::json person = {{"person_id", {-1}}, {"pose_keypoints_2d", poseArray()}};
  for (int index : {10, 2, 1}) {
    nlohmann::json p = person;
    p["pose_keypoints_2d"][0] = 1000.0 + index;  // Nose x tells which file it came from
    writeText(dir / ("clip." + std::to_string(index) + ".json"), document({p}));
  }
  writeText(dir / "README.txt", "not a frame");
  writeText(dir / "calibration.json", "{}");
  fs::create_directories(dir / "sub.3.json");  // a folder with a frame-like name is not a frame

  const CameraKeypoints cam = readOpenPoseFolder(dir.string(), PoseFormat::kBody25);
  REQUIRE(cam.frames.size() == 3);
  CHECK(cam.frames[0].index == 1);
  CHECK(cam.frames[1].index == 2);
  CHECK(cam.frames[2].index == 10);  // numeric, not lexicographic ("10" < "2")
  CHECK(cam.frames[2].people.at(0).px[kNose].x() == 1010.0);

  const fs::path op = freshDir("openpose_naming");
  writeText(op / "run_000000000001_keypoints.json", document({person}));
  writeText(op / "run_000000000000_keypoints.json", document({}));
  const CameraKeypoints cam2 = readOpenPoseFolder(op.string(), PoseFormat::kBody25);
  REQUIRE(cam2.frames.size() == 2);
  CHECK(cam2.frames[0].people.empty());  // nobody detected is a valid frame
  CHECK(cam2.frames[1].people.size() == 1);
}

TEST_CASE("folder errors name the folder: missing, without frames, duplicate frame index") {
  const fs::path empty = freshDir("empty");
  writeText(empty / "notes.txt", "x");
  CHECK_THROWS_WITH_AS(readOpenPoseFolder(empty.string(), PoseFormat::kBody25),
                       doctest::Contains("no OpenPose frame files"), UserError);
  CHECK_THROWS_WITH_AS(readOpenPoseFolder((empty / "nope").string(), PoseFormat::kBody25),
                       doctest::Contains("does not exist"), UserError);
  const fs::path dup = freshDir("duplicate");
  writeText(dup / "a.1.json", document({}));
  writeText(dup / "b_000000000001_keypoints.json", document({}));
  CHECK_THROWS_WITH_AS(readOpenPoseFolder(dup.string(), PoseFormat::kBody25),
                       doctest::Contains("two files for frame 1"), UserError);
  // A malformed frame inside a folder names that file.
  const fs::path bad = freshDir("bad_frame");
  writeText(bad / "a.0.json", document({}));
  writeText(bad / "a.1.json", "{\"people\": [");
  CHECK_THROWS_WITH_AS(readOpenPoseFolder(bad.string(), PoseFormat::kBody25), doctest::Contains("a.1.json"), UserError);
}

TEST_CASE("several people are kept in file order with their ids, hands mapped from 0/5/9/17") {
  nlohmann::json hand = nlohmann::json::array();
  for (int k = 0; k < 21; ++k) hand.push_back(500.0 + k), hand.push_back(600.0 + k), hand.push_back(0.8);
  const nlohmann::json people = nlohmann::json::array({
      {{"person_id", {-1}}, {"pose_keypoints_2d", poseArray(0)}, {"hand_right_keypoints_2d", nlohmann::json::array()}},
      {{"person_id", 7}, {"pose_keypoints_2d", poseArray(50)}, {"hand_right_keypoints_2d", hand}},
      {{"pose_keypoints_2d", poseArray(90)}}});
  const std::vector<Person2d> p = parseOpenPoseJson(documentOf(people), PoseFormat::kBody25, "f.json");
  REQUIRE(p.size() == 3);
  CHECK(p[0].person_id == -1);
  CHECK(p[1].person_id == 7);
  CHECK(p[2].person_id == -1);
  for (int k = 0; k < kNumBody25; ++k) {
    CHECK(p[1].px[k].x() == 150.0 + k);
    CHECK(p[1].px[k].y() == 250.0 + k);
    CHECK(p[1].confidence[k] == doctest::Approx(0.5 + k / 100.0));
  }
  for (int h = 0; h < 4; ++h) {
    CHECK_FALSE(p[0].detected(kRHand0 + h));  // empty hand array: not detected
    CHECK_FALSE(p[2].detected(kRHand0 + h));  // absent hand array: not detected
    CHECK(p[1].px[kRHand0 + h].x() == 500.0 + kHandKeypointIds[static_cast<std::size_t>(h)]);
    CHECK(p[1].confidence[kRHand0 + h] == 0.8);
  }
}

TEST_CASE("0,0,0 keypoints and zero-confidence keypoints are not detected, never kept as points") {
  nlohmann::json pose = poseArray();
  pose[3 * kRElbow] = 0.0, pose[3 * kRElbow + 1] = 0.0, pose[3 * kRElbow + 2] = 0.0;
  pose[3 * kLWrist + 2] = 0.0;                               // a position but no confidence
  pose[3 * kNeck] = 0.0, pose[3 * kNeck + 1] = 0.0;          // pixel 0,0 with a confidence
  const std::vector<Person2d> p =
      parseOpenPoseJson(document({personWith("pose_keypoints_2d", pose)}), PoseFormat::kBody25, "f.json");
  REQUIRE(p.size() == 1);
  CHECK_FALSE(p[0].detected(kRElbow));
  CHECK_FALSE(p[0].detected(kLWrist));
  CHECK_FALSE(p[0].detected(kNeck));
  CHECK(p[0].detected(kRWrist));
  CHECK(p[0].px[kLWrist] == Eigen::Vector2d::Zero());
}

TEST_CASE("a confidence above 1 (real OpenPose output, e.g. 1.40701) is read as 1, the point kept") {
  nlohmann::json pose = poseArray();
  pose[3 * kRWrist + 2] = 1.40701;
  pose[3 * kLElbow + 2] = 1.0000001;
  nlohmann::json hand = nlohmann::json::array();
  for (int k = 0; k < 21; ++k) hand.push_back(500.0 + k), hand.push_back(600.0 + k), hand.push_back(k == 9 ? 1.2 : 0.8);
  nlohmann::json person = personWith("pose_keypoints_2d", pose);
  person["hand_right_keypoints_2d"] = hand;
  const std::vector<Person2d> p = parseOpenPoseJson(document({person}), PoseFormat::kBody25, "f.json");
  REQUIRE(p.size() == 1);
  CHECK(p[0].confidence[kRWrist] == 1.0);
  CHECK(p[0].confidence[kLElbow] == 1.0);
  CHECK(p[0].confidence[kRHand9] == 1.0);  // hand point 9 (middle-finger knuckle)
  CHECK(p[0].px[kRWrist] == Eigen::Vector2d(104.0, 204.0));  // position untouched
  CHECK(p[0].confidence[kRElbow] == doctest::Approx(0.53));  // others unchanged
}

TEST_CASE("BODY_25B is mapped onto BODY_25 names: COCO order, UpperNeck -> Neck, no MidHip, HeadTop dropped") {
  // Written from OpenPose's BODY_25B part list, independently of the reader's table.
  const std::vector<std::pair<std::string, int>> b25b = {
      {"Nose", kNose},         {"LEye", kLEye},         {"REye", kREye},         {"LEar", kLEar},
      {"REar", kREar},         {"LShoulder", kLShoulder}, {"RShoulder", kRShoulder}, {"LElbow", kLElbow},
      {"RElbow", kRElbow},     {"LWrist", kLWrist},     {"RWrist", kRWrist},     {"LHip", kLHip},
      {"RHip", kRHip},         {"LKnee", kLKnee},       {"RKnee", kRKnee},       {"LAnkle", kLAnkle},
      {"RAnkle", kRAnkle},     {"UpperNeck", kNeck},    {"HeadTop", -1},         {"LBigToe", kLBigToe},
      {"LSmallToe", kLSmallToe}, {"LHeel", kLHeel},     {"RBigToe", kRBigToe},   {"RSmallToe", kRSmallToe},
      {"RHeel", kRHeel}};
  REQUIRE(b25b.size() == 25);
  // Point k of the file sits at x = 300 + k.
  const std::vector<Person2d> p =
      parseOpenPoseJson(document({personWith("pose_keypoints_2d", poseArray(200))}), PoseFormat::kBody25B, "b.json");
  REQUIRE(p.size() == 1);
  std::array<bool, kNumSkeletonPoints> mapped{};
  for (int k = 0; k < 25; ++k) {
    const int target = b25b[static_cast<std::size_t>(k)].second;
    if (target < 0) continue;
    mapped[static_cast<std::size_t>(target)] = true;
    CHECK_MESSAGE(p[0].px[target].x() == 300.0 + k, b25b[static_cast<std::size_t>(k)].first << " misplaced");
  }
  CHECK_FALSE(p[0].detected(kMidHip));  // triangulation derives it from the 3D hips
  for (int i = 0; i < kNumBody25; ++i)
    if (!mapped[static_cast<std::size_t>(i)]) CHECK_FALSE(p[0].detected(i));
  // The writer is the reader's inverse: a BODY_25B round trip keeps every mapped point.
  const std::vector<Person2d> back = parseOpenPoseJson(formatOpenPoseJson(p, PoseFormat::kBody25B),
                                                       PoseFormat::kBody25B, "roundtrip.json");
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    CHECK(back[0].px[i] == p[0].px[i]);
    CHECK(back[0].confidence[i] == p[0].confidence[i]);
  }
}

TEST_CASE("format names parse and unknown ones are rejected") {
  CHECK(parsePoseFormat("body25") == PoseFormat::kBody25);
  CHECK(parsePoseFormat("body25b") == PoseFormat::kBody25B);
  CHECK_THROWS_WITH_AS(parsePoseFormat("coco"), doctest::Contains("expected body25 or body25b"), UserError);
}

TEST_CASE("malformed OpenPose files give one clear line each") {
  const nlohmann::json good_person = personWith("pose_keypoints_2d", poseArray());
  SUBCASE("truncated JSON") { expectError("{\"version\": 1.3, \"people\": [{\"pose_keypoints_2d\": [1, 2", "not valid JSON"); }
  SUBCASE("NaN written by a non-JSON writer") {
    std::string text = document({good_person});
    text.replace(text.find("100.0"), 5, "NaN");
    expectError(text, "NaN/Infinity are not JSON numbers");
  }
  SUBCASE("no people array") { expectError("{\"version\": 1.3}", "no 'people' array"); }
  SUBCASE("people is not an array") { expectError("{\"people\": {}}", "'people' is not an array"); }
  SUBCASE("person without pose keypoints") {
    expectError(document({personWith("face_keypoints_2d", nlohmann::json::array())}), "people[0] has no 'pose_keypoints_2d'");
  }
  SUBCASE("keypoint array of the wrong length") {
    nlohmann::json pose = poseArray();
    pose.erase(pose.end() - 3, pose.end());
    expectError(document({good_person, personWith("pose_keypoints_2d", pose)}), "people[1].pose_keypoints_2d has 72 values, expected 75");
  }
  SUBCASE("null (NaN) value") {
    nlohmann::json pose = poseArray();
    pose[3 * kRWrist + 1] = nullptr;
    expectError(document({personWith("pose_keypoints_2d", pose)}), "(point 4) is null");
  }
  SUBCASE("string value") {
    nlohmann::json pose = poseArray();
    pose[0] = "12";
    expectError(document({personWith("pose_keypoints_2d", pose)}), "expected a number");
  }
  SUBCASE("a value nested a million deep: refused before the parser, and never dumped") {
    const std::string deep = std::string(1000000, '[') + std::string(1000000, ']');
    expectError("{\"people\": [{\"pose_keypoints_2d\": " + deep + "}]}", "the JSON text nests deeper than 64 levels");
  }
  SUBCASE("an array where a number belongs is named by its kind, not its text") {
    nlohmann::json pose = poseArray();
    pose[0] = nlohmann::json::array({1, 2, 3});
    expectError(document({personWith("pose_keypoints_2d", pose)}), "value 0 (point 0) is an array, expected a number");
  }
  SUBCASE("negative confidence") {
    nlohmann::json pose = poseArray();
    pose[3 * kRElbow + 2] = -0.2;
    expectError(document({personWith("pose_keypoints_2d", pose)}), "point 3 has confidence -0.2, expected a value in [0, 1]");
  }
  SUBCASE("confidence too large for a double (no finite value): an error, not clamped") {
    std::string text = document({personWith("pose_keypoints_2d", poseArray())});
    const std::string first_confidence = "0.5,";  // point 0's confidence
    text.replace(text.find(first_confidence), first_confidence.size() - 1, "1e999");
    expectError(text, "not valid JSON: number overflow parsing '1e999'");
  }
  SUBCASE("hand array of the wrong length") {
    nlohmann::json person = good_person;
    person["hand_right_keypoints_2d"] = nlohmann::json::array({1.0, 2.0, 0.5});
    expectError(document({person}), "hand_right_keypoints_2d has 3 values, expected 63");
  }
  SUBCASE("not an object") { expectError("[1, 2, 3]", "expected a JSON object"); }
}
