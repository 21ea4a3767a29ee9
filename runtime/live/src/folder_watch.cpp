#include "nao/folder_watch.hpp"

#include <sys/inotify.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>

namespace nao {
namespace {

namespace fs = std::filesystem;

// A folder's own watch: its files being written, and the folder itself going away.
constexpr std::uint32_t kFolderMask =
    IN_CREATE | IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO | IN_DELETE_SELF | IN_MOVE_SELF | IN_ONLYDIR | IN_MASK_ADD;
// An ancestor's watch (the parent of a present folder, or the deepest existing ancestor of an
// absent one): folders appearing in it, and it going away. IN_MASK_ADD: one directory may be a
// watched folder and another folder's ancestor at once, and the masks must add up.
constexpr std::uint32_t kAncestorMask = IN_CREATE | IN_MOVED_TO | IN_DELETE_SELF | IN_MOVE_SELF | IN_ONLYDIR | IN_MASK_ADD;

// The first path component of `path` below `ancestor` (`path` lies inside `ancestor`).
fs::path childBelow(const fs::path& ancestor, const fs::path& path) {
  fs::path child = ancestor;
  auto a = ancestor.begin();
  auto p = path.begin();
  for (; a != ancestor.end() && p != path.end() && *a == *p; ++a, ++p) {
  }
  if (p != path.end()) child /= *p;
  return child;
}

}  // namespace

FolderWatch::FolderWatch(const std::vector<std::string>& folders) : buffer_(64 * 1024) {
  fd_ = inotify_init1(IN_NONBLOCK | IN_CLOEXEC);
  if (fd_ < 0) throw std::runtime_error(std::string("cannot watch camera folders: inotify_init1: ") + std::strerror(errno));
  for (const std::string& f : folders) {
    std::error_code ec;
    fs::path p = fs::absolute(fs::path(f), ec).lexically_normal();
    if (ec) p = fs::path(f).lexically_normal();
    std::string s = p.string();
    while (s.size() > 1 && s.back() == '/') s.pop_back();
    folders_.push_back({s, -1});
  }
  resolveAll(nullptr);
}

FolderWatch::~FolderWatch() {
  if (fd_ >= 0) close(fd_);
}

int FolderWatch::addWatch(const std::string& path, std::uint32_t mask) {
  const int wd = inotify_add_watch(fd_, path.c_str(), mask);
  if (wd >= 0) watched_.emplace(wd, path);
  return wd;
}

void FolderWatch::resolve(std::size_t i, std::vector<FolderEvent>* out) {
  Folder& folder = folders_[i];
  const fs::path path(folder.path);
  // A folder (or an ancestor) created between the failed watch and the ancestor's watch raises
  // no event: look again after each ancestor watch, a bounded number of times.
  for (int attempt = 0; attempt < 64; ++attempt) {
    const int wd = addWatch(folder.path, kFolderMask);
    if (wd >= 0) {
      folder.wd = wd;
      // The parent too, so that the folder is seen coming back after it was removed.
      if (path.has_parent_path() && path.parent_path() != path) addWatch(path.parent_path().string(), kAncestorMask);
      if (out != nullptr) out->push_back({FolderEvent::Kind::kAppeared, static_cast<int>(i), {}, false});
      return;
    }
    fs::path ancestor = path.parent_path();
    while (ancestor.has_parent_path() && ancestor.parent_path() != ancestor && addWatch(ancestor.string(), kAncestorMask) < 0)
      ancestor = ancestor.parent_path();
    std::error_code ec;
    if (!fs::exists(childBelow(ancestor, path), ec)) return;
  }
}

void FolderWatch::resolveAll(std::vector<FolderEvent>* out) {
  for (std::size_t i = 0; i < folders_.size(); ++i) {
    Folder& folder = folders_[i];
    if (folder.wd >= 0) {
      // Still the watched directory at its path? (An ancestor moved away takes the folder with
      // it, and the watch would follow the folder to its new place.)
      struct stat at_path {};
      const bool exists = stat(folder.path.c_str(), &at_path) == 0 && S_ISDIR(at_path.st_mode);
      const int wd_now = exists ? inotify_add_watch(fd_, folder.path.c_str(), kFolderMask) : -1;
      if (wd_now == folder.wd) continue;
      inotify_rm_watch(fd_, folder.wd);
      watched_.erase(folder.wd);
      folder.wd = -1;
      if (out != nullptr) out->push_back({FolderEvent::Kind::kGone, static_cast<int>(i), {}, false});
      if (wd_now >= 0) inotify_rm_watch(fd_, wd_now);  // resolve() adds it again, as a new appearance
    }
    resolve(i, out);
  }
}

void FolderWatch::readEvents(std::vector<FolderEvent>& out) {
  bool structural = false;
  for (;;) {
    const ssize_t n = read(fd_, buffer_.data(), buffer_.size());
    if (n <= 0) break;  // EAGAIN: nothing more (a read error is treated alike)
    for (ssize_t offset = 0; offset < n;) {
      inotify_event ev;
      std::memcpy(&ev, buffer_.data() + offset, sizeof ev);
      const char* name = buffer_.data() + offset + sizeof(inotify_event);
      offset += static_cast<ssize_t>(sizeof(inotify_event) + ev.len);
      if (ev.mask & IN_Q_OVERFLOW) {
        out.push_back({FolderEvent::Kind::kOverflow, -1, {}, false});
        structural = true;
        continue;
      }
      const bool is_dir = (ev.mask & IN_ISDIR) != 0;
      if (!is_dir && ev.len > 0 && (ev.mask & (IN_CREATE | IN_MODIFY | IN_CLOSE_WRITE | IN_MOVED_TO)))
        for (std::size_t i = 0; i < folders_.size(); ++i)
          if (folders_[i].wd == ev.wd)
            out.push_back({FolderEvent::Kind::kFile, static_cast<int>(i), std::string(name),
                           (ev.mask & (IN_CLOSE_WRITE | IN_MOVED_TO)) != 0});
      if (is_dir && (ev.mask & (IN_CREATE | IN_MOVED_TO))) structural = true;
      if (ev.mask & (IN_DELETE_SELF | IN_MOVE_SELF | IN_IGNORED)) {
        // The watched directory went away (a moved one is unwatched here: its watch would follow it).
        if (ev.mask & IN_MOVE_SELF) inotify_rm_watch(fd_, ev.wd);
        watched_.erase(ev.wd);
        for (std::size_t i = 0; i < folders_.size(); ++i)
          if (folders_[i].wd == ev.wd) {
            folders_[i].wd = -1;
            out.push_back({FolderEvent::Kind::kGone, static_cast<int>(i), {}, false});
          }
        structural = true;
      }
    }
  }
  if (structural) resolveAll(&out);
}

FolderScan::FolderScan(const std::string& path) : dir_(opendir(path.c_str())) {}

FolderScan::~FolderScan() {
  if (dir_ != nullptr) closedir(dir_);
}

bool FolderScan::next(std::string_view& name) {
  if (dir_ == nullptr) return false;
  while (const dirent* e = readdir(dir_)) {  // nullptr: the end, or a read error (treated alike)
    bool regular = e->d_type == DT_REG;
    if (e->d_type == DT_UNKNOWN || e->d_type == DT_LNK) {
      // The file system does not say, or a link: what it names (a link to a file counts).
      struct stat st {};
      regular = fstatat(dirfd(dir_), e->d_name, &st, 0) == 0 && S_ISREG(st.st_mode);
    }
    if (!regular) continue;
    name = e->d_name;
    return true;
  }
  return false;
}

}  // namespace nao
