// The vectorised pair kernels (forces.cpp: generic, avx2, avx512) against the reference
// scalar loop (bit for bit) and the all-pairs oracle (round-off), for every kernel this CPU
// runs: random, deformed and sheared (tilted, flipped) configurations, across list rebuilds,
// with attractive forces allowed or clamped, and whole runs of the engine.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "test_support.hpp"

using dem::PairKernel;
using dem::Vec3;
using dem::VelGrad;

namespace {

// A state deformed by `steps` steps of g (the list rebuilt along the way; a tilted cell flips).
dem::State deformed_state(const dem::Model& m, const VelGrad& g, unsigned seed, int steps) {
  dem::State s = dem_test::random_state(437, 0.38, 3.0, seed);   // 437: a short last group of 4
  dem::Engine e(m, s);
  for (int k = 0; k < steps; ++k) e.step(g);
  return s;
}

struct Case {
  const char* name;
  VelGrad shape;
};
const Case kCases[] = {{"D2", VelGrad(Vec3(1, 0, -1))},
                       {"isotropic", VelGrad(Vec3(-1, -1, -1))},
                       {"SS_xz", VelGrad(Vec3(0, 0, 0), Vec3(0, 2, 0))},
                       {"general", VelGrad(Vec3(0.2, -0.1, -0.1), Vec3(1.3, -1.1, 1.7))}};

}  // namespace

TEST(PairKernels, ReferenceAndGenericAreAlwaysAvailable) {
  const auto k = dem::supported_pair_kernels();
  ASSERT_GE(k.size(), 2u);
  EXPECT_EQ(k[0], PairKernel::reference);
  EXPECT_EQ(k[1], PairKernel::generic);
  EXPECT_EQ(dem::pair_kernel_from_name("auto"), dem::best_pair_kernel());
  EXPECT_THROW(dem::pair_kernel_from_name("sse9"), std::runtime_error);
  for (PairKernel kernel : k) EXPECT_EQ(dem::pair_kernel_from_name(dem::pair_kernel_name(kernel)), kernel);
}

TEST(PairKernels, EveryKernelGivesTheReferenceBitsAndTheOracleForces) {
  for (bool attractive : {false, true}) {
    dem::Model m = dem_test::model_with({"integration.threads=1", std::string("contact.allow_attractive=") +
                                                                       (attractive ? "true" : "false")});
    for (const Case& c : kCases)
      for (unsigned seed : {1u, 2u}) {
        const VelGrad g = c.shape * (4e-3 / m.t_contact);
        dem::State s = deformed_state(m, g, seed, 800);
        dem::NeighborList list;
        dem::restore_neighbor_list(s, list, m.skin_over_rmin * m.radius_min);
        dem::State oracle = s;
        dem::compute_forces_all_pairs(m, oracle, g);
        const double scale = dem_test::max_force(oracle);
        ASSERT_GT(scale, 0);
        for (int blocks : {1, 3}) {
          dem::State ref = s;
          dem::ForceScratch rs;
          rs.kernel = PairKernel::reference;
          dem::compute_forces(m, ref, list, g, 1, blocks, rs);
          EXPECT_LT(dem_test::max_force_difference(ref, oracle) / scale, 1e-12) << c.name;
          for (PairKernel kernel : dem::supported_pair_kernels()) {
            dem::State t = s;
            dem::ForceScratch ks;
            ks.kernel = kernel;
            dem::compute_forces(m, t, list, g, 1, blocks, ks);
            EXPECT_TRUE(dem_test::same_bits(t.force, ref.force))
                << dem::pair_kernel_name(kernel) << " " << c.name << " seed " << seed << " blocks " << blocks
                << (attractive ? " attractive" : "");
          }
        }
      }
  }
}

TEST(PairKernels, RunsAreBitIdenticalForEveryKernelAcrossRebuilds) {
  // Whole runs: kick, drift, rebuilds (particles re-sorted and repacked), flips of the cell.
  dem::Model m = dem_test::model_with({"integration.threads=1"});
  for (const Case& c : {kCases[0], kCases[2]}) {
    const VelGrad g = c.shape * (3e-3 / m.t_contact);
    std::vector<Vec3> x_ref, v_ref;
    long builds = 0;
    for (PairKernel kernel : dem::supported_pair_kernels())
      for (int threads : {1, 2}) {
        dem::Model mt = m;
        mt.threads = threads;
        dem::State s = dem_test::random_state(437, 0.38, 3.0, 5);
        dem::Engine e(mt, s);
        e.set_pair_kernel(kernel);
        for (int k = 0; k < 1500; ++k) e.step(g);
        if (x_ref.empty()) {
          x_ref = s.position;
          v_ref = s.velocity;
          builds = e.neighbor_list().builds;
          EXPECT_GT(builds, 3) << "the run must rebuild the list";
          continue;
        }
        EXPECT_TRUE(dem_test::same_bits(s.position, x_ref) && dem_test::same_bits(s.velocity, v_ref))
            << dem::pair_kernel_name(kernel) << ", " << threads << " threads, " << c.name;
      }
  }
}

TEST(PairKernels, AResumedEngineFeedsTheKernelsItsParticles) {
  // An engine built on a state with current forces (a checkpoint) must pack its particles
  // before the first step: the next step equals a continuous run's.
  for (const char* blocks : {"integration.blocks=1", "integration.blocks=4"}) {
    dem::Model m = dem_test::model_with({"integration.threads=1", blocks});
    const VelGrad g = VelGrad(Vec3(1, 0, -1)) * (2e-3 / m.t_contact);
    dem::State a = dem_test::random_state(300, 0.38, 1.0, 8);
    dem::Engine ea(m, a);
    for (int k = 0; k < 200; ++k) ea.step(g);
    dem::State b = a;
    dem::Engine eb(m, b, /*forces_are_current=*/true);
    for (int k = 0; k < 50; ++k) { ea.step(g); eb.step(g); }
    EXPECT_TRUE(dem_test::same_bits(a.position, b.position) && dem_test::same_bits(a.velocity, b.velocity)) << blocks;
  }
}
