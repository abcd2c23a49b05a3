// A bounded single-producer/single-consumer queue of messages copied whole, between the
// daemon's receive thread (push) and its main thread (front/pop). It holds at most `count`
// messages within a buffer allocated at construction: by default room for `count` of the
// stream's largest valid size; a smaller buffer when the largest is rare and large (a slot
// per largest params update would make 10000 of them 174 MB), then fewer of the largest fit.
// Each message takes a record: a header and its bytes, contiguous, never split at the end
// (the rest of the buffer is skipped).
// push and pop never allocate, lock or block. A message pushed to a full ring is dropped and
// counted there: what the ring loses is known exactly. One larger than the largest valid size
// is never truncated: it takes its place in the order empty and marked oversized (its stream
// refuses it as undecodable), and is counted.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace chaincomp {

class MessageRing {
 public:
  struct Message {
    std::int64_t arrival = 0;      // the receive thread's number, across every ring
    std::int64_t recv_utime = 0;   // LCM's receive stamp, µs
    std::uint32_t size = 0;        // 0 when oversized
    bool oversized = false;        // larger than the largest valid size: its bytes were not kept
    const unsigned char* data = nullptr;
  };
  enum class Push { kOk, kFull, kOversized };

  // `bytes`: the buffer (0: room for `count` of `max_size`); at least two of the largest.
  MessageRing(std::size_t count, std::size_t max_size, std::size_t bytes = 0)
      : count_(count > 0 ? count : 1), max_size_(max_size),
        bytes_(std::max(bytes > 0 ? bytes / sizeof(Header) * sizeof(Header) : count_ * record(max_size),
                        2 * record(max_size))) {}
  MessageRing(const MessageRing&) = delete;
  MessageRing& operator=(const MessageRing&) = delete;

  // Producer only.
  Push push(const void* data, std::size_t size, std::int64_t arrival, std::int64_t recv_utime) noexcept {
    const bool oversized = size > max_size_;
    if (oversized) size = 0;
    const std::size_t n = bytes_.size(), need = record(size);
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    const std::size_t at = head % n;
    const std::size_t skip = n - at < need ? n - at : 0;   // the end's rest, too short for it
    const std::uint64_t pushed = pushed_.load(std::memory_order_relaxed);
    if (pushed - popped_.load(std::memory_order_acquire) == count_ ||
        head + skip + need - tail_.load(std::memory_order_acquire) > n) {
      dropped_.store(dropped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
      return Push::kFull;
    }
    if (skip > 0) put_header({0, 0, 0, kSkip}, at);
    const std::size_t to = (at + skip) % n;
    put_header({arrival, recv_utime, static_cast<std::uint32_t>(size), oversized ? kOversized : kMessage}, to);
    if (size > 0) std::memcpy(bytes_.data() + to + sizeof(Header), data, size);
    if (oversized) oversized_.store(oversized_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
    pushed_.store(pushed + 1, std::memory_order_relaxed);
    head_.store(head + skip + need, std::memory_order_release);   // the bytes before the consumer sees them
    return oversized ? Push::kOversized : Push::kOk;
  }

  // Consumer only: the oldest message (valid until pop), or nullptr when empty.
  const Message* front() noexcept {
    const std::size_t n = bytes_.size();
    std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    if (tail == head) return nullptr;
    Header h = get_header(tail % n);
    if (h.kind == kSkip) {
      tail += n - tail % n;
      tail_.store(tail, std::memory_order_release);
      h = get_header(0);
    }
    front_ = {h.arrival, h.recv_utime, h.size, h.kind == kOversized, bytes_.data() + tail % n + sizeof(Header)};
    return &front_;
  }
  // After front() gave a message.
  void pop() noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    popped_.store(popped_.load(std::memory_order_relaxed) + 1, std::memory_order_release);
    tail_.store(tail + record(front_.size), std::memory_order_release);
  }

  // Either thread: counters only the producer writes.
  std::int64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }
  std::int64_t oversized() const noexcept { return oversized_.load(std::memory_order_relaxed); }
  std::size_t capacity() const noexcept { return count_; }
  std::size_t max_size() const noexcept { return max_size_; }
  std::size_t buffer_bytes() const noexcept { return bytes_.size(); }

 private:
  enum Kind : std::uint32_t { kMessage, kOversized, kSkip };
  struct Header {   // 32 bytes, and records in multiples of them: a skipped rest holds a header
    std::int64_t arrival, recv_utime;
    std::uint32_t size;
    Kind kind;
    std::uint64_t unused = 0;
  };
  static_assert(sizeof(Header) == 32, "records are multiples of the header");
  static std::size_t record(std::size_t size) noexcept {
    return (sizeof(Header) + size + sizeof(Header) - 1) / sizeof(Header) * sizeof(Header);
  }
  void put_header(const Header& h, std::size_t at) noexcept { std::memcpy(bytes_.data() + at, &h, sizeof h); }
  Header get_header(std::size_t at) const noexcept {
    Header h{};
    std::memcpy(&h, bytes_.data() + at, sizeof h);
    return h;
  }

  std::size_t count_, max_size_;
  std::vector<unsigned char> bytes_;
  Message front_;
  // on lines of their own: the producer writes head_, the consumer tail_
  alignas(64) std::atomic<std::uint64_t> head_{0}, pushed_{0};
  alignas(64) std::atomic<std::uint64_t> tail_{0}, popped_{0};
  alignas(64) std::atomic<std::int64_t> dropped_{0};
  std::atomic<std::int64_t> oversized_{0};
};

}  // namespace chaincomp
