#include "nao/tools/evaluate.hpp"

#include "nao/kinematics.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/kmeans.hpp"
#include "nao/tools/linear_ar.hpp"
#include "nao/tools/retarget_pipeline.hpp"
#include "nao/tools/triangulate.hpp"
#include "nao/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>

namespace nao::tools {

namespace fs = std::filesystem;

HandPath handPath(const ArmModel& arm, const std::vector<JointVector>& q) {
  ArmData kin;
  HandPath path;
  path.reserve(q.size());
  for (const JointVector& v : q) path.push_back(forwardKinematics(arm, kin, v));
  return path;
}

double median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

NearestDemo nearestDemo(const HandPath& path, const std::vector<HandPath>& demos, int exclude) {
  NearestDemo best;
  best.dtw_m = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < demos.size(); ++i) {
    if (static_cast<int>(i) == exclude) continue;
    const double d = rt::dtwMeanDistance(path, demos[i]);
    if (best.index < 0 || d < best.dtw_m) {
      best.dtw_m = d;
      best.index = static_cast<int>(i);
    }
  }
  return best;
}

DemoSet demoSetFrom(const ArmModel& arm, const PolicyData& data, const std::string& movement,
                    const std::vector<std::string>& names) {
  DemoSet set;
  for (const std::string& name : names) {
    const auto it = std::find_if(data.demos.begin(), data.demos.end(), [&](const PolicyDemo& d) { return d.name == name; });
    if (it == data.demos.end() || data.movement_names[static_cast<std::size_t>(it->movement)] != movement)
      throw UserError("the data set holds no demonstration '" + name + "' of " + movement);
    set.names.push_back(name);
    set.f.push_back(it->f);
    set.start.push_back(it->start);
    set.hand.push_back(handPath(arm, it->f));
  }
  return set;
}

std::vector<std::string> recordingNames(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) throw UserError(dir + ": not a directory of recordings");
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (!entry.is_directory()) continue;
    const std::string name = entry.path().filename().string();
    const auto cut = name.rfind('_');
    if (cut == std::string::npos || cut == 0 || cut + 1 == name.size() ||
        name.find_first_not_of("0123456789", cut + 1) != std::string::npos)
      continue;
    bool cameras = false;
    for (const auto& sub : fs::directory_iterator(entry.path()))
      cameras = cameras || (sub.is_directory() && sub.path().filename().string().rfind("cam", 0) == 0);
    if (cameras) names.push_back(name);
  }
  std::sort(names.begin(), names.end());
  if (names.empty())
    throw UserError(dir + ": no recording (<movement>_<index>/cam<k>/ folders of OpenPose JSON, docs/formats.md)");
  return names;
}

PolicyDemo processRecording(const ArmModel& arm, const std::string& dir, const std::string& name,
                            const RecordingInput& input, const RetargetParams& retarget,
                            const std::vector<JointVector>& key_poses) {
  const std::string where = (fs::path(dir) / name).string();
  try {
    TriangulateOptions topt = recordingOptions();
    topt.fps = input.fps;
    topt.format = parsePoseFormat(input.format);
    const Skeleton skeleton = triangulateDemo(where, topt);
    RetargetOptions ropt;
    ropt.params = retarget;
    const std::vector<RetargetRow> rows = retargetSkeleton(arm, skeleton, ropt);
    std::vector<double> t_meas, t_grid;
    std::vector<JointVector> q_meas;
    PolicyDemo demo;
    demo.name = name;
    for (const RetargetRow& r : rows) {
      const bool measured = (r.flags & kRowHumanMissing) == 0;
      t_grid.push_back(r.t_s);
      demo.measured.push_back(measured ? 1 : 0);
      if (!measured) continue;
      if (t_meas.empty()) demo.start = r.result.q_r;
      t_meas.push_back(r.t_s);
      q_meas.push_back(r.result.q_r);
    }
    if (q_meas.empty()) throw UserError("no sample with a measured human arm");
    demo.t_s = t_grid;
    demo.f = featureTrajectory(key_poses, t_meas, q_meas, t_grid);
    demo.label = keyPoseLabels(key_poses, t_meas, q_meas, t_grid);
    return demo;
  } catch (const UserError& e) {
    throw UserError(where + ": " + e.what());
  }
}

DemoSet demoSetFromRecordings(const ArmModel& arm, const std::string& dir, const std::vector<std::string>& names,
                              const RecordingInput& input, const RetargetParams& retarget,
                              const std::vector<JointVector>& key_poses, const std::string& what) {
  DemoSet set;
  for (std::size_t i = 0; i < names.size(); ++i) {
    std::fprintf(stderr, "evaluate: %s: triangulating and retargeting %s (%zu/%zu)\n", what.c_str(), names[i].c_str(),
                 i + 1, names.size());
    const PolicyDemo d = processRecording(arm, dir, names[i], input, retarget, key_poses);
    set.names.push_back(names[i]);
    set.f.push_back(d.f);
    set.start.push_back(d.start);
    set.hand.push_back(handPath(arm, d.f));
  }
  return set;
}

HeldOutScores scoreHeldOut(std::vector<HandPath> hand, double period_s) {
  HeldOutScores s;
  s.hand = std::move(hand);
  s.period_s = period_s;
  s.plane = loopPlane(s.hand);
  for (std::size_t i = 0; i < s.hand.size(); ++i) {
    s.nn_dtw_m.push_back(nearestDemo(s.hand[i], s.hand, static_cast<int>(i)).dtw_m);
    s.speed_m_s.push_back(middleRmsSpeed(s.hand[i], period_s));
    s.loops.push_back(loopCount(s.hand[i], s.plane));
  }
  return s;
}

RunScore scoreRun(const HandPath& run, const HeldOutScores& held) {
  RunScore r;
  r.nearest = nearestDemo(run, held.hand);
  r.speed_m_s = middleRmsSpeed(run, held.period_s);
  r.loops = loopCount(run, held.plane);
  return r;
}

std::vector<double> speedVsReplay(const std::vector<HandPath>& runs, const std::vector<HandPath>& replays,
                                  double period_s) {
  if (runs.size() != replays.size()) throw std::invalid_argument("speedVsReplay: one replay per run");
  std::vector<double> ratio;
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const double replay = middleRmsSpeed(replays[i], period_s);
    ratio.push_back(replay > 0.0 ? middleRmsSpeed(runs[i], period_s) / replay : std::numeric_limits<double>::quiet_NaN());
  }
  return ratio;
}

Rollout trackDemoRollout(const ArmModel& arm, RobotBackend& robot, double period_s, double gain,
                         const std::vector<JointVector>& f, const JointVector& start, int ticks) {
  int t = 0;
  return rolloutOn(arm, robot, period_s, start, ticks, [&](const JointVector& q, const std::vector<JointVector>&) {
    // The demonstration's next sample, held at its last one when the run outlasts it.
    const JointVector target = clampToLimits(arm, f[std::min<std::size_t>(static_cast<std::size_t>(t) + 1, f.size() - 1)]);
    ++t;
    return JointVector(gain * (target - q));
  });
}

std::vector<JointVector> trackDemo(const ArmModel& arm, RobotBackend& robot, double period_s, double gain,
                                   const std::vector<JointVector>& f, const JointVector& start, int ticks) {
  const Rollout r = trackDemoRollout(arm, robot, period_s, gain, f, start, ticks);
  std::vector<JointVector> q{clampToLimits(arm, start)};
  q.insert(q.end(), r.q.begin(), r.q.end());
  return q;
}

std::vector<JointVector> trackDemo(const SimModel& sim, double period_s, double gain, const std::vector<JointVector>& f,
                                   const JointVector& start, int ticks) {
  SimData data(sim, start);
  OdeArmBackend robot(sim, data);
  return trackDemo(sim.arm, robot, period_s, gain, f, start, ticks);
}

NeighbourReplays neighbourReplays(const SimModel& sim, double period_s, double gain, const DemoSet& train,
                                  const JointVector& start, int ticks, std::size_t k) {
  NeighbourReplays out;
  out.demos = nearestStarts(train.start, start, k);
  out.medoid = medoid(train.hand, out.demos);
  for (int d : out.demos) out.q.push_back(trackDemo(sim, period_s, gain, train.f[static_cast<std::size_t>(d)], start, ticks));
  return out;
}

void writeTrajectoryCsv(const std::string& path, const std::vector<JointVector>& q, double period_s) {
  std::ofstream csv(path);
  if (!csv) throw UserError("cannot write " + path);
  csv << "t_s,q_0,q_1,q_2,q_3,q_4\n";
  char buf[64];
  for (std::size_t i = 0; i < q.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%.17g", static_cast<double>(i) * period_s);
    csv << buf;
    for (int j = 0; j < kNumJoints; ++j) {
      std::snprintf(buf, sizeof buf, ",%.17g", q[i][j]);
      csv << buf;
    }
    csv << '\n';
  }
  if (!csv) throw UserError("cannot write " + path);
}

}  // namespace nao::tools
