// LCM event logs (the format lcm-logger writes and lcm-logplayer plays) read and written
// without an allocation or a system call per event: liblcm's reader allocates three blocks
// and seeks back and forth for every event, which cost chaincomp_replay more than the
// compensation. Format, per event, big-endian: sync word 0xEDA1DA01, event number (int64),
// timestamp in µs (int64), channel length (int32), data length (int32), channel, data.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace chaincomp {

struct LogEvent {
  std::int64_t eventnum = 0, timestamp = 0;
  std::string_view channel;
  const unsigned char* data = nullptr;
  std::int32_t datalen = 0;
  std::uint64_t offset = 0;  // byte offset of the event's sync word in the file
};

// Reads a whole log through a read-only memory map (a log cut short by another process
// while it is read ends the reader with SIGBUS, as any mapped reader: replay logs at rest).
class LogReader {
 public:
  LogReader() = default;
  LogReader(const LogReader&) = delete;
  LogReader& operator=(const LogReader&) = delete;
  ~LogReader();

  // False with `error` naming the file when it cannot be opened or mapped. Opening again
  // starts over with the new file.
  bool open(const std::string& path, std::string& error);
  // The next event; false at the end. A damaged stretch (no sync word where one belongs, a
  // length that does not fit) is skipped up to the next sync word and recorded in damage().
  bool next(LogEvent& ev) noexcept;

  struct Damage {
    std::uint64_t offset = 0;  // where the damaged stretch starts
    std::uint64_t bytes = 0;   // how long it is
    const char* what = "";     // why it is not an event
  };
  // Every damaged stretch seen so far, in file order.
  const std::vector<Damage>& damage() const noexcept { return damage_; }

 private:
  // Skips from pos_ to the next sync word (or to the end) and records the stretch.
  void skip_damaged(const char* what, bool to_end = false) noexcept;

  const unsigned char* data_ = nullptr;
  std::size_t size_ = 0, pos_ = 0;
  std::vector<Damage> damage_;
};

// Appends events through one large buffer; event numbers count from 0, as lcm-logger's.
class LogWriter {
 public:
  LogWriter() = default;
  LogWriter(const LogWriter&) = delete;
  LogWriter& operator=(const LogWriter&) = delete;
  ~LogWriter();

  bool open(const std::string& path, std::string& error);
  // false once a write has failed (the disk is full...), or for an event no reader would
  // take (empty or 1000+ byte channel, negative length, refused): see close().
  bool write(std::int64_t timestamp, std::string_view channel, const void* data, std::int32_t datalen) noexcept;
  // Flushes and closes; false with `error` if any write failed.
  bool close(std::string& error);

 private:
  bool flush() noexcept;
  bool append(const void* p, std::size_t n) noexcept;

  std::FILE* file_ = nullptr;
  std::string path_;
  std::vector<unsigned char> buffer_;
  std::size_t used_ = 0;
  std::int64_t count_ = 0;
  bool failed_ = false, invalid_ = false;
};

}  // namespace chaincomp
