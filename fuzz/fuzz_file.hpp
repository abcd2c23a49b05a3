// The fuzz input as a file (the loaders under test take paths): one memfd per process,
// rewritten for every input and named through /proc/self/fd.
#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>

namespace chaincomp_fuzz {

inline std::string as_file(const std::uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("fuzz_input", 0);
  if (fd < 0 || ftruncate(fd, 0) != 0) std::abort();
  for (std::size_t done = 0; done < size;) {
    const ssize_t k = pwrite(fd, data + done, size - done, static_cast<off_t>(done));
    if (k <= 0) std::abort();
    done += static_cast<std::size_t>(k);
  }
  return "/proc/self/fd/" + std::to_string(fd);
}

}  // namespace chaincomp_fuzz
