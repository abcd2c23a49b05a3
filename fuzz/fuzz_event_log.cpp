// The LCM log reader on any bytes: every event it returns lies inside the file and is
// well formed; damaged stretches tile what is not an event.
#include <cstdint>
#include <cstdlib>

#include "chaincomp/event_log.hpp"
#include "fuzz_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string error;
  chaincomp::LogReader in;
  if (!in.open(chaincomp_fuzz::as_file(data, size), error)) std::abort();
  chaincomp::LogEvent ev;
  std::uint64_t covered = 0;  // bytes in events
  while (in.next(ev)) {
    const std::uint64_t len = 28 + ev.channel.size() + static_cast<std::uint64_t>(ev.datalen);
    if (ev.offset + len > size || ev.channel.empty() || ev.datalen < 0) std::abort();
    if (ev.channel.data() != reinterpret_cast<const char*>(ev.data) - ev.channel.size()) std::abort();
    covered += len;
  }
  for (const auto& d : in.damage()) covered += d.bytes;
  if (covered != size) std::abort();  // every byte is in an event or in a damaged stretch
  return 0;
}
