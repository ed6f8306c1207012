// SLCAN line parser/encoder (cdam/slcan.hpp). Expected lines written out from the Lawicel
// protocol as python-can's slcan interface sends them (upper-case hex).
#include <doctest/doctest.h>

#include <cstdint>
#include <cstring>
#include <string>

#include "cdam/slcan.hpp"

namespace slcan = cdam::slcan;
using cdam::CanFrame;

static slcan::Event parse(const std::string& s) { return slcan::parse_line(s.data(), s.size()); }

TEST_CASE("slcan: standard data frame") {
  const slcan::Event ev = parse("t20180102030405060708");
  REQUIRE(ev.kind == slcan::Kind::Frame);
  CHECK(ev.frame.id == 0x201);
  CHECK(ev.frame.dlc == 8);
  CHECK(!ev.frame.extended);
  CHECK(!ev.frame.remote);
  for (int k = 0; k < 8; ++k) CHECK(ev.frame.data[k] == k + 1);
}

TEST_CASE("slcan: extended, remote, empty, lower-case hex") {
  slcan::Event ev = parse("T1ABCDEF02abCD");
  REQUIRE(ev.kind == slcan::Kind::Frame);
  CHECK(ev.frame.extended);
  CHECK(ev.frame.id == 0x1ABCDEF0u);
  CHECK(ev.frame.dlc == 2);
  CHECK(ev.frame.data[0] == 0xAB);
  CHECK(ev.frame.data[1] == 0xCD);
  ev = parse("r7FF3");
  REQUIRE(ev.kind == slcan::Kind::Frame);
  CHECK(ev.frame.remote);
  CHECK(ev.frame.dlc == 3);
  CHECK(parse("t1230").kind == slcan::Kind::Frame);
  CHECK(parse("").kind == slcan::Kind::Empty);
}

TEST_CASE("slcan: commands") {
  CHECK(parse("O").kind == slcan::Kind::Open);
  CHECK(parse("C").kind == slcan::Kind::Close);
  CHECK(parse("L").kind == slcan::Kind::ListenOnly);
  const slcan::Event ev = parse("S8");
  CHECK(ev.kind == slcan::Kind::Bitrate);
  CHECK(ev.arg == 8);
  CHECK(parse("s031C").kind == slcan::Kind::BitTiming);
  CHECK(parse("V").kind == slcan::Kind::Version);
  CHECK(parse("Z1").kind == slcan::Kind::Timestamp);
}

TEST_CASE("slcan: malformed lines are errors") {
  for (const char* bad : {"t800", "t2019", "t20180102", "t201801020304050607080", "t20G1", "tx",
                          "T2000000000", "S9", "Ox", "Q", "t201", "s03", "Z2", "T1ABCDEF0"}) {
    INFO(bad);
    CHECK(parse(bad).kind == slcan::Kind::Error);
  }
}

TEST_CASE("slcan: encode matches python-can's format and round-trips") {
  CanFrame f;
  f.id = 0x200;
  f.dlc = 8;
  const std::uint8_t d[8] = {0x03, 0xE8, 0xFC, 0x18, 0, 0, 0xAB, 0x0C};
  std::memcpy(f.data, d, 8);
  char out[32];
  const std::size_t n = slcan::encode(f, out, sizeof out);
  CHECK(std::string(out, n) == "t200803E8FC180000AB0C\r");
  const slcan::Event ev = slcan::parse_line(out, n - 1);
  REQUIRE(ev.kind == slcan::Kind::Frame);
  CHECK(std::memcmp(ev.frame.data, d, 8) == 0);
  CHECK(slcan::encode(f, out, 21) == 0);  // too small: needs 22
  f.extended = true;
  f.id = 0x12345;
  f.dlc = 0;
  CHECK(std::string(out, slcan::encode(f, out, sizeof out)) == "T000123450\r");
  f.id = 0x20000000;
  CHECK(slcan::encode(f, out, sizeof out) == 0);
}

TEST_CASE("slcan: LineReader splits lines and drops overlong ones") {
  slcan::LineReader r;
  slcan::Event ev;
  const std::string stream = "S8\rO\r" + std::string(100, 'A') + "\rt2010\r\n";
  int lines = 0;
  slcan::Kind kinds[8];
  for (char c : stream)
    if (r.push(c, &ev)) kinds[lines++] = ev.kind;
  REQUIRE(lines == 4);
  CHECK(kinds[0] == slcan::Kind::Bitrate);
  CHECK(kinds[1] == slcan::Kind::Open);
  CHECK(kinds[2] == slcan::Kind::Error);
  CHECK(kinds[3] == slcan::Kind::Frame);
  CHECK(r.pending() == 0);
}
