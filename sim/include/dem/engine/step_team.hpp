// The threads that run the engine's step: a fixed team with its own barrier that spins
// briefly and then yields the core, instead of OpenMP's barriers (libgomp spins for ~0.3 M
// iterations by default, so on a machine busy with other jobs a waiting thread burns the core
// the thread it waits for needs: 2 threads beside 2 busy jobs on 2 cores ran 35x slower than
// one thread; docs/benchmarks.md). Between steps idle members spin, yield, then sleep.
#pragma once
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

namespace dem {

class StepTeam {
 public:
  /// A team of `size` members: the calling thread (rank 0) and size - 1 workers.
  explicit StepTeam(int size);
  ~StepTeam();
  StepTeam(const StepTeam&) = delete;
  StepTeam& operator=(const StepTeam&) = delete;

  int size() const { return size_; }

  /// Runs body(rank) on every member, rank 0 on the caller; returns when all have finished.
  /// body must not throw.
  void run(const std::function<void(int rank)>& body);

  /// Waits until every member has reached it (only inside run's body). What a member wrote
  /// before it is visible to every member after it.
  void barrier();

  /// How a wait behaves: `spins` polls with a CPU pause, then polls with a yield of the core
  /// in between, `yields` times (between steps; inside a step a barrier yields until done),
  /// then (between steps only) sleeps until woken.
  struct WaitPolicy {
    int spins = 2000;
    int yields = 2000;
  };
  void set_wait_policy(WaitPolicy p) { policy_ = p; }

 private:
  void worker(int rank);
  template <class Done>
  void spin_then_yield(const Done& done, int yields) const;

  int size_;
  WaitPolicy policy_;
  std::vector<std::thread> workers_;
  const std::function<void(int)>* body_ = nullptr;
  std::atomic<std::uint64_t> generation_{0};   // one per run()
  std::atomic<int> finished_{0};               // workers done with this run()
  std::atomic<int> arrived_{0};                // members at the current barrier
  std::atomic<std::uint64_t> phase_{0};        // barriers passed
  std::atomic<bool> stop_{false};
  std::atomic<int> sleepers_{0};
  std::mutex mutex_;
  std::condition_variable wake_;
};

/// Chooses, step by step, whether the team or the calling thread alone runs the step: both
/// give the same bits (the block count, not the thread count, fixes the summation order), so
/// the choice is only about speed. It times windows of steps (>= 64 steps and >= 20 ms) in
/// each mode, runs the team unless one thread was more than 15 % faster than it in two team
/// windows in a row, and re-measures the other mode after 1 s (doubling up to 32 s while it
/// keeps losing). On an idle
/// machine the team wins; beside other busy jobs, where every barrier may wait for a
/// descheduled member, one thread can win (docs/benchmarks.md).
class TeamSizeChooser {
 public:
  /// `team` members available; `adaptive` false: always the whole team.
  TeamSizeChooser(int team, bool adaptive);
  /// Members to use for the next step (1 or the team).
  int members() const { return use_team_ ? team_ : 1; }
  /// Call after each step.
  void step_done();

 private:
  using Clock = std::chrono::steady_clock;
  int team_;
  bool adaptive_;
  bool use_team_ = true;
  int steps_ = 0;
  Clock::time_point window_start_ = Clock::now();
  double rate_[2] = {0, 0};            // steps/s measured alone [0] and as a team [1]; 0: not yet
  Clock::time_point measured_[2] = {};
  bool probing_ = false;                 // the current window re-measures the losing mode
  bool started_ = false;                 // a first step was seen (windows start after it)
  int team_losses_ = 0;                  // team windows in a row that one thread beat
  static constexpr Clock::duration kMaxRecheck = std::chrono::seconds(32);
  static constexpr double kSwitchMargin = 1.15;   // one thread must be this much faster to be chosen
  Clock::duration recheck_ = std::chrono::seconds(1);
};

}  // namespace dem
