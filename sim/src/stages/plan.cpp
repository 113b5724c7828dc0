#include "dem/stages/plan.hpp"
#include "dem/io/preparation.hpp"

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
