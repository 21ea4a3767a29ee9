// Watches folders for files being written, with Linux inotify: the live camera source's view
// of OpenPose's --write_json folders. A folder, and any of its ancestors, need not exist: the
// deepest existing ancestor is watched until the folder appears; a folder may disappear
// (deleted or moved away) and come back, and the watch follows. Not real-time code (reader
// thread only): it allocates and makes system calls.
#pragma once

#include <dirent.h>

#include <cstdint>
#include <string>
#include <string_view>
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

/// The regular files of a folder, read one name at a time (readdir): nothing is kept but the
/// current name, so scanning a folder of an hour's frames (~106,000 files at 30 fps) costs the
/// memory a folder of one frame does. Empty when the folder cannot be opened.
class FolderScan {
 public:
  explicit FolderScan(const std::string& path);
  FolderScan(const FolderScan&) = delete;
  FolderScan& operator=(const FolderScan&) = delete;
  ~FolderScan();
  /// The next regular file's name (valid until the next call or the scan's end); false at the end.
  bool next(std::string_view& name);

 private:
  DIR* dir_ = nullptr;
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
  /// The regular files in folder `i` now, one at a time (none when it does not exist). A scan
  /// holds no list of names: what it costs does not grow with the number of files.
  FolderScan scanFiles(int i) const { return FolderScan(path(i)); }

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
