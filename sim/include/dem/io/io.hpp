// Files: packings (YADE text format), checkpoints (binary, bit-exact), VTK snapshots,
// and atomic writes (write to NAME.part, then rename: a file that exists is complete).
#pragma once
#include <istream>
#include <string>
#include <vector>

#include "dem/common/atomic_file.hpp"
#include "dem/core/model.hpp"
#include "dem/core/state.hpp"

namespace dem {

// write_file_atomic and create_exclusive: dem/common/atomic_file.hpp (shared with fit/).

/// The whole of an input file, refused unless it is a regular file (not a device such as
/// /dev/zero, a FIFO or a socket: opened without blocking, then checked) of at most max_bytes.
/// `what` names it in the error ("packing file", "checkpoint").
std::string read_regular_file(const std::string& path, const std::string& what,
                              std::size_t max_bytes = std::size_t(1) << 34);

/// Reads a packing in YADE's text format: a line "##PERIODIC:: Lx Ly Lz" [m], then one line
/// "x y z r" [m] per sphere ('#' lines are comments). Masses from `density` [kg/m^3].
/// Throws std::runtime_error naming the line when the format is wrong, a radius is not
/// positive, or a centre lies outside the cell [0, L) (tolerance 1e-9 L).
/// The same, from a stream; `origin` names it in messages. A line with anything after its
/// numbers (e.g. "0.00063abc") is refused.
State read_packing(const std::string& path, double density);
State parse_packing(std::istream& in, double density, const std::string& origin);

/// Writes the state's packing in the same format (17 significant digits, original id order).
/// Throws std::runtime_error for an invalid state (e.g. ids not a permutation).
void write_packing(const std::string& path, const State& state);

/// Random non-overlapping placement of `model.count` spheres with radii uniform in
/// [radius_min, radius_max] (seeded) in a cubic box at volume fraction `phi`.
/// Largest spheres first; throws std::runtime_error if a sphere finds no free spot.
State random_packing(const Model& model, double phi);

/// Uniform double in [0, 1) from a 64-bit generator value (portable, unlike <random>'s).
double unit_uniform(unsigned long long bits);

/// Checkpoint: the whole State plus the scene text and a label, bit-exact.
struct Checkpoint {
  std::string scene_toml;   ///< the resolved scene the state was produced with
  std::string label;        ///< e.g. "unloading phi=0.700"
  State state;
};
void write_checkpoint(const std::string& path, const Checkpoint& ckpt);
/// Format version 3: a FNV-1a 64 checksum over the whole file; version 4 (written only for a
/// sheared state) adds the tilted cell; version 2, without the checksum, is still read.
/// Throws std::runtime_error if the file is not a checkpoint of version 2, 3 or 4, is
/// truncated, fails its checksum, or holds an invalid state (validate_state: ids a
/// permutation, radii and masses finite and positive, positions finite, box positive).
Checkpoint read_checkpoint(const std::string& path);
/// The same from the file's bytes; `origin` names it in messages.
Checkpoint parse_checkpoint(const std::string& bytes, const std::string& origin);

/// ParaView collection index of (time [s], file) pairs (written by vtk.cpp, beside the
/// snapshots of dem/io/vtk.hpp).
void write_pvd(const std::string& path, const std::vector<std::pair<double, std::string>>& files);

}  // namespace dem
