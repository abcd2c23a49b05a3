// One ordering rule for every input stream of the daemon (and of chaincomp_rt and replay):
// commands and params updates by their seq, each temperature sensor by its readings' utime.
// No message can lock a stream out:
//   - the first message, and the first after reset(), starts the stream whatever its key;
//   - a key 1 .. max_jump ahead of the last taken one is next;
//   - any other key (equal, behind, or more than max_jump ahead) is refused, except that
//     kRestartRun such messages in a row, each 1 .. max_jump ahead of the one before it
//     (and `continues`, the stream's own test, e.g. a command's step), are a new stream:
//     the fifth is taken, or the first after it that passes the stream's other checks.
// Keys are any int64: differences are taken in unsigned arithmetic, never overflowing.
// Header-only and allocation-free (the realtime component compiles it too).
#pragma once

#include <algorithm>
#include <cstdint>

namespace chaincomp {

// Messages in a row that restart a stream (compensator.hpp documents it for commands).
constexpr int kRestartRun = 5;
// A seq further ahead than this is not a gap of lost messages (2^32: five days at 10 kHz).
constexpr std::uint64_t kMaxSeqJump = std::uint64_t(1) << 32;
// A reading's utime further ahead than this (µs: one day) is a clock glitch, not a pause.
constexpr std::uint64_t kMaxTimeJump = std::uint64_t(86400) * 1000000;

// How far `to` is ahead of `from` (0 when it is not): exact for every pair of int64.
constexpr std::uint64_t ahead_by(std::int64_t from, std::int64_t to) noexcept {
  return to > from ? static_cast<std::uint64_t>(to) - static_cast<std::uint64_t>(from) : 0;
}

class StreamOrder {
 public:
  enum class Verdict { kNext, kRestart, kSame, kBehind, kTooFarAhead };

  explicit constexpr StreamOrder(std::uint64_t max_jump) noexcept : max_jump_(max_jump) {}

  // Judges one message's key; a refused one is remembered in the restart run. Call accept()
  // when the message is then taken whole (a later check of the stream may still refuse it).
  Verdict judge(std::int64_t key, bool continues = true) noexcept {
    if (!known_) return Verdict::kNext;
    const std::uint64_t ahead = ahead_by(last_, key);
    if (ahead >= 1 && ahead <= max_jump_) {
      run_ = 0;
      return Verdict::kNext;
    }
    const std::uint64_t step = ahead_by(run_key_, key);
    run_ = (run_ > 0 && continues && step >= 1 && step <= max_jump_) ? std::min(run_ + 1, kRestartRun) : 1;
    run_key_ = key;
    // (the run lasts until a message is taken: one refused by another check, or by another
    // sensor of its message, does not cost the stream five more)
    if (run_ == kRestartRun) return Verdict::kRestart;
    return key == last_ ? Verdict::kSame : key < last_ ? Verdict::kBehind : Verdict::kTooFarAhead;
  }
  static constexpr bool taken(Verdict v) noexcept { return v == Verdict::kNext || v == Verdict::kRestart; }

  void accept(std::int64_t key) noexcept {
    known_ = true;
    last_ = key;
    run_ = 0;
  }
  // A new stream (a control message's reset): the next message starts it.
  void reset() noexcept {
    known_ = false;
    run_ = 0;
  }
  bool known() const noexcept { return known_; }
  std::int64_t last() const noexcept { return last_; }
  int run() const noexcept { return run_; }   // refused messages in the current restart run

 private:
  std::uint64_t max_jump_;
  bool known_ = false;
  std::int64_t last_ = 0, run_key_ = 0;
  int run_ = 0;
};

}  // namespace chaincomp
