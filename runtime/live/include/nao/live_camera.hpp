// Live camera source of nao_rt (`--reference openpose:DIR0,DIR1[,...]`, docs/cameras.md): OpenPose
// running with `--write_json DIR` on two or more synchronised, calibrated cameras, one folder
// per camera, one file per frame (`<name>_<12 digits>_keypoints.json`), each written plainly
// (not renamed into place) as its frame is processed.
//
// A reader thread (started by the constructor, stopped by the destructor) does all the work:
//  - watches the folders with inotify (nao/folder_watch.hpp): a folder and its parents need not
//    exist at start and may appear later; a folder may disappear and come back. Files already
//    in a folder when the source starts are an earlier session's and are ignored; files in a
//    folder that appears later are read (of many, the newest 4 s + 64 frames': older ones would
//    be skipped anyway), by a scan that keeps no list of the folder's names;
//  - parses each new frame file (nao/openpose_json.hpp) when its writer closes it, and retries
//    a file that does not parse yet (half written: seen created or modified, not closed) every
//    retry_s until file_wait_s after it appeared; then it is dropped and counted malformed;
//  - pairs the cameras by frame index: an index is complete when every live camera's file for
//    it has parsed, or when a newer index is complete (its missing cameras then see nobody), or
//    when every camera has been quiet for camera_stopped_s with no file left to parse. A
//    camera is live from its first parsed file while its folder exists; one whose last parsed
//    file is more than camera_stopped_s older than any camera's newest is stopped and left out
//    until it parses a file again;
//  - triangulates each complete index with the shared per-frame core (nao/triangulation.hpp:
//    the same subject choice and camera consensus as `nao_toolchain triangulate`), then the
//    causal steps of nao/live_skeleton.hpp (bone-length rule, low-pass, gap bridge, d_h);
//  - publishes the skeleton to the control thread without a lock (nao/newest_ring.hpp).
// The control thread takes the newest skeleton with takeNewestFromRT: no allocation, no lock,
// no system call, no parsing. A skeleton whose newest file appeared more than stale_s ago, or
// without a subject, is "no human". Failures are counted (LiveCameraCounters), never fatal.
//
// Times are CLOCK_MONOTONIC. A file "appears" when the reader thread reads the first inotify
// event naming it (created or written): the latency of a skeleton runs from the appearance of
// the newest file of its frame (the one that completed it) to the control thread's first take
// of it; each take of a new skeleton records one sample (latencyStats).
//
// Lifecycle: construct at configure time (throws InputError on a bad configuration), take from
// the control loop, read the counters and the latency at the end; destroy to stop the thread.
#pragma once

#include "nao/body25.hpp"
#include "nao/camera.hpp"
#include "nao/live_skeleton.hpp"
#include "nao/newest_ring.hpp"
#include "nao/openpose_json.hpp"
#include "nao/triangulation.hpp"

#include <nlohmann/json_fwd.hpp>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <ctime>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace nao {

/// The skeleton handed from the reader thread to the control thread (trivially copyable).
struct LiveSkeleton {
  std::int64_t frame_index = 0;      ///< OpenPose frame index
  std::int64_t arrival_ns = 0;       ///< when the frame's newest file appeared (CLOCK_MONOTONIC)
  std::int64_t published_ns = 0;     ///< when the reader thread published it (CLOCK_MONOTONIC)
  double t_s = 0.0;                  ///< (frame_index - first index of the capture) / fps
  double human_scale_m = 0.0;        ///< d_h: given, or estimated (0 until the estimate is fixed)
  double hand_length_m = 0.0;        ///< hand segment of the estimate (0: given d_h or not yet)
  /// d_h to scale this skeleton with (LiveSkeletonState::current_scale_m): human_scale_m once
  /// fixed or given, before that the estimate's medians over the frames so far (0: no arm yet).
  double current_scale_m = 0.0;
  double current_hand_m = 0.0;       ///< its hand segment (0 with a given d_h: the per-frame rule)
  std::uint32_t n_cameras = 0;       ///< cameras that had a file for this frame
  std::uint32_t subject = 0;         ///< 1: a subject was triangulated or bridged (some point valid)
  double p_W[kNumSkeletonPoints][3] = {};         ///< world (calibration) frame, m
  std::uint8_t ok[kNumSkeletonPoints] = {};       ///< 0 missing, 1 measured, 2 bridged across a gap
  std::uint32_t views[kNumSkeletonPoints] = {};   ///< cameras of each measured point (bit c = camera c)
};

struct LiveCameraConfig {
  std::vector<std::string> dirs;       ///< one --write_json folder per camera, in calibration order
  CameraSet cameras;                   ///< the calibration (nao/calibration_json.hpp), >= 2 cameras
  double fps = 30.0;                   ///< capture rate, Hz
  TriangulationParams triangulation;   ///< the per-frame core's settings
  LiveSkeletonParams skeleton;         ///< bone rule, low-pass, gap bridge, d_h (its format is the keypoint layout)
  double stale_s = 0.3;                ///< takeNewestFromRT: a skeleton older than this is "no human", s
  double file_wait_s = 0.5;            ///< a file that does not parse is dropped this long after it appeared, s
  double retry_s = 0.005;              ///< interval between parse attempts of an unclosed file, s
  double camera_stopped_s = 0.5;       ///< a camera whose last parsed file is this much older than the newest is stopped, s
  int max_catch_up_frames = 8;         ///< complete frames processed at once; older ones are skipped
  std::size_t latency_capacity = 36000;  ///< latency samples kept (1 h of 10 Hz takes)
  /// Called first on the reader thread (e.g. to attach a counting allocator's ThreadAllocations).
  std::function<void()> on_reader_start;
  /// Called on the reader thread after each skeleton is published (logs, tests).
  std::function<void(const LiveSkeleton&)> on_skeleton;
};

/// What happened, per kind (reader thread counts; control thread counts the takes).
struct LiveCameraCounters {
  std::uint64_t files_parsed = 0;          ///< frame files read
  std::uint64_t files_malformed = 0;       ///< frame files that never parsed within file_wait_s (half written or bad)
  std::uint64_t files_late = 0;            ///< frame files that parsed after their index was processed
  std::uint64_t frames_complete = 0;       ///< indices processed with every live camera's file
  std::uint64_t frames_incomplete = 0;     ///< indices processed because a newer one completed
  std::uint64_t frames_skipped = 0;        ///< complete indices skipped to catch up (reader behind)
  std::uint64_t frames_no_person = 0;      ///< processed indices without a subject seen by >= 2 cameras
  std::uint64_t points_bridged = 0;        ///< missing points held across a short gap
  std::uint64_t folder_gone = 0;           ///< a camera folder disappeared
  std::uint64_t folder_back = 0;           ///< a camera folder (re)appeared after the start
  std::uint64_t camera_stopped = 0;        ///< a camera stopped writing while others went on
  std::uint64_t camera_resumed = 0;        ///< a stopped camera wrote again
  std::uint64_t capture_restarts = 0;      ///< frame indices started over (OpenPose restarted)
  std::uint64_t watch_overflows = 0;       ///< the kernel dropped folder events
  std::uint64_t reader_errors = 0;         ///< unexpected errors on the reader thread (e.g. out of memory), survived
  std::uint64_t takes = 0;                 ///< takeNewestFromRT calls
  std::uint64_t takes_fresh = 0;           ///< ... that returned a skeleton not taken before
  std::uint64_t takes_no_human = 0;        ///< ... that returned false (nothing yet, stale, or no subject)
};

/// Latency percentiles, ms.
struct LatencyStats {
  std::size_t n = 0;
  double p50_ms = 0.0, p99_ms = 0.0, max_ms = 0.0;
};

class LiveCamera;

/// Copies the newest fresh skeleton into `out` (SkeletonFrame: t_s, p_W, ok, interpolated for
/// bridged points, views) and returns true; false ("no human") when none was published yet, the
/// newest one's frame appeared more than stale_s before `now`, or it has no subject (then `out`
/// is left unchanged). The first take of each skeleton records its latency. Control thread
/// only; real-time safe: no allocation, lock, system call or parsing.
bool takeNewestFromRT(LiveCamera& camera, const timespec& now, SkeletonFrame& out,
                      LiveSkeleton* record = nullptr) noexcept;

class LiveCamera {
 public:
  /// Checks the configuration (throws InputError: fewer than 2 cameras, folder and camera
  /// counts differ, the same folder twice, a non-positive fps or time), reserves the buffers,
  /// starts watching and starts the reader thread (throws std::runtime_error if it cannot).
  explicit LiveCamera(LiveCameraConfig config);
  LiveCamera(const LiveCamera&) = delete;
  LiveCamera& operator=(const LiveCamera&) = delete;
  /// Stops and joins the reader thread.
  ~LiveCamera();

  const LiveCameraConfig& config() const { return config_; }
  /// The counters now. Any thread.
  LiveCameraCounters counters() const;
  /// Percentiles of the latencies recorded so far. Not real-time (sorts a copy): call it from
  /// the control thread after its last take, or from any thread once takes have stopped.
  LatencyStats latencyStats() const;
  /// summary.json's `camera` object: the counters, the latency {n, p50, p99, max} (ms), d_h
  /// and the reader thread's allocation count when a counter was attached (else null).
  nlohmann::json summaryJson(std::optional<std::int64_t> reader_allocations = std::nullopt) const;
  /// d_h of the newest published skeleton (0: not yet fixed). Any thread.
  double humanScale() const { return human_scale_m_.load(std::memory_order_relaxed); }

 private:
  friend bool takeNewestFromRT(LiveCamera&, const timespec&, SkeletonFrame&, LiveSkeleton*) noexcept;
  struct Reader;
  struct AtomicCounters;

  LiveCameraConfig config_;
  NewestRing<LiveSkeleton> ring_;
  std::unique_ptr<AtomicCounters> counts_;
  std::atomic<double> human_scale_m_{0.0};
  // Control thread side (takeNewestFromRT).
  std::uint64_t last_taken_ = 0;
  std::unique_ptr<float[]> latency_ms_;
  std::size_t n_latency_ = 0;
  std::unique_ptr<LiveSkeleton> scratch_;  // a record being taken (kept off the control thread's stack)
  std::unique_ptr<Reader> reader_;         // last: stopped first
};

}  // namespace nao
