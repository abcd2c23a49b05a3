// Content hash of a machine file: FNV-1a 64 over its bytes. It detects a machine file that
// changed after its model was compiled; it is not a cryptographic hash.
#pragma once

#include <cstddef>
#include <cstdint>

namespace chaincomp {

constexpr std::uint64_t fnv1a64(const unsigned char* data, std::size_t n) noexcept {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (std::size_t i = 0; i < n; ++i) {
    h ^= data[i];
    h *= 0x100000001b3ull;
  }
  return h;
}

}  // namespace chaincomp
