// The scene's deformations: [modes] (a velocity-gradient shape per name), [paths] (stages with
// their rate, stress targets and stop) and protocol.modes resolved against them and the built-in
// modes (builtin_mode); the scene loader's part that reads them (scene_modes.hpp).
#include "io/scene_modes.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <functional>
#include <set>

#include "dem/core/errors.hpp"
#include "dem/io/scene.hpp"
#include "dem/measure/control.hpp"

namespace dem {

namespace {

// A name that becomes part of a file name (a curve MODE_phiX.csv, a task of the ensemble) or of a
// CSV cell: letters, digits, _ and - only, as the preparation's stage names.
bool file_safe_name(const std::string& s) {
  return !s.empty() && s.size() <= 64 && std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  });
}

void check_entry_name(const std::string& origin, const std::string& section, const std::string& name) {
  if (!file_safe_name(name))
    throw SceneError(origin + ": " + section + " name '" + name + "' must be 1-64 letters, digits, _ or - (it becomes "
                     "part of file names, deviatoric/NAME_phi0.800.csv, and of the ensemble's task names): rename it, e.g. my_path_1");
  if (builtin_mode(name, nullptr))
    throw SceneError(origin + ": " + section + " name '" + name + "' is a built-in mode (D2, D3, iso_compress, "
                     "iso_expand, uniaxial_x/y/z, SS_xy/xz/yz): a scene cannot redefine one (protocol.modes and rate = \"...\" could not tell them apart); rename it, e.g. my_" + name);
}

using Fail = std::function<void(const std::string&)>;   // throws SceneError naming the stage

// A path stage's rate: [rx, ry, rz], a velocity gradient, or a mode's name ("-NAME" reversed).
void read_stage_rate(const toml::table& t, PathStage& s, const Fail& fail, const CustomModes& custom) {
  // rate: [rx, ry, rz] or a mode name, "-NAME" for its reverse
  if (const toml::node* r = t.get("rate")) {
    if (auto name = r->value<std::string>()) {
      const bool neg = !name->empty() && (*name)[0] == '-';
      const std::string base = neg ? name->substr(1) : *name;
      DeformationMode dm;
      if (custom.count(base)) dm = custom.at(base);
      else if (!builtin_mode(base, &dm))
        fail("rate = \"" + *name + "\" names no mode (built in: D2, D3, iso_compress, iso_expand, uniaxial_x/y/z, "
             "SS_xy/xz/yz, or a [modes] entry; \"-D2\" reverses D2)");
      s.shape = neg ? dm.shape * -1.0 : dm.shape;
      if (s.name.empty()) s.name = *name;
    } else if (auto* a = r->as_array(); a && a->size() == 3 && (*a)[0].value<double>() && (*a)[1].value<double>() &&
                                        (*a)[2].value<double>()) {
      s.shape.diag = Vec3(*(*a)[0].value<double>(), *(*a)[1].value<double>(), *(*a)[2].value<double>());
      if (!std::isfinite(s.shape.diag.x) || !std::isfinite(s.shape.diag.y) || !std::isfinite(s.shape.diag.z))
        fail("rate = [rate_x, rate_y, rate_z] must be finite numbers (nan and inf are no rates)");
    } else if (a && a->size() == 3 && (*a)[0].as_array()) {
      // a velocity gradient [[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]], as in [modes]
      double L[3][3];
      for (int i = 0; i < 3; ++i) {
        auto* row = (*a)[i].as_array();
        if (!row || row->size() != 3)
          fail("rate as a velocity gradient must be [[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]] (three rows of three numbers)");
        for (int c = 0; c < 3; ++c) {
          auto x = (*row)[c].value<double>();
          if (!x || !std::isfinite(*x))
            fail("rate as a velocity gradient must be [[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]] (numbers)");
          L[i][c] = *x;
        }
      }
      if (L[1][0] != 0 || L[2][0] != 0 || L[2][1] != 0)
        fail("rate has entries below the diagonal (L_yx, L_zx or L_zy): the sheared cell is upper triangular, so "
             "name the axes such that the flow is v_x = L_xy y + L_xz z, v_y = L_yz z (e.g. v_z = g x is v_x = g z "
             "with x and z swapped; docs/simple_shear.md)");
      s.shape.diag = Vec3(L[0][0], L[1][1], L[2][2]);
      s.shape.shear = Vec3(L[0][1], L[0][2], L[1][2]);
    } else {
      fail("rate must be [rate_x, rate_y, rate_z] (multiples of protocol.deviatoric_rate_tc), a velocity gradient "
           "[[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]] or a mode name");
    }
  }
}

// A path stage's stress targets (sigma_*, pressure_*: in multiples of p0 or in pascals) and
// constant_volume.
void read_stage_targets(const toml::table& t, PathStage& s, const Fail& fail) {
  // A stress target is present (the key is there) and then must be a positive finite number;
  // in multiples of p0 at most 1e6 (so that the target in pascals, p0 times it, stays finite).
  auto check_target = [&](const std::string& key, double v, bool relative) {
    if (!std::isfinite(v) || !(v > 0))
      fail(key + " = " + std::to_string(v) + ": a stress target must be a positive finite number (compression); "
           "leave the key out for a strain-controlled axis");
    if (relative && v > 1e6)
      fail(key + " = " + std::to_string(v) + " is more than 1e6 times the starting pressure p0: no element test; give "
           "a target of the order of 1 (or in pascals, *_Pa)");
  };
  const bool p0 = t.contains("sigma_p0") || t.contains("pressure_p0");
  const bool pa = t.contains("sigma_Pa") || t.contains("pressure_Pa");
  if (p0 && pa) fail("give targets either in multiples of p0 (*_p0) or in pascals (*_Pa), not both");
  s.relative = !pa;
  for (const char* key : {"sigma_p0", "sigma_Pa"}) {
    const toml::node* n = t.get(key);
    if (!n) continue;
    const toml::table* st = n->as_table();
    if (!st) fail(std::string(key) + " must be a table of axes, e.g. { x = 1.0, y = 1.0 }");
    for (auto&& [k, v] : *st) {
      const std::string ax(k.str());
      auto val = v.value<double>();
      if ((ax != "x" && ax != "y" && ax != "z") || !val)
        fail(std::string(key) + "." + ax + ": axes are x, y, z and each target is a number");
      check_target(std::string(key) + "." + ax, *val, key[6] == 'p');
      (ax == "x" ? s.sigma.x : ax == "y" ? s.sigma.y : s.sigma.z) = *val;
    }
  }
  for (const char* key : {"pressure_p0", "pressure_Pa"})
    if (const toml::node* n = t.get(key)) {
      auto v = n->value<double>();
      if (!v) fail(std::string(key) + " must be a number");
      check_target(key, *v, key[9] == 'p');
      s.pressure = *v;
    }
  if (const toml::node* n = t.get("lode_b")) {
    auto v = n->value<double>();
    if (!v || !std::isfinite(*v)) fail("lode_b must be a number in [0, 1]: b = (sigma_2 - sigma_3)/(sigma_1 - sigma_3)");
    s.lode_b = *v;
  }
  if (const toml::node* n = t.get("constant_volume")) {
    auto v = n->value_exact<bool>();
    if (!v) fail("constant_volume must be true or false");
    s.constant_volume = *v;
  }
}

// A path stage's stop (until = { STOP = value }) and its max_time_tc.
void read_stage_stop(const toml::table& t, PathStage& s, const Fail& fail) {
  const toml::table* until = t.get("until") ? t.get("until")->as_table() : nullptr;
  if (!until || until->size() != 1)
    fail("until must be a table with one stop condition, e.g. until = { eps_d = 0.2 }; stops: eps_d (added by the "
         "stage), time_tc (duration / t_c), eps_v, eps_xx, eps_yy, eps_zz (since the path start), p_p0, p_Pa, s_dev, phi, ke_ratio, tau_xz_p0, tau_xz_Pa (also xy, yz)");
  static const std::map<std::string, PathStop> stops = {
      {"tau_xy_p0", PathStop::TauXY}, {"tau_xy_Pa", PathStop::TauXY}, {"tau_xz_p0", PathStop::TauXZ},
      {"tau_xz_Pa", PathStop::TauXZ}, {"tau_yz_p0", PathStop::TauYZ}, {"tau_yz_Pa", PathStop::TauYZ},
      {"ke_ratio", PathStop::Relaxed},
      {"eps_d", PathStop::EpsD},   {"time_tc", PathStop::Time}, {"eps_v", PathStop::EpsV},
      {"eps_xx", PathStop::EpsXX}, {"eps_yy", PathStop::EpsYY}, {"eps_zz", PathStop::EpsZZ},
      {"p_p0", PathStop::Pressure}, {"p_Pa", PathStop::Pressure}, {"s_dev", PathStop::SDev}, {"phi", PathStop::Phi}};
  const auto first = until->begin();
  const std::string stop(first->first.str());
  const toml::node& uv = first->second;
  if (!stops.count(stop))
    fail("until." + stop + " is not a stop condition; use eps_d, time_tc, eps_v, eps_xx, eps_yy, eps_zz, p_p0, p_Pa, s_dev, phi, ke_ratio (a servo stage at "
         "rest) or tau_ij_p0 / tau_ij_Pa (ij = xy, xz, yz: the shear stress -sigma_ij)");
  auto value = uv.value<double>();
  if (!value || !std::isfinite(*value)) fail("until." + stop + " must be a finite number");
  const bool relative_stop = stop == "p_p0" || (stop.size() > 3 && stop.compare(stop.size() - 3, 3, "_p0") == 0);
  if (relative_stop && std::fabs(*value) > 1e6)
    fail("until." + stop + " = " + std::to_string(*value) + " is more than 1e6 times the starting pressure: give a value of the order of 1");
  s.stop = stops.at(stop);
  s.until = *value;
  s.until_relative = relative_stop;
  if (const toml::node* n = t.get("max_time_tc")) {
    auto v = n->value<double>();
    if (s.stop != PathStop::Relaxed) fail("max_time_tc bounds a stage that stops on until.ke_ratio; remove it");
    if (!v || !std::isfinite(*v) || !(*v > 0)) fail("max_time_tc must be a positive number (times t_c)");
    s.max_time = *v;   // in t_c until the scene's t_c is known
  }
}

// One stage of a [paths] entry: an inline table (see data/scenes/paths_example.toml).
PathStage parse_path_stage(const toml::table& t, const std::string& where,
                           const std::map<std::string, DeformationMode>& custom) {
  const Fail fail = [&](const std::string& what) { throw SceneError(where + ": " + what); };
  static const std::set<std::string> keys = {"name", "rate", "sigma_p0", "sigma_Pa", "pressure_p0", "pressure_Pa",
                                             "lode_b", "constant_volume", "until", "max_time_tc"};
  for (auto&& [k, v] : t)
    if (!keys.count(std::string(k.str())))
      fail("unknown key '" + std::string(k.str()) + "'; a stage has name, rate, sigma_p0 or sigma_Pa, "
           "pressure_p0 or pressure_Pa, lode_b (with a pressure), constant_volume, until, max_time_tc (with until.ke_ratio)");
  PathStage s;
  if (auto n = t["name"].value<std::string>()) s.name = *n;
  else if (t.contains("name")) fail("name must be a string");
  if (t.contains("name") && !file_safe_name(s.name))
    fail("name '" + s.name + "' must be 1-64 letters, digits, _ or - (it is written into the curve's stage column)");
  read_stage_rate(t, s, fail, custom);
  read_stage_targets(t, s, fail);
  read_stage_stop(t, s, fail);
  return s;
}

}  // namespace

// [paths] name = [ {stage}, {stage}, ... ]
PathMap parse_paths(toml::table& root, const std::string& origin, const CustomModes& custom) {
  std::map<std::string, std::vector<PathStage>> paths;
  toml::table* t = root.get("paths") ? root.get("paths")->as_table() : nullptr;
  if (!t) { root.insert("paths", toml::table{}); return paths; }
  for (auto&& [k, v] : *t) {
    const std::string name(k.str());
    check_entry_name(origin, "[paths]", name);
    const toml::array* a = v.as_array();
    if (!a) throw SceneError(origin + ": paths." + name + " must be an array of stage tables, e.g. "
                             "[{ rate = \"D2\", until = { eps_d = 0.2 } }, { rate = \"-D2\", until = { eps_d = 0.4 } }]");
    std::vector<PathStage> stages;
    for (std::size_t i = 0; i < a->size(); ++i) {
      const std::string where = origin + ": paths." + name + " stage " + std::to_string(i + 1);
      const toml::table* st = (*a)[i].as_table();
      if (!st) throw SceneError(where + " must be a table { rate = ..., until = { ... } }");
      stages.push_back(parse_path_stage(*st, where, custom));
      if (stages.back().name.empty()) stages.back().name = "s" + std::to_string(i + 1);
    }
    validate_path(name, stages);
    paths[name] = stages;
  }
  return paths;
}

bool builtin_mode(const std::string& name, DeformationMode* mode) {
  // Simple shear SS_ij: v_i = 2 r x_j (constant volume). The factor 2 gives its stretching
  // D = sym(L) the eigenvalues (1, 0, -1) r of D2: simple shear is D2 rotated by 45 degrees
  // about the third axis plus a spin, at the same eps_d rate.
  static const std::map<std::string, Vec3> shears = {{"SS_xy", {2, 0, 0}}, {"SS_xz", {0, 2, 0}}, {"SS_yz", {0, 0, 2}}};
  if (auto sh = shears.find(name); sh != shears.end()) {
    if (mode) { mode->name = name; mode->shape = VelGrad(Vec3{0, 0, 0}, sh->second); }
    return true;
  }
  static const std::map<std::string, Vec3> modes = {
      {"D2", {1, 0, -1}},          {"D3", {0.5, 0.5, -1}},      {"iso_compress", {-1, -1, -1}},
      {"iso_expand", {1, 1, 1}},   {"uniaxial_x", {-1, 0, 0}},  {"uniaxial_y", {0, -1, 0}},
      {"uniaxial_z", {0, 0, -1}}};
  auto it = modes.find(name);
  if (it == modes.end()) return false;
  if (mode) { mode->name = name; mode->shape = VelGrad(it->second); }
  return true;
}

CustomModes read_custom_modes(toml::table& root, const std::string& origin) {
  CustomModes custom;
  if (auto* t = root.get("modes") ? root.get("modes")->as_table() : nullptr) {
    for (auto&& [k, v] : *t) {
      const std::string key(k.str());
      check_entry_name(origin, "[modes]", key);
      DeformationMode dm;
      dm.name = key;
      auto* a = v.as_array();
      auto row_of = [](const toml::node& n, double out[3]) {
        auto* r3 = n.as_array();
        if (!r3 || r3->size() != 3) return false;
        for (int c = 0; c < 3; ++c) {
          auto x = (*r3)[c].value<double>();
          if (!x || !std::isfinite(*x)) return false;
          out[c] = *x;
        }
        return true;
      };
      double L[3][3];
      if (a && a->size() == 3 && (*a)[0].value<double>() && (*a)[1].value<double>() && (*a)[2].value<double>()) {
        dm.shape.diag = Vec3(*(*a)[0].value<double>(), *(*a)[1].value<double>(), *(*a)[2].value<double>());
        if (!std::isfinite(dm.shape.diag.x) || !std::isfinite(dm.shape.diag.y) || !std::isfinite(dm.shape.diag.z))
          throw SceneError(origin + ": modes." + key + " must be finite numbers (nan and inf are no rates)");
      } else if (a && a->size() == 3 && row_of((*a)[0], L[0]) && row_of((*a)[1], L[1]) && row_of((*a)[2], L[2])) {
        if (L[1][0] != 0 || L[2][0] != 0 || L[2][1] != 0)
          throw SceneError(origin + ": modes." + key + " has entries below the diagonal (L_yx, L_zx or L_zy): the "
                           "sheared cell is upper triangular (LAMMPS' convention), so name the axes such that the "
                           "flow is v_x = L_xy y + L_xz z, v_y = L_yz z (e.g. v_z = g x is v_x = g z with x and z "
                           "swapped); a symmetric (pure-shear) gradient is diagonal in its principal axes: give that "
                           "diagonal [rx, ry, rz] (docs/simple_shear.md)");
        dm.shape.diag = Vec3(L[0][0], L[1][1], L[2][2]);
        dm.shape.shear = Vec3(L[0][1], L[0][2], L[1][2]);
      } else {
        throw SceneError(origin + ": modes." + key +
                         " must be [rate_x, rate_y, rate_z] (diagonal strain-rate shape) or a velocity gradient "
                         "[[Lxx, Lxy, Lxz], [0, Lyy, Lyz], [0, 0, Lzz]] (multiples of protocol.deviatoric_rate_tc)");
      }
      custom[key] = dm;
    }
  } else {
    root.insert("modes", toml::table{});
  }
  return custom;
}

std::vector<DeformationMode> resolve_modes(const std::vector<std::string>& modes, const CustomModes& custom,
                                           const PathMap& paths, const std::string& origin) {
  std::vector<DeformationMode> out;
  for (auto& name : modes) {
    DeformationMode dm;
    if (custom.count(name) && paths.count(name))
      throw SceneError(origin + ": '" + name + "' is both a [modes] and a [paths] entry: rename one");
    if (custom.count(name)) dm = custom.at(name);
    else if (paths.count(name)) { dm.name = name; dm.path = paths.at(name); }
    else if (!builtin_mode(name, &dm))
      throw SceneError(origin + ": protocol.modes names '" + name + "', which is neither built in "
                       "(D2, D3, iso_compress, iso_expand, uniaxial_x/y/z, SS_xy/xz/yz) nor defined in [modes] or [paths]");
    out.push_back(dm);
  }

  return out;
}

void check_mode_rates(const std::vector<DeformationMode>& modes, double dev_tc, const std::string& origin) {
  for (const auto& mode : modes) {
    std::vector<std::pair<std::string, VelGrad>> shapes;
    if (mode.path.empty()) shapes.push_back({"modes." + mode.name, mode.shape});
    for (const auto& st : mode.path) shapes.push_back({"paths." + mode.name + " stage '" + st.name + "'", st.shape});
    for (const auto& [where, sh] : shapes) {
      const double peak = std::max({std::fabs(sh.diag.x), std::fabs(sh.diag.y), std::fabs(sh.diag.z),
                                    std::fabs(sh.shear.x), std::fabs(sh.shear.y), std::fabs(sh.shear.z)});
      if (peak * dev_tc > 1e-2) {
        char b[400];
        std::snprintf(b, sizeof b, "%s: %s: a rate entry of %g times protocol.deviatoric_rate_tc = %g deforms the box "
                      "by %.3g%% per contact time: far from quasi-static; keep the rate entries of the order of 1",
                      origin.c_str(), where.c_str(), peak, dev_tc, 100 * peak * dev_tc);
        throw SceneError(b);
      }
    }
  }
}

}  // namespace dem
