#include "nao/tools/retarget_pipeline.hpp"

#include "nao/file_io.hpp"
#include "nao/tools/command.hpp"
#include "nao/tools/csv.hpp"

#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

namespace nao::tools {

bool sameRetargetSetting(const RetargetParams& a, const RetargetParams& b) {
  return a.priority == b.priority && a.lambda_q == b.lambda_q && a.posture_weights == b.posture_weights;
}

nlohmann::json retargetSettingJson(const RetargetParams& params) {
  return {{"priority", retargetPriorityName(params.priority)},
          {"lambda_q", params.lambda_q},
          {"posture_weights", std::vector<double>(params.posture_weights.data(),
                                                  params.posture_weights.data() + kNumJoints)}};
}

void writeRetargetCsv(const std::string& path, const std::vector<RetargetRow>& rows, const RetargetParams& params) {
  std::ostringstream out;
  out.precision(10);
  out << "t_s";
  for (const char* name : {"qx", "qq"})
    for (int j = 0; j < kNumJoints; ++j) out << ',' << name << '_' << j;
  out << ",xt_x,xt_y,xt_z,ex_x,ex_y,ex_z,eq_x,eq_y,eq_z,flags";
  for (int j = 0; j < kNumJoints; ++j) out << ",qt_" << j;
  for (int j = 0; j < kNumJoints; ++j) out << ",qr_" << j;
  out << ",priority,lambda_q";
  for (int j = 0; j < kNumJoints; ++j) out << ",pw_" << j;
  out << '\n';
  for (const RetargetRow& r : rows) {
    out << r.t_s;
    for (int j = 0; j < kNumJoints; ++j) out << ',' << r.result.q_x[j];
    for (int j = 0; j < kNumJoints; ++j) out << ',' << r.result.q_q[j];
    for (const Eigen::Vector3d* v : {&r.target.p_target_TH, &r.result.p_TH_x, &r.result.p_TH_q})
      out << ',' << v->x() << ',' << v->y() << ',' << v->z();
    out << ',' << r.flags;
    for (int j = 0; j < kNumJoints; ++j) out << ',' << r.target.q_target[j];
    for (int j = 0; j < kNumJoints; ++j) out << ',' << r.result.q_r[j];
    out << ',' << static_cast<int>(params.priority) << ',' << params.lambda_q;
    for (int j = 0; j < kNumJoints; ++j) out << ',' << params.posture_weights[j];
    out << '\n';
  }
  // Whole or not at all: cluster never reads half a demonstration.
  const std::string text = out.str();
  if (const std::string problem = writeFileAtomically(path, text.data(), text.size()); !problem.empty())
    throw UserError("cannot write " + path + ": " + problem);
}

std::vector<RetargetRow> readRetargetCsv(const std::string& path, RetargetParams* setting) {
  CsvReader csv(path, "retarget CSV");
  const std::size_t c_t = csv.column("t_s"), c_flags = csv.column("flags"), c_priority = csv.column("priority"),
                    c_lambda_q = csv.column("lambda_q");
  std::array<std::size_t, kNumJoints> c_qx, c_qq, c_qt, c_qr, c_pw;
  for (int j = 0; j < kNumJoints; ++j) {
    c_pw[j] = csv.column("pw_" + std::to_string(j));
    c_qx[j] = csv.column("qx_" + std::to_string(j));
    c_qq[j] = csv.column("qq_" + std::to_string(j));
    c_qt[j] = csv.column("qt_" + std::to_string(j));
    c_qr[j] = csv.column("qr_" + std::to_string(j));
  }
  std::array<std::size_t, 9> c_xyz;
  int k = 0;
  for (const char* p : {"xt", "ex", "eq"})
    for (const char* a : {"_x", "_y", "_z"}) c_xyz[k++] = csv.column(std::string(p) + a);

  std::vector<RetargetRow> rows;
  while (csv.next()) {
    RetargetRow r;
    r.t_s = csv.number(c_t);
    for (int j = 0; j < kNumJoints; ++j) {
      r.result.q_x[j] = csv.number(c_qx[j]);
      r.result.q_q[j] = csv.number(c_qq[j]);
      r.target.q_target[j] = csv.number(c_qt[j]);
      r.result.q_r[j] = csv.number(c_qr[j]);
    }
    // The retargeting setting q_r was made with: the same on every row.
    RetargetParams row_setting;
    const double p = csv.number(c_priority);
    if (p != 0.0 && p != 1.0)
      throw UserError(path + ": priority must be 0 (hand) or 1 (joints), got " + std::to_string(p));
    row_setting.priority = p == 0.0 ? RetargetPriority::kHand : RetargetPriority::kJoints;
    row_setting.lambda_q = csv.number(c_lambda_q);
    for (int j = 0; j < kNumJoints; ++j) row_setting.posture_weights[j] = csv.number(c_pw[j]);
    if (rows.empty()) {
      if (setting != nullptr) {
        setting->priority = row_setting.priority;
        setting->lambda_q = row_setting.lambda_q;
        setting->posture_weights = row_setting.posture_weights;
      }
    } else if (setting != nullptr && !sameRetargetSetting(*setting, row_setting)) {
      throw UserError(path + ": rows retargeted with different settings (priority, lambda_q, pw_*)");
    }
    for (int a = 0; a < 3; ++a) {
      r.target.p_target_TH[a] = csv.number(c_xyz[a]);
      r.result.p_TH_x[a] = csv.number(c_xyz[3 + a]);
      r.result.p_TH_q[a] = csv.number(c_xyz[6 + a]);
    }
    // Flags are a bit set written as an unsigned integer: anything else (1e20, -1, 0.5) would
    // be undefined behaviour to cast.
    const double flags = csv.number(c_flags);
    if (!(flags >= 0.0 && flags <= 4294967295.0) || flags != std::floor(flags))
      throw UserError(csv.where() + ": column 'flags' holds " + std::to_string(flags) +
                      ", expected an integer bit set 0..4294967295");
    r.flags = static_cast<std::uint32_t>(flags);
    r.result.flags = r.flags & ~static_cast<std::uint32_t>(kRowHumanMissing | kRowHandNotSeen);
    rows.push_back(r);
  }
  return rows;
}

}  // namespace nao::tools
