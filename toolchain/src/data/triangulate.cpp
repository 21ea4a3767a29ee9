// Offline triangulation of whole recordings: the runtime's per-frame core (nao/triangulation.hpp)
// over every frame, then the sequence rules (bone lengths over the capture, gap interpolation)
// and resampling.
#include "nao/tools/triangulate.hpp"
#include "nao/tools/stats.hpp"

#include "nao/tools/command.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <utility>

namespace nao::tools {
namespace {

constexpr double kTimeEps = 1e-9;  // s; two times closer than this are the same sample
constexpr double kMaxCaptureSpan_s = 24.0 * 3600.0;  // longest capture accepted
constexpr long long kMaxCaptureFrames = 3000000;    // ... and most frames (27 h at 30 fps)

std::string shortNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

int rejectBoneLengthOutliers(Skeleton& frames, double tolerance) {
  const BoneLengths bones = medianBoneLengths(frames.data(), frames.size());
  int n_marked = 0;
  for (SkeletonFrame& f : frames) n_marked += rejectBoneOutliers(f, bones, tolerance);
  return n_marked;
}

Skeleton triangulateCapture(const CameraSet& cameras, const std::vector<CameraKeypoints>& keypoints,
                            const TriangulateOptions& opt, TriangulationReport* report) {
  if (!(opt.fps > 0.0) || !std::isfinite(opt.fps)) throw UserError("--fps must be a positive number of frames per second");
  if (cameras.size() < 2)
    throw UserError("triangulation needs at least 2 cameras, the calibration has " + std::to_string(cameras.size()));
  if (keypoints.size() != cameras.size())
    throw UserError("the calibration has " + std::to_string(cameras.size()) + " cameras but " +
                    std::to_string(keypoints.size()) + " keypoint folders were given (cameras pair with folders in order)");
  for (const CameraKeypoints& cam : keypoints) {
    const bool anyone = std::any_of(cam.frames.begin(), cam.frames.end(),
                                    [](const KeypointFrame& f) { return !f.people.empty(); });
    if (!anyone)
      throw UserError(cam.dir + ": no person detected in any of its " + std::to_string(cam.frames.size()) + " frames");
  }

  // Frames pair across cameras by their file index, never by position: a frame file missing in
  // one folder must not shift the others. The capture frames are the union of the indices; a
  // camera without a file for an index sees nobody in that frame.
  std::map<long long, std::vector<const KeypointFrame*>> by_index;
  for (std::size_t c = 0; c < keypoints.size(); ++c)
    for (const KeypointFrame& f : keypoints[c].frames) {
      std::vector<const KeypointFrame*>& slot = by_index[f.index];
      slot.resize(keypoints.size(), nullptr);
      if (slot[c] != nullptr)
        throw UserError(keypoints[c].dir + ": two files for frame " + std::to_string(f.index) + ": " + slot[c]->file +
                        " and " + f.file);
      slot[c] = &f;
    }
  const long long first_index = by_index.begin()->first;
  const long long last_index = by_index.rbegin()->first;
  const std::size_t n_frames = by_index.size();
  // Output samples and report counts span the indices; an absurd span (a stray file) would
  // allocate without bound and overflow the counts.
  if (last_index - first_index >= kMaxCaptureFrames || static_cast<double>(last_index - first_index) / opt.fps > kMaxCaptureSpan_s)
    throw UserError("frame indices run from " + std::to_string(first_index) + " to " + std::to_string(last_index) +
                    ": more than 3 million frames or 24 h at --fps (a stray file in a keypoint folder?)");
  const std::vector<Person2d> nobody;  // a camera without a file for a frame

  TriangulationReport rep;
  // Frames absent from every folder are capture frames nobody was seen in: the report counts
  // them (no subject, every point missing) so its totals match the resampled output's time span.
  rep.n_frames_absent = static_cast<int>(last_index - first_index + 1 - static_cast<long long>(n_frames));
  rep.n_frames = static_cast<int>(n_frames) + rep.n_frames_absent;
  rep.n_frames_without_subject = rep.n_frames_absent;
  rep.n_points_missing = rep.n_frames_absent * kNumSkeletonPoints;
  Skeleton frames(n_frames);
  std::vector<double> rms;
  TriangulationState state;
  std::vector<std::vector<const std::vector<Person2d>*>> frame_people(n_frames);
  std::size_t k = 0;
  for (const auto& [index, files] : by_index) {
    std::vector<const std::vector<Person2d>*>& people = frame_people[k];
    for (const KeypointFrame* f : files) people.push_back(f != nullptr ? &f->people : &nobody);
    if (std::find(files.begin(), files.end(), nullptr) != files.end()) ++rep.n_frames_incomplete;
    // Time from the file index, so frames absent from every folder keep their gap.
    const double t_s = static_cast<double>(index - first_index) / opt.fps;
    const FrameTriangulation done = triangulateFrame(cameras, people, t_s, opt, state, frames[k]);
    rep.subject_person.push_back(done.subject.found ? done.subject.person : std::vector<int>(cameras.size(), -1));
    if (!done.subject.found) ++rep.n_frames_without_subject;
    rep.n_observations_rejected += done.n_observations_rejected;
    rep.n_points_inconsistent += done.n_points_inconsistent;
    for (int i = 0; i < kNumSkeletonPoints; ++i)
      if (frames[k].ok[i]) rms.push_back(done.rms_px[i]);
    ++k;
    if (opt.progress) opt.progress(static_cast<int>(k), static_cast<int>(n_frames));
  }
  if (opt.check_bone_lengths) rep.n_bone_rejections = rejectBoneLengthOutliers(frames, opt.bone_tolerance);
  if (opt.bone_fit_px_per_m > 0.0) {
    const BoneLengths bones = medianBoneLengths(frames.data(), frames.size());
    for (std::size_t f = 0; f < frames.size(); ++f) {
      const FrameObservations observations{&cameras, &frame_people[f], &rep.subject_person[f]};
      rep.n_arm_bone_fits +=
          fitArmBoneLengths(observations, bones, opt.bone_fit_px_per_m, opt.max_refine_iterations, frames[f]) ? 1 : 0;
    }
  }
  smoothSkeletonZeroLag(frames, opt.zero_lag_sigma_s, opt.fps);
  for (SkeletonFrame& f : frames)
    for (int i = 0; i < kNumSkeletonPoints; ++i)
      if (!f.ok[i]) f.views[i] = 0, f.reprojection_px[i] = 0.0f;
  fillShortGaps(frames, opt.max_gap_s, opt.fps);
  for (SkeletonFrame& f : frames) {
    if (opt.format == PoseFormat::kBody25B) completeMidHip(f);
    for (int i = 0; i < kNumSkeletonPoints; ++i)
      (f.interpolated[i] ? rep.n_points_interpolated : f.ok[i] ? rep.n_points_valid : rep.n_points_missing) += 1;
  }
  rep.median_reprojection_px = median(rms);
  if (report != nullptr) *report = rep;
  return frames;
}

int smoothSkeletonZeroLag(Skeleton& frames, double sigma_s, double capture_fps) {
  if (!(sigma_s > 0.0) || !(capture_fps > 0.0) || frames.empty()) return 0;
  const double reach_s = 3.0 * sigma_s;
  const double max_step_s = 1.5 / capture_fps;
  // Runs of frames without absent indices between them: nothing is smoothed across those.
  std::vector<std::size_t> run_start(frames.size(), 0);
  for (std::size_t k = 1; k < frames.size(); ++k)
    run_start[k] = frames[k].t_s - frames[k - 1].t_s > max_step_s ? k : run_start[k - 1];
  const Skeleton raw = frames;
  int n_changed = 0;
  std::size_t lo = 0;  // first frame within reach of frame k (times increase)
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const double t = raw[k].t_s;
    lo = std::max(lo, run_start[k]);
    while (raw[lo].t_s < t - reach_s) ++lo;
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      if (!raw[k].ok[i] || raw[k].interpolated[i]) continue;
      // Weighted sums of the local line p(t + u) = a + b u.
      double s0 = 0.0, s1 = 0.0, s2 = 0.0;
      Eigen::Vector3d m0 = Eigen::Vector3d::Zero(), m1 = Eigen::Vector3d::Zero();
      int n = 0;
      for (std::size_t j = lo; j < raw.size() && run_start[j] == run_start[k]; ++j) {
        const double u = raw[j].t_s - t;
        if (u > reach_s) break;
        if (!raw[j].ok[i] || raw[j].interpolated[i]) continue;
        const double w = std::exp(-0.5 * (u / sigma_s) * (u / sigma_s));
        s0 += w, s1 += w * u, s2 += w * u * u;
        m0 += w * raw[j].p_W[i], m1 += (w * u) * raw[j].p_W[i];
        ++n;
      }
      const double det = s0 * s2 - s1 * s1;
      if (n < 3 || !(det > 1e-12 * s0 * s2)) continue;
      frames[k].p_W[i] = (s2 * m0 - s1 * m1) / det;
      ++n_changed;
    }
  }
  return n_changed;
}

int fillShortGaps(Skeleton& frames, double max_gap_s, double capture_fps) {
  if (!(max_gap_s > 0.0) || !(capture_fps > 0.0)) return 0;
  const double period_s = 1.0 / capture_fps;
  int n_filled = 0;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    std::size_t last = frames.size();  // last valid sample of point i so far
    for (std::size_t k = 0; k < frames.size(); ++k) {
      if (!frames[k].ok[i]) continue;
      if (last < frames.size() && k > last + 1) {
        const SkeletonFrame& a = frames[last];
        const SkeletonFrame& b = frames[k];
        const double span_s = b.t_s - a.t_s;
        // Missing frames only (an absent index would make the span longer than the count says).
        const bool contiguous = std::abs(span_s - static_cast<double>(k - last) * period_s) <= kTimeEps * static_cast<double>(k - last + 1);
        if (contiguous && span_s - period_s <= max_gap_s + kTimeEps) {
          for (std::size_t m = last + 1; m < k; ++m) {
            const double w = (frames[m].t_s - a.t_s) / span_s;
            SkeletonFrame& f = frames[m];
            f.p_W[i] = (1.0 - w) * a.p_W[i] + w * b.p_W[i];
            f.ok[i] = true;
            f.interpolated[i] = true;
            f.views[i] = 0;
            f.reprojection_px[i] = 0.0f;
            ++n_filled;
          }
        }
      }
      last = k;
    }
  }
  return n_filled;
}

Skeleton resampleSkeleton(const Skeleton& frames, double rate_hz, double capture_fps) {
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz)) throw UserError("--rate must be a positive number of samples per second");
  if (!(capture_fps > 0.0) || !std::isfinite(capture_fps))
    throw UserError("--fps must be a positive number of frames per second");
  Skeleton out;
  if (frames.empty()) return out;
  // Neighbours further apart than one capture period have absent frames between them: nothing
  // was measured there, so nothing is interpolated across.
  const double max_step_s = 1.0 / capture_fps + kTimeEps;
  const double t0 = frames.front().t_s, t_last = frames.back().t_s;
  // The count in double first: (t_last - t0) * rate_hz may not fit a size_t (--rate 1e300), or
  // fit and still be more than memory (--rate 1e12).
  const double n_samples = std::floor((t_last - t0) * rate_hz + kTimeEps) + 1.0;
  if (!(n_samples <= static_cast<double>(kMaxCaptureFrames)))
    throw UserError("--rate " + shortNumber(rate_hz) + " over the capture's " + shortNumber(t_last - t0) + " s gives " +
                    shortNumber(n_samples) + " samples, more than the cap of " + std::to_string(kMaxCaptureFrames));
  const auto n_out = static_cast<std::size_t>(n_samples);
  std::size_t k = 0;
  for (std::size_t j = 0; j < n_out; ++j) {
    const double t = t0 + static_cast<double>(j) / rate_hz;
    while (k + 1 < frames.size() && frames[k + 1].t_s <= t + kTimeEps) ++k;
    SkeletonFrame f;
    f.p_W.fill(Eigen::Vector3d::Zero());
    f.ok.fill(false);
    if (std::abs(frames[k].t_s - t) <= kTimeEps || k + 1 == frames.size()) {
      f = frames[k];
    } else if (frames[k + 1].t_s - frames[k].t_s <= max_step_s) {
      const SkeletonFrame& a = frames[k];
      const SkeletonFrame& b = frames[k + 1];
      const double w = (t - a.t_s) / (b.t_s - a.t_s);
      for (int i = 0; i < kNumSkeletonPoints; ++i) {
        f.ok[i] = a.ok[i] && b.ok[i];
        f.p_W[i] = f.ok[i] ? Eigen::Vector3d((1.0 - w) * a.p_W[i] + w * b.p_W[i]) : Eigen::Vector3d::Zero();
        if (!f.ok[i]) continue;
        f.interpolated[i] = a.interpolated[i] || b.interpolated[i];
        f.views[i] = a.views[i] | b.views[i];
        f.reprojection_px[i] = std::max(a.reprojection_px[i], b.reprojection_px[i]);
      }
    }
    f.t_s = t;
    out.push_back(f);
  }
  return out;
}

}  // namespace nao::tools
