#include "train_data.hpp"

#include "nao/tools/command.hpp"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace nao::tools {
namespace {

torch::Tensor put(const std::vector<JointVector>& v) {
  torch::Tensor x = torch::empty({static_cast<std::int64_t>(v.size()), kNumJoints});
  auto acc = x.accessor<float, 2>();
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int j = 0; j < kNumJoints; ++j) acc[static_cast<std::int64_t>(i)][j] = static_cast<float>(v[i][j]);
  return x;
}

// Sequences packed as doubles, one after another: demo, movement, rollout, the lengths of q,
// a_prev, r and a, worst_miss_rad, then the four vectors' joints. Exact: every field is a double
// or a small integer.
constexpr std::size_t kPackedHead = 8;

std::size_t packedSize(const PolicySequence& s) {
  return kPackedHead + kNumJoints * (s.q.size() + s.a_prev.size() + s.r.size() + s.a.size());
}

double* pack(const PolicySequence& s, double* out) {
  const double head[kPackedHead] = {static_cast<double>(s.demo),         static_cast<double>(s.movement),
                                    static_cast<double>(s.rollout),      static_cast<double>(s.q.size()),
                                    static_cast<double>(s.a_prev.size()), static_cast<double>(s.r.size()),
                                    static_cast<double>(s.a.size()),      s.worst_miss_rad};
  out = std::copy(head, head + kPackedHead, out);
  for (const std::vector<JointVector>* v : {&s.q, &s.a_prev, &s.r, &s.a})
    for (const JointVector& x : *v) out = std::copy(x.data(), x.data() + kNumJoints, out);
  return out;
}

const double* unpack(const double* in, const double* end, PolicySequence& s) {
  if (end - in < static_cast<std::ptrdiff_t>(kPackedHead)) throw std::logic_error("gatherSequences: truncated record");
  s.demo = static_cast<int>(in[0]);
  s.movement = static_cast<int>(in[1]);
  s.rollout = static_cast<int>(in[2]);
  s.worst_miss_rad = in[7];
  std::vector<JointVector>* vs[4] = {&s.q, &s.a_prev, &s.r, &s.a};
  const double* x = in + kPackedHead;
  for (int k = 0; k < 4; ++k) {
    const auto n = static_cast<std::size_t>(in[3 + k]);
    if (static_cast<std::size_t>(end - x) < n * kNumJoints) throw std::logic_error("gatherSequences: truncated record");
    vs[k]->resize(n);
    for (JointVector& v : *vs[k]) {
      std::copy(x, x + kNumJoints, v.data());
      x += kNumJoints;
    }
  }
  return x;
}

}  // namespace

SequenceTensors toTensors(const PolicyNet& net, const std::vector<PolicySequence>& seqs) {
  SequenceTensors t;
  const std::int64_t C = net->arch().chunk;
  for (const PolicySequence& s : seqs) {
    const torch::Tensor q = put(s.q), a_prev = put(s.a_prev), r = put(s.r), a = put(s.a);
    t.qn.push_back((q - net->q_mean) / net->q_std);
    t.an.push_back((a_prev - net->a_mean) / net->a_std);
    t.rn.push_back((r - net->r_mean) / net->r_std);
    t.action.push_back(a);
    t.r.push_back(r);
    // The net's part of each label: the label less the law the runtime adds (reference mode).
    const torch::Tensor net_part = a - net->law_gain * r;
    const std::int64_t n = net_part.size(0);
    // Past the end the arm holds: a = 0 and r = 0, so the net's part is 0 too.
    const torch::Tensor padded = torch::cat({net_part, torch::zeros({C, kNumJoints})}, 0);
    torch::Tensor chunk = torch::empty({n, kNumJoints, C});
    for (std::int64_t c = 0; c < C; ++c) chunk.select(2, c).copy_(padded.slice(0, c, c + n));
    t.target.push_back((chunk - net->a_mean.view({1, -1, 1})) / net->a_std.view({1, -1, 1}));
    t.movement.push_back(s.movement);
    t.ticks += n;
  }
  return t;
}

Padded pad(const SequenceTensors& t, const std::vector<std::size_t>& index) {
  std::int64_t longest = 0;
  for (std::size_t i : index) longest = std::max(longest, t.qn[i].size(0));
  const auto n = static_cast<std::int64_t>(index.size());
  const std::int64_t C = t.target.front().size(2);
  Padded p;
  p.in.qn = torch::zeros({n, longest, kNumJoints});
  p.in.an = torch::zeros({n, longest, kNumJoints});
  p.in.rn = torch::zeros({n, longest, kNumJoints});
  p.target = torch::zeros({n, longest, kNumJoints, C});
  p.action = torch::zeros({n, longest, kNumJoints});
  p.r = torch::zeros({n, longest, kNumJoints});
  p.mask = torch::zeros({n, longest});
  std::vector<std::int64_t> movement;
  for (std::int64_t b = 0; b < n; ++b) {
    const std::size_t i = index[static_cast<std::size_t>(b)];
    const std::int64_t len = t.qn[i].size(0);
    p.in.qn[b].slice(0, 0, len).copy_(t.qn[i]);
    p.in.an[b].slice(0, 0, len).copy_(t.an[i]);
    p.in.rn[b].slice(0, 0, len).copy_(t.rn[i]);
    p.target[b].slice(0, 0, len).copy_(t.target[i]);
    p.action[b].slice(0, 0, len).copy_(t.action[i]);
    p.r[b].slice(0, 0, len).copy_(t.r[i]);
    p.mask[b].slice(0, 0, len).fill_(1.0);
    movement.push_back(t.movement[i]);
    p.ticks += len;
  }
  p.in.movement = torch::tensor(movement, torch::kInt64);
  return p;
}

LossSums lossSums(const PolicyNet& net, const Padded& p) {
  const PolicyHeadOutput out = net->forward(p.in);
  LossSums s;
  const torch::Tensor per_tick = (out.chunk - p.target).square().mean({2, 3});  // [B,T]
  s.loss = (per_tick * p.mask).sum();
  {
    torch::NoGradGuard no_grad;
    // The executed action's first term: the chunk's a(t) in rad plus the law.
    const torch::Tensor first = out.chunk.select(3, 0) * net->a_std + net->a_mean + net->law_gain * p.r;
    s.action_sse_rad2 = ((first - p.action).square().sum(2) * p.mask).sum().item<double>();
  }
  return s;
}

SplitLoss evaluateLoss(const PolicyNet& net, const SequenceTensors& t, ProcessGroup* group) {
  SplitLoss out;
  if (t.size() == 0) return out;
  torch::NoGradGuard no_grad;
  std::int64_t begin = 0, end = static_cast<std::int64_t>(t.size());
  if (group) std::tie(begin, end) = shardRange(end, group->worldSize(), group->rank());
  double loss = 0.0, sse = 0.0;
  for (std::int64_t i = begin; i < end; ++i) {
    const LossSums s = lossSums(net, pad(t, {static_cast<std::size_t>(i)}));
    loss += s.loss.item<double>();
    sse += s.action_sse_rad2;
  }
  if (group) {
    torch::Tensor both = torch::tensor({loss, sse}, torch::kFloat64);
    group->sum(both, "validation sums");
    loss = both[0].item<double>();
    sse = both[1].item<double>();
  }
  out.loss = loss / static_cast<double>(t.ticks);
  out.mse_rad2 = sse / (static_cast<double>(t.ticks) * kNumJoints);
  return out;
}

void writeSequences(const std::string& path, const std::vector<PolicySequence>& seqs) {
  std::size_t n = 1;
  for (const PolicySequence& s : seqs) n += packedSize(s);
  std::vector<double> buf(n);
  buf[0] = static_cast<double>(seqs.size());
  double* out = buf.data() + 1;
  for (const PolicySequence& s : seqs) out = pack(s, out);
  // Written aside and renamed: a run killed while writing leaves no half file behind.
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (f == nullptr) throw UserError("cannot write " + tmp);
  const bool ok = std::fwrite(buf.data(), sizeof(double), n, f) == n;
  if (std::fclose(f) != 0 || !ok || std::rename(tmp.c_str(), path.c_str()) != 0)
    throw UserError("cannot write " + path);
}

bool readSequences(const std::string& path, std::vector<PolicySequence>& seqs) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return false;
  std::vector<double> buf;
  double chunk[4096];
  for (std::size_t got; (got = std::fread(chunk, sizeof(double), 4096, f)) > 0;) buf.insert(buf.end(), chunk, chunk + got);
  std::fclose(f);
  if (buf.empty()) throw UserError(path + ": empty execution cache");
  seqs.clear();
  const double* in = buf.data() + 1;
  const double* end = buf.data() + buf.size();
  try {
    for (std::size_t i = 0; i < static_cast<std::size_t>(buf[0]); ++i) {
      PolicySequence s;
      in = unpack(in, end, s);
      seqs.push_back(std::move(s));
    }
  } catch (const std::logic_error&) {
    throw UserError(path + ": a truncated execution cache (delete it to execute again)");
  }
  if (in != end) throw UserError(path + ": an execution cache with trailing data (delete it to execute again)");
  return true;
}

std::vector<PolicySequence> gatherSequences(ProcessGroup& g, std::vector<PolicySequence> mine) {
  const int w = g.worldSize();
  torch::Tensor sizes = torch::zeros({w}, torch::kInt64);
  std::int64_t my_size = 0;
  for (const PolicySequence& s : mine) my_size += static_cast<std::int64_t>(packedSize(s));
  sizes[g.rank()] = my_size;
  g.sum(sizes, "sequence sizes");
  std::vector<PolicySequence> all;
  for (int r = 0; r < w; ++r) {
    torch::Tensor buf = torch::empty({sizes[r].item<std::int64_t>()}, torch::kFloat64);
    double* const b = buf.data_ptr<double>();
    double* const e = b + buf.numel();
    if (r == g.rank()) {
      double* out = b;
      for (const PolicySequence& s : mine) out = pack(s, out);
    }
    g.broadcast(buf, r, "executed sequences");
    if (r == g.rank()) {
      for (PolicySequence& s : mine) all.push_back(std::move(s));
      continue;
    }
    for (const double* in = b; in < e;) {
      PolicySequence s;
      in = unpack(in, e, s);
      all.push_back(std::move(s));
    }
  }
  return all;
}

}  // namespace nao::tools
