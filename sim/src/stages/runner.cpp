// The runners every door shares (`dem run`, `dem mode`, demtk, the workflow's tasks through the
// CLI): the stage specs, one function per kind of stage, a preparation stage as the scene lists
// it, and a mode or loading path from a state.
#include <cmath>
#include <iostream>

#include "dem/io/checks.hpp"
#include "dem/io/preparation.hpp"
#include "dem/stages/protocol.hpp"

namespace dem {

StageSpec mode_stage(const Model& model, const DeformationMode& mode, const std::string& name) {
  StageSpec s;
  s.name = name.empty() ? mode.name : name;
  s.gradient = mode.shape * model.protocol.deviatoric_rate;
  s.stop = StopKind::DeviatoricStrain;
  s.target = model.protocol.eps_d_max;
  s.definition = mode_definition(model, mode);
  return s;
}

StageSpec relax_stage(const PrepStage& p) {
  StageSpec s;
  s.name = p.name;
  s.stop = StopKind::Relaxed;
  s.ke_ratio = p.ke_ratio;
  s.max_time = p.max_time;
  return s;
}

StageSpec volume_stage(const PrepStage& p) {
  const bool up = p.kind == PrepStage::Kind::Compress;
  StageSpec s;
  s.name = p.name;
  s.gradient = VelGrad(Vec3{1, 1, 1} * (up ? -p.rate : p.rate));
  s.stop = up ? StopKind::VolumeFractionUp : StopKind::VolumeFractionDown;
  s.target = p.phi;
  return s;
}

DeformationMode stress_stage_path(const PrepStage& s) {
  PathStage st;
  st.name = s.name;
  st.relative = false;
  if (s.kind == PrepStage::Kind::Pressure) st.pressure = s.target;
  else st.sigma.z = s.target;
  st.stop = PathStop::Relaxed;
  st.until = s.ke_ratio;
  st.max_time = s.max_time;
  DeformationMode m;
  m.name = s.name;
  m.path = {st};
  return m;
}

bool prep_stage_skipped(const PrepStage& s, double phi0) {
  if (s.kind != PrepStage::Kind::Compress && s.kind != PrepStage::Kind::Expand) return false;
  return s.kind == PrepStage::Kind::Compress ? phi0 >= s.phi : phi0 <= s.phi;
}

std::int64_t run_mode(const Model& model, State& state, const DeformationMode& mode, const std::string& name,
                      const StageOutput& out) {
  if (!mode.path.empty()) return run_path(model, state, mode, name.empty() ? mode.name : name, out);
  return run_stage(model, state, mode_stage(model, mode, name), out);
}

namespace {

// A compress or expand stage: its checkpoints at the start, during and at the end (those already
// passed are said and left out).
std::int64_t run_volume_stage(const Model& model, const PrepStage& s, State& st, const StageOutput& out,
                              const SaveCheckpoint& save) {
  const bool up = s.kind == PrepStage::Kind::Compress;
  const double phi0 = st.volume_fraction();
  StageSpec spec = volume_stage(s);
  auto same = [](double a, double b) { return std::fabs(a - b) <= 1e-9 * b; };
  std::vector<double> at_start, at_end;
  for (double cp : s.checkpoints) {
    if (same(cp, phi0)) at_start.push_back(cp);
    else if (same(cp, s.phi)) at_end.push_back(cp);
    else if (up ? (cp > phi0 && cp < s.phi) : (cp < phi0 && cp > s.phi)) spec.checkpoint_phis.push_back(cp);
    else
      std::cerr << "dem: warning: checkpoint " << checkpoint_stem(s.checkpoint_name, cp) << " not written: stage "
                << s.name << " started at phi " << phi0 << ", already past it\n";
  }
  for (double cp : at_start) save(s.checkpoint_name, cp, st);
  const std::int64_t steps =
      run_stage(model, st, spec, out, [&](double phi, const State& now) { save(s.checkpoint_name, phi, now); });
  for (double cp : at_end) save(s.checkpoint_name, cp, st);
  return steps;
}

}  // namespace

std::int64_t run_prep_stage(const Model& model, const PrepStage& s, State& st, const StageOutput& out,
                            const SaveCheckpoint& save) {
  if (s.kind == PrepStage::Kind::Pressure || s.kind == PrepStage::Kind::Uniaxial) {
    Model m = model;   // the stage's rate is its servo's rate limit
    m.protocol.servo.rate_max = s.rate;
    m.protocol.servo.rate_max_tc = s.rate * model.t_contact;
    const std::int64_t steps = run_path(m, st, stress_stage_path(s), s.name, out);
    if (!s.checkpoint_name.empty()) save(s.checkpoint_name, st.volume_fraction(), st);
    return steps;
  }
  if (s.kind == PrepStage::Kind::Relax) return run_stage(model, st, relax_stage(s), out);
  if (prep_stage_skipped(s, st.volume_fraction())) {
    const bool up = s.kind == PrepStage::Kind::Compress;
    std::cerr << "dem: stage " << s.name << " skipped: the packing is already at phi " << st.volume_fraction() << ", "
              << (up ? "at or above" : "at or below") << " its target " << s.phi << "\n";
    if (!s.checkpoints.empty())
      std::cerr << "dem: warning: the checkpoints of stage " << s.name << " (" << s.checkpoint_name
                << ") are not written\n";
    return -1;
  }
  return run_volume_stage(model, s, st, out, save);
}

}  // namespace dem
