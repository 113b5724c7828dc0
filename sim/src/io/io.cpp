#include "dem/io/io.hpp"

#include "dem/io/checks.hpp"
#include "dem/contact/contact_model.hpp"
#include "dem/core/errors.hpp"
#include "dem/io/scene.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

#include <cerrno>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace dem {

std::string read_regular_file(const std::string& path, const std::string& what, std::size_t max_bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot read " + what + " '" + path + "' (" + std::strerror(errno) + ")");
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw std::runtime_error(what + " '" + path + "' is not a regular file (a device, FIFO, socket or folder): give "
                             "the path of a " + what + " on disk");
  }
  if (static_cast<std::uintmax_t>(st.st_size) > max_bytes) {
    ::close(fd);
    throw std::runtime_error(what + " '" + path + "' is " + std::to_string(st.st_size) + " bytes, more than the " +
                             std::to_string(max_bytes) + " a " + what + " can be: is it the right file?");
  }
  std::string buf;
  buf.reserve(static_cast<std::size_t>(st.st_size));
  char chunk[1 << 16];
  for (;;) {
    const ssize_t r = ::read(fd, chunk, sizeof chunk);
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      const int e = errno;
      ::close(fd);
      throw std::runtime_error("reading " + what + " '" + path + "' failed (" + std::strerror(e) + ")");
    }
    if (r == 0) break;
    buf.append(chunk, static_cast<std::size_t>(r));
    if (buf.size() > max_bytes) {   // it grew while we read it
      ::close(fd);
      throw std::runtime_error(what + " '" + path + "' grows beyond " + std::to_string(max_bytes) + " bytes while read");
    }
  }
  ::close(fd);
  return buf;
}

State read_packing(const std::string& path, double density) {
  std::istringstream in(read_regular_file(path, "packing file"));
  return parse_packing(in, density, path);
}

namespace {
[[noreturn]] void packing_error(const std::string& origin, int lineno, const std::string& what) {
  throw std::runtime_error(origin + ":" + std::to_string(lineno) + ": " + what);
}
// The numbers of a line, which must be exactly `want` numbers and nothing else.
bool read_numbers(const std::string& text, double* v, int want) {
  std::istringstream ls(text);
  for (int k = 0; k < want; ++k)
    if (!(ls >> v[k])) return false;
  std::string extra;
  return !(ls >> extra);
}
}  // namespace

State parse_packing(std::istream& in, double density, const std::string& path) {
  std::string line;
  State s;
  bool have_cell = false;
  std::vector<double> xs;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    if (line.size() > 4096)
      packing_error(path, lineno, "a line of " + std::to_string(line.size()) + " bytes: a packing line is 'x y z r' "
                    "(is this a packing file?)");
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (line.rfind("##PERIODIC::", 0) == 0) {
      double L[3];
      if (have_cell || !read_numbers(line.substr(12), L, 3) || !(L[0] > 0 && L[1] > 0 && L[2] > 0) ||
          !std::isfinite(L[0] + L[1] + L[2]))
        packing_error(path, lineno, "expected '##PERIODIC:: Lx Ly Lz' (one such line, positive finite lengths)");
      s.box.length = Vec3{L[0], L[1], L[2]};
      have_cell = true;
      continue;
    }
    if (line[0] == '#') continue;
    double v[4];
    if (!read_numbers(line, v, 4))
      packing_error(path, lineno, "expected 'x y z r' (four numbers, metres, nothing else on the line)");
    if (!(v[3] > 0) || !std::isfinite(v[0] + v[1] + v[2] + v[3]))
      packing_error(path, lineno, "radius must be positive and values finite");
    xs.insert(xs.end(), v, v + 4);
  }
  if (!have_cell)
    throw std::runtime_error(path + ": no '##PERIODIC:: Lx Ly Lz' line; only periodic packings "
                             "are supported (YADE: export with the periodic cell)");
  const int n = static_cast<int>(xs.size() / 4);
  if (n < 2) throw std::runtime_error(path + ": fewer than 2 spheres");
  s.resize(n);
  const Vec3 L = s.box.length;
  for (int i = 0; i < n; ++i) {
    Vec3 x{xs[4 * i], xs[4 * i + 1], xs[4 * i + 2]};
    for (int k = 0; k < 3; ++k) {
      const double tol = 1e-9 * L[k];
      if (x[k] < -tol || x[k] > L[k] + tol)
        throw std::runtime_error(path + ": sphere " + std::to_string(i) + " lies outside the "
                                 "periodic cell along axis " + std::to_string(k) +
                                 ": wrap the positions into [0, L) before export");
      x[k] = std::min(std::max(x[k], 0.0), std::nextafter(L[k], 0.0));
    }
    s.position[i] = x;
    s.radius[i] = xs[4 * i + 3];
    s.mass[i] = sphere_mass(s.radius[i], density);
  }
  s.box.length0 = s.box.length;
  return s;
}

void write_packing(const std::string& path, const State& s) {
  validate_state(s, "write_packing " + path);
  if (s.box.tilted())
    throw std::runtime_error("write_packing " + path + ": the cell is tilted (a sheared state), which the packing "
                             "format '##PERIODIC:: Lx Ly Lz' cannot hold: keep the state as a checkpoint (.ckpt)");   // ids a permutation: order[] below is safe
  std::vector<int> order(s.count());
  for (int i = 0; i < s.count(); ++i) order[s.id[i]] = i;
  std::ostringstream out;
  out.precision(17);
  out << "##PERIODIC:: " << s.box.length.x << " " << s.box.length.y << " " << s.box.length.z << "\n";
  for (int a : order) {
    Vec3 x = s.position[a];
    for (int k = 0; k < 3; ++k) {
      x[k] -= s.box.length[k] * std::floor(x[k] / s.box.length[k]);
      if (x[k] >= s.box.length[k]) x[k] = 0;
    }
    out << x.x << " " << x.y << " " << x.z << " " << s.radius[a] << "\n";
  }
  write_file_atomic(path, out.str());
}

double unit_uniform(unsigned long long bits) { return (bits >> 11) * 0x1.0p-53; }

State random_packing(const Model& m, double phi) {
  std::mt19937_64 rng(m.seed);
  State s;
  s.resize(m.count);
  std::vector<double> r(m.count);
  for (auto& ri : r) ri = m.radius_min + (m.radius_max - m.radius_min) * unit_uniform(rng());
  double vp = 0;
  for (double ri : r) vp += 4.0 / 3.0 * M_PI * ri * ri * ri;
  const double L = std::cbrt(vp / phi);
  s.box.length = s.box.length0 = Vec3{L, L, L};
  // Largest first; a cell grid of size 2 r_max finds conflicts.
  std::vector<int> order(m.count);
  for (int i = 0; i < m.count; ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return r[a] > r[b]; });
  const double rmax = *std::max_element(r.begin(), r.end());
  const int nc = std::max(1, static_cast<int>(L / (2 * rmax)));
  const double cs = L / nc;
  std::vector<std::vector<int>> cells(static_cast<size_t>(nc) * nc * nc);
  auto cell_index = [&](int a, int b, int c) {
    a = (a % nc + nc) % nc; b = (b % nc + nc) % nc; c = (c % nc + nc) % nc;
    return (static_cast<size_t>(a) * nc + b) * nc + c;
  };
  const int span = nc < 3 ? 0 : 1;
  for (int idx : order) {
    bool placed = false;
    for (int attempt = 0; attempt < 100000 && !placed; ++attempt) {
      const Vec3 x{L * unit_uniform(rng()), L * unit_uniform(rng()), L * unit_uniform(rng())};
      const int cx = std::min(nc - 1, static_cast<int>(x.x / cs));
      const int cy = std::min(nc - 1, static_cast<int>(x.y / cs));
      const int cz = std::min(nc - 1, static_cast<int>(x.z / cs));
      bool free = true;
      auto test_cell = [&](size_t c) {
        for (int j : cells[c]) {
          Vec3 d = s.position[j] - x;
          for (int k = 0; k < 3; ++k) d[k] -= L * std::round(d[k] / L);
          const double reach = r[idx] + r[j];
          if (dot(d, d) < reach * reach) return false;
        }
        return true;
      };
      if (span == 0) {
        for (size_t c = 0; c < cells.size() && free; ++c) free = test_cell(c);
      } else {
        for (int a = -1; a <= 1 && free; ++a)
          for (int b = -1; b <= 1 && free; ++b)
            for (int c = -1; c <= 1 && free; ++c) free = test_cell(cell_index(cx + a, cy + b, cz + c));
      }
      if (free) {
        s.position[idx] = x;
        cells[cell_index(cx, cy, cz)].push_back(idx);
        placed = true;
      }
    }
    if (!placed)
      throw std::runtime_error("random placement failed at volume fraction " + std::to_string(phi) +
                               ": no free spot after 100000 tries; lower protocol.initial_phi "
                               "(random sequential addition stalls near 0.35-0.4)");
  }
  for (int i = 0; i < m.count; ++i) { s.radius[i] = r[i]; s.mass[i] = sphere_mass(r[i], m.density); }
  return s;
}

// ---- checkpoints ----
// Version 3: magic "DEMCKPT3", the fields below, "END!", then the FNV-1a 64 checksum of every
// byte before it. Version 2 (the same without the checksum) is still read. Version 4
// ("DEMCKPT4"): version 3 with the sheared cell after the list flag (tilt, tilt0, flips,
// tilt_at_build), written only for a state whose cell has a tilt or was sheared since its
// strains were zeroed: every diagonal run still writes the bytes of version 3. Version 5
// ("DEMCKPT5"): version 4 plus the rotations and the per-contact history of a frictional state
// (angular velocities, torques, history width, odd mask, records, their pair ids, the energy
// dissipated by friction), written only for such a state: frictionless runs keep 3 or 4.
namespace {
const char kMagic[8] = {'D', 'E', 'M', 'C', 'K', 'P', 'T', '3'};
const char kMagicV4[8] = {'D', 'E', 'M', 'C', 'K', 'P', 'T', '4'};
const char kMagicV2[8] = {'D', 'E', 'M', 'C', 'K', 'P', 'T', '2'};
const char kMagicV5[8] = {'D', 'E', 'M', 'C', 'K', 'P', 'T', '5'};

std::uint64_t fnv1a(const char* data, std::size_t n) {
  std::uint64_t h = 14695981039346656037ULL;
  for (std::size_t i = 0; i < n; ++i) { h ^= static_cast<unsigned char>(data[i]); h *= 1099511628211ULL; }
  return h;
}

struct Writer {
  std::string buf;
  template <class T> void pod(const T& v) { buf.append(reinterpret_cast<const char*>(&v), sizeof v); }
  void str(const std::string& s) { pod<std::uint64_t>(s.size()); buf += s; }
  template <class T> void vec(const std::vector<T>& v) {
    pod<std::uint64_t>(v.size());
    if (!v.empty()) buf.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  }
};
struct Reader {
  const std::string& buf; size_t pos = 0; std::string path;
  void need(std::uint64_t n) {
    if (n > buf.size() - pos) throw std::runtime_error(path + ": checkpoint is truncated");
  }
  template <class T> T pod() { need(sizeof(T)); T v; std::memcpy(&v, buf.data() + pos, sizeof v); pos += sizeof v; return v; }
  std::string str() { auto n = pod<std::uint64_t>(); need(n); std::string s = buf.substr(pos, n); pos += n; return s; }
  template <class T> std::vector<T> vec() {
    auto n = pod<std::uint64_t>();
    if (n > (buf.size() - pos) / sizeof(T)) throw std::runtime_error(path + ": checkpoint is truncated");
    std::vector<T> v(n);
    if (n > 0) std::memcpy(v.data(), buf.data() + pos, n * sizeof(T));   // data() may be null when n == 0 (UBSan)
    pos += n * sizeof(T);
    return v;
  }
};
}  // namespace

void write_checkpoint(const std::string& path, const Checkpoint& c) {
  validate_state(c.state, "write_checkpoint " + path);
  Writer w;
  const State& st = c.state;
  const Vec3& tb = st.tilt_at_build;
  const bool v5 = st.rotations() || st.history.width > 0;
  const bool v4 = v5 || st.box.sheared() || tb.x != 0 || tb.y != 0 || tb.z != 0;
  w.buf.append(v5 ? kMagicV5 : v4 ? kMagicV4 : kMagic, 8);
  w.str(c.scene_toml);
  w.str(c.label);
  const State& s = c.state;
  w.vec(s.position); w.vec(s.velocity); w.vec(s.force); w.vec(s.radius); w.vec(s.mass); w.vec(s.id);
  w.pod(s.box.length); w.pod(s.box.length0); w.pod(s.box.reference); w.pod(s.box.log_strain); w.pod(s.time); w.pod(s.step);
  w.vec(s.position_at_build); w.pod(s.length_at_build); w.pod<std::uint8_t>(s.list_valid);
  if (v4) {
    w.pod(s.box.tilt); w.pod(s.box.tilt0);
    for (int k = 0; k < 3; ++k) w.pod(s.box.flips[k]);
    w.pod(s.tilt_at_build);
  }
  if (v5) {
    w.vec(s.angular_velocity); w.vec(s.torque);
    w.pod<std::int32_t>(s.history.width); w.pod<std::uint32_t>(s.history.odd);
    w.vec(s.history.values); w.vec(s.history.ids);
    w.pod(s.friction_dissipated);
  }
  w.buf.append("END!", 4);
  w.pod(fnv1a(w.buf.data(), w.buf.size()));
  write_file_atomic(path, w.buf);
}

Checkpoint read_checkpoint(const std::string& path) {
  return parse_checkpoint(read_regular_file(path, "checkpoint"), path);
}

namespace {
// A checkpoint's contact history is of the contact model of its own scene: a record width that
// model does not keep (a file assembled or altered with a valid checksum) would be dropped when
// the state is stepped. A stored scene that does not load is reported where it is used.
void check_history_width(const Checkpoint& c, const std::string& path) {
  if (c.scene_toml.empty() || (c.state.history.width == 0 && c.state.history.values.empty())) return;
  Model m;
  try {
    m = load_scene(c.scene_toml, {}, nullptr, path + " (its scene)");
  } catch (const SceneError&) {
    return;
  }
  const int w = contact::history_width(m.contact);
  if (c.state.history.width != w)
    throw std::runtime_error(path + ": checkpoint is corrupt (its contact history has " +
                             std::to_string(c.state.history.width) + " numbers per contact, but the contact model of "
                             "the scene stored in it keeps " + std::to_string(w) + "): rerun the preparation");
}
}  // namespace

Checkpoint parse_checkpoint(const std::string& buf, const std::string& path) {
  const bool v5 = buf.size() >= 8 && std::memcmp(buf.data(), kMagicV5, 8) == 0;
  const bool v4 = v5 || (buf.size() >= 8 && std::memcmp(buf.data(), kMagicV4, 8) == 0);
  const bool v3 = v4 || (buf.size() >= 8 && std::memcmp(buf.data(), kMagic, 8) == 0);   // v3 and up: checksum
  const bool v2 = buf.size() >= 8 && std::memcmp(buf.data(), kMagicV2, 8) == 0;
  if (!v3 && !v2) {
    if (buf.size() >= 7 && std::memcmp(buf.data(), kMagic, 7) == 0)
      throw std::runtime_error(path + ": checkpoint format version '" + std::string(1, buf[7]) +
                               "' is not readable by this dem (versions 2 to 5 are): rerun the preparation");
    throw std::runtime_error(path + ": not a dem checkpoint (wrong magic; version 3, 4 or 5 expected)");
  }
  if (v3) {
    if (buf.size() < 8 + 12) throw std::runtime_error(path + ": checkpoint is truncated");
    std::uint64_t stored;
    std::memcpy(&stored, buf.data() + buf.size() - 8, 8);
    if (fnv1a(buf.data(), buf.size() - 8) != stored)
      throw std::runtime_error(path + ": checkpoint is corrupt (checksum mismatch: the file was altered or damaged); "
                               "rerun the preparation (dem run SCENE --out DIR --stages prep --force)");
  }
  const std::string body = v3 ? buf.substr(0, buf.size() - 8) : buf;
  Reader r{body, 8, path};
  Checkpoint c;
  c.scene_toml = r.str();
  c.label = r.str();
  State& s = c.state;
  s.position = r.vec<Vec3>(); s.velocity = r.vec<Vec3>(); s.force = r.vec<Vec3>();
  s.radius = r.vec<double>(); s.mass = r.vec<double>(); s.id = r.vec<std::int32_t>();
  s.box.length = r.pod<Vec3>(); s.box.length0 = r.pod<Vec3>(); s.box.reference = r.pod<Vec3>(); s.box.log_strain = r.pod<Vec3>(); s.time = r.pod<double>();
  s.step = r.pod<std::int64_t>();
  s.position_at_build = r.vec<Vec3>(); s.length_at_build = r.pod<Vec3>();
  s.list_valid = r.pod<std::uint8_t>() != 0;
  if (v4) {
    s.box.tilt = r.pod<Vec3>(); s.box.tilt0 = r.pod<Vec3>();
    for (int k = 0; k < 3; ++k) s.box.flips[k] = r.pod<std::int32_t>();
    s.tilt_at_build = r.pod<Vec3>();
  }
  if (v5) {
    s.angular_velocity = r.vec<Vec3>(); s.torque = r.vec<Vec3>();
    s.history.width = r.pod<std::int32_t>(); s.history.odd = r.pod<std::uint32_t>();
    s.history.values = r.vec<double>(); s.history.ids = r.vec<std::int32_t>();
    s.friction_dissipated = r.pod<double>();
    const std::size_t n = s.position.size();
    if ((s.angular_velocity.size() != n && !s.angular_velocity.empty()) || s.torque.size() != s.angular_velocity.size() ||
        s.history.width < 0 || s.history.width > 64 || s.history.ids.size() % 2 != 0 ||
        s.history.values.size() != s.history.ids.size() / 2 * static_cast<std::size_t>(s.history.width) ||
        !std::isfinite(s.friction_dissipated))
      throw std::runtime_error(path + ": checkpoint is corrupt (rotations or contact history do not fit the particles)");
    for (double v : s.history.values)
      if (!std::isfinite(v)) throw std::runtime_error(path + ": checkpoint is corrupt (non-finite contact history)");
    for (const Vec3& w : s.angular_velocity)
      if (!std::isfinite(w.x + w.y + w.z)) throw std::runtime_error(path + ": checkpoint is corrupt (non-finite angular velocity)");
  }
  r.need(4);
  if (body.compare(r.pos, 4, "END!") != 0 || r.pos + 4 != body.size())
    throw std::runtime_error(path + ": checkpoint is corrupt (no end marker where expected)");
  validate_state(s, path);
  if (s.list_valid && s.position_at_build.size() != s.position.size()) s.list_valid = false;
  check_history_width(c, path);
  return c;
}

}  // namespace dem
