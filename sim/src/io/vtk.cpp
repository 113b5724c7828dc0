// VTK XML unstructured grids with raw binary appended data (dem/io/vtk.hpp).
#include "dem/io/vtk.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <sstream>

#include "dem/forces/contact_forces.hpp"
#include "dem/io/io.hpp"

namespace dem {

namespace {

constexpr std::uint8_t kVertex = 1, kLine = 3, kHexahedron = 12;

// One grid: data arrays described in the XML, their bytes appended after it
// (<AppendedData encoding="raw">_ then, per array, a UInt64 byte count and the bytes).
class Grid {
 public:
  Grid(std::size_t points, std::size_t cells) : points_(points), cells_(cells) {}
  template <class T>
  void array(const char* section, const std::string& name, const std::string& type, int components,
             const std::vector<T>& data) {
    std::ostringstream x;
    x << "<DataArray type=\"" << type << "\" Name=\"" << name << "\" NumberOfComponents=\"" << components
      << "\" format=\"appended\" offset=\"" << blob_.size() << "\"/>\n";
    xml_[section] += x.str();
    const std::uint64_t bytes = data.size() * sizeof(T);
    append(&bytes, sizeof bytes);
    if (bytes) append(data.data(), bytes);
  }
  void vec3(const char* section, const std::string& name, const std::vector<Vec3>& v) {
    std::vector<double> flat;
    flat.reserve(3 * v.size());
    for (const auto& a : v) { flat.push_back(a.x); flat.push_back(a.y); flat.push_back(a.z); }
    array(section, name, "Float64", 3, flat);
  }
  std::string text(const std::string& point_scalars, const std::string& cell_scalars) const {
    std::ostringstream o;
    o << "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
         "header_type=\"UInt64\">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\""
      << points_ << "\" NumberOfCells=\"" << cells_ << "\">\n";
    o << "<PointData" << (point_scalars.empty() ? "" : " Scalars=\"" + point_scalars + "\"") << ">\n" << get("PointData")
      << "</PointData>\n";
    o << "<CellData" << (cell_scalars.empty() ? "" : " Scalars=\"" + cell_scalars + "\"") << ">\n" << get("CellData")
      << "</CellData>\n";
    o << "<Points>\n" << get("Points") << "</Points>\n<Cells>\n" << get("Cells") << "</Cells>\n";
    o << "</Piece>\n</UnstructuredGrid>\n<AppendedData encoding=\"raw\">\n_";
    o.write(blob_.data(), static_cast<std::streamsize>(blob_.size()));
    o << "\n</AppendedData>\n</VTKFile>\n";
    return o.str();
  }

 private:
  void append(const void* p, std::size_t n) {
    const char* c = static_cast<const char*>(p);
    blob_.insert(blob_.end(), c, c + n);
  }
  std::string get(const std::string& s) const {
    const auto it = xml_.find(s);
    return it == xml_.end() ? "" : it->second;
  }
  std::size_t points_, cells_;
  std::map<std::string, std::string> xml_;   // section -> its DataArray lines
  std::vector<char> blob_;
};

// Cells of one kind (vertices, lines, a hexahedron): connectivity, offsets, types.
void cells(Grid& g, std::size_t count, int points_per_cell, std::uint8_t type) {
  std::vector<std::int64_t> conn(count * points_per_cell), off(count);
  for (std::size_t k = 0; k < conn.size(); ++k) conn[k] = static_cast<std::int64_t>(k);
  for (std::size_t c = 0; c < count; ++c) off[c] = static_cast<std::int64_t>((c + 1) * points_per_cell);
  g.array("Cells", "connectivity", "Int64", 1, conn);
  g.array("Cells", "offsets", "Int64", 1, off);
  g.array("Cells", "types", "UInt8", 1, std::vector<std::uint8_t>(count, type));
}

}  // namespace

int auto_vtk_per_stage(int particles) {
  if (particles <= 2000) return 20;
  return particles > 40000 ? 0 : static_cast<int>(40000 / particles);
}

std::vector<Vec3> wrapped_positions(const State& s) {
  std::vector<Vec3> out(s.count());
  for (int i = 0; i < s.count(); ++i) {
    Vec3 f = s.box.fractional(s.position[i]);
    for (int k = 0; k < 3; ++k) {
      f[k] -= std::floor(f[k]);
      if (f[k] >= 1.0) f[k] = 0.0;   // -1e-17 wraps to 1 - 1e-17, which rounds to 1
    }
    out[i] = s.box.lattice(f.x, f.y, f.z);
  }
  return out;
}

VtkContacts contact_network(const Model& model, const State& s, const NeighborList& list) {
  const std::vector<Vec3> x = wrapped_positions(s);
  const bool frictional = model.contact.frictional();
  VtkContacts c;
  std::vector<double> force, overlap, sliding;
  std::vector<Vec3> normal, tangential;
  // The model's forces at the state's velocities and stored springs (contact_forces.hpp); the
  // normal force is the normal sub-model's elastic part (the dashpot's is velocity noise here).
  contact::for_each_contact_force(model, s, list, VelGrad{}, [&](const contact::ContactForce& f) {
    c.i.push_back(f.i);
    c.j.push_back(f.j);
    c.from.push_back(x[f.i]);
    c.to.push_back(x[f.i] + f.d);
    force.push_back(f.fn_elastic);
    overlap.push_back(f.delta);
    normal.push_back(f.n);
    if (frictional) {
      tangential.push_back(f.ft);
      sliding.push_back(f.sliding ? 1.0 : 0.0);
    }
  });
  c.scalars = {{"normal_force_N", force}, {"overlap_m", overlap}};
  c.vectors = {{"normal", normal}};
  if (frictional) {
    c.scalars.push_back({"sliding", sliding});
    c.vectors.push_back({"tangential_force_N", tangential});
  }
  return c;
}

void write_vtk_particles(const std::string& path, const State& s, const std::vector<Vec3>& wrapped,
                         const std::vector<int>& contacts) {
  const std::size_t n = s.count();
  Grid g(n, n);
  g.vec3("Points", "Points", wrapped);
  cells(g, n, 1, kVertex);
  g.array("PointData", "radius_m", "Float64", 1, s.radius);
  g.vec3("PointData", "velocity_m_s", s.velocity);
  std::vector<std::int32_t> cc(n, 0), ids(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (i < contacts.size()) cc[i] = contacts[i];
    ids[i] = static_cast<std::int32_t>(s.id[i]);
  }
  g.array("PointData", "contacts", "Int32", 1, cc);
  g.array("PointData", "id", "Int32", 1, ids);
  write_file_atomic(path, g.text("radius_m", ""));
}

void write_vtk_contacts(const std::string& path, const VtkContacts& c) {
  const std::size_t n = c.size();
  Grid g(2 * n, n);
  std::vector<Vec3> pts;
  pts.reserve(2 * n);
  for (std::size_t k = 0; k < n; ++k) { pts.push_back(c.from[k]); pts.push_back(c.to[k]); }
  g.vec3("Points", "Points", pts);
  cells(g, n, 2, kLine);
  std::vector<std::int32_t> ii(c.i.begin(), c.i.end()), jj(c.j.begin(), c.j.end());
  g.array("CellData", "i", "Int32", 1, ii);
  g.array("CellData", "j", "Int32", 1, jj);
  for (const auto& [name, v] : c.scalars) g.array("CellData", name, "Float64", 1, v);
  for (const auto& [name, v] : c.vectors) g.vec3("CellData", name, v);
  write_file_atomic(path, g.text("", c.scalars.empty() ? "" : c.scalars.front().first));
}

void write_vtk_cell(const std::string& path, const Box& box) {
  // VTK_HEXAHEDRON order: bottom face (0,0,0) (1,0,0) (1,1,0) (0,1,0), then the top face.
  static const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  std::vector<Vec3> pts;
  for (const auto& k : corner) pts.push_back(box.lattice(k[0], k[1], k[2]));
  Grid g(8, 1);
  g.vec3("Points", "Points", pts);
  cells(g, 1, 8, kHexahedron);
  g.array("CellData", "volume_m3", "Float64", 1, std::vector<double>{box.volume()});
  write_file_atomic(path, g.text("", "volume_m3"));
}

void write_pvd(const std::string& path, const std::vector<std::pair<double, std::string>>& files) {
  std::ostringstream o;
  o.precision(12);
  o << "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n";
  for (auto& f : files) o << "<DataSet timestep=\"" << f.first << "\" file=\"" << f.second << "\"/>\n";
  o << "</Collection>\n</VTKFile>\n";
  write_file_atomic(path, o.str());
}

}  // namespace dem
