// A caller's poll between two steps (demtk: Ctrl-C). The engine calls poll_interrupt() at the
// start of every step, before it changes anything, so whatever the poll throws leaves the state
// as the last full step left it. The poll is per thread (set with InterruptPoll, RAII) and runs
// at most every 0.1 s of wall time; without one, a step pays one thread-local test.
#pragma once
#include <chrono>
#include <functional>

namespace dem {

namespace detail {
struct InterruptSlot {
  const std::function<void()>* poll = nullptr;
  std::chrono::steady_clock::time_point last{};
};
inline thread_local InterruptSlot interrupt_slot;
}  // namespace detail

/// Installs `poll` for the steps this thread takes while the object lives (nested: restores the outer).
class InterruptPoll {
 public:
  explicit InterruptPoll(const std::function<void()>& poll) : outer_(detail::interrupt_slot.poll), poll_(poll) {
    detail::interrupt_slot.poll = &poll_;
    detail::interrupt_slot.last = std::chrono::steady_clock::now();
  }
  ~InterruptPoll() { detail::interrupt_slot.poll = outer_; }
  InterruptPoll(const InterruptPoll&) = delete;
  InterruptPoll& operator=(const InterruptPoll&) = delete;

 private:
  const std::function<void()>* outer_;
  std::function<void()> poll_;
};

/// Calls this thread's poll if one is installed and 0.1 s passed since it last ran (a clock read,
/// some 20 ns, against steps of 0.1 ms and more). May throw whatever the poll throws.
inline void poll_interrupt() {
  auto& s = detail::interrupt_slot;
  if (!s.poll) return;
  const auto now = std::chrono::steady_clock::now();
  if (now - s.last < std::chrono::milliseconds(100)) return;
  s.last = now;
  (*s.poll)();
}

}  // namespace dem
