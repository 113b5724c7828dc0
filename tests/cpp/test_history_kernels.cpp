// The vector kernels of the models with per-contact history (history_kernels.hpp) against the
// scalar reference loop (pair_loop_history, the oracle), bit for bit: every composed model
// (friction; + rolling; + rolling + twisting; Luding; Luding + friction; Hertz alone, which has
// no history but reads its pair's masses; Hertz + Mindlin with either rule for a changing k_t,
// + rolling + twisting; Hertz + Cundall-Strack) on every kernel this
// CPU runs, whole runs of the engine in a sheared cell (simple shear through flips, list
// rebuilds, particles re-sorted), 1, 2 and 4 threads, and a checkpoint restart in the middle.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <type_traits>
#include <filesystem>
#include <string>
#include <vector>

#include "dem/engine/engine.hpp"
#include "dem/forces/forces.hpp"
#include "dem/io/io.hpp"
#include "test_support.hpp"

using dem::PairKernel;
using dem::Vec3;
using dem::VelGrad;

namespace {

struct Composed {
  const char* name;
  std::vector<std::string> keys;
};
// Adhesive Luding contacts (kc > 0) so that every branch of the law is visited.
const Composed kModels[] = {
    {"frictional", {"contact.friction=0.5"}},
    {"rolling", {"contact.friction=0.5", "contact.rolling_friction=0.1"}},
    {"rolling+twisting", {"contact.friction=0.5", "contact.rolling_friction=0.1", "contact.twisting_friction=0.1"}},
    {"luding", {"contact.normal=luding", "contact.luding_kc_N_m=2e7", "contact.luding_plasticity_depth=0.01"}},
    {"luding+friction",
     {"contact.normal=luding", "contact.luding_kc_N_m=2e7", "contact.luding_plasticity_depth=0.01",
      "contact.friction=0.5"}},
    {"hertz", {"contact.normal=hertz", "contact.restitution=0.7"}},
    {"hertz+mindlin", {"contact.normal=hertz", "contact.restitution=0.7", "contact.tangential=mindlin",
                       "contact.friction=0.5"}},
    {"hertz+mindlin_force+rolling+twisting",
     {"contact.normal=hertz", "contact.restitution=0.7", "contact.tangential=mindlin_force", "contact.friction=0.5",
      "contact.rolling_friction=0.1", "contact.twisting_friction=0.1"}},
    {"hertz+cundall_strack", {"contact.normal=hertz", "contact.restitution=0.7", "contact.friction=0.5"}},
};

struct ShearRun {
  dem::State s;
  long builds = 0, flips = 0;
};

dem::Model model_of(const Composed& c, int threads) {
  std::vector<std::string> keys = c.keys;
  keys.push_back("integration.threads=" + std::to_string(threads));
  return dem_test::model_with(keys);
}

// Simple shear v_x = gdot z to a strain of 0.7 (past the flip at 0.5) over `steps` steps.
VelGrad shear_of(const dem::Model& m, int steps) { return VelGrad{Vec3{0, 0, 0}, Vec3{0, 0.7 / (steps * m.dt), 0}}; }

ShearRun run(const Composed& c, PairKernel kernel, int threads, int steps) {
  const dem::Model m = model_of(c, threads);
  ShearRun r{dem_test::random_state(437, 0.40, 1.0, 17)};   // 437: short last groups of 2, 4 and 8 lanes
  dem::Engine e(m, r.s);
  e.set_pair_kernel(kernel);
  const VelGrad g = shear_of(m, steps);
  for (int k = 0; k < steps; ++k) e.step(g);
  r.builds = e.neighbor_list().builds;
  r.flips = e.flips();
  return r;
}

bool same_history(const dem::State& a, const dem::State& b) {
  return a.history.values.size() == b.history.values.size() &&
         (a.history.values.empty() ||   // data() may be null: memcmp must not get it (UBSan)
          0 == std::memcmp(a.history.values.data(), b.history.values.data(), a.history.values.size() * sizeof(double)));
}

::testing::AssertionResult same_run(const dem::State& a, const dem::State& b) {
  if (!dem_test::same_bits(a.position, b.position)) return ::testing::AssertionFailure() << "positions differ";
  if (!dem_test::same_bits(a.velocity, b.velocity)) return ::testing::AssertionFailure() << "velocities differ";
  if (!dem_test::same_bits(a.angular_velocity, b.angular_velocity))
    return ::testing::AssertionFailure() << "angular velocities differ";
  if (!same_history(a, b)) return ::testing::AssertionFailure() << "histories differ";
  if (std::memcmp(&a.friction_dissipated, &b.friction_dissipated, sizeof(double)) != 0)
    return ::testing::AssertionFailure() << "dissipation differs: " << a.friction_dissipated << " vs "
                                         << b.friction_dissipated;
  return ::testing::AssertionSuccess();
}

// History entries that are nonzero at a stride (entry k of each contact's record).
long nonzero_entries(const dem::State& s, int k) {
  long n = 0;
  const int w = s.history.width;
  for (std::size_t r = k; r < s.history.values.size(); r += w) n += s.history.values[r] != 0.0;
  return n;
}

}  // namespace

TEST(HistoryKernels, EveryComposedModelGivesTheReferenceBitsOnEveryKernelAndThreadCount) {
  constexpr int kSteps = 900;
  for (const Composed& c : kModels) {
    const ShearRun ref = run(c, PairKernel::reference, 1, kSteps);
    // the run exercises what it claims: rebuilds, a flip, contacts with history, sliding
    ASSERT_GT(ref.builds, 3) << c.name;
    ASSERT_GE(ref.flips, 1) << c.name;
    const dem::Model m = model_of(c, 1);
    if (dem::contact::history_width(m.contact) > 0) {   // Hertz alone has none: positions and velocities
      ASSERT_GT(ref.s.history.width, 0) << c.name;
      ASSERT_GT(nonzero_entries(ref.s, 0), 100) << c.name;
    }
    if (m.contact.frictional()) EXPECT_GT(ref.s.friction_dissipated, 0.0) << c.name << ": no contact slid";
    for (PairKernel kernel : dem::supported_pair_kernels())
      for (int threads : {1, 2, 4}) {
        if (kernel == PairKernel::reference && threads == 1) continue;
        if (threads > 1 && kernel != dem::best_pair_kernel() && kernel != PairKernel::reference) continue;
        const ShearRun r = run(c, kernel, threads, kSteps);
        EXPECT_TRUE(same_run(r.s, ref.s)) << c.name << " " << dem::pair_kernel_name(kernel) << " " << threads
                                          << " threads";
      }
  }
}

TEST(HistoryKernels, ForcesOfOneStepMatchTheReferenceOnEveryKernel) {
  // One force evaluation on a sheared, deformed state with blocks 1 and 3 (spills across blocks),
  // every kernel: forces, torques, history and dissipation identical to the reference loop's.
  for (const Composed& c : kModels) {
    const dem::Model m = model_of(c, 1);
    const ShearRun base = run(c, PairKernel::reference, 1, 300);
    const VelGrad g = shear_of(m, 300);
    dem::NeighborList list;
    dem::restore_neighbor_list(base.s, list, m.skin_over_rmin * m.radius_min);
    for (int blocks : {1, 3}) {
      dem::State ref = base.s;
      dem::ForceScratch rs;
      rs.kernel = PairKernel::reference;
      dem::compute_forces(m, ref, list, g, 1, blocks, rs);
      for (PairKernel kernel : dem::supported_pair_kernels()) {
        dem::State t = base.s;
        dem::ForceScratch ks;
        ks.kernel = kernel;
        dem::compute_forces(m, t, list, g, 1, blocks, ks);
        EXPECT_TRUE(dem_test::same_bits(t.force, ref.force) && dem_test::same_bits(t.torque, ref.torque) &&
                    same_history(t, ref) && t.friction_dissipated == ref.friction_dissipated)
            << c.name << " " << dem::pair_kernel_name(kernel) << " blocks " << blocks;
      }
    }
  }
}

TEST(HistoryKernels, ACheckpointRestartOnTheVectorKernelEqualsAStraightReferenceRun) {
  constexpr int kSteps = 600;
  for (const Composed& c : {kModels[2], kModels[4], kModels[6], kModels[7]}) {
    const ShearRun straight = run(c, PairKernel::reference, 1, kSteps);
    const dem::Model m = model_of(c, 2);
    const VelGrad g = shear_of(m, kSteps);
    dem::State split = dem_test::random_state(437, 0.40, 1.0, 17);
    const std::string path = (std::filesystem::temp_directory_path() / "dem_history_kernels.ckpt").string();
    {
      dem::Engine e(m, split);
      e.set_pair_kernel(dem::best_pair_kernel());
      for (int k = 0; k < kSteps / 2; ++k) e.step(g);
      dem::write_checkpoint(path, dem::Checkpoint{"", "mid", split});
    }
    dem::Checkpoint ck = dem::read_checkpoint(path);
    std::remove(path.c_str());
    dem::Engine e(m, ck.state, /*forces_are_current=*/true);
    e.set_pair_kernel(dem::best_pair_kernel());
    for (int k = 0; k < kSteps / 2; ++k) e.step(g);
    EXPECT_TRUE(same_run(ck.state, straight.s)) << c.name;
  }
}

TEST(HistoryKernels, EveryHistoryModelOfTheSceneRunsVectorised) {
  // The trait that sends a model to the vector kernels: true for every composition the scene can
  // ask for (a sub-model without a lane body would fall back to the scalar loop).
  for (const Composed& c : kModels)
    dem::contact::with_contact_model(model_of(c, 1).contact, [&](const auto& cm) {
      using CM = std::decay_t<decltype(cm)>;
      EXPECT_TRUE(CM::vectorised) << c.name;
      EXPECT_TRUE(CM::history_loop) << c.name;
    });
}
