#include "dem/stages/plan.hpp"
#include "dem/stages/preparation.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <stdexcept>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include "dem/core/errors.hpp"
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/protocol.hpp"

namespace dem {

namespace {

// Steps of one path stage: exact for eps_d and time stops without servo; otherwise an estimate
// (a strain stop taken from 0, a stress or phi stop as eps_d_max of shear).
double path_stage_steps(const Model& m, const PathStage& s) {
  const Vec3& r = s.shape.diag;
  const double unit = m.protocol.deviatoric_rate * m.dt;   // strain per step of a unit rate shape
  const Vec3& g = s.shape.shear;
  const double dev = s.sheared() ? deviatoric_magnitude_eig(Sym3{r.x, r.y, r.z, 0.5 * g.x, 0.5 * g.y, 0.5 * g.z})
                                 : deviatoric_magnitude(r.x, r.y, r.z);
  const double comp[3] = {r.x, r.y, r.z};
  switch (s.stop) {
    case PathStop::EpsD: return s.until / (std::max(dev, 1e-3) * unit);
    case PathStop::Time: return s.until / m.dt;
    case PathStop::EpsV: return std::fabs(s.until) / (std::max(std::fabs(r.x + r.y + r.z) / 3, 1e-3) * unit);
    case PathStop::EpsXX: case PathStop::EpsYY: case PathStop::EpsZZ: {
      const int a = s.stop == PathStop::EpsXX ? 0 : s.stop == PathStop::EpsYY ? 1 : 2;
      return std::fabs(s.until) / (std::max(std::fabs(comp[a]), 1e-3) * unit);
    }
    default: return m.protocol.eps_d_max / (std::max(dev, 1.0) * unit);
  }
}

}  // namespace

double mode_steps(const Model& m, const DeformationMode& mode) {
  if (!mode.path.empty()) {
    double steps = 0;
    for (const auto& s : mode.path) steps += path_stage_steps(m, s);
    return steps;
  }
  const Vec3& r = mode.shape.diag;
  const Vec3& g = mode.shape.shear;
  // A shear: the eps_d rate of D = sym(L) (the log strain's eps_d grows a little slower at large
  // shear: an estimate).
  const double dev = mode.sheared() ? deviatoric_magnitude_eig(Sym3{r.x, r.y, r.z, 0.5 * g.x, 0.5 * g.y, 0.5 * g.z})
                                    : deviatoric_magnitude(r.x, r.y, r.z);
  const double per_step = (dev > 0 ? dev : std::fabs(r.x + r.y + r.z) / 3) * m.protocol.deviatoric_rate * m.dt;
  return m.protocol.eps_d_max / per_step;
}

double mode_particle_steps(const Model& m, const DeformationMode& mode) { return m.count * mode_steps(m, mode); }

double prep_particle_steps(const Model& m) {
  return 3.0 * preparation_particle_steps(m);
}

std::string plan_json(const Model& m) {
  nlohmann::ordered_json j;
  j["packings"] = m.ensemble_packings;
  j["members"] = nlohmann::ordered_json::array();
  for (int k = 0; k < m.ensemble_packings; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "m%03d", k);
    j["members"].push_back({{"name", name}, {"seed", member_seed(m.seed, k)}});
  }
  j["series"] = m.protocol.modes_from;
  j["checkpoints"] = nlohmann::ordered_json::array();
  for (double phi : mode_checkpoints(m.protocol))
    j["checkpoints"].push_back({{"phi", phi}, {"stem", checkpoint_stem(m.protocol.modes_from, phi)}});
  j["modes"] = nlohmann::ordered_json::array();
  for (const auto& mode : m.protocol.modes) j["modes"].push_back(mode.name);
  j["prep_particle_steps"] = prep_particle_steps(m);
  j["mode_particle_steps"] = nlohmann::ordered_json::object();
  for (const auto& mode : m.protocol.modes) j["mode_particle_steps"][mode.name] = mode_particle_steps(m, mode);
  j["tasks"] = planned_task_files(m);
  j["threads"] = m.threads;
  return j.dump(2) + "\n";
}

std::vector<double> preparation_stage_steps(const Model& m) {
  std::vector<double> steps;
  double phi = m.protocol.initial_phi;
  for (const auto& s : m.protocol.preparation) {
    if (s.kind == PrepStage::Kind::Relax || s.kind == PrepStage::Kind::Pressure ||
        s.kind == PrepStage::Kind::Uniaxial) {   // at most; a stress stage ends where it finds its target at rest
      steps.push_back(s.max_time / m.dt);
      continue;
    }
    const bool runs = s.kind == PrepStage::Kind::Compress ? s.phi > phi : s.phi < phi;
    steps.push_back(runs ? std::fabs(std::log(s.phi / phi)) / (3 * s.rate * m.dt) : 0.0);
    phi = s.phi;
  }
  return steps;
}

void check_work(const Model& m, const std::string& origin) {
  auto refuse = [&](const std::string& what, double steps, const std::string& fix) {
    if (std::isfinite(steps) && steps <= kMaxSteps) return;
    const double ps = steps * m.count;
    char b[600];
    std::snprintf(b, sizeof b, "%s: %s would take about %.3g time steps (%.3g particle-steps at N = %d, about %.3g "
                  "years at 25 M particle-steps/s), beyond the bound of %.0e steps: %s", origin.c_str(), what.c_str(),
                  steps, ps, m.count, ps / 25e6 / 3.15e7, kMaxSteps, fix.c_str());
    throw SceneError(b);
  };
  const auto prep = preparation_stage_steps(m);
  for (std::size_t i = 0; i < prep.size(); ++i)
    refuse("preparation stage '" + m.protocol.preparation[i].name + "'", prep[i],
           "raise its rate_tc (typical 1e-5 to 1e-3) or shorten its max_time_tc");
  for (const auto& mode : m.protocol.modes)
    refuse(std::string(mode.path.empty() ? "mode '" : "path '") + mode.name + "'", mode_steps(m, mode),
           "raise protocol.deviatoric_rate_tc (typical 1e-6 to 1e-4), or the rate entries of the mode");
}

std::vector<std::string> planned_task_files(const Model& m) {
  std::vector<std::string> files;
  const std::vector<double> phis = mode_checkpoints(m.protocol);
  for (int k = 0; k < m.ensemble_packings; ++k) {
    char name[32];
    std::snprintf(name, sizeof name, "m%03d", k);
    files.push_back(std::string("members/") + name + "/prep.json");
    for (double phi : phis)
      for (const auto& mode : m.protocol.modes)
        files.push_back(std::string("members/") + name + "/deviatoric/" + mode.name + "_" + fmt_phi(phi) + ".json");
  }
  return files;
}

namespace {

std::vector<std::string> lines_of(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string ln; std::getline(in, ln);) out.push_back(ln);
  return out;
}

// The first lines of `a` that `b` lacks (a short hint of what differs).
std::string differing_lines(const std::string& a, const std::string& b) {
  const auto la = lines_of(a), lb = lines_of(b);
  std::string d;
  int shown = 0;
  for (const auto& ln : la)
    if (std::find(lb.begin(), lb.end(), ln) == lb.end() && shown++ < 4) d += "\n    " + ln;
  return d;
}

}  // namespace

namespace {

// The folder's lock, held by the `dem ensemble` working on it (the kernel drops it when the
// process dies): refused at once if another one holds it.
int lock_ensemble_folder(const std::filesystem::path& dir) {
  const std::string path = (dir / ".dem-ensemble.lock").string();
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_NOFOLLOW, 0644);   // no O_CLOEXEC: the driver inherits it
  if (fd < 0) throw std::runtime_error("cannot open " + path + " (" + std::strerror(errno) + ")");
  if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd);
    throw std::runtime_error("another `dem ensemble` is running on " + dir.string() + " (it holds " + path +
                             "); nothing was changed, --force or not: wait for it to finish, or stop it first");
  }
  return fd;
}

}  // namespace

namespace {

// The text without its `skin_over_rmin = ...` line.
std::string without_skin_line(const std::string& text) {
  std::istringstream in(text);
  std::string out, line;
  while (std::getline(in, line))
    if (line.rfind("skin_over_rmin", 0) != 0) out += line + "\n";
  return out;
}

// Whether a folder's stored scene and this resolved scene are the same scene: the same text, or
// texts that differ only in how the skin is given (a number in folders of versions before
// "auto", or "auto") when both give the same skin (the same list and bits).
bool same_scene(const std::string& stored, const std::string& resolved) {
  if (stored == resolved) return true;
  if (without_skin_line(stored) != without_skin_line(resolved)) return false;
  try {
    return load_scene(stored).skin_over_rmin == load_scene(resolved).skin_over_rmin;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

int prepare_ensemble_folder(const std::string& dir_name, const std::string& resolved, bool force) {
  namespace fs = std::filesystem;
  const fs::path dir(dir_name), scene = dir / "scene.toml";
  int lock = -1;
  if (fs::exists(scene)) {
    lock = lock_ensemble_folder(dir);
    std::ifstream in(scene);
    std::stringstream old;
    old << in.rdbuf();
    if (same_scene(old.str(), resolved) && !force) return lock;   // the same ensemble: continue where it stopped
    if (!force)
      throw std::runtime_error(dir_name + " holds the results of another scene (its scene.toml differs in:" +
                               differing_lines(old.str(), resolved) +
                               "\n  ); choose another --out, or pass --force to remove those results");
    for (const char* sub : {"members", "ensemble", "fit", "plots", "logs", ".snakemake"}) fs::remove_all(dir / sub);
    for (const char* f : {"scene.toml", "manifest.json"}) fs::remove(dir / f);   // not the lock: it is held
  } else if (fs::exists(dir) && !fs::is_empty(dir) && !force) {
    throw std::runtime_error(dir_name + " exists and is not an ensemble folder (no scene.toml): choose another --out");
  }
  fs::create_directories(dir);
  if (lock < 0) lock = lock_ensemble_folder(dir);
  write_file_atomic(scene.string(), resolved);
  return lock;
}

namespace {

std::string file_text(const std::filesystem::path& f) {
  std::ifstream in(f, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// What of a sweep folder differs from this sweep ("" when nothing: the same sweep continues).
std::string sweep_difference(const std::filesystem::path& dir, const std::string& json,
                             const std::vector<std::pair<std::string, std::string>>& rows) {
  std::string d;
  if (file_text(dir / "sweep.json") != json) d += "\n    its sweep.json (keys, rows or base --set)" +
                                                  differing_lines(file_text(dir / "sweep.json"), json);
  for (const auto& [name, scene] : rows) {
    const auto f = dir / "rows" / name / "scene.toml";
    if (std::filesystem::exists(f) && !same_scene(file_text(f), scene))
      d += "\n    rows/" + name + "/scene.toml:" + differing_lines(file_text(f), scene);
  }
  return d;
}

}  // namespace

int prepare_sweep_folder(const std::string& dir_name, const std::string& json,
                         const std::vector<std::pair<std::string, std::string>>& rows, bool force) {
  namespace fs = std::filesystem;
  const fs::path dir(dir_name);
  int lock = -1;
  if (fs::exists(dir / "sweep.json")) {
    lock = lock_ensemble_folder(dir);
    const std::string diff = sweep_difference(dir, json, rows);
    if (diff.empty() && !force) return lock;   // the same sweep: continue where it stopped
    if (!force)
      throw std::runtime_error(dir_name + " holds the results of another sweep (it differs in:" + diff +
                               "\n  ); choose another --out, or pass --force to remove those results");
    for (const char* sub : {"rows", "sweep", "logs", ".snakemake"}) fs::remove_all(dir / sub);
    fs::remove(dir / "sweep.json");
  } else if (fs::exists(dir / "scene.toml")) {
    throw std::runtime_error(dir_name + " is the folder of an ensemble (scene.toml), not of a sweep: choose another "
                             "--out for the sweep");
  } else if (fs::exists(dir) && !fs::is_empty(dir) && !force) {
    throw std::runtime_error(dir_name + " exists and is not a sweep folder (no sweep.json): choose another --out");
  }
  fs::create_directories(dir);
  if (lock < 0) lock = lock_ensemble_folder(dir);
  for (const auto& [name, scene] : rows) {
    const fs::path row = dir / "rows" / name;
    fs::create_directories(row);
    const fs::path f = row / "scene.toml";
    if (!fs::exists(f) || file_text(f) != scene) write_file_atomic(f.string(), scene);
  }
  write_file_atomic((dir / "sweep.json").string(), json);   // last: a folder without it was not readied
  return lock;
}

}  // namespace dem
