// Reading LCM's encoding by hand, without allocating: big-endian integers and doubles,
// strings as int32 length (with the NUL), the bytes and the NUL. For the messages whose
// variable-length arrays lcm-gen's decoder would allocate for (params updates, readings).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string_view>

namespace chaincomp {

struct WireReader {
  const unsigned char* p;
  std::size_t left;

  bool u64(std::uint64_t& v) noexcept {
    if (left < 8) return false;
    v = 0;
    for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
    p += 8;
    left -= 8;
    return true;
  }
  bool i64(std::int64_t& v) noexcept {
    std::uint64_t u;
    if (!u64(u)) return false;
    v = static_cast<std::int64_t>(u);
    return true;
  }
  bool i32(std::int32_t& v) noexcept {
    if (left < 4) return false;
    v = static_cast<std::int32_t>((std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) |
                                  (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]));
    p += 4;
    left -= 4;
    return true;
  }
  bool f64(double& v) noexcept {
    std::uint64_t u;
    if (!u64(u)) return false;
    std::memcpy(&v, &u, sizeof v);
    return true;
  }
  // A string of at most `max_bytes` (without the NUL), viewed in place.
  bool str(std::string_view& s, std::int32_t max_bytes = 255) noexcept {
    std::int32_t len;
    if (!i32(len) || len < 1 || len > max_bytes + 1 || static_cast<std::size_t>(len) > left || p[len - 1] != 0)
      return false;
    s = std::string_view(reinterpret_cast<const char*>(p), static_cast<std::size_t>(len - 1));
    p += len;
    left -= static_cast<std::size_t>(len);
    return true;
  }
  // The end of a message: `n` strings (names[]) and then `n` doubles (values[]), nothing after.
  bool names_then_values(int n, std::string_view* names, double* values) noexcept {
    for (int i = 0; i < n; ++i) {
      if (!str(names[i])) return false;
    }
    for (int i = 0; i < n; ++i) {
      if (!f64(values[i])) return false;
    }
    return left == 0;
  }
};

}  // namespace chaincomp
