// demtk._core: the Python binding of the engine (pybind11). The Python package demtk
// (python/demtk/__init__.py) re-exports it and adds the pure-Python parts (scenes from dicts,
// curve files as pandas). Units are SI throughout, as in the C++ headers.
//
// Arrays: a State's per-particle vectors are viewed, not copied (Vec3 is three doubles, so a
// std::vector<Vec3> is an (N, 3) float64 array). Their buffers do not move while N is fixed (the
// neighbour list's re-sort permutes them in place), so a view stays valid and aliased across
// steps; each view keeps its State alive. Rows are in the engine's (cell-sorted) order, which
// changes at list rebuilds: `ids` says which particle each row is.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "dem/forces/contact_forces.hpp"
#include "dem/contact/registry.hpp"
#include "dem/core/errors.hpp"
#include "dem/core/model.hpp"
#include "dem/core/state.hpp"
#include "dem/engine/engine.hpp"
#include "dem/engine/interrupt.hpp"
#include "dem/forces/neighbor_list.hpp"
#include "dem/io/checks.hpp"
#include "dem/io/io.hpp"
#include "dem/io/scene.hpp"
#include "dem/measure/measure.hpp"
#include "dem/stages/plan.hpp"
#include "dem/stages/protocol.hpp"
#include "demfit/fit.hpp"
#include "demfit/table.hpp"

namespace py = pybind11;
namespace fs = std::filesystem;

namespace {

static_assert(sizeof(dem::Vec3) == 3 * sizeof(double), "Vec3 must be three packed doubles to be viewed as (N, 3)");

py::object g_scene_error, g_blow_up;

// ---------------------------------------------------------------------------------------
// Scene

struct Scene {
  std::shared_ptr<const dem::Model> model;
  std::string toml;     // the resolved scene: every key with its value
  std::string origin;
};

Scene load_text(const std::string& text, const std::vector<std::string>& overrides, const std::string& origin) {
  Scene s;
  s.origin = origin;
  s.model = std::make_shared<const dem::Model>(dem::load_scene(text, overrides, &s.toml, origin));
  return s;
}

Scene load_file(const std::string& path, const std::vector<std::string>& overrides) {
  Scene s;
  s.origin = path;
  s.model = std::make_shared<const dem::Model>(dem::load_scene_file(path, overrides, &s.toml));
  return s;
}

const dem::DeformationMode& find_mode(const dem::Model& m, const std::string& name) {
  for (const auto& mode : m.protocol.modes)
    if (mode.name == name) return mode;
  throw dem::SceneError("mode '" + name + "' is not in this scene's protocol.modes; load the scene with "
                        "set={\"protocol.modes\": [\"" + name + "\"]}");
}

py::array_t<double> mat3(const double a[3][3]) {
  py::array_t<double> out({3, 3});
  auto r = out.mutable_unchecked<2>();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r(i, j) = a[i][j];
  return out;
}

py::array_t<double> sym3(const dem::Sym3& t) {
  const double a[3][3] = {{t.xx, t.xy, t.xz}, {t.xy, t.yy, t.yz}, {t.xz, t.yz, t.zz}};
  return mat3(a);
}

py::array_t<double> vec3(const dem::Vec3& v) {
  py::array_t<double> out(3);
  auto r = out.mutable_unchecked<1>();
  r(0) = v.x; r(1) = v.y; r(2) = v.z;
  return out;
}

py::array_t<double> velgrad_matrix(const dem::VelGrad& L) {
  double a[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) a[i][j] = L.at(i, j);
  return mat3(a);
}

// A velocity gradient [1/s] from Python: None (0), 3 numbers (the diagonal) or a 3x3 upper-triangular matrix.
dem::VelGrad to_velgrad(const py::object& o) {
  if (o.is_none()) return {};
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a) throw py::type_error("velocity_gradient: expected 3 numbers (the diagonal) or a 3x3 matrix [1/s]");
  if (a.ndim() == 1 && a.shape(0) == 3) {
    auto r = a.unchecked<1>();
    return dem::VelGrad(dem::Vec3{r(0), r(1), r(2)});
  }
  if (a.ndim() == 2 && a.shape(0) == 3 && a.shape(1) == 3) {
    auto r = a.unchecked<2>();
    if (r(1, 0) != 0 || r(2, 0) != 0 || r(2, 1) != 0)
      throw py::value_error("velocity_gradient: entries below the diagonal must be 0 (the cell is upper "
                            "triangular; simple shear v_x = gdot z is L[0, 2] = gdot)");
    return dem::VelGrad(dem::Vec3{r(0, 0), r(1, 1), r(2, 2)}, dem::Vec3{r(0, 1), r(0, 2), r(1, 2)});
  }
  throw py::value_error("velocity_gradient: expected shape (3,) or (3, 3)");
}

// ---------------------------------------------------------------------------------------
// State

// One thread at a time steps, measures or writes a State (two threads stepping one Engine freed
// its buffers twice). The thread that holds it may nest (a step() callback that measures).
struct StateUse {
  std::mutex m;
  std::thread::id owner;
  int depth = 0;
};

class UseGuard {
 public:
  explicit UseGuard(const std::shared_ptr<StateUse>& u) : u_(u) {
    std::lock_guard<std::mutex> lock(u_->m);
    const auto me = std::this_thread::get_id();
    if (u_->depth > 0 && u_->owner != me)
      throw std::runtime_error("this State is in use by another thread (an Engine.step, measure or run_* call on it "
                               "is running there): one thread at a time may step or read a State; give each thread "
                               "its own state.copy() and Engine, or serialise the calls with a threading.Lock");
    u_->owner = me;
    ++u_->depth;
  }
  ~UseGuard() {
    std::lock_guard<std::mutex> lock(u_->m);
    --u_->depth;
  }
  UseGuard(const UseGuard&) = delete;
  UseGuard& operator=(const UseGuard&) = delete;

 private:
  std::shared_ptr<StateUse> u_;
};

struct PyState {
  std::shared_ptr<dem::State> s = std::make_shared<dem::State>();
  std::shared_ptr<StateUse> use = std::make_shared<StateUse>();
};

// Values written from Python (a writable view, set_velocities, set_positions, a callback) must be
// finite before the engine steps them: a NaN would be reported as a blow-up blamed on dt, and its
// "last good state" saved as a file that reads back as corrupt.
void check_written(const dem::State& s) {
  auto scan = [&](const std::vector<dem::Vec3>& v, const std::string& what) {
    for (std::size_t i = 0; i < v.size(); ++i)
      if (!std::isfinite(v[i].x) || !std::isfinite(v[i].y) || !std::isfinite(v[i].z)) {
        std::ostringstream o;
        o << "state." << what << " row " << i << " (particle " << (i < s.id.size() ? s.id[i] : -1) << ") is ["
          << v[i].x << ", " << v[i].y << ", " << v[i].z << "]: a non-finite value written from Python (through the "
          << what << " view or set_" << what << "); nothing was stepped: write finite values (a state.copy() taken "
          << "before the write keeps the earlier ones)";
        throw py::value_error(o.str());
      }
  };
  scan(s.position, "positions");
  scan(s.velocity, "velocities");
  scan(s.angular_velocity, "angular_velocities");
}

// Ctrl-C while the engine steps with the GIL released: the poll (every 0.1 s, between two steps)
// takes the GIL and lets Python run its signal handlers; KeyboardInterrupt (or whatever a
// handler raises) propagates from there, the state left as the last full step left it.
void poll_python_signals() {
  py::gil_scoped_acquire acquire;
  if (PyErr_CheckSignals() != 0) throw py::error_already_set();
}

// A view of a vector's buffer, owned by `owner` (the Python State); read-only unless `writable`.
template <class T>
py::array view(std::vector<T>& v, const py::object& owner, bool writable) {
  py::array a;
  if constexpr (std::is_same_v<T, dem::Vec3>)
    a = py::array(py::dtype::of<double>(), {static_cast<py::ssize_t>(v.size()), py::ssize_t(3)},
                  {py::ssize_t(sizeof(dem::Vec3)), py::ssize_t(sizeof(double))}, reinterpret_cast<double*>(v.data()),
                  owner);
  else
    a = py::array(py::dtype::of<T>(), {static_cast<py::ssize_t>(v.size())}, {py::ssize_t(sizeof(T))}, v.data(), owner);
  if (!writable) py::detail::array_proxy(a.ptr())->flags &= ~py::detail::npy_api::NPY_ARRAY_WRITEABLE_;
  return a;
}

// memcpy with a count of 0 still needs valid pointers, and an empty vector's data() may be null
// (UBSan, tests/SANITIZE.md): every copy into a state's arrays goes through here.
void copy_bytes(void* dst, const void* src, std::size_t bytes) {
  if (bytes > 0) std::memcpy(dst, src, bytes);
}

void copy_rows(std::vector<dem::Vec3>& dst, const py::object& src, const char* what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(src);
  if (!a || a.ndim() != 2 || a.shape(1) != 3 || static_cast<std::size_t>(a.shape(0)) != dst.size())
    throw py::value_error(std::string(what) + ": expected an array of shape (" + std::to_string(dst.size()) + ", 3)");
  const double* d = a.data();
  for (std::size_t k = 0; k < 3 * dst.size(); ++k)
    if (!std::isfinite(d[k]))
      throw py::value_error(std::string(what) + ": row " + std::to_string(k / 3) + " has a non-finite value (" +
                            std::to_string(d[k]) + "); nothing was copied: give finite values");
  copy_bytes(static_cast<void*>(dst.data()), a.data(), dst.size() * sizeof(dem::Vec3));
}

std::vector<double> to_doubles(const py::object& o, std::size_t n, const char* what) {
  auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(o);
  if (!a || a.ndim() != 1 || (n && static_cast<std::size_t>(a.shape(0)) != n))
    throw py::value_error(std::string(what) + ": expected a 1-d array" + (n ? " of " + std::to_string(n) + " values" : ""));
  return std::vector<double>(a.data(), a.data() + a.shape(0));
}

PyState state_from_arrays(const py::object& positions, const py::object& radii, const py::object& box,
                          const py::object& density, const py::object& masses, const py::object& velocities,
                          const py::object& ids) {
  PyState ps;
  dem::State& s = *ps.s;
  const std::vector<double> r = to_doubles(radii, 0, "radii");
  const int n = static_cast<int>(r.size());
  s.resize(n);
  s.radius = r;
  copy_rows(s.position, positions, "positions");
  const std::vector<double> L = to_doubles(box, 3, "box");
  s.box.length = s.box.length0 = s.box.reference = dem::Vec3{L[0], L[1], L[2]};
  if (!masses.is_none()) s.mass = to_doubles(masses, n, "masses");
  else if (!density.is_none()) {
    const double rho = density.cast<double>();
    for (int i = 0; i < n; ++i) s.mass[i] = dem::sphere_mass(s.radius[i], rho);
  } else
    throw py::value_error("State.from_arrays: give density [kg/m^3] (or a scene) or masses [kg]");
  if (!velocities.is_none()) copy_rows(s.velocity, velocities, "velocities");
  if (!ids.is_none()) {
    auto a = py::array_t<std::int32_t, py::array::c_style | py::array::forcecast>::ensure(ids);
    if (!a || a.ndim() != 1 || a.shape(0) != n) throw py::value_error("ids: expected " + std::to_string(n) + " integers");
    copy_bytes(s.id.data(), a.data(), n * sizeof(std::int32_t));
  } else
    for (int i = 0; i < n; ++i) s.id[i] = i;
  s.list_valid = false;
  dem::validate_state(s, "State.from_arrays");
  return ps;
}

// ---------------------------------------------------------------------------------------
// Measurement: the curve columns (in curve_columns() order) and the tensors.

// Every column the CLI writes for this measurement (the column table, measure.hpp: the Every
// group, and the Rotations group for a model with rotations), in file order.
py::dict columns_dict(const dem::Measurement& m) {
  py::dict d;
  for (const dem::CurveColumn& c : dem::column_table()) {
    if (!c.value || (c.group == dem::ColumnGroup::Rotations && !m.frictional)) continue;
    const double v = c.value(m);
    if (c.integer) d[py::str(c.name)] = py::int_(static_cast<long long>(v));
    else d[py::str(c.name)] = py::float_(v);
  }
  return d;
}

// ---------------------------------------------------------------------------------------
// Engine

struct PyEngine {
  Scene scene;
  py::object state_obj;                 // the Python State (keeps the arrays' owner alive)
  std::shared_ptr<dem::State> state;
  std::shared_ptr<StateUse> use;
  std::unique_ptr<dem::Engine> engine;
  dem::VelGrad last_rate;
  bool stop_requested = false;

  PyEngine(const Scene& sc, py::object st, bool forces_are_current) : scene(sc), state_obj(std::move(st)) {
    state = state_obj.cast<PyState&>().s;
    use = state_obj.cast<PyState&>().use;
    UseGuard guard(use);
    check_written(*state);
    make(forces_are_current);
  }
  void make(bool forces_are_current) {
    engine.reset();
    engine = std::make_unique<dem::Engine>(*scene.model, *state, forces_are_current);
  }
  // A state marked invalid (positions or radii set from Python) gets a fresh list and forces.
  void ensure() {
    if (!state->list_valid || !engine) make(false);
  }
};

[[noreturn]] void raise_blow_up(const dem::BlowUp& e, const dem::State* last_good) {
  py::object exc = g_blow_up(py::str(e.what()));
  if (last_good) {
    PyState ps;
    *ps.s = *last_good;
    exc.attr("last_good_state") = py::cast(std::move(ps));
  } else
    exc.attr("last_good_state") = py::none();
  const std::string msg = e.what();
  const auto at = msg.rfind("was saved as ");
  exc.attr("checkpoint") = at == std::string::npos ? py::object(py::none()) : py::object(py::str(msg.substr(at + 13)));
  PyErr_SetObject(g_blow_up.ptr(), exc.ptr());
  throw py::error_already_set();
}

constexpr long kSignalCheckSteps = 5000;

// Steps n times with the GIL released; a callback (with the GIL) every `every` steps may stop
// the run by returning True or calling engine.stop(). Returns the steps taken.
long run_steps(PyEngine& pe, py::object self, long n, const dem::VelGrad& L, const py::object& callback, long every,
               double every_strain, bool keep_last_good) {
  UseGuard guard(pe.use);
  check_written(*pe.state);
  pe.ensure();
  pe.stop_requested = false;
  pe.last_rate = L;
  dem::State last_good;
  if (keep_last_good) last_good = *pe.state;
  const bool has_cb = !callback.is_none();
  if (has_cb && every <= 0 && every_strain <= 0) throw py::value_error("callback: give every > 0 steps or every_strain > 0");
  long done = 0;
  double last_eps = every_strain > 0 ? dem::deviatoric_magnitude_eig(dem::log_strain_tensor(pe.state->box)) : 0;
  try {
    while (done < n && !pe.stop_requested) {
      long chunk = n - done;
      if (has_cb && every > 0) chunk = std::min(chunk, every - (done % every));
      chunk = std::min(chunk, kSignalCheckSteps);   // Ctrl-C is seen between chunks
      bool call = false;
      {
        py::gil_scoped_release release;
        const dem::InterruptPoll poll(poll_python_signals);
        if (every_strain > 0 && has_cb) {
          for (long k = 0; k < chunk; ++k) {
            pe.engine->step(L);
            ++done;
            const double eps = dem::deviatoric_magnitude_eig(dem::log_strain_tensor(pe.state->box));
            if (std::fabs(eps - last_eps) >= every_strain) { last_eps = eps; call = true; break; }
            if (every > 0 && done % every == 0) { call = true; break; }
          }
        } else {
          for (long k = 0; k < chunk; ++k) pe.engine->step(L);
          done += chunk;
          call = has_cb && every > 0 && done % every == 0;
        }
      }
      if (call) {
        if (PyErr_CheckSignals() != 0) throw py::error_already_set();
        py::object r = callback(self);
        if (!r.is_none() && r.cast<bool>()) pe.stop_requested = true;
        check_written(*pe.state);   // the callback may have written through a view
        pe.ensure();   // the callback may have set positions
        if (keep_last_good) last_good = *pe.state;
      } else if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    }
  } catch (const dem::BlowUp& e) {
    raise_blow_up(e, keep_last_good ? &last_good : nullptr);
  }
  return done;
}

py::dict contacts(PyEngine& pe) {
  UseGuard guard(pe.use);
  pe.ensure();
  const dem::State& s = *pe.state;
  const auto& list = pe.engine->neighbor_list();
  const dem::VelGrad& L = pe.last_rate;
  std::vector<int> ii, jj;
  std::vector<dem::Vec3> branch, normal, force, ft, xi_t, xi_r;
  std::vector<double> overlap, fn, xi_o;
  std::vector<bool> sliding;
  // The model's forces (normal + tangential with friction) at the state's velocities and springs.
  dem::contact::for_each_contact_force(*pe.scene.model, s, list, L, [&](const dem::contact::ContactForce& c) {
    ii.push_back(c.i); jj.push_back(c.j);
    branch.push_back(c.d); normal.push_back(c.n); force.push_back(c.n * c.fn + c.ft);
    overlap.push_back(c.delta); fn.push_back(c.fn);
    ft.push_back(c.ft); sliding.push_back(c.sliding);
    xi_t.push_back(c.spring_tangential); xi_r.push_back(c.spring_rolling); xi_o.push_back(c.spring_twisting);
  });
  const py::ssize_t c = static_cast<py::ssize_t>(ii.size());
  auto ids = [&](const std::vector<int>& idx) {
    py::array_t<std::int32_t> a(c);
    auto r = a.mutable_unchecked<1>();
    for (py::ssize_t k = 0; k < c; ++k) r(k) = s.id[idx[k]];
    return a;
  };
  auto rows = [&](const std::vector<int>& idx) {
    py::array_t<std::int64_t> a(c);
    auto r = a.mutable_unchecked<1>();
    for (py::ssize_t k = 0; k < c; ++k) r(k) = idx[k];
    return a;
  };
  auto vecs = [&](const std::vector<dem::Vec3>& v) {
    py::array_t<double> a({c, py::ssize_t(3)});
    if (c) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(dem::Vec3));
    return a;
  };
  auto scal = [&](const std::vector<double>& v) {
    py::array_t<double> a(c);
    if (c) std::memcpy(a.mutable_data(), v.data(), v.size() * sizeof(double));
    return a;
  };
  py::dict d;
  d["id_i"] = ids(ii); d["id_j"] = ids(jj);
  d["row_i"] = rows(ii); d["row_j"] = rows(jj);
  d["branch"] = vecs(branch); d["normal"] = vecs(normal);
  d["overlap"] = scal(overlap); d["force_normal"] = scal(fn); d["force"] = vecs(force);
  d["force_tangential"] = vecs(ft);
  py::array_t<bool> sl(c);
  for (py::ssize_t k = 0; k < c; ++k) sl.mutable_at(k) = sliding[static_cast<std::size_t>(k)];
  d["sliding"] = sl;
  d["spring_tangential"] = vecs(xi_t); d["spring_rolling"] = vecs(xi_r); d["spring_twisting"] = scal(xi_o);
  return d;
}

// ---------------------------------------------------------------------------------------
// Stage runners (the CLI's, reused).

template <class F>
auto nogil_blowup(F&& f) {
  try {
    py::gil_scoped_release release;
    const dem::InterruptPoll poll(poll_python_signals);
    return f();
  } catch (const dem::BlowUp& e) {
    raise_blow_up(e, nullptr);
  }
}

void check_out(const std::string& out, bool force) {
  if (!force && fs::exists(out))
    throw std::runtime_error(out + " exists; pass force=True to overwrite it");
}

// A Python callback on_checkpoint(phi, state_copy), called from a stage runner without the GIL.
std::function<void(double, const dem::State&)> checkpoint_callback(const py::object& on_checkpoint) {
  if (on_checkpoint.is_none()) return nullptr;
  return [on_checkpoint](double phi, const dem::State& now) {
    py::gil_scoped_acquire acquire;
    PyState copy;
    *copy.s = now;
    on_checkpoint(phi, copy);
  };
}

long run_mode(const Scene& sc, PyState& ps, const std::string& mode, const std::string& out, const std::string& name,
              bool quiet, bool force, bool check) {
  const dem::Model& model = *sc.model;
  const dem::DeformationMode& m = find_mode(model, mode);
  check_out(out, force);
  UseGuard guard(ps.use);
  check_written(*ps.s);
  if (check) dem::check_packing(model, *ps.s, "state");
  return nogil_blowup([&] { return static_cast<long>(dem::run_mode(model, *ps.s, m, name, dem::StageOutput{out, "", "", quiet})); });
}

dem::StopKind stop_kind(const std::string& s) {
  if (s == "phi_up") return dem::StopKind::VolumeFractionUp;
  if (s == "phi_down") return dem::StopKind::VolumeFractionDown;
  if (s == "eps_d") return dem::StopKind::DeviatoricStrain;
  if (s == "relaxed") return dem::StopKind::Relaxed;
  throw py::value_error("stop: one of 'phi_up', 'phi_down', 'eps_d', 'relaxed' (got '" + s + "')");
}

long run_stage_py(const Scene& sc, PyState& ps, const std::string& name, const py::object& velocity_gradient,
                  const std::string& stop, double target, const std::vector<double>& checkpoint_phis,
                  const py::object& on_checkpoint, double ke_ratio, double max_time, const std::string& out,
                  const std::string& vtk_dir, bool quiet, bool force) {
  check_out(out, force);
  UseGuard guard(ps.use);
  check_written(*ps.s);
  dem::StageSpec spec;
  spec.name = name;
  spec.gradient = to_velgrad(velocity_gradient);
  spec.stop = stop_kind(stop);
  spec.target = target;
  spec.checkpoint_phis = checkpoint_phis;
  spec.ke_ratio = ke_ratio;
  spec.max_time = max_time;
  const auto cb = checkpoint_callback(on_checkpoint);
  return nogil_blowup([&] {
    return static_cast<long>(dem::run_stage(*sc.model, *ps.s, spec, dem::StageOutput{out, vtk_dir, "", quiet}, cb));
  });
}

// One stage of the scene's preparation list: run_prep_stage, as run_protocol runs it.
long run_prep_stage(const Scene& sc, PyState& ps, const std::string& stage, const std::string& out,
                    const py::object& on_checkpoint, bool quiet, bool force) {
  const dem::Model& model = *sc.model;
  const dem::PrepStage* st = nullptr;
  std::string names;
  for (const auto& s : model.protocol.preparation) {
    names += (names.empty() ? "" : ", ") + s.name;
    if (s.name == stage) st = &s;
  }
  if (!st) throw dem::SceneError("preparation stage '" + stage + "' is not in this scene (its stages: " + names + ")");
  check_out(out, force);
  UseGuard guard(ps.use);
  check_written(*ps.s);
  const auto cb = checkpoint_callback(on_checkpoint);
  const dem::SaveCheckpoint save = [&](const std::string&, double phi, const dem::State& now) { if (cb) cb(phi, now); };
  const long steps = nogil_blowup([&] {
    return static_cast<long>(dem::run_prep_stage(model, *st, *ps.s, dem::StageOutput{out, "", "", quiet}, save));
  });
  return std::max(steps, 0L);   // -1: skipped
}

void run_protocol(const Scene& sc, const std::string& out, const std::string& stages, bool force, bool quiet) {
  dem::RunOptions opt;
  opt.out_dir = out;
  opt.stages = stages;
  opt.force = force;
  opt.scene_toml = sc.toml;
  opt.command_line = "demtk.run_protocol(" + sc.origin + ", out=" + out + ", stages=" + stages + ")";
  opt.quiet = quiet;
  nogil_blowup([&] { dem::run_protocol(*sc.model, opt); return 0; });
}

// The binding of the module's doc, errors and version.
void def_module(py::module_& m) {
  m.doc() = "demtk._core: the compiled part of demtk (use `import demtk`).";

  g_scene_error = py::exception<dem::SceneError>(m, "SceneError", PyExc_ValueError);
  g_blow_up = py::exception<dem::BlowUp>(m, "BlowUp", PyExc_RuntimeError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const dem::SceneError& e) {
      PyErr_SetString(g_scene_error.ptr(), e.what());
    } catch (const dem::BlowUp& e) {
      py::object exc = g_blow_up(py::str(e.what()));
      exc.attr("last_good_state") = py::none();
      exc.attr("checkpoint") = py::none();
      PyErr_SetObject(g_blow_up.ptr(), exc.ptr());
    }
  });
  m.attr("version") = DEM_VERSION;
  m.def("_contact_models_json", [] { return dem::contact::registry_json().dump(); },
        "the contact sub-model registry as JSON text (demtk.contact_models() parses it)");
}

// The binding of Scene, its loaders.
void def_scene(py::module_& m) {
  // ---- Scene
  py::class_<Scene>(m, "Scene", "A validated scene (the C++ Model): immutable. Build it with demtk.load_scene().")
      .def_property_readonly("toml", [](const Scene& s) { return s.toml; },
                             "the resolved scene as TOML text: every key with the value used")
      .def_property_readonly("origin", [](const Scene& s) { return s.origin; }, "where the scene came from (file or text)")
      .def_property_readonly("count", [](const Scene& s) { return s.model->count; }, "particles.count N")
      .def_property_readonly("radius_min", [](const Scene& s) { return s.model->radius_min; }, "[m]")
      .def_property_readonly("radius_max", [](const Scene& s) { return s.model->radius_max; }, "[m]")
      .def_property_readonly("density", [](const Scene& s) { return s.model->density; }, "[kg/m^3]")
      .def_property_readonly("stiffness", [](const Scene& s) { return s.model->contact.reference_stiffness(); },
                             "k [N/m]: the normal sub-model's reference stiffness (k of the linear law, k1 of Luding's)")
      .def_property_readonly("damping", [](const Scene& s) { return s.model->contact.time_step_damping(); },
                             "gamma [kg/s]: the normal dashpot")
      .def_property_readonly("contact",
                             [](const Scene& s) {
                               const dem::ContactLaw& law = s.model->contact;
                               py::dict models, values;
                               for (dem::ContactSlot slot : {dem::ContactSlot::Normal, dem::ContactSlot::Tangential,
                                                             dem::ContactSlot::Rolling, dem::ContactSlot::Twisting})
                                 models[py::str(dem::contact::slot_name(slot))] = law.model(slot);
                               for (const auto& [k, v] : law.values()) values[py::str("contact." + k)] = v;
                               py::dict d;
                               d["models"] = models;
                               d["values"] = values;
                               return d;
                             },
                             "the contact model: {'models': slot -> sub-model name, 'values': 'contact.KEY' -> value} "
                             "(demtk.contact_models() describes every sub-model and key)")
      .def_property_readonly("background_damping", [](const Scene& s) { return s.model->background_damping; },
                             "gamma_b [kg/s]")
      .def_property_readonly("t_c", [](const Scene& s) { return s.model->t_contact; },
                             "contact duration of two radius_min spheres [s]")
      .def_property_readonly("e", [](const Scene& s) { return s.model->restitution; },
                             "restitution coefficient of two radius_min spheres [-]")
      .def_property_readonly("dt", [](const Scene& s) { return s.model->dt; }, "time step [s] = dt_over_tc * t_c")
      .def_property_readonly("threads", [](const Scene& s) { return s.model->threads; },
                             "integration.threads (0: all available)")
      .def_property_readonly("deviatoric_rate", [](const Scene& s) { return s.model->protocol.deviatoric_rate; },
                             "mode rate [1/s] (protocol.deviatoric_rate_tc / t_c)")
      .def_property_readonly("compress_rate", [](const Scene& s) { return s.model->protocol.compress_rate; },
                             "isotropic compression rate per axis [1/s]")
      .def_property_readonly("cycle_rate", [](const Scene& s) { return s.model->protocol.cycle_rate; },
                             "isotropic rate of the cycle [1/s]")
      .def_property_readonly("eps_d_max", [](const Scene& s) { return s.model->protocol.eps_d_max; },
                             "deviatoric runs stop at this eps_d [-]")
      .def_property_readonly("modes", [](const Scene& s) {
            std::vector<std::string> v;
            for (const auto& mode : s.model->protocol.modes) v.push_back(mode.name);
            return v;
          }, "names of protocol.modes (modes and [paths])")
      .def_property_readonly("preparation", [](const Scene& s) {
            std::vector<std::string> v;
            for (const auto& st : s.model->protocol.preparation) v.push_back(st.name);
            return v;
          }, "names of the preparation stages in order")
      .def("velocity_gradient", [](const Scene& s, const std::string& mode, py::object rate) {
            const dem::DeformationMode* m = nullptr;
            dem::DeformationMode builtin;
            for (const auto& x : s.model->protocol.modes) if (x.name == mode) m = &x;
            if (!m && dem::builtin_mode(mode, &builtin)) m = &builtin;
            if (!m) throw dem::SceneError("mode '" + mode + "' is neither built in nor in this scene's protocol.modes");
            if (!m->path.empty()) throw dem::SceneError("'" + mode + "' is a loading path, not a constant velocity gradient");
            const double r = rate.is_none() ? s.model->protocol.deviatoric_rate : rate.cast<double>();
            return velgrad_matrix(m->shape * r);
          }, py::arg("mode"), py::arg("rate") = py::none(),
          "The velocity gradient L [1/s] (3x3) of a mode at `rate` [1/s] (default: the scene's deviatoric_rate), "
          "exactly as `dem mode` applies it.")
      .def("mode_steps", [](const Scene& s, const std::string& mode) { return dem::mode_steps(*s.model, find_mode(*s.model, mode)); },
           "estimated steps of a mode or path of protocol.modes")
      .def("__repr__", [](const Scene& s) {
        std::ostringstream o;
        o << "<demtk.Scene " << s.origin << ": N=" << s.model->count << " t_c=" << s.model->t_contact
          << " s dt=" << s.model->dt << " s>";
        return o.str();
      });
  m.def("_load_scene_text", &load_text, py::arg("text"), py::arg("overrides"), py::arg("origin"));
  m.def("_load_scene_file", &load_file, py::arg("path"), py::arg("overrides"));
}

// The binding of Box.
void def_box(py::module_& m) {
  // ---- Box (a copy; the state's box is changed only by the engine)
  py::class_<dem::Box>(m, "Box", "The periodic cell (a copy of the state's box). Lengths [m], tilt [m], strains [-].")
      .def_property_readonly("lengths", [](const dem::Box& b) { return vec3(b.length); }, "edge lengths L_x, L_y, L_z [m]")
      .def_property_readonly("lengths0", [](const dem::Box& b) { return vec3(b.length0); },
                             "edge lengths when strains were last zeroed [m]")
      .def_property_readonly("tilt", [](const dem::Box& b) { return vec3(b.tilt); }, "(xy, xz, yz) tilt [m]")
      .def_property_readonly("volume", &dem::Box::volume, "[m^3]")
      .def_property_readonly("true_strain", [](const dem::Box& b) { return vec3(b.true_strain()); },
                             "ln(L/L0) per axis [-], extension positive")
      .def_property_readonly("log_strain", [](const dem::Box& b) { return vec3(b.log_strain); },
                             "accumulated true strain since the reference [-]")
      .def_property_readonly("strain_tensor", [](const dem::Box& b) { return sym3(dem::log_strain_tensor(b)); },
                             "logarithmic strain 0.5 ln(F F^T) since strains were zeroed (3x3) [-]")
      .def_property_readonly("deformation_gradient", [](const dem::Box& b) {
            double F[3][3];
            b.deformation_gradient(F);
            return mat3(F);
          }, "F (3x3) since strains were zeroed [-]")
      .def_property_readonly("cell", [](const dem::Box& b) {
            const double H[3][3] = {{b.length.x, b.tilt.x, b.tilt.y}, {0, b.length.y, b.tilt.z}, {0, 0, b.length.z}};
            return mat3(H);
          }, "cell matrix H (columns: the lattice vectors) [m]")
      .def_property_readonly("flips", [](const dem::Box& b) { return std::vector<int>{b.flips[0], b.flips[1], b.flips[2]}; },
                             "(xy, xz, yz) remaps of a sheared cell to its most orthogonal equivalent so far");
}

// The binding of State and the packing readers.
void def_state(py::module_& m) {
  // ---- State
  py::class_<PyState>(m, "State",
                      "Particles and box. Array properties are numpy views of the engine's memory (no copy), rows "
                      "in the engine's cell-sorted order (`ids` maps rows to particles). velocities is writable; "
                      "positions, radii, masses, ids and forces are read-only: change positions with "
                      "set_positions(), which makes the next step rebuild the neighbour list and the forces.")
      .def_static("from_arrays", &state_from_arrays, py::arg("positions"), py::arg("radii"), py::arg("box"),
                  py::arg("density") = py::none(), py::arg("masses") = py::none(), py::arg("velocities") = py::none(),
                  py::arg("ids") = py::none(),
                  "A state from positions (N, 3) [m] inside [0, L), radii (N) [m], box lengths (3) [m], and "
                  "density [kg/m^3] or masses (N) [kg]; velocities (N, 3) [m/s] (default 0), ids (default 0..N-1).")
      .def_property_readonly("count", [](const PyState& p) { return p.s->count(); }, "number of particles N")
      .def_property_readonly("positions", [](py::object self) { return view(self.cast<PyState&>().s->position, self, false); },
                             "(N, 3) [m], read-only view")
      .def_property_readonly("velocities", [](py::object self) { return view(self.cast<PyState&>().s->velocity, self, true); },
                             "(N, 3) fluctuation velocities (relative to the affine flow) [m/s], writable view")
      .def_property_readonly("forces", [](py::object self) { return view(self.cast<PyState&>().s->force, self, false); },
                             "(N, 3) total force of the last evaluation [N], read-only view")
      .def_property_readonly("angular_velocities", [](py::object self) { return view(self.cast<PyState&>().s->angular_velocity, self, true); },
                             "(N, 3) [rad/s], writable view; (0, 3) unless the contact model rotates (friction), "
                             "sized when an Engine is built on the state: take the view after that")
      .def_property_readonly("torques", [](py::object self) { return view(self.cast<PyState&>().s->torque, self, false); },
                             "(N, 3) torque of the last evaluation [N m], read-only view; (0, 3) without rotations")
      .def_property_readonly("radii", [](py::object self) { return view(self.cast<PyState&>().s->radius, self, false); },
                             "(N) [m], read-only view")
      .def_property_readonly("masses", [](py::object self) { return view(self.cast<PyState&>().s->mass, self, false); },
                             "(N) [kg], read-only view")
      .def_property_readonly("ids", [](py::object self) { return view(self.cast<PyState&>().s->id, self, false); },
                             "(N) int32 original particle index of each row, read-only view")
      .def_property_readonly("box", [](const PyState& p) { return p.s->box; }, "a copy of the box (demtk.Box)")
      .def_property_readonly("time", [](const PyState& p) { return p.s->time; }, "simulated time [s]")
      .def_property_readonly("step", [](const PyState& p) { return p.s->step; }, "steps taken since the state began")
      .def_property_readonly("volume_fraction", [](const PyState& p) { return p.s->volume_fraction(); },
                             "sphere volume / cell volume [-]")
      .def_property_readonly("kinetic_energy", [](const PyState& p) { return p.s->kinetic_energy(); }, "[J]")
      .def_property_readonly("list_valid", [](const PyState& p) { return p.s->list_valid; },
                             "False: the next step builds a fresh neighbour list (and sorts the rows)")
      .def("set_positions", [](PyState& p, const py::object& x) {
            UseGuard guard(p.use);
            copy_rows(p.s->position, x, "positions");
            p.s->list_valid = false;
          }, py::arg("positions"),
          "Copies positions (N, 3) [m] (rows in the current order) and marks the neighbour list invalid: the "
          "next step rebuilds it and the forces.")
      .def("set_velocities", [](PyState& p, const py::object& v) {
             UseGuard guard(p.use);
             copy_rows(p.s->velocity, v, "velocities");
           },
           py::arg("velocities"), "Copies velocities (N, 3) [m/s] (rows in the current order).")
      .def("invalidate", [](PyState& p) { p.s->list_valid = false; },
           "Makes the next step rebuild the neighbour list and the forces (after writing through a view).")
      .def("zero_strain", [](PyState& p) {
            UseGuard guard(p.use);
            p.s->box.zero_strain();
            p.s->box.reference = p.s->box.length;
            p.s->box.log_strain = dem::Vec3{0, 0, 0};
          }, "Zeroes the box strains here, as every stage runner does at a stage start (then Engine gives `dem mode`'s steps).")
      .def("copy", [](const PyState& p) { UseGuard guard(p.use); PyState c; *c.s = *p.s; return c; }, "an independent copy")
      .def("save_packing", [](const PyState& p, const std::string& path) { UseGuard guard(p.use); dem::write_packing(path, *p.s); },
           py::arg("path"), "YADE text packing (17 digits, original id order; positions and radii only)")
      .def("save_checkpoint", [](const PyState& p, const std::string& path, py::object scene, const std::string& label) {
            std::string toml;
            if (!scene.is_none()) toml = scene.cast<const Scene&>().toml;
            UseGuard guard(p.use);
            dem::write_checkpoint(path, dem::Checkpoint{toml, label, *p.s});
          }, py::arg("path"), py::arg("scene") = py::none(), py::arg("label") = "",
          "bit-exact checkpoint (format of `dem`): the whole state with its neighbour-list reference")
      .def("check_against", [](const PyState& p, const Scene& sc, const std::string& origin) {
            dem::check_packing(*sc.model, *p.s, origin);
          }, py::arg("scene"), py::arg("origin") = "state",
          "the checks `dem mode` makes on a packing (radius bounds, coincident centres, overlaps); raises RuntimeError")
      .def("__repr__", [](const PyState& p) {
        std::ostringstream o;
        o << "<demtk.State N=" << p.s->count() << " phi=" << p.s->volume_fraction() << " step=" << p.s->step << ">";
        return o.str();
      });

  m.def("read_packing", [](const std::string& path, double density) {
        PyState p;
        *p.s = dem::read_packing(path, density);
        return p;
      }, py::arg("path"), py::arg("density"), "A YADE-format text packing; masses from density [kg/m^3].");
  m.def("_read_checkpoint", [](const std::string& path) {
        dem::Checkpoint c = dem::read_checkpoint(path);
        PyState p;
        *p.s = std::move(c.state);
        return py::make_tuple(p, c.scene_toml, c.label);
      }, py::arg("path"));
  m.def("random_packing", [](const Scene& sc, double phi) {
        PyState p;
        *p.s = dem::random_packing(*sc.model, phi);
        return p;
      }, py::arg("scene"), py::arg("phi"), "random non-overlapping placement of the scene's N spheres (seeded)");
}

// The binding of Measurement and the column table.
void def_measurement(py::module_& m) {
  // ---- Measurement
  py::class_<dem::Measurement>(m, "Measurement",
                               "What measure() returns: `columns` (every curve column by its CSV name), the tensors.")
      .def_property_readonly("columns", &columns_dict, "dict: every numeric curve column (names with units, as the CSV)")
      .def("__getitem__", [](const dem::Measurement& me, const std::string& k) {
        py::dict d = columns_dict(me);
        if (!d.contains(k)) throw py::key_error(k);
        return py::object(d[py::str(k)]);
      })
      .def("keys", [](const dem::Measurement& me) { return columns_dict(me).attr("keys")(); },
           "the curve column names, with their units in the names (_Pa, _J, _s; others dimensionless)")
      .def_property_readonly("stress", [](const dem::Measurement& me) { return sym3(me.stress); },
                             "3x3 [Pa], compression positive, contact + kinetic")
      .def_property_readonly("stress_kinetic", [](const dem::Measurement& me) { return sym3(me.stress_kinetic); }, "3x3 [Pa]")
      .def_property_readonly("fabric", [](const dem::Measurement& me) { return sym3(me.fabric); }, "3x3 [-]")
      .def_property_readonly("strain_tensor", [](const dem::Measurement& me) { return sym3(me.strain_tensor); },
                             "log strain 3x3 since the stage start [-]")
      .def("row", [](const dem::Measurement& me) { return dem::curve_row(me); },
           "the CSV row `dem` writes for it (without the stage column)");
  m.def("curve_columns",
        [](bool rotations) {
          std::vector<std::string> c = dem::curve_columns();
          if (rotations) c.insert(c.end(), dem::friction_columns().begin(), dem::friction_columns().end());
          return c;
        },
        py::arg("rotations") = false,
        "the numeric curve columns in file order (the column table, measure.hpp); rotations=True adds those of a "
        "model with rotations (friction); the file's last column, `stage`, is text");
  m.def("column_table",
        [] {
          py::list out;
          for (const dem::CurveColumn& c : dem::column_table()) {
            py::dict d;
            d["name"] = c.name;
            d["unit"] = c.unit;
            d["meaning"] = c.meaning;
            d["group"] = dem::group_name(c.group);
            out.append(d);
          }
          return out;
        },
        "every curve column: name, unit, meaning, group ('every', 'rotations': models with rotations, 'path', "
        "'path_sheared')");
}

// The binding of Engine.
void def_engine(py::module_& m) {
  // ---- Engine
  py::class_<PyEngine>(m, "Engine",
                       "Engine(scene, state): the C++ time stepper over a state (modified in place). "
                       "step() releases the GIL; threads as integration.threads.")
      .def(py::init([](const Scene& sc, py::object st, bool forces_are_current) {
             if (!py::isinstance<PyState>(st)) throw py::type_error("Engine(scene, state): state must be a demtk.State");
             return std::make_unique<PyEngine>(sc, st, forces_are_current);
           }),
           py::arg("scene"), py::arg("state"), py::arg("forces_are_current") = false,
           "Binds to the state: a valid neighbour-list reference (checkpoint) is restored, else a fresh list is built "
           "(rows wrapped and re-sorted). Forces are evaluated unless forces_are_current.")
      .def("step", [](py::object self, long n, py::object L, py::object callback, long every, double every_strain,
                      bool keep_last_good) {
            PyEngine& pe = self.cast<PyEngine&>();
            return run_steps(pe, self, n, to_velgrad(L), callback, every, every_strain, keep_last_good);
          }, py::arg("n") = 1, py::arg("velocity_gradient") = py::none(), py::arg("callback") = py::none(),
          py::arg("every") = 0, py::arg("every_strain") = 0.0, py::arg("keep_last_good") = true,
          "Runs n steps of dt with the velocity gradient [1/s] (3 numbers: the diagonal, or a 3x3 upper-triangular "
          "matrix; None: a fixed box), the GIL released. callback(engine) runs every `every` steps (or whenever "
          "eps_d of the box changed by every_strain); returning True or calling engine.stop() ends the run. "
          "Returns the steps taken. A blow-up raises demtk.BlowUp with .last_good_state (the state at the "
          "last callback, or at the call; keep_last_good=False skips that copy, for loops of short calls).")
      .def("stop", [](PyEngine& pe) { pe.stop_requested = true; }, "ends the running step() after the current callback")
      .def("measure", [](PyEngine& pe, py::object L) {
            UseGuard guard(pe.use);
            pe.ensure();
            const dem::VelGrad g = L.is_none() ? pe.last_rate : to_velgrad(L);
            return dem::measure(*pe.scene.model, *pe.state, pe.engine->neighbor_list(), g);
          }, py::arg("velocity_gradient") = py::none(),
          "Measures the state as `dem` does for a curve row (the velocity gradient of the last step unless given).")
      .def("contacts", &contacts,
           "Per-contact arrays (a dict): id_i, id_j (particle ids), row_i, row_j (rows now), branch (N_c, 3) from i to "
           "j's image [m], normal (unit, i to j), overlap [m], force_normal [N] (the contact law with the last step's "
           "velocity gradient), force (N_c, 3) on j [N] (minus it on i), force_tangential (N_c, 3) on j [N] (its "
           "tangential part: the spring and dashpot, capped at mu force_normal), sliding (bool: at the Coulomb limit "
           "at the last step), spring_tangential (N_c, 3) [m] (the Cundall-Strack spring xi: -k_t xi is its force), "
           "spring_rolling (N_c, 3) [m] and spring_twisting [m] (the rolling and twisting springs). Without friction, "
           "rolling or twisting resistance those are zeros and False.")
      .def("check_sanity", [](PyEngine& pe) {
            UseGuard guard(pe.use);
            try { pe.engine->check_sanity(); } catch (const dem::BlowUp& e) { raise_blow_up(e, nullptr); }
          }, "the engine's sanity checks now (BlowUp)")
      .def_property_readonly("state", [](const PyEngine& pe) { return pe.state_obj; }, "the State it steps (the same object)")
      .def_property_readonly("scene", [](const PyEngine& pe) { return pe.scene; }, "its Scene")
      .def_property_readonly("time", [](const PyEngine& pe) { return pe.state->time; }, "[s]")
      .def_property_readonly("step_count", [](const PyEngine& pe) { return pe.state->step; }, "the state's step counter")
      .def_property_readonly("threads", [](const PyEngine& pe) { return pe.engine->threads(); }, "threads stepping")
      .def_property_readonly("list_builds", [](const PyEngine& pe) { return pe.engine->neighbor_list().builds; },
                             "neighbour-list builds so far")
      .def_property_readonly("pair_kernel", [](const PyEngine& pe) { return std::string(dem::pair_kernel_name(pe.engine->pair_kernel())); },
                             "the pair loop's kernel (avx512, avx2, generic, reference: the same bits)")
      .def_property_readonly("velocity_gradient", [](const PyEngine& pe) { return velgrad_matrix(pe.last_rate); },
                             "of the last step [1/s]");
}

// The binding of the stage runners.
void def_runners(py::module_& m) {
  // ---- Stage runners
  m.def("run_mode", &run_mode, py::arg("scene"), py::arg("state"), py::arg("mode"), py::arg("out"),
        py::arg("name") = "", py::arg("quiet") = true, py::arg("force") = false, py::arg("check") = true,
        "What `dem mode` does: one mode or [paths] entry of protocol.modes from the state (modified in place), "
        "curve CSV to `out`. Returns the steps.");
  m.def("run_stage", &run_stage_py, py::arg("scene"), py::arg("state"), py::arg("name"), py::arg("velocity_gradient"),
        py::arg("stop"), py::arg("target") = 0.0, py::arg("checkpoint_phis") = std::vector<double>{},
        py::arg("on_checkpoint") = py::none(), py::arg("ke_ratio") = 0.0, py::arg("max_time") = 0.0,
        py::arg("out"), py::arg("vtk_dir") = "", py::arg("quiet") = true, py::arg("force") = false,
        "The C++ stage runner (run_stage): constant velocity gradient until `stop` ('phi_up', 'phi_down', 'eps_d', "
        "'relaxed') reaches `target`; on_checkpoint(phi, state_copy) at each of checkpoint_phis.");
  m.def("run_prep_stage", &run_prep_stage, py::arg("scene"), py::arg("state"), py::arg("stage"), py::arg("out"),
        py::arg("on_checkpoint") = py::none(), py::arg("quiet") = true, py::arg("force") = false,
        "One named stage of the scene's preparation, as `dem run` runs it (run_prep_stage; stress-controlled stages "
        "included); on_checkpoint(phi, state_copy) at its checkpoints. 0 steps: skipped, already past its target.");
  m.def("run_protocol", &run_protocol, py::arg("scene"), py::arg("out"), py::arg("stages") = "all",
        py::arg("force") = false, py::arg("quiet") = true, "What `dem run` does: the whole run folder.");
}

// The binding of the fit.
void def_fit(py::module_& m) {
  // ---- Fit
  py::class_<demfit::FitResult>(m, "FitResult", "The saturating fit x(e) = x_max - (x_max - x0) exp(-beta e).")
      .def_readonly("ok", &demfit::FitResult::ok)
      .def_readonly("x0", &demfit::FitResult::x0).def_readonly("x_max", &demfit::FitResult::x_max)
      .def_readonly("beta", &demfit::FitResult::beta)
      .def_readonly("se_x0", &demfit::FitResult::se_x0).def_readonly("se_x_max", &demfit::FitResult::se_x_max)
      .def_readonly("se_beta", &demfit::FitResult::se_beta)
      .def_property_readonly("corr", [](const demfit::FitResult& r) { return mat3(r.corr); })
      .def_readonly("initial_slope", &demfit::FitResult::initial_slope)
      .def_readonly("se_initial_slope", &demfit::FitResult::se_initial_slope)
      .def_readonly("eps_95", &demfit::FitResult::eps_95).def_readonly("rmse", &demfit::FitResult::rmse)
      .def_readonly("r_squared", &demfit::FitResult::r_squared).def_readonly("cost", &demfit::FitResult::cost)
      .def_readonly("residual_autocorrelation", &demfit::FitResult::residual_autocorrelation)
      .def_readonly("se_inflation", &demfit::FitResult::se_inflation).def_readonly("n", &demfit::FitResult::n)
      .def_readonly("e_first", &demfit::FitResult::e_first).def_readonly("e_last", &demfit::FitResult::e_last)
      .def_readonly("jacobian_rcond", &demfit::FitResult::jacobian_rcond)
      .def_readonly("warnings", &demfit::FitResult::warnings)
      .def_property_readonly("usable", [](const demfit::FitResult& r) { return demfit::unusable_reason(r).empty(); },
                             "the tables' one rule: the data determine the numbers (see not_usable_because)")
      .def_property_readonly("not_usable_because", &demfit::unusable_reason,
                             "why the fit is not usable (ill-conditioned, not converged, a bound, a curve the law does "
                             "not describe); '' when it is")
      .def("__repr__", [](const demfit::FitResult& r) {
        std::ostringstream o;
        o << "<demtk.FitResult ok=" << r.ok << " x0=" << r.x0 << " x_max=" << r.x_max << " beta=" << r.beta
          << " R2=" << r.r_squared << " warnings=" << r.warnings.size() << ">";
        return o.str();
      });
  m.def("fit_saturating", [](const std::vector<double>& e, const std::vector<double>& y, double eps_min, double eps_max,
                             const std::string& loss, bool correct_autocorrelation, py::object fix_x0) {
        demfit::FitOptions o;
        o.window_min = eps_min;
        o.window_max = eps_max;
        if (loss == "huber") o.loss = demfit::Loss::Huber;
        else if (loss == "cauchy") o.loss = demfit::Loss::Cauchy;
        else if (loss != "none") throw py::value_error("loss: 'none', 'huber' or 'cauchy'");
        o.correct_autocorrelation = correct_autocorrelation;
        if (!fix_x0.is_none()) { o.fix_x0 = true; o.x0_value = fix_x0.cast<double>(); }
        py::gil_scoped_release release;
        return demfit::fit_saturating(e, y, o);
      }, py::arg("e"), py::arg("y"), py::arg("eps_min") = -1e300, py::arg("eps_max") = 1e300, py::arg("loss") = "none",
      py::arg("correct_autocorrelation") = false, py::arg("fix_x0") = py::none(),
      "Fits x(e) = x_max - (x_max - x0) exp(-beta e) (Ceres) to strain e [-] and values y; raises ValueError for "
      "unusable input (fewer than 6 points, non-finite values, a flat curve).");
  m.def("saturating", &demfit::saturating, py::arg("x0"), py::arg("x_max"), py::arg("beta"), py::arg("e"),
        "x_max - (x_max - x0) exp(-beta e) at strain e [-] (x0, x_max in the units of the fitted quantity, beta [-])");
  m.def("format_paren", &demfit::format_paren, py::arg("value"), py::arg("error"),
        "the value rounded to its standard error, as the fit tables print it: '0.197(2)', '3.7(11)e-4'");
  m.def("format_pm", &demfit::format_pm, py::arg("value"), py::arg("error"),
        "the same as '0.197 \u00b1 0.002', '(3.7 \u00b1 1.1)e-4'");
}

}  // namespace

PYBIND11_MODULE(_core, m) {
  def_module(m);
  def_scene(m);
  def_box(m);
  def_state(m);
  def_measurement(m);
  def_engine(m);
  def_runners(m);
  def_fit(m);
}
