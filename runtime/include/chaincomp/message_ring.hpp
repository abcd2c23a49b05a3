// A bounded single-producer/single-consumer queue of messages copied whole, between the
// daemon's receive thread (push) and its main thread (front/pop). Every slot is allocated at
// construction, sized for the stream's largest valid message: push and pop never allocate,
// lock or block. A message pushed to a full ring is dropped and counted there: what the ring
// loses is known exactly. One larger than a slot is never truncated: it takes its place in the
// order empty and marked oversized (its stream refuses it as undecodable), and is counted.
#pragma once

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
    bool oversized = false;        // larger than a slot: its bytes were not kept
    const unsigned char* data = nullptr;
  };
  enum class Push { kOk, kFull, kOversized };

  MessageRing(std::size_t capacity, std::size_t max_size)
      : capacity_(capacity > 0 ? capacity : 1), max_size_(max_size), slots_(capacity_), bytes_(capacity_ * max_size) {
    for (std::size_t i = 0; i < capacity_; ++i) slots_[i].data = bytes_.data() + i * max_size;
  }
  MessageRing(const MessageRing&) = delete;
  MessageRing& operator=(const MessageRing&) = delete;

  // Producer only.
  Push push(const void* data, std::size_t size, std::int64_t arrival, std::int64_t recv_utime) noexcept {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);
    if (head - tail_.load(std::memory_order_acquire) == capacity_) {
      dropped_.store(dropped_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
      return Push::kFull;
    }
    const std::size_t i = head % capacity_;
    Message& s = slots_[i];
    s.oversized = size > max_size_;
    if (s.oversized) {
      oversized_.store(oversized_.load(std::memory_order_relaxed) + 1, std::memory_order_relaxed);
      size = 0;
    }
    if (size > 0) std::memcpy(bytes_.data() + i * max_size_, data, size);
    s.size = static_cast<std::uint32_t>(size);
    s.arrival = arrival;
    s.recv_utime = recv_utime;
    head_.store(head + 1, std::memory_order_release);   // the slot's bytes before the consumer sees it
    return s.oversized ? Push::kOversized : Push::kOk;
  }

  // Consumer only: the oldest message (valid until pop), or nullptr when empty.
  const Message* front() const noexcept {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    if (head_.load(std::memory_order_acquire) == tail) return nullptr;
    return &slots_[tail % capacity_];
  }
  void pop() noexcept { tail_.store(tail_.load(std::memory_order_relaxed) + 1, std::memory_order_release); }

  // Either thread: counters only the producer writes.
  std::int64_t dropped() const noexcept { return dropped_.load(std::memory_order_relaxed); }
  std::int64_t oversized() const noexcept { return oversized_.load(std::memory_order_relaxed); }
  std::size_t capacity() const noexcept { return capacity_; }
  std::size_t max_size() const noexcept { return max_size_; }

 private:
  std::size_t capacity_, max_size_;
  std::vector<Message> slots_;
  std::vector<unsigned char> bytes_;
  // on lines of their own: the producer writes head_, the consumer tail_
  alignas(64) std::atomic<std::uint64_t> head_{0};
  alignas(64) std::atomic<std::uint64_t> tail_{0};
  alignas(64) std::atomic<std::int64_t> dropped_{0};
  std::atomic<std::int64_t> oversized_{0};
};

}  // namespace chaincomp
