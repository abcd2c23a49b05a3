// Latency percentiles over a sliding window of the last N samples. The storage is sized at
// start-up; recording and summarising never allocate.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

namespace chaincomp {

class LatencyWindow {
 public:
  explicit LatencyWindow(int size) : samples_(size), scratch_(size) {}

  void record(std::int64_t ns) noexcept {
    samples_[next_] = ns;
    next_ = (next_ + 1) % samples_.size();
    count_ = std::min(count_ + 1, samples_.size());
  }

  struct Summary {
    int count = 0;
    std::int64_t p50 = 0, p99 = 0, p999 = 0, max = 0;
  };

  Summary summary() noexcept {
    Summary s;
    s.count = static_cast<int>(count_);
    if (count_ == 0) return s;
    std::copy(samples_.begin(), samples_.begin() + count_, scratch_.begin());
    auto end = scratch_.begin() + count_;
    auto at = [&](double q) {
      auto it = scratch_.begin() + static_cast<std::size_t>(q * (count_ - 1) + 0.5);
      std::nth_element(scratch_.begin(), it, end);
      return *it;
    };
    s.p50 = at(0.5);
    s.p99 = at(0.99);
    s.p999 = at(0.999);
    s.max = *std::max_element(scratch_.begin(), end);
    return s;
  }

 private:
  std::vector<std::int64_t> samples_, scratch_;
  std::size_t next_ = 0, count_ = 0;
};

}  // namespace chaincomp
