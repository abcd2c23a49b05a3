// The one writer of the C++ programs' files: see output_file.hpp.
#include "chaincomp/output_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <climits>
#include <cstdlib>
#include <cstring>

namespace chaincomp {

namespace {

std::string cannot(const std::string& path, int err) { return path + ": cannot write: " + std::strerror(err); }

std::string folder_of(const std::string& path) {
  const auto k = path.rfind('/');
  return k == std::string::npos ? "." : k == 0 ? "/" : path.substr(0, k);
}

std::string name_of(const std::string& path) {
  const auto k = path.rfind('/');
  return k == std::string::npos ? path : path.substr(k + 1);
}

// The file a chain of symbolic links ends at, or would be created at (each link read relative
// to its own folder); `path` itself when it is not a link. false with `err` (ELOOP, EACCES...).
bool resolve(std::string path, std::string& out, int& err) {
  for (int hops = 0; hops < 40; ++hops) {
    struct stat st {};
    if (lstat(path.c_str(), &st) != 0 && errno != ENOENT) {
      err = errno;
      return false;
    }
    if (!S_ISLNK(st.st_mode)) {  // a file, or nothing there (st zeroed)
      out = path;
      return true;
    }
    std::string link(PATH_MAX, '\0');
    const ssize_t n = readlink(path.c_str(), link.data(), link.size());
    if (n < 0) {
      err = errno;
      return false;
    }
    link.resize(static_cast<std::size_t>(n));
    path = link[0] == '/' ? link : folder_of(path) + "/" + link;
  }
  err = ELOOP;
  return false;
}

mode_t current_umask() {
  const mode_t mask = umask(022);
  umask(mask);
  return mask;
}

}  // namespace

OutputFile::~OutputFile() { discard(); }

bool OutputFile::open(const std::string& path, std::string& error) {
  discard();
  path_ = path;
  struct stat st {};
  const bool exists = ::stat(path.c_str(), &st) == 0;  // through links
  if (!exists && errno != ENOENT) {
    error = cannot(path, errno);
    return false;
  }
  special_ = exists && !S_ISREG(st.st_mode);
  if (special_) {  // a pipe or a device: written into, never replaced (a directory: EISDIR)
    fd_ = ::open(path.c_str(), O_WRONLY | O_CLOEXEC | O_NOCTTY);
    if (fd_ < 0) {
      error = cannot(path, errno);
      return false;
    }
    return true;
  }
  int err = 0;
  if (!resolve(path, target_, err)) {
    error = cannot(path, err);
    return false;
  }
  mode_ = exists ? (st.st_mode & 07777) : (0666 & ~current_umask());
  std::string tmp = folder_of(target_) + "/." + name_of(target_) + ".XXXXXX.tmp";
  fd_ = mkostemps(tmp.data(), 4, O_CLOEXEC);  // O_CREAT | O_EXCL: never through a planted link
  if (fd_ < 0) {
    error = cannot(path, errno);
    return false;
  }
  tmp_ = tmp;
  return true;
}

bool OutputFile::commit(std::string& error) {
  if (fd_ < 0) {
    error = cannot(path_, EBADF);
    return false;
  }
  int err = 0;
  if (!special_ && (fchmod(fd_, mode_) != 0 || fsync(fd_) != 0)) err = errno;  // on disk before the rename
  if (::close(fd_) != 0 && err == 0) err = errno;
  fd_ = -1;
  if (err == 0 && !special_ && ::rename(tmp_.c_str(), target_.c_str()) != 0) err = errno;
  if (err != 0) {
    discard();
    error = cannot(path_, err);
    return false;
  }
  tmp_.clear();
  return true;
}

void OutputFile::discard() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!tmp_.empty()) ::unlink(tmp_.c_str());
  tmp_.clear();
}

}  // namespace chaincomp
