// The live reference of a nao_rt run, --reference openpose:DIR0,DIR1[,...] (docs/nao_rt.md "Live
// reference", docs/cameras.md): the live camera source (nao/live_camera.hpp) behind the run's
// HumanSource.
//
// Threads: the source's reader thread (inotify, parse, pair by frame index, triangulate, the
// causal filters, d_h) starts at configure time, when the source is made, and stops when it is
// destroyed, after the run directory is written. The control thread's frameAt takes the newest
// skeleton with takeNewestFromRT at CLOCK_MONOTONIC now: no allocation, no lock, no system call
// (clock_gettime is the vDSO's), no parsing. No skeleton yet, the newest one's file older than
// 0.3 s, or a frame without a subject is "no human" (nullptr): the controller's own no-human
// path (bridge, hold, return home).
//
// The human scale d_h: --human-scale M if given; otherwise the source's estimate (the medians of
// the arm's segments over the subject's first 3 s with the arm measured, then fixed), and until
// it is fixed the same medians over the frames so far (LiveSkeleton::current_scale_m), so the
// arm imitates from the first frame. Each frame goes to the controller with the scale it came
// with (scaleOfLastFrame).
#pragma once

#include "rt_config.hpp"

#include "nao/live_camera.hpp"

#include <memory>
#include <string>

namespace nao::rt {

class LiveSource final : public HumanSource {
 public:
  /// Starts the live camera source (its reader thread). Throws InputError (a bad
  /// configuration: cameras and folders differ in number, ...) or std::runtime_error.
  explicit LiveSource(LiveCameraConfig config);

  /// The newest fresh skeleton, or nullptr ("no human"). Control thread; real-time safe.
  const SkeletonFrame* frameAt(std::int64_t tick) override;
  /// The scale the last frame came with (see the top of this file). Real-time safe.
  LiveHumanScale scaleOfLastFrame() const override;

  const LiveCamera& camera() const { return camera_; }

 private:
  LiveCamera camera_;
  SkeletonFrame frame_;
  LiveSkeleton record_;
};

/// The live camera configuration of a run: the folders of `spec`, the cameras of
/// --calibration (checked against the folders' count), --format, --fps, --human-scale, the
/// reader thread's allocation counter. Configure time: reads the calibration; throws UsageError
/// (a bad flag value, cameras and folders differ in number) or InputError (the calibration).
LiveCameraConfig liveCameraConfig(const RunOptions& options, const ReferenceSpec& spec);

/// What summary.json's `reference` says of a live run.
std::string liveDescription(const RunOptions& options, const ReferenceSpec& spec);

}  // namespace nao::rt
