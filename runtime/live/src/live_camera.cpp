#include "nao/live_camera.hpp"

#include "nao/folder_watch.hpp"
#include "nao/input_error.hpp"

#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>
#include <stdexcept>
#include <thread>
#include <utility>

namespace nao {
namespace {

std::int64_t monotonicNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1000000000LL + ts.tv_nsec;
}

std::int64_t nanoseconds(double seconds) { return static_cast<std::int64_t>(std::llround(seconds * 1e9)); }

// Reads a whole file into `text` (reused buffer). False if it cannot be opened or read.
bool readWholeFile(const std::string& path, std::string& text) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  text.clear();
  char chunk[16384];
  bool ok = true;
  for (;;) {
    const ssize_t n = read(fd, chunk, sizeof chunk);
    if (n == 0) break;
    if (n < 0) {
      if (errno == EINTR) continue;
      ok = false;
      break;
    }
    text.append(chunk, static_cast<std::size_t>(n));
    if (text.size() > (std::size_t{64} << 20)) break;  // the parser refuses it with a message
  }
  close(fd);
  return ok;
}

}  // namespace

struct LiveCamera::AtomicCounters {
  std::atomic<std::uint64_t> files_parsed{0}, files_malformed{0}, files_late{0}, frames_complete{0},
      frames_incomplete{0}, frames_skipped{0}, frames_no_person{0}, points_bridged{0}, folder_gone{0}, folder_back{0},
      camera_stopped{0}, camera_resumed{0}, capture_restarts{0}, watch_overflows{0}, takes{0}, takes_fresh{0},
      takes_no_human{0}, reader_errors{0};
};

namespace {

// The counter the reader (or control) thread is the only writer of: a relaxed load and store
// (no locked read-modify-write needed).
void bump(std::atomic<std::uint64_t>& c, std::uint64_t by = 1) {
  c.store(c.load(std::memory_order_relaxed) + by, std::memory_order_relaxed);
}

}  // namespace

// The reader thread and everything only it touches.
struct LiveCamera::Reader {
  enum class CameraState { kWaiting, kLive, kStopped };

  struct PendingFile {
    std::string path;
    std::int64_t first_seen_ns = 0;
    std::int64_t next_try_ns = 0;
  };
  struct FrameSlot {
    std::vector<std::vector<Person2d>> people;
    std::vector<char> have;
    std::int64_t newest_arrival_ns = 0;
  };

  LiveCamera& owner;
  const LiveCameraConfig& cfg;
  AtomicCounters& counts;
  const std::size_t n_cam;
  FolderWatch watch;
  int stop_fd = -1;

  std::map<std::pair<int, long long>, PendingFile> pending;
  std::vector<std::set<long long>> parsed;  // per camera: indices parsed and not yet forgotten
  std::map<long long, FrameSlot> frames;
  bool any_processed = false;
  long long last_processed = 0, first_index = 0;
  std::vector<CameraState> state;
  std::vector<char> ever_present;
  std::vector<std::int64_t> last_parse_ns;
  std::int64_t newest_parse_ns = 0;
  TriangulationState triangulation;
  LiveSkeletonState skeleton;
  const std::vector<Person2d> nobody;
  std::string text;
  std::vector<FolderEvent> events;
  std::vector<long long> scan_newest;  // scanFolder: the newest indices of the folder (a min-heap)
  SkeletonFrame frame;
  LiveSkeleton record;
  std::thread thread;

  Reader(LiveCamera& camera, AtomicCounters& c)
      : owner(camera), cfg(camera.config_), counts(c), n_cam(cfg.dirs.size()), watch(cfg.dirs), parsed(n_cam),
        state(n_cam, CameraState::kWaiting), ever_present(n_cam, 0), last_parse_ns(n_cam, 0) {
    for (std::size_t i = 0; i < n_cam; ++i) ever_present[i] = watch.present(static_cast<int>(i)) ? 1 : 0;
    scan_newest.reserve(maxFrames());
    resetLiveSkeleton(cfg.skeleton, cfg.fps, skeleton);
    stop_fd = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (stop_fd < 0) throw std::runtime_error(std::string("live camera: eventfd: ") + std::strerror(errno));
    thread = std::thread([this] { run(); });
  }

  ~Reader() {
    const std::uint64_t one = 1;
    if (write(stop_fd, &one, sizeof one) < 0) {
      // Cannot happen for an eventfd below its maximum; the join below would then hang, so say so.
      std::fprintf(stderr, "live camera: cannot signal the reader thread to stop: %s\n", std::strerror(errno));
    }
    if (thread.joinable()) thread.join();
    close(stop_fd);
  }

  void run() {
    if (cfg.on_reader_start) cfg.on_reader_start();
    pollfd fds[2] = {{watch.fd(), POLLIN, 0}, {stop_fd, POLLIN, 0}};
    for (;;) {
      const int timeout_ms = pollTimeoutMs(monotonicNs());
      const int n = poll(fds, 2, timeout_ms);
      if (n < 0 && errno != EINTR) bump(counts.reader_errors);
      if (fds[1].revents & POLLIN) break;
      try {
        step(monotonicNs());
      } catch (const std::exception&) {
        // Nothing here may stop the source (bad_alloc, a filesystem error): count and go on.
        bump(counts.reader_errors);
      }
    }
  }

  int pollTimeoutMs(std::int64_t now) const {
    std::int64_t due = now + 50000000;  // liveness is checked at least every 50 ms
    for (const auto& [key, file] : pending) due = std::min(due, file.next_try_ns);
    const std::int64_t wait = due - now;
    return wait <= 0 ? 0 : static_cast<int>((wait + 999999) / 1000000);
  }

  void step(std::int64_t now) {
    events.clear();
    watch.readEvents(events);
    for (const FolderEvent& ev : events) handle(ev, now);
    retryDue(now);
    updateLiveness(now);
    processComplete(now);
  }

  void handle(const FolderEvent& ev, std::int64_t now) {
    switch (ev.kind) {
      case FolderEvent::Kind::kFile:
        onFile(ev.folder, ev.name, ev.complete, false, now);
        break;
      case FolderEvent::Kind::kAppeared:
        if (ever_present[static_cast<std::size_t>(ev.folder)]) bump(counts.folder_back);
        ever_present[static_cast<std::size_t>(ev.folder)] = 1;
        // Files written before the watch was in place (the folder was made with them in it).
        scanFolder(ev.folder, now);
        break;
      case FolderEvent::Kind::kGone:
        bump(counts.folder_gone);
        state[static_cast<std::size_t>(ev.folder)] = CameraState::kWaiting;
        for (auto it = pending.begin(); it != pending.end();)
          it = it->first.first == ev.folder ? pending.erase(it) : std::next(it);
        break;
      case FolderEvent::Kind::kOverflow:
        bump(counts.watch_overflows);
        for (std::size_t c = 0; c < n_cam; ++c)
          if (watch.present(static_cast<int>(c))) scanFolder(static_cast<int>(c), now);
        break;
    }
  }

  // Frames kept waiting at most: beyond them the oldest are skipped (processComplete).
  std::size_t maxFrames() const { return static_cast<std::size_t>(std::ceil(4.0 * cfg.fps)) + 64; }

  // Every file in folder `c` now that onFile would take, as if just closed; of them only the
  // newest maxFrames() indices, as the older ones would be skipped unprocessed anyway (frames
  // are kept to maxFrames(), oldest dropped first). Two passes of one name at a time, nothing
  // kept but those indices: a folder that comes back holding an hour's frames costs what one
  // holding a second's does, whether its frames are older than the last processed one (each is
  // looked at and let go) or not (only the newest are read).
  void scanFolder(int c, std::int64_t now) {
    const auto cam = static_cast<std::size_t>(c);
    const std::size_t keep = maxFrames();
    const auto newer = std::greater<long long>();  // a min-heap: front() is the oldest kept
    std::string_view name;
    scan_newest.clear();
    for (FolderScan scan = watch.scanFiles(c); scan.next(name);) {
      const std::optional<long long> index = openPoseFrameIndex(name);
      if (!index || parsed[cam].count(*index) || (any_processed && *index <= last_processed)) continue;
      if (scan_newest.size() == keep && *index <= scan_newest.front()) continue;
      if (std::find(scan_newest.begin(), scan_newest.end(), *index) != scan_newest.end()) continue;
      if (scan_newest.size() == keep) {
        std::pop_heap(scan_newest.begin(), scan_newest.end(), newer);
        scan_newest.pop_back();
      }
      scan_newest.push_back(*index);
      std::push_heap(scan_newest.begin(), scan_newest.end(), newer);
    }
    if (scan_newest.empty()) return;
    const long long oldest = scan_newest.size() == keep ? scan_newest.front() : LLONG_MIN;
    for (FolderScan scan = watch.scanFiles(c); scan.next(name);) {
      const std::optional<long long> index = openPoseFrameIndex(name);
      if (index && *index >= oldest) onFile(c, name, true, true, now);
    }
  }

  void restart() {
    bump(counts.capture_restarts);
    frames.clear();
    pending.clear();
    for (std::set<long long>& p : parsed) p.clear();
    any_processed = false;
    resetTriangulationState(triangulation);
    resetLiveSkeleton(cfg.skeleton, cfg.fps, skeleton);
  }

  // A frame file was created or written (or found by a scan).
  void onFile(int c, std::string_view name, bool complete, bool from_scan, std::int64_t now) {
    const std::optional<long long> index = openPoseFrameIndex(name);
    if (!index) return;
    const auto cam = static_cast<std::size_t>(c);
    if (parsed[cam].count(*index)) return;  // written again after it parsed: the first complete text counts
    // Indices far below the last processed one: the capture started over.
    const auto restart_margin = static_cast<long long>(std::ceil(2.0 * cfg.fps)) + 1;
    if (any_processed && *index < last_processed - restart_margin) {
      if (from_scan) return;
      restart();
    }
    if (from_scan && any_processed && *index <= last_processed) return;
    auto [it, inserted] = pending.try_emplace({c, *index});
    PendingFile& file = it->second;
    if (inserted) {
      file.path = watch.path(c);
      file.path += '/';
      file.path += name;
      file.first_seen_ns = now;
      file.next_try_ns = now + nanoseconds(cfg.retry_s);
    }
    if (complete) tryParse(it, now);
  }

  void retryDue(std::int64_t now) {
    for (auto it = pending.begin(); it != pending.end();) {
      auto next = std::next(it);
      if (it->second.next_try_ns <= now) tryParse(it, now);
      it = next;
    }
  }

  void tryParse(std::map<std::pair<int, long long>, PendingFile>::iterator it, std::int64_t now) {
    const auto [c, index] = it->first;
    PendingFile& file = it->second;
    std::vector<Person2d> people;
    bool ok = false;
    if (readWholeFile(file.path, text)) {
      try {
        people = parseOpenPoseFrame(text, cfg.skeleton.format, file.path);
        ok = true;
      } catch (const InputError&) {
        // Half written (or bad): tried again until file_wait_s after it appeared.
      }
    }
    if (!ok) {
      if (now - file.first_seen_ns >= nanoseconds(cfg.file_wait_s)) {
        bump(counts.files_malformed);
        pending.erase(it);
      } else {
        file.next_try_ns = now + nanoseconds(cfg.retry_s);
      }
      return;
    }
    const auto cam = static_cast<std::size_t>(c);
    bump(counts.files_parsed);
    parsed[cam].insert(index);
    const std::int64_t arrival = file.first_seen_ns;
    pending.erase(it);
    last_parse_ns[cam] = now;
    newest_parse_ns = std::max(newest_parse_ns, now);
    if (state[cam] == CameraState::kStopped) bump(counts.camera_resumed);
    state[cam] = CameraState::kLive;
    if (any_processed && index <= last_processed) {
      bump(counts.files_late);
      return;
    }
    FrameSlot& slot = frames[index];
    if (slot.people.empty()) slot.people.resize(n_cam), slot.have.assign(n_cam, 0);
    slot.people[cam] = std::move(people);
    slot.have[cam] = 1;
    slot.newest_arrival_ns = std::max(slot.newest_arrival_ns, arrival);
  }

  // A live camera that parsed nothing for camera_stopped_s while another did has stopped.
  void updateLiveness(std::int64_t now) {
    (void)now;
    for (std::size_t c = 0; c < n_cam; ++c)
      if (state[c] == CameraState::kLive && newest_parse_ns - last_parse_ns[c] > nanoseconds(cfg.camera_stopped_s)) {
        state[c] = CameraState::kStopped;
        bump(counts.camera_stopped);
      }
  }

  bool completeFor(const FrameSlot& slot, std::size_t* n_live) const {
    std::size_t live = 0;
    bool all = true;
    for (std::size_t c = 0; c < n_cam; ++c)
      if (state[c] == CameraState::kLive) {
        ++live;
        all = all && slot.have[c];
      }
    if (n_live != nullptr) *n_live = live;
    return live > 0 && all;
  }

  void processComplete(std::int64_t now) {
    // Frames no live camera completes (every camera waiting or gone) are not kept without bound.
    const std::size_t max_frames = maxFrames();
    while (frames.size() > max_frames) {
      bump(counts.frames_skipped);
      frames.erase(frames.begin());
    }
    // The newest complete index: it and every older pending index are processed, in order.
    auto newest = frames.end();
    for (auto it = frames.begin(); it != frames.end(); ++it)
      if (completeFor(it->second, nullptr)) newest = it;
    // Every camera quiet for camera_stopped_s and no file left to parse: nothing will complete
    // the waiting frames (the capture paused or ended on a lost file), so they go with what they have.
    if (newest == frames.end() && !frames.empty() && pending.empty() &&
        now - newest_parse_ns >= nanoseconds(cfg.camera_stopped_s))
      newest = std::prev(frames.end());
    if (newest == frames.end()) return;
    const auto last = std::next(newest);
    auto n_ready = static_cast<int>(std::distance(frames.begin(), last));
    // Behind by more than max_catch_up_frames: only the newest ones are processed.
    while (n_ready > std::max(cfg.max_catch_up_frames, 1)) {
      bump(counts.frames_skipped);
      frames.erase(frames.begin());
      --n_ready;
    }
    while (frames.begin() != last) {
      auto it = frames.begin();
      processFrame(it->first, it->second);
      frames.erase(it);
    }
    // Forget parse marks well behind the processed index (bounded memory).
    const auto keep = static_cast<long long>(std::ceil(4.0 * cfg.fps)) + 8;
    for (std::set<long long>& p : parsed)
      while (!p.empty() && *p.begin() < last_processed - keep) p.erase(p.begin());
  }

  void processFrame(long long index, const FrameSlot& slot) {
    if (!any_processed) first_index = index;
    any_processed = true;
    last_processed = index;
    std::vector<const std::vector<Person2d>*> people(n_cam);
    std::uint32_t n_with_file = 0;
    for (std::size_t c = 0; c < n_cam; ++c) {
      people[c] = slot.have[c] ? &slot.people[c] : &nobody;
      n_with_file += slot.have[c] ? 1u : 0u;
    }
    std::size_t n_live = 0;
    bump(completeFor(slot, &n_live) ? counts.frames_complete : counts.frames_incomplete);
    const double t_s = static_cast<double>(index - first_index) / cfg.fps;
    const FrameTriangulation done = triangulateFrame(cfg.cameras, people, t_s, cfg.triangulation, triangulation, frame);
    if (!done.subject.found) bump(counts.frames_no_person);
    const FrameObservations observations{&cfg.cameras, &people, &done.subject.person};
    const LiveSkeletonStep skeleton_step =
        advanceLiveSkeleton(cfg.skeleton, skeleton, frame, done.subject.found ? &observations : nullptr);
    bump(counts.points_bridged, static_cast<std::uint64_t>(skeleton_step.n_bridged));

    record.frame_index = index;
    record.arrival_ns = slot.newest_arrival_ns;
    record.t_s = t_s;
    record.human_scale_m = skeleton.human_scale_m;
    record.hand_length_m = skeleton.hand_length_m;
    record.current_scale_m = skeleton.current_scale_m;
    record.current_hand_m = skeleton.current_hand_m;
    record.n_cameras = n_with_file;
    record.subject = 0;
    for (int i = 0; i < kNumSkeletonPoints; ++i) {
      for (int k = 0; k < 3; ++k) record.p_W[i][k] = frame.p_W[i][k];
      record.ok[i] = static_cast<std::uint8_t>(!frame.ok[i] ? 0 : frame.interpolated[i] ? 2 : 1);
      record.views[i] = frame.views[i];
      if (frame.ok[i]) record.subject = 1;
    }
    record.published_ns = monotonicNs();
    publishNewest(owner.ring_, record);
    owner.human_scale_m_.store(skeleton.human_scale_m, std::memory_order_relaxed);
    if (cfg.on_skeleton) cfg.on_skeleton(record);
  }
};

LiveCamera::LiveCamera(LiveCameraConfig config) : config_(std::move(config)), counts_(std::make_unique<AtomicCounters>()) {
  const LiveCameraConfig& c = config_;
  if (c.cameras.size() < 2)
    throw InputError("live camera: triangulation needs at least 2 cameras, the calibration has " +
                     std::to_string(c.cameras.size()));
  if (c.cameras.size() > 32) throw InputError("live camera: at most 32 cameras");
  if (c.dirs.size() != c.cameras.size())
    throw InputError("live camera: the calibration has " + std::to_string(c.cameras.size()) + " cameras but " +
                     std::to_string(c.dirs.size()) + " folders were given (cameras pair with folders in order)");
  for (std::size_t a = 0; a < c.dirs.size(); ++a) {
    if (c.dirs[a].empty()) throw InputError("live camera: folder " + std::to_string(a) + " is an empty path");
    for (std::size_t b = a + 1; b < c.dirs.size(); ++b)
      if (c.dirs[a] == c.dirs[b]) throw InputError("live camera: folder " + c.dirs[a] + " is given for two cameras");
  }
  const auto positive = [](double v) { return v > 0.0 && std::isfinite(v); };
  if (!positive(c.fps)) throw InputError("live camera: the frame rate must be a positive number of frames per second");
  if (!positive(c.stale_s) || !positive(c.file_wait_s) || !positive(c.retry_s) || !positive(c.camera_stopped_s))
    throw InputError("live camera: stale_s, file_wait_s, retry_s and camera_stopped_s must be positive times");
  if (!(c.skeleton.max_gap_s >= 0.0) || !(c.skeleton.reference_window_s >= 0.0) || !(c.skeleton.human_scale_m >= 0.0))
    throw InputError("live camera: max_gap_s, reference_window_s and human_scale_m must not be negative");
  latency_ms_ = std::make_unique<float[]>(std::max<std::size_t>(c.latency_capacity, 1));
  scratch_ = std::make_unique<LiveSkeleton>();
  human_scale_m_.store(c.skeleton.human_scale_m > 0.0 ? c.skeleton.human_scale_m : 0.0);
  reader_ = std::make_unique<Reader>(*this, *counts_);
}

LiveCamera::~LiveCamera() { reader_.reset(); }

bool takeNewestFromRT(LiveCamera& camera, const timespec& now, SkeletonFrame& out, LiveSkeleton* record) noexcept {
  LiveCamera::AtomicCounters& counts = *camera.counts_;
  bump(counts.takes);
  LiveSkeleton& rec = *camera.scratch_;
  const std::uint64_t n = readNewest(camera.ring_, rec);
  const std::int64_t now_ns = static_cast<std::int64_t>(now.tv_sec) * 1000000000LL + now.tv_nsec;
  const bool fresh = n != 0 && now_ns - rec.arrival_ns <= nanoseconds(camera.config_.stale_s);
  if (!fresh || rec.subject == 0) {
    bump(counts.takes_no_human);
    return false;
  }
  if (n != camera.last_taken_) {
    camera.last_taken_ = n;
    bump(counts.takes_fresh);
    if (camera.n_latency_ < camera.config_.latency_capacity)
      camera.latency_ms_[camera.n_latency_++] = static_cast<float>(static_cast<double>(now_ns - rec.arrival_ns) * 1e-6);
  }
  out.t_s = rec.t_s;
  for (int i = 0; i < kNumSkeletonPoints; ++i) {
    out.p_W[i] = Eigen::Vector3d(rec.p_W[i][0], rec.p_W[i][1], rec.p_W[i][2]);
    out.ok[i] = rec.ok[i] != 0;
    out.interpolated[i] = rec.ok[i] == 2;
    out.views[i] = rec.views[i];
    out.reprojection_px[i] = 0.0f;
  }
  if (record != nullptr) *record = rec;
  return true;
}

LiveCameraCounters LiveCamera::counters() const {
  const AtomicCounters& a = *counts_;
  const auto get = [](const std::atomic<std::uint64_t>& v) { return v.load(std::memory_order_relaxed); };
  LiveCameraCounters c;
  c.files_parsed = get(a.files_parsed);
  c.files_malformed = get(a.files_malformed);
  c.files_late = get(a.files_late);
  c.frames_complete = get(a.frames_complete);
  c.frames_incomplete = get(a.frames_incomplete);
  c.frames_skipped = get(a.frames_skipped);
  c.frames_no_person = get(a.frames_no_person);
  c.points_bridged = get(a.points_bridged);
  c.folder_gone = get(a.folder_gone);
  c.folder_back = get(a.folder_back);
  c.camera_stopped = get(a.camera_stopped);
  c.camera_resumed = get(a.camera_resumed);
  c.capture_restarts = get(a.capture_restarts);
  c.watch_overflows = get(a.watch_overflows);
  c.takes = get(a.takes);
  c.takes_fresh = get(a.takes_fresh);
  c.takes_no_human = get(a.takes_no_human);
  c.reader_errors = get(a.reader_errors);
  return c;
}

LatencyStats LiveCamera::latencyStats() const {
  LatencyStats s;
  std::vector<float> v(latency_ms_.get(), latency_ms_.get() + n_latency_);
  s.n = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  // Nearest rank: the smallest sample with at least p % of the samples at or below it.
  const auto rank = [&](double p) {
    const auto k = static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(v.size())));
    return static_cast<double>(v[std::min(v.size(), std::max<std::size_t>(k, 1)) - 1]);
  };
  s.p50_ms = rank(50.0);
  s.p99_ms = rank(99.0);
  s.max_ms = static_cast<double>(v.back());
  return s;
}

nlohmann::json LiveCamera::summaryJson(std::optional<std::int64_t> reader_allocations) const {
  const LiveCameraCounters c = counters();
  const LatencyStats l = latencyStats();
  nlohmann::json j;
  j["files_parsed"] = c.files_parsed;
  j["files_malformed"] = c.files_malformed;
  j["files_late"] = c.files_late;
  j["frames_complete"] = c.frames_complete;
  j["frames_incomplete"] = c.frames_incomplete;
  j["frames_skipped"] = c.frames_skipped;
  j["frames_no_person"] = c.frames_no_person;
  j["points_bridged"] = c.points_bridged;
  j["folder_gone"] = c.folder_gone;
  j["folder_back"] = c.folder_back;
  j["camera_stopped"] = c.camera_stopped;
  j["camera_resumed"] = c.camera_resumed;
  j["capture_restarts"] = c.capture_restarts;
  j["watch_overflows"] = c.watch_overflows;
  j["reader_errors"] = c.reader_errors;
  j["takes"] = c.takes;
  j["takes_fresh"] = c.takes_fresh;
  j["takes_no_human"] = c.takes_no_human;
  j["latency_ms"] = {{"n", l.n}, {"p50", l.p50_ms}, {"p99", l.p99_ms}, {"max", l.max_ms}};
  j["human_scale_m"] = humanScale();
  j["reader_allocations"] = reader_allocations ? nlohmann::json(*reader_allocations) : nlohmann::json(nullptr);
  return j;
}

}  // namespace nao
