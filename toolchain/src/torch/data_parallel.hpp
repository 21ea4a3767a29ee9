// Data-parallel training over libtorch's c10d process groups, Gloo backend
// (docs/training.md). Every rank holds the whole model; gradients and validation sums are
// summed by Gloo all-reduce. No home-made exchange: this file only wires c10d's stores and
// ProcessGroupGloo to the training loop. Offline only (libtorch).
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace nao::tools {

/// Where and how a rank joins the group.
struct DistOptions {
  int world_size = 1;      ///< ranks in the group; 1 trains in this process, no group
  int rank = 0;            ///< 0 .. world_size-1; rank 0 writes model, card and checkpoints
  std::string rendezvous;  ///< tcp://HOST:PORT (rank 0 serves the store) or file://PATH (shared file)
  std::string interface;   ///< network interface Gloo binds to; empty: loopback for file:// and
                           ///< tcp://127.0.0.1|localhost, else the address the host name resolves to
  double timeout_s = 300;  ///< rendezvous and every collective: a dead or stuck rank ends the others
};

/// Half-open range [begin, end) of the positions of a global batch of `n` items that `rank`
/// takes: contiguous, sizes differ by at most one, disjoint across ranks and together 0..n-1.
std::pair<std::int64_t, std::int64_t> shardRange(std::int64_t n, int world_size, int rank);

/// One rank's membership of a Gloo process group. Construction rendezvouses with the other
/// ranks; every member function is a collective every rank must call in the same order.
/// Errors (bad rendezvous address, timeout, a peer that died) throw UserError naming the rank
/// and the rendezvous.
class ProcessGroup {
 public:
  /// Joins the group described by `options` (world_size >= 2, rendezvous set).
  explicit ProcessGroup(const DistOptions& options);
  ~ProcessGroup();
  ProcessGroup(const ProcessGroup&) = delete;
  ProcessGroup& operator=(const ProcessGroup&) = delete;

  int rank() const { return rank_; }
  int worldSize() const { return world_size_; }

  /// Sums the contiguous tensor `t` over all ranks in place (Gloo all-reduce, SUM); every
  /// rank receives the same bytes. `what` names the exchange in error messages.
  void sum(torch::Tensor& t, const char* what);

  /// Copies `root`'s contiguous tensor `t` into every rank's `t` (Gloo broadcast): the same
  /// bytes everywhere. Every rank passes a tensor of the same size and type.
  void broadcast(torch::Tensor& t, int root, const char* what);

  /// Sums the gradients of `params` over all ranks in place: they are copied into one flat
  /// float bucket in the order given (the manifest order), all-reduced, copied back.
  /// Undefined gradients count as zeros.
  void sumGradients(const std::vector<torch::Tensor>& params);

  /// Throws UserError naming `what` unless every rank passes the same `value` (MIN and MAX
  /// all-reduces): ranks that disagree on options, data or weights must not go on.
  void checkSame(std::uint64_t value, const char* what);

  /// checkSame of a hash of the bytes of `params`: the ranks must stay in lock step.
  void checkInSync(const std::vector<torch::Tensor>& params);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  int rank_ = 0, world_size_ = 1;
  std::string where_;  ///< "rank R of W at URL" for messages
};

}  // namespace nao::tools
