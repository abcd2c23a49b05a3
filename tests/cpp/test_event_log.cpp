// The LCM log reader and writer against the format as liblcm writes it (lcm_eventlog_*).
#include <catch2/catch.hpp>
#include <lcm/eventlog.h>

#include <cstdio>
#include <string>
#include <vector>

#include "chaincomp/event_log.hpp"

namespace {

std::string temp_path(const char* name) { return std::string("/tmp/chaincomp_test_") + name; }

}  // namespace

TEST_CASE("events written by liblcm read back, and ours read back with liblcm", "[event_log]") {
  // one event of 3 MB crosses the 1 MiB write buffer; the log's length is not a whole block
  const std::string theirs = temp_path("theirs.lcmlog");
  {
    lcm_eventlog_t* l = lcm_eventlog_create(theirs.c_str(), "w");
    REQUIRE(l != nullptr);
    for (int k = 0; k < 50; ++k) {
      std::vector<unsigned char> data(static_cast<std::size_t>(k * 7 + (k == 20 ? 3000000 : 0)),
                                      static_cast<unsigned char>(k));
      std::string channel = k % 2 ? "CHAINCOMP_COMMAND" : "OTHER";
      lcm_eventlog_event_t ev{};
      ev.timestamp = 1000 * k - 7;
      ev.channellen = static_cast<int32_t>(channel.size());
      ev.datalen = static_cast<int32_t>(data.size());
      ev.channel = channel.data();
      ev.data = data.data();
      REQUIRE(lcm_eventlog_write_event(l, &ev) == 0);
    }
    lcm_eventlog_destroy(l);
  }
  // direct I/O (where /tmp takes it), plain writes, and whatever /dev/shm (tmpfs) allows
  const bool direct = GENERATE(true, false);
  const std::string ours_dir = GENERATE(as<std::string>{}, "/tmp", "/dev/shm");
  const std::string ours_path = ours_dir + "/chaincomp_test_ours.lcmlog";
  INFO("direct " << direct << ", " << ours_path);
  std::string error;
  chaincomp::LogReader in;
  REQUIRE(in.open(theirs, error));
  chaincomp::LogWriter out;
  if (!out.open(ours_path, error, direct)) {
    WARN("skipped: " << error);  // no /dev/shm here
    return;
  }
  chaincomp::LogEvent ev;
  int k = 0;
  while (in.next(ev)) {
    CHECK(ev.eventnum == k);
    CHECK(ev.timestamp == 1000 * k - 7);
    CHECK(ev.channel == (k % 2 ? "CHAINCOMP_COMMAND" : "OTHER"));
    REQUIRE(ev.datalen == 7 * k + (k == 20 ? 3000000 : 0));
    bool same = true;
    for (int i = 0; i < ev.datalen; ++i) same = same && ev.data[i] == k;
    CHECK(same);
    CHECK(out.write(ev.timestamp, ev.channel, ev.data, ev.datalen));
    ++k;
  }
  CHECK(k == 50);
  CHECK(in.damage().empty());
  REQUIRE(out.close(error));
  // liblcm reads ours: the same events, numbered from 0
  lcm_eventlog_t* l = lcm_eventlog_create(ours_path.c_str(), "r");
  REQUIRE(l != nullptr);
  int n = 0;
  while (lcm_eventlog_event_t* e = lcm_eventlog_read_next_event(l)) {
    CHECK(e->eventnum == n);
    CHECK(e->timestamp == 1000 * n - 7);
    CHECK(e->datalen == 7 * n + (n == 20 ? 3000000 : 0));
    lcm_eventlog_free_event(e);
    ++n;
  }
  lcm_eventlog_destroy(l);
  CHECK(n == 50);
  std::remove(theirs.c_str());
  std::remove(ours_path.c_str());
}

TEST_CASE("the writer refuses an event no reader would take, and says so on close", "[event_log]") {
  const std::string path = temp_path("refused.lcmlog");
  std::string error;
  chaincomp::LogWriter out;
  REQUIRE(out.open(path, error));
  const unsigned char data[4] = {1, 2, 3, 4};
  CHECK(out.write(1, "GOOD", data, 4));
  CHECK_FALSE(out.write(2, "", data, 4));
  CHECK_FALSE(out.write(3, std::string(1000, 'C'), data, 4));
  CHECK_FALSE(out.write(4, "GOOD", data, -1));
  CHECK_FALSE(out.close(error));
  CHECK(error.find("refused") != std::string::npos);
  chaincomp::LogReader in;
  REQUIRE(in.open(path, error));
  chaincomp::LogEvent ev;
  int events = 0;
  while (in.next(ev)) ++events;
  CHECK(events == 1);  // the good event, and nothing of the refused ones
  CHECK(in.damage().empty());
  std::remove(path.c_str());
}

TEST_CASE("an empty log has no events and no damage; a missing one is an error", "[event_log]") {
  const std::string path = temp_path("empty.lcmlog");
  std::FILE* f = std::fopen(path.c_str(), "wb");
  REQUIRE(f != nullptr);
  std::fclose(f);
  std::string error;
  chaincomp::LogReader in;
  REQUIRE(in.open(path, error));
  chaincomp::LogEvent ev;
  CHECK_FALSE(in.next(ev));
  CHECK(in.damage().empty());
  std::remove(path.c_str());
  CHECK_FALSE(in.open(path, error));
  CHECK(error == path + ": no such log file");
}
