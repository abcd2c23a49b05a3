#include "chaincomp/event_log.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace chaincomp {

namespace {

constexpr std::uint32_t kSync = 0xEDA1DA01u;
constexpr std::size_t kHeader = 4 + 8 + 8 + 4 + 4;
constexpr std::int32_t kMaxChannel = 1000;  // liblcm refuses longer channel names
constexpr std::size_t kWriteBuffer = 1 << 20;

std::uint64_t be(const unsigned char* p, int bytes) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

void put_be(unsigned char* p, std::uint64_t v, int bytes) noexcept {
  for (int i = bytes - 1; i >= 0; --i, v >>= 8) p[i] = static_cast<unsigned char>(v);
}

}  // namespace

LogReader::~LogReader() {
  if (data_ != nullptr && size_ > 0) munmap(const_cast<unsigned char*>(data_), size_);
}

bool LogReader::open(const std::string& path, std::string& error) {
  if (data_ != nullptr && size_ > 0) munmap(const_cast<unsigned char*>(data_), size_);
  data_ = nullptr;
  size_ = pos_ = 0;
  damage_.clear();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    error = path + ": " + (errno == ENOENT ? "no such log file" : std::strerror(errno));
    return false;
  }
  struct stat st {};
  if (fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    error = path + ": not a regular file";
    ::close(fd);
    return false;
  }
  size_ = static_cast<std::size_t>(st.st_size);
  if (size_ > 0) {
    void* p = mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (p == MAP_FAILED) {
      error = path + ": cannot map the log: " + std::strerror(errno);
      size_ = 0;
      ::close(fd);
      return false;
    }
    madvise(p, size_, MADV_SEQUENTIAL);
    data_ = static_cast<const unsigned char*>(p);
  }
  ::close(fd);
  return true;
}

void LogReader::skip_damaged(const char* what, bool to_end) noexcept {
  const std::size_t start = pos_;
  std::size_t p = pos_ + 1;
  while (!to_end && p + 4 <= size_ && be(data_ + p, 4) != kSync) ++p;
  pos_ = !to_end && p + 4 <= size_ ? p : size_;
  // one report per damaged stretch: a stretch that continues the last one extends it
  if (!damage_.empty() && damage_.back().offset + damage_.back().bytes == start) {
    damage_.back().bytes += pos_ - start;
  } else {
    damage_.push_back({start, pos_ - start, what});
  }
}

bool LogReader::next(LogEvent& ev) noexcept {
  while (pos_ < size_) {
    if (size_ - pos_ < kHeader) {
      skip_damaged("truncated event at the end of the log", true);
      continue;
    }
    const unsigned char* h = data_ + pos_;
    if (be(h, 4) != kSync) {
      skip_damaged("no sync word");
      continue;
    }
    const auto channellen = static_cast<std::int32_t>(be(h + 20, 4));
    const auto datalen = static_cast<std::int32_t>(be(h + 24, 4));
    if (channellen <= 0 || channellen >= kMaxChannel || datalen < 0) {
      skip_damaged("invalid channel or data length");
      continue;
    }
    const std::size_t total = kHeader + static_cast<std::size_t>(channellen) + static_cast<std::size_t>(datalen);
    if (total > size_ - pos_) {
      skip_damaged("event length runs past the end of the log (a damaged length, or the log was cut short)");
      continue;
    }
    ev.offset = pos_;
    ev.eventnum = static_cast<std::int64_t>(be(h + 4, 8));
    ev.timestamp = static_cast<std::int64_t>(be(h + 12, 8));
    ev.channel = std::string_view(reinterpret_cast<const char*>(h + kHeader), static_cast<std::size_t>(channellen));
    ev.data = h + kHeader + channellen;
    ev.datalen = datalen;
    pos_ += total;
    return true;
  }
  return false;
}

LogWriter::~LogWriter() {
  std::string ignored;
  if (file_ != nullptr) close(ignored);
}

bool LogWriter::open(const std::string& path, std::string& error) {
  file_ = std::fopen(path.c_str(), "wb");
  if (file_ == nullptr) {
    error = path + ": cannot create the log: " + std::strerror(errno);
    return false;
  }
  path_ = path;
  buffer_.resize(kWriteBuffer);
  return true;
}

bool LogWriter::flush() noexcept {
  if (used_ > 0 && !failed_ && std::fwrite(buffer_.data(), 1, used_, file_) != used_) failed_ = true;
  used_ = 0;
  return !failed_;
}

bool LogWriter::append(const void* p, std::size_t n) noexcept {
  if (used_ + n > buffer_.size() && !flush()) return false;
  if (n > buffer_.size()) {  // larger than the buffer: straight through
    failed_ = std::fwrite(p, 1, n, file_) != n;
  } else if (n > 0) {
    std::memcpy(buffer_.data() + used_, p, n);
    used_ += n;
  }
  return !failed_;
}

bool LogWriter::write(std::int64_t timestamp, std::string_view channel, const void* data,
                      std::int32_t datalen) noexcept {
  if (channel.empty() || channel.size() >= static_cast<std::size_t>(kMaxChannel) || datalen < 0) {
    invalid_ = true;  // not an event a reader would take: refused, reported by close()
    return false;
  }
  unsigned char h[kHeader];
  put_be(h, kSync, 4);
  put_be(h + 4, static_cast<std::uint64_t>(count_++), 8);
  put_be(h + 12, static_cast<std::uint64_t>(timestamp), 8);
  put_be(h + 20, channel.size(), 4);
  put_be(h + 24, static_cast<std::uint64_t>(datalen), 4);
  return append(h, kHeader) && append(channel.data(), channel.size()) &&
         append(data, static_cast<std::size_t>(datalen));
}

bool LogWriter::close(std::string& error) {
  if (file_ == nullptr) return true;
  flush();
  if (std::fclose(file_) != 0) failed_ = true;
  file_ = nullptr;
  if (failed_) error = path_ + ": writing the log failed (disk full?)";
  else if (invalid_) error = path_ + ": an event with an empty or too long channel, or a negative length, was refused";
  return !failed_ && !invalid_;
}

}  // namespace chaincomp
