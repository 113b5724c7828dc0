// The step team (step_team.hpp): every member runs the body, barriers order writes, idle
// members sleep and wake, and the engine's threaded step on it equals the one-thread step.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "dem/engine/step_team.hpp"

TEST(StepTeam, EveryMemberRunsAndBarriersOrderTheirWrites) {
  for (int size : {1, 2, 3, 4}) {
    dem::StepTeam team(size);
    std::vector<long> slot(size, 0);
    std::atomic<int> wrong{0};
    for (int round = 1; round <= 300; ++round) {
      team.run([&](int r) {
        slot[r] = round * 10 + r;            // plain writes, published by the barrier
        team.barrier();
        for (int o = 0; o < size; ++o)
          if (slot[o] != round * 10 + o) ++wrong;
        team.barrier();                      // nobody writes the next round before all have read
      });
    }
    EXPECT_EQ(wrong.load(), 0) << size << " members";
  }
}

TEST(StepTeam, IdleMembersSleepAndWakeForTheNextRun) {
  dem::StepTeam team(3);
  team.set_wait_policy({10, 10});   // sleep almost at once
  std::atomic<int> runs{0};
  for (int k = 0; k < 5; ++k) {
    team.run([&](int) { ++runs; });
    std::this_thread::sleep_for(std::chrono::milliseconds(20));   // long enough for the workers to sleep
  }
  EXPECT_EQ(runs.load(), 15);
}

TEST(StepTeam, SumsOverRunsAreExact) {
  // A reduction through the barrier, as the engine does for the list's staleness test.
  dem::StepTeam team(4);
  std::vector<double> part(4);
  double total = 0;
  for (int k = 0; k < 500; ++k)
    team.run([&](int r) {
      part[r] = k + r;
      team.barrier();
      if (r == 0) for (double p : part) total += p;
      team.barrier();
    });
  double want = 0;
  for (int k = 0; k < 500; ++k) want += 4.0 * k + 6;
  EXPECT_EQ(total, want);
}
