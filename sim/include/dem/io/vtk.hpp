// VTK XML files for ParaView: per snapshot three unstructured grids, binary appended data.
//   NAME_NNNN.vtu           the particles: one vertex cell per particle (shown on opening),
//                           point data radius_m, velocity_m_s, contacts, id
//   NAME_contacts_NNNN.vtu  the contact network: one line cell per contact from the centre of
//                           i to the centre of the image of j it touches (so a contact across
//                           the periodic boundary is a short line, not one across the box);
//                           cell data normal_force_N, overlap_m, normal (unit, i -> j), and any
//                           further field a contact model adds (VtkContacts::vectors/scalars:
//                           e.g. tangential_force_N)
//   NAME_cell_NNNN.vtu      the periodic cell: one hexahedron on the lattice vectors (follows
//                           the tilt of a sheared cell), cell data volume_m3
// and NAME.pvd, NAME_contacts.pvd, NAME_cell.pvd, the time series of each.
#pragma once
#include <string>
#include <utility>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/core/state.hpp"
#include "dem/forces/neighbor_list.hpp"

namespace dem {

/// The contacts of a snapshot as lines, with per-contact fields.
struct VtkContacts {
  std::vector<int> i, j;               ///< particle indices (State order)
  std::vector<Vec3> from, to;          ///< line ends [m]: x_i (wrapped into the cell) and x_i + branch
  std::vector<std::pair<std::string, std::vector<double>>> scalars;   ///< name -> one value per contact
  std::vector<std::pair<std::string, std::vector<Vec3>>> vectors;     ///< name -> one vector per contact
  std::size_t size() const { return i.size(); }
};

/// Positions wrapped into the (possibly tilted) cell: x = H frac(H^-1 x).
std::vector<Vec3> wrapped_positions(const State& s);
/// The contact network of the listed pairs in contact (for_each_contact): normal_force_N is the
/// spring part k delta of the normal force (the dashpot's share, gamma d(delta)/dt, is of the
/// order of the inertial number in quasi-static runs and needs the rate), overlap_m, normal.
VtkContacts contact_network(const Model& model, const State& s, const NeighborList& list);
/// The three files of one snapshot (names as above; `stem` is DIR/NAME, `index` NNNN).
void write_vtk_particles(const std::string& path, const State& s, const std::vector<Vec3>& wrapped,
                         const std::vector<int>& contacts);
void write_vtk_contacts(const std::string& path, const VtkContacts& c);
void write_vtk_cell(const std::string& path, const Box& box);
/// Snapshots per stage for output.vtk_per_stage = -1 (auto): 20 up to N = 2000, 4e4/N above
/// (a few MB per stage), none beyond N = 40 000 (start and end only).
int auto_vtk_per_stage(int particles);

}  // namespace dem
