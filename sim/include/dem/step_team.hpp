// The threads that run the engine's step: a fixed team with its own barrier that spins
// briefly and then yields the core, instead of OpenMP's barriers (libgomp spins for ~0.3 M
// iterations by default, so on a machine busy with other jobs a waiting thread burns the core
// the thread it waits for needs: 2 threads beside 2 busy jobs on 2 cores ran 35x slower than
// one thread; docs/benchmarks.md). Between steps idle members spin, yield, then sleep.
#pragma once
#include <atomic>
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

}  // namespace dem
