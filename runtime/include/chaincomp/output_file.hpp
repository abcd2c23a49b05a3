// The one writer of every file the C++ programs write (design §11), with the rules of the
// Python side's chaincomp.output: a file appears whole or not at all, and nothing but the named
// path changes.
//
// - A regular file (or a name not there yet) is written to a temporary file created exclusively
//   (mkostemps: O_EXCL, an unpredictable name, never through a planted link) in the target's
//   folder, flushed to disk, then renamed over the target. The old file's permissions are kept;
//   a new file gets 0666 less the umask, as open() would give it.
// - Through a symbolic link the link is resolved and the file it names is replaced: the link
//   stays a link.
// - A target that is not a regular file (a named pipe, /dev/stdout, a device) is written into:
//   a rename would replace the node itself.
// - Until commit() succeeds nothing is in place; the destructor removes the temporary file.
#pragma once

#include <string>

namespace chaincomp {

class OutputFile {
 public:
  OutputFile() = default;
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;
  ~OutputFile();  // not committed: the temporary file is removed, the target untouched

  // A descriptor to write `path`'s new content to; false with `error` ("PATH: cannot write: ...").
  bool open(const std::string& path, std::string& error);
  int fd() const { return fd_; }
  bool special() const { return special_; }  // written into directly (a pipe, a device)
  // Puts the written content in place (fsync and rename; a pipe or device: closed); false with
  // `error`, the temporary file removed and the target untouched.
  bool commit(std::string& error);
  // Gives up: the temporary file removed (a pipe or device: closed), the target untouched.
  void discard() noexcept;

 private:
  std::string path_, target_, tmp_;  // as named; the file replaced (links resolved); the temporary
  int fd_ = -1;
  unsigned mode_ = 0;
  bool special_ = false;
};

}  // namespace chaincomp
