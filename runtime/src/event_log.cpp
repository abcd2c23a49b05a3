#include "chaincomp/event_log.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace chaincomp {

namespace {

constexpr std::uint32_t kSync = 0xEDA1DA01u;
constexpr std::size_t kHeader = 4 + 8 + 8 + 4 + 4;
constexpr std::int32_t kMaxChannel = 1000;  // liblcm refuses longer channel names

std::uint64_t be(const unsigned char* p, int bytes) noexcept {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

void put_be(unsigned char* p, std::uint64_t v, int bytes) noexcept {
  for (int i = bytes - 1; i >= 0; --i, v >>= 8) p[i] = static_cast<unsigned char>(v);
}

}  // namespace

LogReader::~LogReader() { close(); }

void LogReader::close() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  start_ = len_ = 0;
  size_ = pos_ = 0;
}

bool LogReader::open(const std::string& path, std::string& error) {
  close();
  damage_.clear();
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) {
    error = path + ": " + (errno == ENOENT ? "no such log file" : std::strerror(errno));
    return false;
  }
  struct stat st {};
  if (fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    error = path + ": not a regular file";
    close();
    return false;
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
  if (capacity_ < kChunk) {
    buf_.reset(static_cast<unsigned char*>(std::malloc(kChunk)));
    capacity_ = buf_ ? kChunk : 0;
    if (!buf_) {
      error = path + ": no memory for the read buffer";
      close();
      return false;
    }
  }
  return true;
}

bool LogReader::have(std::size_t n) noexcept {
  if (pos_ >= start_ && pos_ + n <= start_ + len_) return true;
  if (pos_ + n > size_) return false;
  // keep the unread tail, then fill the buffer from the file
  const std::size_t keep = pos_ >= start_ && pos_ < start_ + len_ ? static_cast<std::size_t>(start_ + len_ - pos_) : 0;
  if (keep > 0) std::memmove(buf_.get(), at(), keep);
  start_ = pos_;
  len_ = keep;
  if (n > capacity_) {
    auto* p = static_cast<unsigned char*>(std::realloc(buf_.release(), n));
    if (p == nullptr) return false;  // cannot happen below kMaxEvent on this machine's sizes
    buf_.reset(p);
    capacity_ = n;
  }
  while (len_ < n) {
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(capacity_ - len_, size_ - (start_ + len_)));
    const ssize_t k = pread(fd_, buf_.get() + len_, want, static_cast<off_t>(start_ + len_));
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) {  // the file shrank (or cannot be read) while it is read: it ends here
      size_ = start_ + len_;
      return false;
    }
    len_ += static_cast<std::size_t>(k);
  }
  return true;
}

void LogReader::skip_damaged(const char* what, bool to_end) noexcept {
  const std::uint64_t start = pos_;
  ++pos_;
  while (!to_end && have(4) && be(at(), 4) != kSync) ++pos_;
  if (to_end || pos_ + 4 > size_) pos_ = size_;
  // one report per damaged stretch: a stretch that continues the last one extends it
  if (!damage_.empty() && damage_.back().offset + damage_.back().bytes == start) {
    damage_.back().bytes += pos_ - start;
  } else {
    damage_.push_back({start, pos_ - start, what});
  }
}

bool LogReader::next(LogEvent& ev) noexcept {
  while (pos_ < size_) {
    if (!have(kHeader)) {
      skip_damaged("truncated event at the end of the log", true);
      continue;
    }
    const unsigned char* h = at();
    if (be(h, 4) != kSync) {
      skip_damaged("no sync word");
      continue;
    }
    const auto channellen = static_cast<std::int32_t>(be(h + 20, 4));
    const auto datalen = static_cast<std::int32_t>(be(h + 24, 4));
    if (channellen <= 0 || channellen >= kMaxChannel || datalen < 0 ||
        static_cast<std::size_t>(datalen) > kMaxEvent) {
      skip_damaged("invalid channel or data length");
      continue;
    }
    const std::size_t total = kHeader + static_cast<std::size_t>(channellen) + static_cast<std::size_t>(datalen);
    if (!have(total)) {
      skip_damaged("event length runs past the end of the log (a damaged length, or the log was cut short)");
      continue;
    }
    h = at();  // the buffer may have moved
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
  if (fd_ >= 0) finish();  // not closed: file_ puts nothing in place
}

bool LogWriter::open(const std::string& path, std::string& error, bool direct) {
  if (fd_ >= 0) finish();
  fd_ = -1;
  if (!file_.open(path, error)) return false;
  fd_ = file_.fd();
  // Direct I/O where the filesystem takes it (a regular file); plain writes otherwise.
  direct_ = direct && !file_.special() && fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) | O_DIRECT) == 0;
  path_ = path;
  for (auto& b : buffers_) {
    if (!b) b.reset(static_cast<unsigned char*>(std::aligned_alloc(kBlock, kWriteBuffer)));
    if (!b) {
      error = path + ": no memory for the write buffers";
      file_.discard();
      fd_ = -1;
      return false;
    }
  }
  filling_ = 0;
  used_ = written_ = 0;
  count_ = 0;
  write_errno_ = 0;
  failed_ = invalid_ = false;
  handed_ = -1;
  stop_ = false;
  writer_ = std::thread([this] { write_loop(); });
  return true;
}

void LogWriter::write_loop() noexcept {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    cv_.wait(lock, [this] { return handed_ >= 0 || stop_; });
    if (handed_ < 0) return;  // stopped, nothing left
    const unsigned char* p = buffers_[handed_].get();
    const std::size_t n = handed_len_;
    lock.unlock();
    write_all(p, n);
    lock.lock();
    handed_ = -1;
    cv_.notify_all();
  }
}

void LogWriter::hand_over(std::size_t n) noexcept {
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait(lock, [this] { return handed_ < 0; });  // the writer is done with the other buffer
  handed_ = filling_;
  handed_len_ = n;
  cv_.notify_all();
  filling_ ^= 1;
}

bool LogWriter::write_all(const unsigned char* p, std::size_t n) noexcept {
  while (n > 0 && !failed_) {
    const ssize_t k = ::write(fd_, p, n);
    if (k < 0 && errno == EINTR) continue;
    if (k < 0 && errno == EINVAL && direct_) {  // the filesystem refuses direct writes after all
      direct_ = fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) & ~O_DIRECT) != 0;
      if (!direct_) continue;
    }
    if (k <= 0) {
      write_errno_ = k < 0 ? errno : EIO;
      failed_ = true;
      break;
    }
    p += k;
    n -= static_cast<std::size_t>(k);
  }
  return !failed_;
}

bool LogWriter::append(const void* data, std::size_t n) noexcept {
  const auto* p = static_cast<const unsigned char*>(data);
  while (n > 0 && !failed_) {
    const std::size_t take = std::min(n, kWriteBuffer - used_);
    std::memcpy(buffers_[filling_].get() + used_, p, take);
    used_ += take;
    p += take;
    n -= take;
    if (used_ == kWriteBuffer) {  // whole blocks: fine for direct I/O
      hand_over(kWriteBuffer);
      written_ += kWriteBuffer;
      used_ = 0;
    }
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

void LogWriter::finish() noexcept {
  // direct I/O writes whole blocks: the last one padded, the file then cut to its length
  const std::size_t padded = direct_ ? (used_ + kBlock - 1) / kBlock * kBlock : used_;
  if (padded > 0) {
    std::memset(buffers_[filling_].get() + used_, 0, padded - used_);
    hand_over(padded);
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  writer_.join();
  if (!failed_ && padded != used_ && ftruncate(fd_, static_cast<off_t>(written_ + used_)) != 0) {
    write_errno_ = errno;
    failed_ = true;
  }
}

bool LogWriter::close(std::string& error) {
  if (fd_ < 0) return true;
  finish();
  fd_ = -1;
  if (failed_) {
    file_.discard();
    error = path_ + ": cannot write: " + std::strerror(write_errno_);
    return false;
  }
  if (invalid_) {
    file_.discard();
    error = path_ + ": an event with an empty or too long channel, or a negative length, was refused";
    return false;
  }
  return file_.commit(error);
}

}  // namespace chaincomp
