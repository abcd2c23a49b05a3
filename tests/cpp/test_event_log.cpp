// The LCM log reader and writer against the format as liblcm writes it (lcm_eventlog_*).
#include <catch2/catch.hpp>
#include <lcm/eventlog.h>

#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <string>
#include <vector>

#include "chaincomp/event_log.hpp"
#include "chaincomp/output_file.hpp"

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
  // a log that lost events is not put in place (output_file.hpp): no file, whole or partial
  struct stat st {};
  CHECK(::stat(path.c_str(), &st) != 0);
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

TEST_CASE("a log cut short or replaced while it is read ends cleanly (no SIGBUS)", "[event_log]") {
  // 3000 events of 4 KiB: 12 MiB, three of the reader's 4 MiB chunks
  const std::string path = temp_path("shrinking.lcmlog");
  const int count = 3000, bytes = 4096;
  auto write_log = [&](const std::string& p, int n) {
    lcm_eventlog_t* l = lcm_eventlog_create(p.c_str(), "w");
    REQUIRE(l != nullptr);
    std::vector<unsigned char> data(bytes);
    for (int k = 0; k < n; ++k) {
      for (int i = 0; i < bytes; ++i) data[i] = static_cast<unsigned char>(k + i);
      lcm_eventlog_event_t ev{};
      ev.timestamp = k;
      ev.channellen = 4;
      ev.datalen = bytes;
      ev.channel = const_cast<char*>("CHAN");
      ev.data = data.data();
      REQUIRE(lcm_eventlog_write_event(l, &ev) == 0);
    }
    lcm_eventlog_destroy(l);
  };
  const bool replace = GENERATE(false, true);
  INFO((replace ? "replaced by a shorter file" : "truncated in place"));
  write_log(path, count);
  std::string error;
  chaincomp::LogReader in;
  REQUIRE(in.open(path, error));
  chaincomp::LogEvent ev;
  REQUIRE(in.next(ev));
  if (replace) {
    write_log(path + ".new", 10);
    REQUIRE(std::rename((path + ".new").c_str(), path.c_str()) == 0);
  } else {
    // past the first 4 MiB chunk (already read), mid-event: a mapped reader would fault here
    REQUIRE(truncate(path.c_str(), 5L * (1 << 20) + 13) == 0);
  }
  int k = 1;
  bool intact = true;
  while (in.next(ev)) {
    intact = intact && ev.eventnum == k && ev.timestamp == k && ev.datalen == bytes;
    for (int i = 0; intact && i < bytes; i += 997) intact = ev.data[i] == static_cast<unsigned char>(k + i);
    ++k;
  }
  CHECK(intact);  // every event read is the one written, in order
  if (replace) {
    // the open file is the old one: all of it is read, nothing damaged
    CHECK(k == count);
    CHECK(in.damage().empty());
  } else {
    // the events wholly inside the first 5 MiB, then the torn one reported as damage
    const long event_bytes = 28 + 4 + bytes;
    CHECK(k == (5L * (1 << 20) + 13) / event_bytes);
    REQUIRE(in.damage().size() == 1);
    CHECK(in.damage()[0].offset == static_cast<std::uint64_t>(k) * event_bytes);
    CHECK(in.damage()[0].offset + in.damage()[0].bytes == 5ull * (1 << 20) + 13);
  }
  std::remove(path.c_str());
}

// The one writer (output_file.hpp), by POSIX's rules: rename(2) replaces the name it is given,
// so a temporary file renamed over a link's target leaves the link; a writer that never
// commits must leave the target and its folder as they were.
TEST_CASE("OutputFile: nothing in place until commit; links kept, a dangling one created where it points",
          "[output_file]") {
  char dir_template[] = "/tmp/chaincomp_output_XXXXXX";
  REQUIRE(mkdtemp(dir_template) != nullptr);
  const std::string dir = dir_template, target = dir + "/target", link = dir + "/link";
  auto read = [](const std::string& p) {
    std::string s;
    if (std::FILE* f = std::fopen(p.c_str(), "rb")) {
      char buf[64];
      for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f)) > 0;) s.append(buf, n);
      std::fclose(f);
    }
    return s;
  };
  auto entries = [&]() {
    int n = 0;
    for (const char* name : {"target", "link"}) {
      struct stat st {};
      n += ::lstat((dir + "/" + name).c_str(), &st) == 0;
    }
    return n;
  };
  std::string error;
  REQUIRE(::symlink("target", link.c_str()) == 0);  // dangling: nothing at target yet
  {
    chaincomp::OutputFile out;
    REQUIRE(out.open(link, error));
    REQUIRE(::write(out.fd(), "abandoned", 9) == 9);
  }  // not committed
  CHECK(entries() == 1);  // the link alone: no target, no temporary file
  {
    chaincomp::OutputFile out;
    REQUIRE(out.open(link, error));
    REQUIRE(::write(out.fd(), "new", 3) == 3);
    REQUIRE(out.commit(error));
  }
  struct stat st {};
  REQUIRE(::lstat(link.c_str(), &st) == 0);
  CHECK(S_ISLNK(st.st_mode));
  CHECK(read(target) == "new");
  CHECK(entries() == 2);
  chaincomp::OutputFile folder;
  CHECK_FALSE(folder.open(dir, error));  // a folder is not written into
  CHECK(error == dir + ": cannot write: Is a directory");
  std::remove(link.c_str());
  std::remove(target.c_str());
  CHECK(::rmdir(dir.c_str()) == 0);  // empty: no temporary file was left
}
