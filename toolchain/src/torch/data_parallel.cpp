#include "data_parallel.hpp"

#include "nao/model_file.hpp"
#include "nao/tools/command.hpp"

#include <torch/csrc/distributed/c10d/FileStore.hpp>
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

#include <chrono>
#include <cstdio>
#include <cstring>

namespace nao::tools {

struct ProcessGroup::Impl {
  c10::intrusive_ptr<c10d::Store> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
  torch::Tensor bucket;  ///< flat float gradients, allocated on first use
};

namespace {

// c10::Error's what() carries a C++ backtrace; users need the sentence.
std::string message(const std::exception& e) {
  if (const auto* c = dynamic_cast<const c10::Error*>(&e)) return c->what_without_backtrace();
  return e.what();
}

bool isLoopback(const std::string& host) { return host == "127.0.0.1" || host == "localhost" || host == "::1"; }

}  // namespace

std::pair<std::int64_t, std::int64_t> shardRange(std::int64_t n, int world_size, int rank) {
  const std::int64_t w = world_size, r = rank;
  return {n * r / w, n * (r + 1) / w};
}

ProcessGroup::ProcessGroup(const DistOptions& o) : impl_(std::make_unique<Impl>()), rank_(o.rank), world_size_(o.world_size) {
  if (o.world_size < 2) throw UserError("a process group needs a world size of at least 2");
  if (o.rank < 0 || o.rank >= o.world_size)
    throw UserError("rank " + std::to_string(o.rank) + " is outside 0.." + std::to_string(o.world_size - 1));
  if (!(o.timeout_s > 0.0)) throw UserError("the timeout must be positive");
  where_ = "rank " + std::to_string(o.rank) + " of " + std::to_string(o.world_size) + " at " + o.rendezvous;
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(o.timeout_s * 1000.0));

  std::string host = "127.0.0.1";
  try {
    if (o.rendezvous.rfind("file://", 0) == 0) {
      const std::string path = o.rendezvous.substr(7);
      if (path.empty()) throw UserError("--rendezvous file://PATH: the path is empty");
      impl_->store = c10::make_intrusive<c10d::FileStore>(path, o.world_size);
      impl_->store->setTimeout(timeout);
    } else if (o.rendezvous.rfind("tcp://", 0) == 0) {
      const std::string address = o.rendezvous.substr(6);
      const std::size_t colon = address.rfind(':');
      if (colon == std::string::npos || colon == 0 || colon + 1 == address.size())
        throw UserError("--rendezvous " + o.rendezvous + ": expected tcp://HOST:PORT");
      host = address.substr(0, colon);
      int port = 0;
      try {
        std::size_t used = 0;
        port = std::stoi(address.substr(colon + 1), &used);
        if (used != address.size() - colon - 1) port = -1;
      } catch (const std::exception&) {
        port = -1;
      }
      if (port < 1 || port > 65535) throw UserError("--rendezvous " + o.rendezvous + ": the port must be 1..65535");
      c10d::TCPStoreOptions so;
      so.port = static_cast<std::uint16_t>(port);
      so.isServer = o.rank == 0;
      so.numWorkers = static_cast<std::size_t>(o.world_size);
      so.waitWorkers = true;
      so.timeout = timeout;
      impl_->store = c10::make_intrusive<c10d::TCPStore>(host, so);
    } else {
      throw UserError("--rendezvous must be tcp://HOST:PORT or file://PATH, not '" + o.rendezvous + "'");
    }

    auto go = c10d::ProcessGroupGloo::Options::create(timeout);
    if (!o.interface.empty())
      go->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(o.interface));
    else if (o.rendezvous.rfind("file://", 0) == 0 || isLoopback(host))
      go->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
    else
      go->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
    go->threads = 1;  // one core per rank: the rank's own thread does the arithmetic
    impl_->group = c10::make_intrusive<c10d::ProcessGroupGloo>(impl_->store, o.rank, o.world_size, go);
  } catch (const UserError&) {
    throw;
  } catch (const std::exception& e) {
    char timeout_text[32];
    std::snprintf(timeout_text, sizeof timeout_text, "%g s", o.timeout_s);
    throw UserError("rendezvous failed (" + where_ + ", timeout " + timeout_text +
                    "; are all ranks started with the same --world-size and --rendezvous?): " + message(e));
  }
}

ProcessGroup::~ProcessGroup() = default;

void ProcessGroup::sum(torch::Tensor& t, const char* what) {
  try {
    std::vector<torch::Tensor> ts{t};
    impl_->group->allreduce(ts)->wait();
  } catch (const std::exception& e) {
    throw UserError(std::string("all-reduce of the ") + what + " failed (" + where_ +
                    "): another rank died, stopped or timed out: " + message(e));
  }
}

void ProcessGroup::broadcast(torch::Tensor& t, int root, const char* what) {
  try {
    std::vector<torch::Tensor> ts{t};
    c10d::BroadcastOptions b;
    b.rootRank = root;
    impl_->group->broadcast(ts, b)->wait();
  } catch (const std::exception& e) {
    throw UserError(std::string("broadcast of the ") + what + " from rank " + std::to_string(root) + " failed (" +
                    where_ + "): another rank died, stopped or timed out: " + message(e));
  }
}

void ProcessGroup::sumGradients(const std::vector<torch::Tensor>& params) {
  torch::NoGradGuard no_grad;
  std::int64_t total = 0;
  for (const torch::Tensor& p : params) total += p.numel();
  if (!impl_->bucket.defined() || impl_->bucket.numel() != total) impl_->bucket = torch::empty({total}, torch::kFloat);
  std::int64_t offset = 0;
  for (const torch::Tensor& p : params) {
    torch::Tensor slot = impl_->bucket.slice(0, offset, offset + p.numel());
    if (p.grad().defined())
      slot.copy_(p.grad().reshape({-1}));
    else
      slot.zero_();
    offset += p.numel();
  }
  sum(impl_->bucket, "gradients");
  offset = 0;
  for (const torch::Tensor& p : params) {
    const torch::Tensor slot = impl_->bucket.slice(0, offset, offset + p.numel()).view(p.sizes());
    if (p.grad().defined())
      p.mutable_grad().copy_(slot);
    else
      p.mutable_grad() = slot.clone();
    offset += p.numel();
  }
}

void ProcessGroup::checkInSync(const std::vector<torch::Tensor>& params) {
  std::uint64_t h = fnv1a64(nullptr, 0);
  for (const torch::Tensor& p : params) {
    const torch::Tensor c = p.detach().contiguous();
    h = fnv1a64(static_cast<const std::uint8_t*>(c.data_ptr()), static_cast<std::size_t>(c.numel()) * c.element_size(), h);
  }
  checkSame(h, "weights");
}

void ProcessGroup::checkSame(std::uint64_t value, const char* what) {
  std::int64_t mine = 0;
  std::memcpy(&mine, &value, sizeof mine);
  torch::Tensor lo = torch::full({1}, mine, torch::kInt64), hi = lo.clone();
  try {
    std::vector<torch::Tensor> a{lo}, b{hi};
    c10d::AllreduceOptions min_op, max_op;
    min_op.reduceOp = c10d::ReduceOp::MIN;
    max_op.reduceOp = c10d::ReduceOp::MAX;
    impl_->group->allreduce(a, min_op)->wait();
    impl_->group->allreduce(b, max_op)->wait();
  } catch (const std::exception& e) {
    throw UserError(std::string("all-reduce of the ") + what + " hashes failed (" + where_ +
                    "): another rank died, stopped or timed out: " + message(e));
  }
  if (lo.item<std::int64_t>() != hi.item<std::int64_t>())
    throw UserError(std::string("the ranks' ") + what + " differ (" + where_ +
                    "): every rank must run the same build with the same data and options");
}

}  // namespace nao::tools
