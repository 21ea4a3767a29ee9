// The live camera source (nao/live_camera.hpp) against recordings replayed into camera folders
// the way OpenPose writes them (nao/tools/replay.hpp): agreement with the offline triangulation
// of the same recording, "no human" when nothing (fresh) is there, and the counters of a hostile
// replay (truncated frames, frames with nobody, a folder gone for a second, a camera that stops).
// Also the pieces on their own: the folder watch, the newest-value ring, the causal skeleton
// steps (gap bridge, d_h against the toolchain's estimate, what the bone fit and low-pass do to
// the elbow angle against the plain live triangulation).
#include "support/live_recording.hpp"

#include "nao/folder_watch.hpp"
#include "nao/live_skeleton.hpp"
#include "nao/newest_ring.hpp"
#include "nao/tools/human_scale.hpp"
#include "nao/tools/synth_stress.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <thread>

namespace {

using namespace nao;
using namespace nao::test;
namespace fs = std::filesystem;
using tools::Movement;

void sleepFor(double seconds) { std::this_thread::sleep_for(std::chrono::duration<double>(seconds)); }

std::vector<std::string> rigFolders(const fs::path& base, int n) {
  std::vector<std::string> dirs;
  for (int c = 0; c < n; ++c) dirs.push_back((base / "rig" / ("cam" + std::to_string(c))).string());
  return dirs;
}

// Records every skeleton the reader thread publishes; read them only after the source is gone.
struct Collector {
  std::vector<LiveSkeleton> records;
  std::atomic<long long> newest{-1};
  void attach(LiveCameraConfig& cfg) {
    cfg.on_skeleton = [this](const LiveSkeleton& r) {
      records.push_back(r);
      newest.store(r.frame_index);
    };
  }
  // Waits (bounded) until frame `index` was published.
  bool waitFor(long long index, double timeout_s = 2.0) {
    for (double t = 0.0; t < timeout_s; t += 0.01) {
      if (newest.load() >= index) return true;
      sleepFor(0.01);
    }
    return newest.load() >= index;
  }
};

// The per-frame core alone: no bone rule or fit, low-pass or gap bridge, live or offline.
void coreOnly(LiveCameraConfig& cfg) {
  cfg.skeleton.max_gap_s = 0.0;
  cfg.skeleton.check_bone_lengths = false;
  cfg.skeleton.bone_fit_px_per_m = 0.0;
  cfg.skeleton.low_pass.min_cutoff_hz = 0.0;
}

tools::TriangulateOptions offlineCoreOnly() {
  tools::TriangulateOptions opt;
  opt.fps = 30.0;
  opt.rate_hz = 30.0;  // one sample per capture frame
  opt.max_gap_s = 0.0;
  opt.check_bone_lengths = false;
  opt.bone_fit_px_per_m = 0.0;
  opt.zero_lag_sigma_s = 0.0;
  return opt;
}

}  // namespace

TEST_CASE("a recording replayed into folders that do not exist yet triangulates live exactly as offline, frame by frame") {
  const fs::path base = freshTestDir("exact");
  const fs::path rec = shortRecording("exact_rec", Movement::kElbow, 0, 90);
  const std::vector<std::string> targets = rigFolders(base, 2);
  REQUIRE_FALSE(fs::exists(base / "rig"));  // neither the folders nor their parent exist yet
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  coreOnly(cfg);
  Collector collected;
  collected.attach(cfg);
  {
    LiveCamera live(cfg);
    ReplayThread replay(rec, targets, 2.0);
    replay.join();
    CHECK(collected.waitFor(89));
  }
  const tools::Skeleton offline = tools::triangulateDemo(rec.string(), offlineCoreOnly());
  REQUIRE(offline.size() == 90);
  int n_compared = 0, n_points = 0;
  double worst = 0.0;
  for (const LiveSkeleton& r : collected.records) {
    if (r.n_cameras != 2) continue;  // processed before both cameras were live (the first frame)
    REQUIRE(r.frame_index >= 0);
    REQUIRE(r.frame_index < 90);
    const SkeletonFrame& f = offline[static_cast<std::size_t>(r.frame_index)];
    ++n_compared;
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      CHECK_MESSAGE((r.ok[i] != 0) == f.ok[i], "frame " << r.frame_index << " point " << kSkeletonPointNames[i]
                                                        << ": live ok " << int(r.ok[i]) << ", offline " << f.ok[i]);
      if (!r.ok[i] || !f.ok[i]) continue;
      ++n_points;
      worst = std::max(worst, (Eigen::Vector3d(r.p_W[i][0], r.p_W[i][1], r.p_W[i][2]) - f.p_W[i]).norm());
    }
  }
  MESSAGE(n_compared << " frames, " << n_points << " points compared; largest difference " << worst << " m");
  CHECK(n_compared >= 88);
  CHECK(n_points > 88 * 20);
  CHECK(worst <= 1e-12);  // the same core on the same detections: the same bits
}

TEST_CASE("with its causal steps on, the live skeleton follows nao_toolchain triangulate's within the lag of its low-pass") {
  const fs::path base = freshTestDir("defaults");
  const fs::path rec = shortRecording("defaults_rec", Movement::kWholeArm, 2, 150);
  const std::vector<std::string> targets = rigFolders(base, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);  // the live defaults
  Collector collected;
  collected.attach(cfg);
  {
    LiveCamera live(cfg);
    ReplayThread replay(rec, targets, 2.0);
    replay.join();
    CHECK(collected.waitFor(149));
  }
  tools::TriangulateOptions opt;  // nao_toolchain triangulate's defaults, at the capture rate
  opt.rate_hz = opt.fps;
  opt.zero_lag_sigma_s = 0.05;
  opt.bone_fit_px_per_m = 300.0;
  const tools::Skeleton offline = tools::triangulateDemo(rec.string(), opt);
  REQUIRE(offline.size() == 150);
  std::vector<double> d;
  int n_frames = 0;
  for (const LiveSkeleton& r : collected.records) {
    if (r.n_cameras != 2) continue;
    const SkeletonFrame& f = offline[static_cast<std::size_t>(r.frame_index)];
    ++n_frames;
    for (int i : {kRShoulder, kRElbow, kRWrist})
      if (r.ok[i] == 1 && f.ok[i] && !f.interpolated[i])
        d.push_back((Eigen::Vector3d(r.p_W[i][0], r.p_W[i][1], r.p_W[i][2]) - f.p_W[i]).norm());
  }
  std::sort(d.begin(), d.end());
  REQUIRE(d.size() > 300);
  const double p50 = d[d.size() / 2], p95 = d[d.size() * 95 / 100];
  MESSAGE(n_frames << " frames, " << d.size() << " arm points: live - offline median " << p50 * 1e3 << " mm, p95 "
                   << p95 * 1e3 << " mm, max " << d.back() * 1e3 << " mm");
  // The One Euro filter lags ~40 ms at rest (4 Hz); at the ~0.5 m/s of a circling hand that is
  // ~20 mm, where the zero-lag offline filter has none.
  CHECK(p50 <= 0.010);
  CHECK(p95 <= 0.030);
}

TEST_CASE("no frame ever: every take is 'no human'") {
  const fs::path base = freshTestDir("nothing");
  const fs::path rec = shortRecording("nothing_rec", Movement::kWrist, 0, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, rigFolders(base, 2));
  LiveCamera live(cfg);
  SkeletonFrame out;
  out.t_s = -7.0;
  int n_human = 0;
  for (int k = 0; k < 40; ++k) {
    n_human += takeNewestFromRT(live, monotonicNow(), out) ? 1 : 0;
    sleepFor(0.005);
  }
  CHECK(n_human == 0);
  CHECK(out.t_s == -7.0);  // untouched
  const LiveCameraCounters c = live.counters();
  CHECK(c.takes == 40);
  CHECK(c.takes_no_human == 40);
  CHECK(c.files_parsed == 0);
  CHECK(live.latencyStats().n == 0);
}

TEST_CASE("the newest skeleton is a human while fresh and 'no human' once older than stale_s") {
  const fs::path base = freshTestDir("stale");
  const fs::path rec = shortRecording("stale_rec", Movement::kWholeArm, 0, 30);
  const std::vector<std::string> targets = rigFolders(base, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  LiveCamera live(cfg);
  ReplayThread replay(rec, targets, 1.0);
  SkeletonFrame out;
  LiveSkeleton record;
  int n_human = 0;
  while (replay.thread.joinable() && collected.newest.load() < 29) {
    n_human += takeNewestFromRT(live, monotonicNow(), out, &record) ? 1 : 0;
    sleepFor(0.01);
  }
  replay.join();
  REQUIRE(collected.waitFor(29));
  CHECK(n_human > 10);
  REQUIRE(takeNewestFromRT(live, monotonicNow(), out, &record));
  CHECK(record.frame_index == 29);
  CHECK(record.published_ns >= record.arrival_ns);
  CHECK(out.ok[kRWrist]);
  CHECK(out.t_s == doctest::Approx(record.t_s));
  sleepFor(cfg.stale_s + 0.05);
  CHECK_FALSE(takeNewestFromRT(live, monotonicNow(), out));
  // Each skeleton taken is one latency sample, none of a repeated take.
  const LiveCameraCounters c = live.counters();
  CHECK(live.latencyStats().n == c.takes_fresh);
  CHECK(c.takes_fresh <= 30);
}

TEST_CASE("hostile replay: truncated frames and frames with nobody are counted, and the source goes on") {
  const fs::path base = freshTestDir("hostile");
  const fs::path rec = shortRecording("hostile_rec", Movement::kElbow, 1, 120);
  const std::vector<std::string> targets = rigFolders(base, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  tools::ReplayFaults faults;
  faults.truncate_every = 10;
  faults.no_person_every = 15;
  LiveCameraCounters c;
  tools::ReplayReport report;
  int n_human = 0, n_takes = 0;
  {
    LiveCamera live(cfg);
    ReplayThread replay(rec, targets, 2.0, faults);
    SkeletonFrame out;
    while (replay.thread.joinable() && collected.newest.load() < 118) {
      n_human += takeNewestFromRT(live, monotonicNow(), out) ? 1 : 0;
      ++n_takes;
      sleepFor(0.005);
    }
    replay.join();
    report = replay.report;
    // The last truncated file is given up after file_wait_s, then its frame goes alone.
    CHECK(collected.waitFor(119, cfg.file_wait_s + cfg.camera_stopped_s + 2.0));
    c = live.counters();
  }
  MESSAGE("truncated " << report.n_truncated << ", no person " << report.n_no_person << "; malformed "
                       << c.files_malformed << ", frames without a person " << c.frames_no_person << ", incomplete "
                       << c.frames_incomplete << ", complete " << c.frames_complete << ", skipped "
                       << c.frames_skipped);
  REQUIRE(report.n_truncated == 12);
  REQUIRE(report.n_no_person == 16);  // 8 indices x 2 cameras
  CHECK(c.files_malformed == static_cast<std::uint64_t>(report.n_truncated));
  // The replay's hostile indices (k % N == N - 1): a truncated file (one camera left) or nobody,
  // 12 + 8 - 4 shared. Each one processed is a frame without a person. The last, 119, has a
  // truncated file and no newer frame completes it: it goes alone once both cameras are quiet.
  std::set<long long> processed;
  for (const LiveSkeleton& r : collected.records) processed.insert(r.frame_index);
  const auto hostile = [&](long long k) {
    return k % faults.truncate_every == faults.truncate_every - 1 ||
           k % faults.no_person_every == faults.no_person_every - 1;
  };
  int hostile_processed = 0;
  for (long long i = 0; i < 120; ++i) hostile_processed += hostile(i) && processed.count(i) ? 1 : 0;
  MESSAGE("hostile indices processed: " << hostile_processed << " of 16");
  CHECK(hostile(119));
  CHECK(processed.count(119) == 1);
  CHECK(hostile_processed >= 14);
  CHECK(c.frames_no_person >= static_cast<std::uint64_t>(hostile_processed));
  CHECK(c.frames_incomplete >= 11);
  CHECK(c.frames_complete >= 90);
  CHECK(n_human > n_takes / 2);
  CHECK(c.reader_errors == 0);
}

TEST_CASE("a camera folder removed for a second is counted gone and back, and both cameras triangulate again") {
  const fs::path base = freshTestDir("folder_gone");
  const fs::path rec = shortRecording("folder_gone_rec", Movement::kWholeArm, 1, 120);
  const std::vector<std::string> targets = rigFolders(base, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  tools::ReplayFaults faults;
  faults.remove_folder_at_s = 1.0;
  faults.remove_for_s = 1.0;
  faults.fault_camera = 1;
  LiveCameraCounters c;
  {
    LiveCamera live(cfg);
    ReplayThread replay(rec, targets, 1.0, faults);
    replay.join();
    CHECK(replay.report.n_lost == 30);
    CHECK(collected.waitFor(119));
    c = live.counters();
  }
  CHECK(c.folder_gone == 1);
  CHECK(c.folder_back == 1);
  int n_two_after = 0;
  for (const LiveSkeleton& r : collected.records)
    if (r.frame_index >= 70 && r.n_cameras == 2 && r.ok[kRWrist] == 1) ++n_two_after;
  CHECK(n_two_after >= 40);  // of the 50 frames after the folder came back
}

TEST_CASE("a camera that stops writing is counted stopped, and the others' frames are still processed") {
  const fs::path base = freshTestDir("stopped");
  const fs::path rec = shortRecording("stopped_rec", Movement::kWrist, 1, 90);
  const std::vector<std::string> targets = rigFolders(base, 2);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  tools::ReplayFaults faults;
  faults.stop_at_s = 1.0;
  faults.fault_camera = 1;
  LiveCameraCounters c;
  {
    LiveCamera live(cfg);
    ReplayThread replay(rec, targets, 1.0, faults);
    replay.join();
    CHECK(collected.waitFor(89));
    c = live.counters();
  }
  CHECK(c.camera_stopped == 1);
  CHECK(c.camera_resumed == 0);
  CHECK(collected.newest.load() == 89);  // processed on without the stopped camera (one view: nobody)
  CHECK(c.frames_no_person >= 90 - 30 - static_cast<int>(cfg.camera_stopped_s * 30) - 2);
}

TEST_CASE("frame files already in a folder at start are ignored; a folder moved into place with its frames is read") {
  const fs::path base = freshTestDir("preexisting");
  const fs::path rec = shortRecording("preexisting_rec", Movement::kElbow, 2, 12);
  const std::vector<std::string> cams = tools::demoCameraDirs(rec.string());
  const std::vector<std::string> targets = rigFolders(base, 2);
  // cam0 holds an earlier session's frames; cam1 is made elsewhere and moved into place later.
  fs::create_directories(base / "rig");
  fs::copy(cams[0], targets[0]);
  fs::copy(cams[1], base / "staging");
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  LiveCameraCounters c;
  {
    LiveCamera live(cfg);
    sleepFor(0.2);
    CHECK(live.counters().files_parsed == 0);
    fs::rename(base / "staging", targets[1]);
    sleepFor(0.3);
    c = live.counters();
  }
  CHECK(c.files_parsed == 12);  // cam1's twelve, none of cam0's
  CHECK(c.folder_back == 0);    // a first appearance, not a return
}

TEST_CASE("a folder moved into place holding many frames has only its newest 4 s + 64 frames read, the ones that would be processed") {
  const fs::path base = freshTestDir("many_moved_in");
  const fs::path rec = shortRecording("many_moved_in_rec", Movement::kElbow, 0, 10);
  const std::vector<std::string> cams = tools::demoCameraDirs(rec.string());
  const std::vector<std::string> targets = rigFolders(base, 2);
  // cam1's folder, made elsewhere: 1,990 files that never parse (an earlier session's, cut
  // short), then the recording's 10 frames as indices 1990..1999.
  const int n_old = 1990;
  fs::create_directories(base / "staging");
  const auto frameName = [](long long index) {
    char name[64];
    std::snprintf(name, sizeof name, "cam_%012lld_keypoints.json", index);
    return std::string(name);
  };
  for (int k = 0; k < n_old; ++k) std::ofstream(base / "staging" / frameName(k));
  std::vector<fs::path> frames;
  for (const fs::directory_entry& e : fs::directory_iterator(cams[1])) frames.push_back(e.path());
  std::sort(frames.begin(), frames.end());
  REQUIRE(frames.size() == 10);
  for (int k = 0; k < 10; ++k) fs::copy_file(frames[static_cast<std::size_t>(k)], base / "staging" / frameName(n_old + k));
  fs::create_directories(targets[0]);
  LiveCameraConfig cfg = liveConfigFor(rec, targets);
  Collector collected;
  collected.attach(cfg);
  LiveCameraCounters c;
  {
    LiveCamera live(cfg);
    sleepFor(0.1);
    fs::rename(base / "staging", targets[1]);
    CHECK(collected.waitFor(n_old + 9));
    sleepFor(cfg.file_wait_s + 0.3);  // the unparsable ones given up
    c = live.counters();
  }
  const auto kept = static_cast<std::uint64_t>(std::ceil(4.0 * cfg.fps)) + 64;  // frames kept waiting at most
  MESSAGE("parsed " << c.files_parsed << ", malformed " << c.files_malformed << ", skipped " << c.frames_skipped);
  CHECK(c.files_parsed == 10);
  CHECK(c.files_malformed == kept - 10);  // of the 1,990 only the newest were tried
  // The frames processed are those of reading every file: the newest max_catch_up_frames.
  std::vector<long long> processed;
  for (const LiveSkeleton& r : collected.records) processed.push_back(r.frame_index);
  std::vector<long long> expected;
  for (long long k = n_old + 10 - cfg.max_catch_up_frames; k < n_old + 10; ++k) expected.push_back(k);
  CHECK(processed == expected);
}

TEST_CASE("the folder watch follows a folder whose parents do not exist yet, and reports it gone and back") {
  const fs::path base = freshTestDir("watch");
  const fs::path folder = base / "a" / "b" / "cam";
  FolderWatch watch({folder.string()});
  CHECK_FALSE(watch.present(0));
  std::vector<FolderEvent> events;
  const auto drain = [&] {
    events.clear();
    for (int k = 0; k < 20; ++k) {
      watch.readEvents(events);
      sleepFor(0.005);
    }
  };
  const auto count = [&](FolderEvent::Kind kind) {
    return std::count_if(events.begin(), events.end(), [&](const FolderEvent& e) { return e.kind == kind; });
  };
  fs::create_directories(folder);
  drain();
  CHECK(watch.present(0));
  CHECK(count(FolderEvent::Kind::kAppeared) == 1);
  std::ofstream(folder / "x_000000000001_keypoints.json") << "{}";
  drain();
  CHECK(std::any_of(events.begin(), events.end(), [](const FolderEvent& e) {
    return e.kind == FolderEvent::Kind::kFile && e.name == "x_000000000001_keypoints.json" && e.complete;
  }));
  fs::remove_all(base / "a");
  drain();
  CHECK_FALSE(watch.present(0));
  CHECK(count(FolderEvent::Kind::kGone) == 1);
  fs::create_directories(folder);
  drain();
  CHECK(watch.present(0));
  CHECK(count(FolderEvent::Kind::kAppeared) == 1);
}

TEST_CASE("the newest ring never hands out a torn value while the writer publishes") {
  struct Value {
    std::uint64_t n;
    std::uint64_t words[62];
  };
  static NewestRing<Value> ring;
  std::atomic<bool> stop{false};
  std::atomic<std::uint64_t> n_published{0};
  std::thread writer([&] {
    Value v{};
    for (std::uint64_t n = 1; !stop.load(std::memory_order_relaxed); ++n) {
      v.n = n;
      for (std::uint64_t& w : v.words) w = n * 2654435761u;
      publishNewest(ring, v);
      n_published.store(n, std::memory_order_relaxed);
      if (n % 64 == 0) std::this_thread::yield();  // interleave with the reader on a busy machine
    }
  });
  while (n_published.load() == 0) std::this_thread::yield();
  Value got{};
  std::uint64_t n_read = 0, n_torn = 0, last = 0, n_backwards = 0, n_distinct = 0;
  // Read until this thread itself has made 2000 reads of 50 distinct values: the end depends on
  // the reader's progress, not on how fast the writer runs while the reader waits for a core.
  // The attempt cap only bounds a broken ring.
  for (long k = 0; k < 50000000 && (n_read < 2000 || n_distinct < 50); ++k) {
    if (k % 16 == 0) std::this_thread::yield();
    const std::uint64_t n = readNewest(ring, got);
    if (n == 0) continue;  // every attempt overtaken: allowed, never torn
    ++n_read;
    for (std::uint64_t w : got.words) n_torn += (w != got.n * 2654435761u || got.n != n) ? 1 : 0;
    n_backwards += n < last ? 1 : 0;
    n_distinct += n != last ? 1 : 0;
    last = n;
  }
  stop = true;
  writer.join();
  MESSAGE(n_read << " reads of " << n_distinct << " distinct values while " << n_published.load() << " were published");
  CHECK(n_read >= 2000);
  CHECK(n_distinct >= 50);  // the writer really ran during the reads
  CHECK(n_torn == 0);
  CHECK(n_backwards == 0);
  CHECK(readNewest(ring, got) == n_published.load());
}

TEST_CASE("live d_h is the toolchain's arm-length estimate over the first seconds, then fixed") {
  const tools::SynthDemo demo = tools::generateDemo(Movement::kWholeArm, 3, 7, false);
  LiveSkeletonParams params;
  params.check_bone_lengths = false;
  params.bone_fit_px_per_m = 0.0;
  params.low_pass.min_cutoff_hz = 0.0;  // the truth's own lengths, as the offline estimate sees them
  params.max_gap_s = 0.0;
  params.reference_window_s = 3.0;
  LiveSkeletonState state;
  resetLiveSkeleton(params, demo.fps, state);
  tools::Skeleton window;
  double fixed_at = -1.0, fixed_value = 0.0;
  for (const SkeletonFrame& truth : demo.truth) {
    SkeletonFrame f = truth;
    const LiveSkeletonStep step = advanceLiveSkeleton(params, state, f);
    if (fixed_at < 0.0) window.push_back(truth);
    if (step.scale_fixed) fixed_at = f.t_s, fixed_value = state.human_scale_m;
  }
  REQUIRE(fixed_at >= 0.0);
  CHECK(fixed_at == doctest::Approx(3.0).epsilon(0.02));
  CHECK(state.human_scale_m == fixed_value);  // not changed after the window
  const tools::HumanArmLengths offline = tools::estimateHumanArmLengths(window);
  CHECK(fixed_value == doctest::Approx(offline.scale_m).epsilon(1e-12));
  CHECK(state.hand_length_m == doctest::Approx(offline.hand_m).epsilon(1e-12));
}

TEST_CASE("the gap bridge holds a point across a short gap, flagged, and lets a long gap be missing") {
  LiveSkeletonParams params;
  params.check_bone_lengths = false;
  params.low_pass.min_cutoff_hz = 0.0;  // the held value is the last measurement itself
  params.max_gap_s = 0.1;
  params.human_scale_m = 0.6;
  LiveSkeletonState state;
  resetLiveSkeleton(params, 30.0, state);
  for (int k = 0; k < 12; ++k) {
    SkeletonFrame f;
    f.t_s = k / 30.0;
    f.p_W.fill(Eigen::Vector3d::Zero());
    f.ok.fill(false);
    const bool seen = k < 3;  // the wrist is seen in frames 0..2, then never
    f.ok[kRWrist] = seen;
    f.p_W[kRWrist] = Eigen::Vector3d(0.1 * k, 0.0, 1.0);
    advanceLiveSkeleton(params, state, f);
    const bool bridged = !seen && f.t_s - 2.0 / 30.0 <= 0.1 + 1e-9;
    CHECK_MESSAGE(f.ok[kRWrist] == (seen || bridged), "frame " << k);
    CHECK(f.interpolated[kRWrist] == bridged);
    if (bridged) CHECK(f.p_W[kRWrist].x() == doctest::Approx(0.2));
  }
}

TEST_CASE("the live defaults (bone fit, One Euro low-pass) cut the plain live elbow error on a noisy 4-camera recording, causally") {
  // Stress recordings with a detector whose confidence says how far off it is (addDetectorNoise,
  // as in bench/triangulation_accuracy.cpp), fed frame by frame through the live path.
  std::vector<double> plain_deg, default_deg;
  int plain_out = 0, default_out = 0, n_forearm = 0;
  for (int m = 0; m < 3; ++m) {
    const tools::SynthDemo demo = tools::generateDemo(static_cast<Movement>(m), 1, 4242, false);
    tools::StressOptions so;
    so.seed = 31 + static_cast<std::uint64_t>(m);
    so.n_frames = 360;
    tools::StressScene scene = tools::renderStressScene(demo, so);
    tools::addDetectorNoise(scene, 91 + static_cast<std::uint64_t>(m));
    LiveSkeletonParams plain;
    plain.bone_fit_px_per_m = 0.0;
    plain.low_pass.min_cutoff_hz = 0.0;
    const LiveSkeletonParams defaults;
    for (const LiveSkeletonParams* params : {static_cast<const LiveSkeletonParams*>(&plain), &defaults}) {
      TriangulationState triangulation;
      LiveSkeletonState state;
      resetLiveSkeleton(*params, scene.fps, state);
      HumanArmData est, truth;
      for (std::size_t k = 0; k < scene.truth.size(); ++k) {
        std::vector<const std::vector<Person2d>*> people;
        for (const tools::CameraKeypoints& cam : scene.keypoints) people.push_back(&cam.frames[k].people);
        SkeletonFrame f;
        const FrameTriangulation done =
            triangulateFrame(scene.cameras, people, static_cast<double>(k) / scene.fps, TriangulationParams{}, triangulation, f);
        const FrameObservations obs{&scene.cameras, &people, &done.subject.person};
        advanceLiveSkeleton(*params, state, f, done.subject.found ? &obs : nullptr);
        humanArmKinematics(HumanKinematicsConfig{}, est, f);
        humanArmKinematics(HumanKinematicsConfig{}, truth, scene.truth[k]);
        if (est.valid && truth.valid)
          (params == &plain ? plain_deg : default_deg)
              .push_back(std::abs(est.q[kHumanElbowRoll] - truth.q[kHumanElbowRoll]) * 180.0 / 3.14159265358979323846);
        if (f.ok[kRElbow] && f.ok[kRWrist]) {
          const double l = (f.p_W[kRWrist] - f.p_W[kRElbow]).norm();
          (params == &plain ? plain_out : default_out) += (l < 0.20 || l > 0.32) ? 1 : 0;
          n_forearm += params == &plain ? 1 : 0;
        }
      }
    }
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  MESSAGE("live elbow flexion error median " << median(plain_deg) << " -> " << median(default_deg)
                                             << " deg; forearms outside 0.20-0.32 m " << plain_out << " -> " << default_out
                                             << " of " << n_forearm);
  CHECK(default_deg.size() == plain_deg.size());  // no frame lost
  CHECK(median(default_deg) < 0.7 * median(plain_deg));
  CHECK(plain_out > n_forearm / 50);  // the noise really throws forearms out of the band
  CHECK(default_out < plain_out / 3);
}
