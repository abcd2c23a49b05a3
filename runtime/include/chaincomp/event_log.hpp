// LCM event logs (the format lcm-logger writes and lcm-logplayer plays) read and written
// without an allocation or a system call per event: liblcm's reader allocates three blocks
// and seeks back and forth for every event, which cost chaincomp_replay more than the
// compensation. Format, per event, big-endian: sync word 0xEDA1DA01, event number (int64),
// timestamp in µs (int64), channel length (int32), data length (int32), channel, data.
#pragma once

#include <cstddef>
#include <cstdint>
#include <atomic>
#include <condition_variable>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <thread>
#include <string>
#include <string_view>
#include <vector>

#include "chaincomp/output_file.hpp"

namespace chaincomp {

struct LogEvent {
  std::int64_t eventnum = 0, timestamp = 0;
  std::string_view channel;
  const unsigned char* data = nullptr;
  std::int32_t datalen = 0;
  std::uint64_t offset = 0;  // byte offset of the event's sync word in the file
};

// Reads a log with pread into a buffer of its own (not a memory map: a log cut short or
// replaced by another process while it is read would end a mapped reader with SIGBUS; here
// the shorter file simply ends, the missing tail reported as damage). The buffer grows to
// hold the longest event; events longer than kMaxEvent are taken as damaged lengths.
class LogReader {
 public:
  static constexpr std::size_t kChunk = 4 << 20, kMaxEvent = 256 << 20;

  LogReader() = default;
  LogReader(const LogReader&) = delete;
  LogReader& operator=(const LogReader&) = delete;
  ~LogReader();

  // False with `error` naming the file when it cannot be opened. Opening again starts over
  // with the new file.
  bool open(const std::string& path, std::string& error);
  // The next event (its channel and data valid until the next call); false at the end. A
  // damaged stretch (no sync word where one belongs, a length that does not fit) is skipped
  // up to the next sync word and recorded in damage().
  bool next(LogEvent& ev) noexcept;

  struct Damage {
    std::uint64_t offset = 0;  // where the damaged stretch starts
    std::uint64_t bytes = 0;   // how long it is
    const char* what = "";     // why it is not an event
  };
  // Every damaged stretch seen so far, in file order.
  const std::vector<Damage>& damage() const noexcept { return damage_; }

 private:
  void close() noexcept;
  // Whether bytes [pos_, pos_ + n) are in the buffer, reading them if not; false when the
  // file ends first (then size_ is cut to what could be read).
  bool have(std::size_t n) noexcept;
  const unsigned char* at() const noexcept { return buf_.get() + (pos_ - start_); }
  // Skips from pos_ to the next sync word (or to the end) and records the stretch.
  void skip_damaged(const char* what, bool to_end = false) noexcept;

  struct Free {
    void operator()(unsigned char* p) const noexcept { std::free(p); }
  };
  int fd_ = -1;
  std::unique_ptr<unsigned char, Free> buf_;
  std::size_t capacity_ = 0;  // of buf_
  std::uint64_t start_ = 0;   // file offset of buf_[0]
  std::size_t len_ = 0;       // bytes in buf_
  std::uint64_t size_ = 0, pos_ = 0;  // file size at open (or as far as it could be read)
  std::vector<Damage> damage_;
};

// Appends events through two large buffers, one filled while a thread of its own writes the
// other out, so the device's time overlaps the caller's work; event numbers count from 0,
// as lcm-logger's. Writes whole 4 KiB blocks with direct I/O where the filesystem takes it:
// on this project's VM the page cache took 0.3-5 GB/s depending on its dirty pages, direct
// writes a steady 2 GB/s (dd, 389 MiB), and replay writes its log once, never reads it.
class LogWriter {
 public:
  LogWriter() = default;
  LogWriter(const LogWriter&) = delete;
  LogWriter& operator=(const LogWriter&) = delete;
  ~LogWriter();

  // `direct`: try direct I/O first (tests turn it off to cover the plain path). The log is
  // written by OutputFile's rules: a temporary file put in place by close(), or a pipe or
  // device written into.
  bool open(const std::string& path, std::string& error, bool direct = true);
  // false once a write has failed (the disk is full...), or for an event no reader would
  // take (empty or 1000+ byte channel, negative length, refused): see close().
  bool write(std::int64_t timestamp, std::string_view channel, const void* data, std::int32_t datalen) noexcept;
  // Writes what is buffered and puts the log in place; false with `error` if any write failed
  // or an event was refused, and then nothing is put in place. The destructor of a writer not
  // closed puts nothing in place either.
  bool close(std::string& error);

 private:
  static constexpr std::size_t kBlock = 4096, kWriteBuffer = 4 << 20;
  struct Free {
    void operator()(unsigned char* p) const noexcept { std::free(p); }
  };
  bool append(const void* p, std::size_t n) noexcept;
  void hand_over(std::size_t n) noexcept;  // the filled buffer to the writer thread
  void write_loop() noexcept;              // the writer thread
  bool write_all(const unsigned char* p, std::size_t n) noexcept;
  void finish() noexcept;  // the buffered bytes written, the writer thread ended

  OutputFile file_;
  int fd_ = -1;                // file_'s descriptor while open
  int write_errno_ = 0;        // the failed write's errno (the writer thread's; read after join)
  std::atomic<bool> direct_{false};  // the writer thread may fall back to plain writes
  std::string path_;
  std::unique_ptr<unsigned char, Free> buffers_[2];  // kWriteBuffer bytes each, block-aligned
  int filling_ = 0;            // the buffer being filled
  std::size_t used_ = 0;       // bytes in it
  std::uint64_t written_ = 0;  // bytes handed over before it
  std::int64_t count_ = 0;
  std::atomic<bool> failed_{false};
  bool invalid_ = false;
  // the hand-over: the buffer the writer thread is to write (-1: none) and its length
  std::thread writer_;
  std::mutex mutex_;
  std::condition_variable cv_;
  int handed_ = -1;
  std::size_t handed_len_ = 0;
  bool stop_ = false;
};

}  // namespace chaincomp
