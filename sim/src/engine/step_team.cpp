#include "dem/engine/step_team.hpp"

#include <cstdio>
#include <cstdlib>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define DEM_CPU_PAUSE() _mm_pause()
#else
#define DEM_CPU_PAUSE() std::atomic_signal_fence(std::memory_order_seq_cst)
#endif

namespace dem {

StepTeam::StepTeam(int size) : size_(size < 1 ? 1 : size) {
  for (int r = 1; r < size_; ++r) workers_.emplace_back([this, r] { worker(r); });
}

StepTeam::~StepTeam() {
  stop_.store(true);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    wake_.notify_all();
  }
  for (auto& t : workers_) t.join();
}

// Polls done(): `spins` times with a CPU pause, then up to `yields` times giving the core away
// in between (yields < 0: until done). Returns when done() or the yields are used up.
template <class Done>
void StepTeam::spin_then_yield(const Done& done, int yields) const {
  for (int i = 0; i < policy_.spins; ++i) {
    if (done()) return;
    DEM_CPU_PAUSE();
  }
  for (int i = 0; yields < 0 || i < yields; ++i) {
    if (done()) return;
    std::this_thread::yield();
  }
}

void StepTeam::run(const std::function<void(int)>& body) {
  if (size_ == 1) { body(0); return; }
  body_ = &body;
  finished_.store(0, std::memory_order_relaxed);
  generation_.fetch_add(1);   // seq_cst: ordered with the sleepers_ load below
  if (sleepers_.load() > 0) {
    std::lock_guard<std::mutex> lock(mutex_);
    wake_.notify_all();
  }
  body(0);
  spin_then_yield([&] { return finished_.load(std::memory_order_acquire) == size_ - 1; }, -1);
}

void StepTeam::barrier() {
  if (size_ == 1) return;
  const std::uint64_t phase = phase_.load(std::memory_order_acquire);
  if (arrived_.fetch_add(1, std::memory_order_acq_rel) == size_ - 1) {
    arrived_.store(0, std::memory_order_relaxed);
    phase_.fetch_add(1, std::memory_order_release);   // releases everyone's writes
    return;
  }
  spin_then_yield([&] { return phase_.load(std::memory_order_acquire) != phase; }, -1);
}

void StepTeam::worker(int rank) {
  std::uint64_t seen = 0;
  for (;;) {
    auto started = [&] { return generation_.load(std::memory_order_acquire) != seen || stop_.load(); };
    spin_then_yield(started, policy_.yields);
    if (!started()) {   // a long pause between steps (output, another stage): sleep
      sleepers_.fetch_add(1);   // seq_cst: ordered with run()'s generation_ increment
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, started);
      sleepers_.fetch_sub(1);
    }
    if (stop_.load()) return;
    seen = generation_.load(std::memory_order_acquire);
    (*body_)(rank);
    finished_.fetch_add(1, std::memory_order_release);
  }
}

TeamSizeChooser::TeamSizeChooser(int team, bool adaptive) : team_(team), adaptive_(adaptive && team > 1) {}

void TeamSizeChooser::step_done() {
  if (!adaptive_) return;
  const auto now = Clock::now();
  if (!started_) {   // the first step (thread start, first list) does not count
    started_ = true;
    window_start_ = now;
    return;
  }
  ++steps_;
  const double wall = std::chrono::duration<double>(now - window_start_).count();
  if (steps_ < 64 || wall < 20e-3) return;
  const int mode = use_team_ ? 1 : 0;
  rate_[mode] = steps_ / wall;
  measured_[mode] = now;
  steps_ = 0;
  const int other = 1 - mode;
  // One thread only when clearly faster (windows are noisy: a list rebuild, a neighbour's
  // burst) and only after the team lost twice in a row: a loss is confirmed at once.
  const bool team_wins = rate_[0] < kSwitchMargin * rate_[1];
  if (mode == 1) team_losses_ = team_wins ? 0 : team_losses_ + 1;
  const bool best_is_team = team_losses_ < 2;
  // A probe of the other mode that lost doubles the time to the next probe (up to 32 s).
  if (probing_) recheck_ = (mode == 1) == best_is_team ? std::chrono::seconds(1) : std::min(recheck_ * 2, kMaxRecheck);
  const bool stale = rate_[other] == 0 || now - measured_[other] > recheck_;
  const bool confirm = mode == 1 && team_losses_ == 1;   // measure the team once more
  use_team_ = confirm || (stale ? other == 1 : best_is_team);
  probing_ = stale && !confirm;
  if (std::getenv("DEM_DEBUG_CHOOSER"))
    std::fprintf(stderr, "chooser: mode %d rate %.1f steps/s (alone %.1f team %.1f) -> %s%s\n", mode, rate_[mode], rate_[0],
                 rate_[1], use_team_ ? "team" : "alone", probing_ ? " (probe)" : "");
  window_start_ = Clock::now();
}

}  // namespace dem
