// Watches folders for files being written, with Linux inotify: the live camera source's view
// of OpenPose's --write_json folders. A folder, and any of its ancestors, need not exist: the
// deepest existing ancestor is watched until the folder appears; a folder may disappear
// (deleted or moved away) and come back, and the watch follows. Not real-time code (reader
// thread only): it allocates and makes system calls.
#pragma once

#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

namespace nao {

/// One thing that happened to a watched folder.
struct FolderEvent {
  enum class Kind {
    kFile,      ///< a file in the folder was created or written (`name`; `complete` when closed or moved in)
    kAppeared,  ///< the folder exists now (it did not, or it was gone); its files may predate the watch
    kGone,      ///< the folder was deleted or moved away
    kOverflow,  ///< the kernel dropped events: files of every present folder may have been missed
  };
  Kind kind = Kind::kFile;
  int folder = -1;        ///< index into the watched folders (-1 for kOverflow)
  std::string name;       ///< file name (kFile)
  bool complete = false;  ///< kFile: the writer closed the file (or it was renamed into place)
};

class FolderWatch {
 public:
  /// Starts watching `folders` (made absolute and lexically normal). Throws std::runtime_error
  /// when inotify is not available.
  explicit FolderWatch(const std::vector<std::string>& folders);
  FolderWatch(const FolderWatch&) = delete;
  FolderWatch& operator=(const FolderWatch&) = delete;
  ~FolderWatch();

  /// The inotify descriptor, to poll() for readability.
  int fd() const { return fd_; }
  /// Appends what happened since the last call (non-blocking; nothing when nothing happened).
  void readEvents(std::vector<FolderEvent>& out);
  /// Whether folder `i` exists and is watched now.
  bool present(int i) const { return folders_[static_cast<std::size_t>(i)].wd >= 0; }
  /// The folder's path as watched.
  const std::string& path(int i) const { return folders_[static_cast<std::size_t>(i)].path; }
  /// Names of the regular files in folder `i` now (empty when it does not exist).
  std::vector<std::string> listFiles(int i) const;

 private:
  struct Folder {
    std::string path;
    int wd = -1;  // the folder's own watch, -1 while it does not exist
  };
  void resolve(std::size_t i, std::vector<FolderEvent>* out);
  void resolveAll(std::vector<FolderEvent>* out);
  int addWatch(const std::string& path, std::uint32_t mask);

  int fd_ = -1;
  std::vector<Folder> folders_;
  std::unordered_map<int, std::string> watched_;  // every watch descriptor -> its path
  std::vector<char> buffer_;
};

}  // namespace nao
