#include "nao/attention_shm.hpp"
#include "nao/file_io.hpp"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

// attention.bin stores the payload bytes as they are in memory, and docs/attention_bin.md
// promises little-endian: only true on a little-endian host.
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "attention.bin copies payloads as stored: little-endian host");

namespace nao {
namespace {

[[noreturn]] void fail(const std::string& origin, const std::string& what) {
  throw std::runtime_error(origin + ": " + what);
}

std::string errnoText(int err) { return std::string(" (") + std::strerror(err) + ")"; }

void putU32(unsigned char* p, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}
void putU64(unsigned char* p, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) p[i] = static_cast<unsigned char>(v >> (8 * i));
}

std::string ringOrigin(const std::string& shm_name) { return "attention ring " + shm_name; }

}  // namespace

std::string attentionShmName(const std::string& name) {
  if (name.empty() || name == "/") throw std::runtime_error("attention shared-memory name is empty");
  std::string out = name.front() == '/' ? name : "/" + name;
  if (out.find('/', 1) != std::string::npos)
    throw std::runtime_error("attention shared-memory name '" + name + "' holds a '/' after the leading one");
  if (out.size() > 255) throw std::runtime_error("attention shared-memory name '" + name + "' is longer than 255 characters");
  return out;
}

AttentionShm AttentionShm::create(const std::string& name, std::size_t bytes, bool try_mlock) {
  AttentionShm shm;
  shm.name_ = attentionShmName(name);
  const std::string origin = ringOrigin(shm.name_);
  if (bytes < sizeof(AttentionRingHeader)) fail(origin, "cannot create a region of " + std::to_string(bytes) + " bytes");
  // A region left by a run that crashed before unlinking: replace it, do not attach to it.
  if (::shm_unlink(shm.name_.c_str()) != 0 && errno != ENOENT)
    fail(origin, "cannot remove the stale region of that name" + errnoText(errno));
  const int fd = ::shm_open(shm.name_.c_str(), O_CREAT | O_EXCL | O_RDWR, 0644);
  if (fd < 0) fail(origin, "shm_open(O_CREAT | O_EXCL) failed" + errnoText(errno));
  auto abandon = [&](const std::string& what) {
    const int err = errno;
    ::close(fd);
    ::shm_unlink(shm.name_.c_str());
    fail(origin, what + errnoText(err));
  };
  if (::ftruncate(fd, static_cast<off_t>(bytes)) != 0) abandon("cannot size the region to " + std::to_string(bytes) + " bytes");
  void* data = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  if (data == MAP_FAILED) abandon("cannot map the region");
  ::close(fd);  // the mapping keeps the region
  shm.data_ = data;
  shm.size_ = bytes;
  shm.creator_ = true;
  // Keeps the writer's pages resident: a page fault in pushFromRT would be a deadline risk.
  // Not permitted (RLIMIT_MEMLOCK) is fine: the caller may warn via locked().
  shm.locked_ = try_mlock && ::mlock(data, bytes) == 0;
  return shm;
}

AttentionShm AttentionShm::openReadOnly(const std::string& name) {
  AttentionShm shm;
  shm.name_ = attentionShmName(name);
  const std::string origin = ringOrigin(shm.name_);
  const int fd = ::shm_open(shm.name_.c_str(), O_RDONLY, 0);
  if (fd < 0) {
    const int err = errno;
    if (err == ENOENT) fail(origin, "no shared-memory region of that name (no writer created it, or it has exited)");
    fail(origin, "cannot open the region" + errnoText(err));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int err = errno;
    ::close(fd);
    fail(origin, "cannot stat the region" + errnoText(err));
  }
  const auto bytes = static_cast<std::size_t>(st.st_size);
  if (bytes < sizeof(AttentionRingHeader)) {
    ::close(fd);
    validateAttentionRing(nullptr, bytes, origin);  // throws "smaller than a header"
  }
  // PROT_READ: a reader cannot store into the writer's memory, even by mistake.
  void* data = ::mmap(nullptr, bytes, PROT_READ, MAP_SHARED, fd, 0);
  const int map_err = errno;
  ::close(fd);
  if (data == MAP_FAILED) fail(origin, "cannot map the region read-only" + errnoText(map_err));
  shm.data_ = data;
  shm.size_ = bytes;
  validateAttentionRing(data, bytes, origin);  // on a throw, ~AttentionShm unmaps
  return shm;
}

AttentionShm::AttentionShm(AttentionShm&& other) noexcept
    : name_(std::move(other.name_)),
      data_(std::exchange(other.data_, nullptr)),
      size_(std::exchange(other.size_, 0)),
      creator_(std::exchange(other.creator_, false)),
      locked_(std::exchange(other.locked_, false)) {}

AttentionShm& AttentionShm::operator=(AttentionShm&& other) noexcept {
  if (this != &other) {
    release();
    name_ = std::move(other.name_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    creator_ = std::exchange(other.creator_, false);
    locked_ = std::exchange(other.locked_, false);
  }
  return *this;
}

AttentionShm::~AttentionShm() { release(); }

void AttentionShm::release() noexcept {
  if (data_ != nullptr) {
    if (locked_) ::munlock(data_, size_);
    ::munmap(data_, size_);
    // Readers keep their mappings (and the records in them) after the name is gone.
    if (creator_) ::shm_unlink(name_.c_str());
  }
  data_ = nullptr;
  size_ = 0;
  creator_ = false;
  locked_ = false;
}

AttentionRingView AttentionShm::view() const {
  const auto* h = std::launder(static_cast<const AttentionRingHeader*>(data_));
  return {h, static_cast<const unsigned char*>(data_) + h->header_bytes};
}

AttentionFileSummary writeAttentionFile(const std::string& path, const AttentionRingView& view) {
  const AttentionRingHeader& h = *view.header;
  const std::uint64_t n = recordsWritten(h);
  const std::size_t payload_bytes = static_cast<std::size_t>(h.payload_bytes);
  AttentionFileSummary summary;
  summary.records_written = n;
  summary.first_record = n > h.capacity ? n - h.capacity : 0;

  std::vector<unsigned char> bytes(kAttentionFileHeaderBytes + static_cast<std::size_t>(n - summary.first_record) * payload_bytes);
  for (std::uint64_t r = summary.first_record; r < n; ++r) {
    unsigned char* dst = bytes.data() + kAttentionFileHeaderBytes + static_cast<std::size_t>(summary.record_count) * payload_bytes;
    switch (readFromNonRT(view, r, dst)) {
      case AttentionRead::kOk: ++summary.record_count; break;
      // A writer still running replaced it: keep the file contiguous, start after it.
      case AttentionRead::kOverwritten:
        summary.first_record = r + 1;
        summary.record_count = 0;
        break;
      case AttentionRead::kTorn:
        fail(path, "record " + std::to_string(r) + " of the attention ring stayed half-written (writer stopped mid-push?)");
      case AttentionRead::kNotYetWritten:
        fail(path, "record " + std::to_string(r) + " vanished from the attention ring during the dump");
    }
  }
  bytes.resize(kAttentionFileHeaderBytes + static_cast<std::size_t>(summary.record_count) * payload_bytes);

  // Header (docs/attention_bin.md), little-endian byte by byte.
  unsigned char* p = bytes.data();
  std::memset(p, 0, kAttentionFileHeaderBytes);
  std::memcpy(p, kAttentionFileMagic, 8);
  putU32(p + 8, kAttentionFileVersion);
  putU32(p + 12, kAttentionFileHeaderBytes);
  putU64(p + 16, summary.record_count);
  putU64(p + 24, summary.first_record);
  putU64(p + 32, h.payload_bytes);
  putU64(p + 40, h.capacity);
  putU64(p + 48, summary.records_written);
  for (int i = 0; i < kAttentionDescriptorFields; ++i) putU32(p + 56 + 4 * i, h.descriptor[i]);
  // p + 88 .. 96: reserved, zero.

  const std::string problem = writeFileAtomically(path, bytes.data(), bytes.size());
  if (!problem.empty()) fail(path, problem);
  return summary;
}

}  // namespace nao
