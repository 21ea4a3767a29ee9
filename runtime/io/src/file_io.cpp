#include "nao/file_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

namespace nao {

std::string writeFileAtomically(const std::string& path, const void* data, std::size_t size) {
  const std::filesystem::path target(path);
  const std::filesystem::path dir = target.has_parent_path() ? target.parent_path() : std::filesystem::path(".");
  std::string tmp = (dir / ("." + target.filename().string() + ".tmp-XXXXXX")).string();
  const auto reason = [](int err) { return std::string(" (") + std::strerror(err) + ")"; };
  const int fd = ::mkstemp(tmp.data());
  if (fd < 0) return "cannot create a temporary file in " + dir.string() + reason(errno);
  const auto abandon = [&](const std::string& what) {
    const int err = errno;
    ::close(fd);
    ::unlink(tmp.c_str());
    return what + reason(err);
  };
  const auto* bytes = static_cast<const unsigned char*>(data);
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return abandon("cannot write " + tmp);
    done += static_cast<std::size_t>(n);
  }
  // mkstemp creates 0600; these files are ordinary shared artefacts.
  if (::fchmod(fd, 0644) != 0) return abandon("cannot set the permissions of " + tmp);
  if (::fsync(fd) != 0) return abandon("cannot flush " + tmp);
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return "cannot close " + tmp + reason(err);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return "cannot rename the temporary file into place" + reason(err);
  }
  return {};
}

}  // namespace nao
