// The live reference of a nao_rt run (rt_live.hpp).
#include "rt_live.hpp"

#include "nao/calibration_json.hpp"
#include "nao/openpose_json.hpp"

#include <time.h>

#include <cmath>
#include <cstdio>
#include <utility>

namespace nao::rt {
namespace {

constexpr double kDefaultFps = 30.0;

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace

LiveSource::LiveSource(LiveCameraConfig config) : camera_(std::move(config)) {}

const SkeletonFrame* LiveSource::frameAt(std::int64_t tick) {
  (void)tick;  // the newest skeleton at this instant, whatever the tick
  timespec now{};
  clock_gettime(CLOCK_MONOTONIC, &now);
  return takeNewestFromRT(camera_, now, frame_, &record_) ? &frame_ : nullptr;
}

LiveHumanScale LiveSource::scaleOfLastFrame() const { return {record_.current_scale_m, record_.current_hand_m}; }

LiveCameraConfig liveCameraConfig(const RunOptions& o, const ReferenceSpec& spec) {
  LiveCameraConfig cfg;
  cfg.dirs = spec.dirs;
  const std::string format = o.pose_format.empty() ? "body25" : o.pose_format;
  const std::optional<PoseFormat> f = poseFormatFromName(format);
  if (!f) throw UsageError("--format '" + format + "': expected body25 or body25b");
  cfg.skeleton.format = *f;
  cfg.fps = o.fps > 0.0 ? o.fps : kDefaultFps;
  if (!std::isfinite(cfg.fps) || cfg.fps > 1000.0) throw UsageError("--fps must be a frame rate in (0, 1000] Hz");
  // d_h is an arm's length (shoulder to hand, about 0.5-0.8 m): a value off by 100 or 1000 is
  // centimetres or millimetres.
  if (o.human_scale_m != 0.0 && !(o.human_scale_m >= 0.2 && o.human_scale_m <= 2.0))
    throw UsageError("--human-scale " + number(o.human_scale_m) +
                     ": d_h is the human arm's length in metres (0.2 to 2; about 0.6 for an adult)");
  cfg.skeleton.human_scale_m = o.human_scale_m;
  if (o.calibration_path.empty())
    throw UsageError("--reference openpose: needs --calibration FILE (the cameras, our JSON: nao_toolchain "
                     "calibration --to-json converts an Anipose/OpenCV TOML)");
  cfg.cameras = readCameraSetJson(o.calibration_path);
  if (cfg.cameras.size() != cfg.dirs.size())
    throw UsageError("--calibration " + o.calibration_path + " has " + std::to_string(cfg.cameras.size()) +
                     " cameras but --reference openpose: names " + std::to_string(cfg.dirs.size()) +
                     " folders (one folder per camera, in the calibration's order)");
  if (o.reader_allocations != nullptr) {
    ThreadAllocationCounter* counter = o.reader_allocations;
    cfg.on_reader_start = [counter] { counter->attach(); };
  }
  return cfg;
}

std::string liveDescription(const RunOptions& o, const ReferenceSpec& spec) {
  std::string s = "openpose:";
  for (std::size_t i = 0; i < spec.dirs.size(); ++i) s += (i ? "," : "") + spec.dirs[i];
  s += " (" + std::to_string(spec.dirs.size()) + " cameras of " + o.calibration_path + ", " +
       number(o.fps > 0.0 ? o.fps : kDefaultFps) + " fps, " + (o.pose_format.empty() ? "body25" : o.pose_format) +
       ", d_h " + (o.human_scale_m > 0.0 ? number(o.human_scale_m) + " m" : std::string("estimated")) + ")";
  return s;
}

}  // namespace nao::rt
