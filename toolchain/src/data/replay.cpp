// Replay of a recording into live camera folders (nao/tools/replay.hpp).
#include "nao/tools/replay.hpp"

#include "nao/tools/command.hpp"
#include "nao/tools/openpose.hpp"
#include "nao/tools/triangulate.hpp"

#include <fcntl.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace nao::tools {
namespace {

namespace fs = std::filesystem;

std::string readText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw UserError("cannot read " + path.string());
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// Writes `text` the way OpenPose does: a plain open/write/close, in `chunks` writes so a reader
// may see the file half written. Throws UserError on failure.
void writePlain(const fs::path& path, const std::string& text, int chunks) {
  const int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw UserError("cannot write " + path.string() + ": " + std::strerror(errno));
  const std::size_t n = text.size();
  for (int k = 0; k < chunks; ++k) {
    const std::size_t from = n * static_cast<std::size_t>(k) / static_cast<std::size_t>(chunks);
    const std::size_t to = n * static_cast<std::size_t>(k + 1) / static_cast<std::size_t>(chunks);
    for (std::size_t done = from; done < to;) {
      const ssize_t w = write(fd, text.data() + done, to - done);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        close(fd);
        throw UserError("cannot write " + path.string() + ": " + std::strerror(errno));
      }
      done += static_cast<std::size_t>(w);
    }
    // A short pause between chunks: an encoder's buffered writes do not land at once either.
    if (k + 1 < chunks) usleep(500);
  }
  close(fd);
}

void sleepUntil(const timespec& deadline) {
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &deadline, nullptr) == EINTR) {
  }
}

timespec addSeconds(const timespec& t, double s) {
  const auto ns = static_cast<long long>(std::llround(s * 1e9)) + t.tv_nsec;
  timespec out{};
  out.tv_sec = t.tv_sec + static_cast<time_t>(ns / 1000000000LL);
  out.tv_nsec = static_cast<long>(ns % 1000000000LL);
  return out;
}

}  // namespace

ReplayFaults parseReplayFaults(const char* text, int n_cameras) {
  ReplayFaults f;
  if (text == nullptr || *text == '\0') return f;
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    const auto eq = item.find('=');
    const std::string key = item.substr(0, eq);
    const std::string value = eq == std::string::npos ? "" : item.substr(eq + 1);
    char* end = nullptr;
    const double v = std::strtod(value.c_str(), &end);
    const bool number = !value.empty() && end != nullptr && *end == '\0' && std::isfinite(v);
    const auto bad = [&](const std::string& why) {
      return UserError("NAO_REPLAY_FAULTS: '" + item + "': " + why +
                       " (keys: truncate_every, no_person_every, remove_folder_at, remove_for, stop_at, fault_camera)");
    };
    if (!number) throw bad("expected key=number");
    const bool whole = v == std::floor(v) && v >= 1.0 && v <= 1e9;
    if (key == "truncate_every" || key == "no_person_every") {
      if (!whole) throw bad("expected a whole number >= 1");
      (key == "truncate_every" ? f.truncate_every : f.no_person_every) = static_cast<long long>(v);
    } else if (key == "remove_folder_at" || key == "remove_for" || key == "stop_at") {
      if (!(v >= 0.0) || v > 1e6) throw bad("expected a time in seconds >= 0");
      (key == "remove_folder_at" ? f.remove_folder_at_s : key == "remove_for" ? f.remove_for_s : f.stop_at_s) = v;
    } else if (key == "fault_camera") {
      if (!(v == std::floor(v)) || v < 0.0 || v >= n_cameras) throw bad("expected a camera index below " + std::to_string(n_cameras));
      f.fault_camera = static_cast<int>(v);
    } else {
      throw bad("unknown key");
    }
  }
  return f;
}

ReplayReport replayRecording(const ReplayOptions& args) {
  const std::vector<std::string>& targets = args.targets;
  const std::vector<std::string> sources = demoCameraDirs(args.recording);
  if (targets.size() != sources.size())
    throw UserError("the replay names " + std::to_string(targets.size()) + " folders but " + args.recording + " has " +
                    std::to_string(sources.size()) + " camera folders (cam0/, cam1/, ...)");
  const ReplayFaults& faults = args.faults;
  if (faults.fault_camera < 0 || faults.fault_camera >= static_cast<int>(sources.size()))
    throw UserError("replay: the fault camera " + std::to_string(faults.fault_camera) + " is not one of the " +
                    std::to_string(sources.size()) + " cameras");
  if (!(args.fps > 0.0) || !(args.speed > 0.0) || args.chunks < 1)
    throw UserError("replay: fps and speed must be positive and chunks at least 1");

  // Every frame file of every camera, by index, read before the clock starts.
  struct FrameFile {
    std::string name;
    std::string text;
  };
  std::map<long long, std::vector<const FrameFile*>> by_index;
  std::vector<std::vector<FrameFile>> files(sources.size());
  for (std::size_t c = 0; c < sources.size(); ++c) {
    std::vector<std::pair<long long, fs::path>> found;
    for (const fs::directory_entry& e : fs::directory_iterator(sources[c]))
      if (e.is_regular_file())
        if (const auto index = openPoseFrameIndex(e.path().filename().string())) found.emplace_back(*index, e.path());
    if (found.empty()) throw UserError(sources[c] + ": no OpenPose frame files");
    std::sort(found.begin(), found.end());
    files[c].reserve(found.size());
    for (const auto& [index, path] : found) {
      files[c].push_back({path.filename().string(), readText(path)});
      std::vector<const FrameFile*>& slot = by_index[index];
      slot.resize(sources.size(), nullptr);
      slot[c] = &files[c].back();
    }
  }
  const long long first = by_index.begin()->first;
  const double rate = args.fps * args.speed;
  const std::string no_person = "{\"version\":1.3,\"people\":[]}\n";

  timespec start{};
  clock_gettime(CLOCK_MONOTONIC, &start);
  std::vector<bool> made(targets.size(), false);
  bool removed = false, restored = false;
  ReplayReport report;
  report.n_indices = static_cast<int>(by_index.size());
  for (const auto& [index, slot] : by_index) {
    const double t_s = static_cast<double>(index - first) / rate;
    sleepUntil(addSeconds(start, t_s));
    const auto fc = static_cast<std::size_t>(faults.fault_camera);
    if (faults.remove_folder_at_s >= 0.0 && !removed && t_s >= faults.remove_folder_at_s) {
      std::error_code ec;
      fs::remove_all(targets[fc], ec);
      made[fc] = false;
      removed = true;
    }
    const bool folder_away = removed && !restored && t_s < faults.remove_folder_at_s + faults.remove_for_s;
    if (removed && !folder_away) restored = true;
    for (std::size_t c = 0; c < targets.size(); ++c) {
      if (slot[c] == nullptr) continue;
      if (c == fc && (folder_away || (faults.stop_at_s >= 0.0 && t_s >= faults.stop_at_s))) {
        ++report.n_lost;
        continue;
      }
      if (!made[c]) {
        std::error_code ec;
        fs::create_directories(targets[c], ec);
        if (ec) throw UserError("cannot create " + targets[c] + ": " + ec.message());
        made[c] = true;
      }
      const long long k = index - first;
      std::string text = slot[c]->text;
      if (faults.no_person_every > 0 && k % faults.no_person_every == faults.no_person_every - 1) {
        text = no_person;
        ++report.n_no_person;
      }
      if (faults.truncate_every > 0 && k % faults.truncate_every == faults.truncate_every - 1 &&
          static_cast<long long>(c) == (k / faults.truncate_every) % static_cast<long long>(targets.size())) {
        text = text.substr(0, text.size() / 2);
        ++report.n_truncated;
      }
      writePlain(fs::path(targets[c]) / slot[c]->name, text, args.chunks);
      ++report.n_files;
    }
  }
  return report;
}

}  // namespace nao::tools
