// Helpers for the C++ tests: models and hand-built states.
#pragma once
#include <random>
#include <string>
#include <vector>

#include "dem/core/model.hpp"
#include "dem/io/scene.hpp"
#include "dem/core/state.hpp"

namespace dem_test {

/// The default model (one thread) with scene overrides ("section.key=value").
dem::Model model_with(const std::vector<std::string>& overrides = {});

/// A state of given box and spheres (positions [m], radii [m]); masses from the density.
dem::State make_state(const dem::Vec3& box, const std::vector<dem::Vec3>& x, const std::vector<double>& r,
                      double density = 2000.0);

/// N spheres with radii uniform in [rmin, rmax], randomly placed in a cubic box at volume
/// fraction phi (<= 0.38) with small overlaps (a few % of the radii), random velocities of
/// scale v [m/s].
dem::State random_state(int n, double phi, double v, unsigned seed, double rmin = 0.5e-3, double rmax = 1.5e-3);

/// The largest force magnitude of a state [N] (the scale of force comparisons).
double max_force(const dem::State& s);

/// The largest |f_a - f_b| over the particles of two states of the same particles [N].
double max_force_difference(const dem::State& a, const dem::State& b);

/// True if the two arrays hold the same bits (size and every byte).
bool same_bits(const std::vector<dem::Vec3>& a, const std::vector<dem::Vec3>& b);

}  // namespace dem_test
