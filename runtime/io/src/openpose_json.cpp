#include "nao/openpose_json.hpp"

#include "nao/input_error.hpp"
#include "nao/text_guard.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>

namespace nao {
namespace {

using nlohmann::json;

constexpr int kNumHandPoints = 21;

std::string personLabel(const std::string& source, std::size_t person) {
  return source + ": people[" + std::to_string(person) + "]";
}

// What a JSON value is, for messages: never its text, which may be huge (or, dumped, recurse
// as deep as it nests).
std::string kindOf(const json& v) {
  if (v.is_array()) return "an array";
  if (v.is_object()) return "an object";
  if (v.is_string()) return "a string";
  if (v.is_boolean()) return v.get<bool>() ? "true" : "false";
  return "not a number";
}

// Reads `count` x, y, c triples from `array` (already checked to have 3*count entries).
// Each triple either is a detection or counts as not detected (confidence 0, or pixel 0,0).
// A finite confidence above 1 is clamped to 1; a negative or non-finite one is an error.
void readTriples(const json& array, int count, const std::string& where, std::vector<std::array<double, 3>>& out) {
  out.assign(static_cast<std::size_t>(count), {0.0, 0.0, 0.0});
  for (int k = 0; k < count; ++k) {
    std::array<double, 3> v{};
    for (int c = 0; c < 3; ++c) {
      const json& e = array[static_cast<std::size_t>(3 * k + c)];
      if (!e.is_number())
        throw InputError(where + " value " + std::to_string(3 * k + c) + " (point " + std::to_string(k) + ") is " +
                         (e.is_null() ? std::string("null (a NaN written by some JSON writers)") : kindOf(e)) +
                         ", expected a number");
      v[static_cast<std::size_t>(c)] = e.get<double>();
      if (!std::isfinite(v[static_cast<std::size_t>(c)]))
        throw InputError(where + " point " + std::to_string(k) + " holds a non-finite value");
    }
    if (v[2] < 0.0)
      throw InputError(where + " point " + std::to_string(k) + " has confidence " + json(v[2]).dump() +
                       ", expected a value in [0, 1]");
    // Real OpenPose output holds confidences slightly above 1 (the heatmap peak is not
    // normalised; e.g. 1.40701 in OpenPose's issue tracker): a full-confidence detection.
    v[2] = std::min(v[2], 1.0);
    const bool not_detected = v[2] == 0.0 || (v[0] == 0.0 && v[1] == 0.0);
    out[static_cast<std::size_t>(k)] = not_detected ? std::array<double, 3>{0.0, 0.0, 0.0} : v;
  }
}

void setPoint(Person2d& person, int skeleton_index, const std::array<double, 3>& v) {
  person.px[skeleton_index] = Eigen::Vector2d(v[0], v[1]);
  person.confidence[skeleton_index] = v[2];
}

int personId(const json& person) {
  const auto it = person.find("person_id");
  if (it == person.end()) return -1;
  const json& id = (it->is_array() && !it->empty()) ? (*it)[0] : *it;
  return id.is_number_integer() ? id.get<int>() : -1;
}

bool isDigit(char c) { return c >= '0' && c <= '9'; }

bool endsWith(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// Value of a run of at most 18 decimal digits (fits a long long).
long long digitsValue(std::string_view digits) {
  long long v = 0;
  for (char c : digits) v = 10 * v + (c - '0');
  return v;
}

}  // namespace

std::optional<PoseFormat> poseFormatFromName(std::string_view name) {
  if (name == "body25") return PoseFormat::kBody25;
  if (name == "body25b") return PoseFormat::kBody25B;
  return std::nullopt;
}

const char* poseFormatName(PoseFormat format) { return format == PoseFormat::kBody25 ? "body25" : "body25b"; }

// The namings, as the regular expressions ^(.*_)?([0-9]{12})_keypoints\.json$ and
// ^.*\.([0-9]+)\.json$ (whose '.' matches no line break) read them; by hand, because the reader
// thread checks every file name a folder event carries. OpenPose names a frame of a video
// <video>_<frame>_keypoints.json and one of a camera <frame>_keypoints.json.
std::optional<long long> openPoseFrameIndex(std::string_view name) {
  if (name.find_first_of("\n\r") != std::string_view::npos) return std::nullopt;
  constexpr std::string_view kOpenPoseSuffix = "_keypoints.json";
  if (endsWith(name, kOpenPoseSuffix) && name.size() >= kOpenPoseSuffix.size() + 12) {
    const std::size_t first = name.size() - kOpenPoseSuffix.size() - 12;
    const std::string_view digits = name.substr(first, 12);
    if (std::all_of(digits.begin(), digits.end(), isDigit) && (first == 0 || name[first - 1] == '_'))
      return digitsValue(digits);
  }
  constexpr std::string_view kDottedSuffix = ".json";
  if (!endsWith(name, kDottedSuffix)) return std::nullopt;
  const std::string_view stem = name.substr(0, name.size() - kDottedSuffix.size());
  std::size_t first = stem.size();
  while (first > 0 && isDigit(stem[first - 1])) --first;
  // The longest digit run before ".json" must follow a '.': a shorter one follows a digit.
  if (first == stem.size() || first == 0 || stem[first - 1] != '.') return std::nullopt;
  const std::string_view digits = stem.substr(first);
  if (digits.size() > 18) return std::nullopt;  // would overflow; not a frame counter
  return digitsValue(digits);
}

std::vector<Person2d> parseOpenPoseFrame(const std::string& text, PoseFormat format, const std::string& source) {
  // nlohmann parses iteratively but copies, compares and dumps recursively: bound the nesting
  // (an OpenPose frame nests 3 deep) and the size before it builds anything.
  if (const std::string problem = jsonShapeProblem(text); !problem.empty())
    throw InputError(source + ": not a usable OpenPose file: the JSON text " + problem);
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {  // parse_error, or out_of_range for a number overflowing a double
    std::string what = e.what();
    const auto bracket = what.find("] ");
    if (bracket != std::string::npos) what = what.substr(bracket + 2);
    std::string hint;
    if (text.find("NaN") != std::string::npos || text.find("Infinity") != std::string::npos)
      hint = " (NaN/Infinity are not JSON numbers; OpenPose writes 0,0,0 for an undetected point)";
    throw InputError(source + ": not valid JSON: " + what + hint);
  }
  if (!doc.is_object()) throw InputError(source + ": expected a JSON object with a 'people' array");
  const auto people_it = doc.find("people");
  if (people_it == doc.end()) throw InputError(source + ": no 'people' array (not an OpenPose keypoint file?)");
  if (!people_it->is_array()) throw InputError(source + ": 'people' is not an array");

  std::vector<Person2d> people;
  std::vector<std::array<double, 3>> triples;
  for (std::size_t p = 0; p < people_it->size(); ++p) {
    const json& person_json = (*people_it)[p];
    const std::string label = personLabel(source, p);
    if (!person_json.is_object()) throw InputError(label + " is not an object");
    const auto pose = person_json.find("pose_keypoints_2d");
    if (pose == person_json.end() || !pose->is_array())
      throw InputError(label + " has no 'pose_keypoints_2d' array");
    if (pose->size() != 3 * kNumBody25)
      throw InputError(label + ".pose_keypoints_2d has " + std::to_string(pose->size()) + " values, expected " +
                       std::to_string(3 * kNumBody25) + " (25 points x, y, confidence of " + poseFormatName(format) +
                       ")");
    readTriples(*pose, kNumBody25, label + ".pose_keypoints_2d", triples);

    Person2d person;
    person.person_id = personId(person_json);
    for (int k = 0; k < kNumBody25; ++k) {
      const int target = format == PoseFormat::kBody25 ? k : kBody25bToSkeleton[static_cast<std::size_t>(k)];
      if (target >= 0) setPoint(person, target, triples[static_cast<std::size_t>(k)]);
    }

    const auto hand = person_json.find("hand_right_keypoints_2d");
    if (hand != person_json.end() && !hand->is_null()) {
      if (!hand->is_array()) throw InputError(label + ".hand_right_keypoints_2d is not an array");
      if (!hand->empty()) {
        if (hand->size() != 3 * kNumHandPoints)
          throw InputError(label + ".hand_right_keypoints_2d has " + std::to_string(hand->size()) +
                           " values, expected 63 (21 points) or none");
        readTriples(*hand, kNumHandPoints, label + ".hand_right_keypoints_2d", triples);
        for (std::size_t h = 0; h < kHandKeypointIds.size(); ++h)
          setPoint(person, kRHand0 + static_cast<int>(h), triples[static_cast<std::size_t>(kHandKeypointIds[h])]);
      }
    }
    people.push_back(person);
  }
  return people;
}

std::string formatOpenPoseJson(const std::vector<Person2d>& people, PoseFormat format) {
  json doc;
  doc["version"] = 1.3;
  doc["people"] = json::array();
  auto triple = [](json& array, const Person2d& p, int i) {
    if (i < 0 || !p.detected(i)) {
      array.push_back(0.0), array.push_back(0.0), array.push_back(0.0);
    } else {
      array.push_back(p.px[i].x()), array.push_back(p.px[i].y()), array.push_back(p.confidence[i]);
    }
  };
  for (const Person2d& p : people) {
    json person;
    person["person_id"] = json::array({p.person_id});
    json pose = json::array();
    for (int k = 0; k < kNumBody25; ++k)
      triple(pose, p, format == PoseFormat::kBody25 ? k : kBody25bToSkeleton[static_cast<std::size_t>(k)]);
    person["pose_keypoints_2d"] = pose;
    json hand = json::array();
    bool any_hand = false;
    for (int h = 0; h < 4; ++h) any_hand = any_hand || p.detected(kRHand0 + h);
    if (any_hand) {
      for (int k = 0; k < kNumHandPoints; ++k) {
        const auto it = std::find(kHandKeypointIds.begin(), kHandKeypointIds.end(), k);
        triple(hand, p, it == kHandKeypointIds.end() ? -1 : kRHand0 + static_cast<int>(it - kHandKeypointIds.begin()));
      }
    }
    person["hand_right_keypoints_2d"] = hand;
    person["hand_left_keypoints_2d"] = json::array();
    person["face_keypoints_2d"] = json::array();
    doc["people"].push_back(person);
  }
  return doc.dump();
}

}  // namespace nao
