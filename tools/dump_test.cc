#include "tools/dump.h"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <sstream>
#include <string>

namespace lrfnet::tools {
namespace {

TEST(FormatPythonFloatTest, MatchesPythonRepr) {
  // Expected strings are what CPython 3 prints for repr(x).
  EXPECT_EQ(FormatPythonFloat(15.0), "15.0");
  EXPECT_EQ(FormatPythonFloat(-45.0), "-45.0");
  EXPECT_EQ(FormatPythonFloat(1.0), "1.0");
  EXPECT_EQ(FormatPythonFloat(0.0), "0.0");
  EXPECT_EQ(FormatPythonFloat(-0.0), "-0.0");
  EXPECT_EQ(FormatPythonFloat(0.3333), "0.3333");
  EXPECT_EQ(FormatPythonFloat(0.1667), "0.1667");
  EXPECT_EQ(FormatPythonFloat(0.626), "0.626");
  EXPECT_EQ(FormatPythonFloat(-47.5), "-47.5");
  EXPECT_EQ(FormatPythonFloat(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(FormatPythonFloat(0.0001), "0.0001");
  EXPECT_EQ(FormatPythonFloat(0.00001), "1e-05");
  EXPECT_EQ(FormatPythonFloat(1.5e-7), "1.5e-07");
  EXPECT_EQ(FormatPythonFloat(123456789012345.0), "123456789012345.0");
  EXPECT_EQ(FormatPythonFloat(1e16), "1e+16");
  EXPECT_EQ(FormatPythonFloat(1.234e20), "1.234e+20");
  EXPECT_EQ(FormatPythonFloat(2500.0), "2500.0");
}

TEST(RoundDecimalsTest, MatchesPythonRound) {
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(3333 / 10000.0, 4)), "0.3333");
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(1667 / 10000.0, 4)), "0.1667");
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(0.12345678, 4)), "0.1235");
  // round(2.675, 2) == 2.67 in Python: the double is slightly below 2.675.
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(2.675, 2)), "2.67");
  // Exact ties go to even: round(0.125, 2) == 0.12.
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(0.125, 2)), "0.12");
  EXPECT_EQ(FormatPythonFloat(RoundDecimals(-5.0, 4)), "-5.0");
}

std::unique_ptr<cola::ScanTelegram> SmallScan() {
  auto scan = std::make_unique<cola::ScanTelegram>();
  scan->telegram_counter = 7;
  scan->scan_counter = 9;
  scan->time_since_startup_us = 1000;
  scan->time_of_transmission_us = 1500;
  scan->scan_frequency_raw = 1500;
  scan->layer_angle_raw = -250;
  scan->serial_number = 12345;
  cola::ScanChannel* dist = scan->channels16.emplace_slot();
  std::memcpy(dist->name.data(), "DIST1", 5);
  dist->start_angle_raw = -450000;
  dist->angle_step_raw = 3333;
  dist->count = 4;
  dist->raw[0] = 626;
  dist->raw[1] = 657;
  dist->raw[2] = 616;
  dist->raw[3] = 1;
  cola::ScanChannel* rssi = scan->channels8.emplace_slot();
  std::memcpy(rssi->name.data(), "RSSI1", 5);
  rssi->bits = 8;
  rssi->count = 2;
  rssi->raw[0] = 254;
  rssi->raw[1] = 10;
  return scan;
}

TEST(ScanJsonLineTest, FormatsLikeTheGoldenFilesWithSortedKeys) {
  auto scan = SmallScan();
  EXPECT_EQ(
      ScanJsonLine(*scan, 99),
      "{\"angle_step_deg\": 0.3333, \"device_status\": [0, 0], \"dist1_first3_m\": [0.626, 0.657, "
      "0.616], \"dist1_raw_sum\": 1900, \"dist1_scale\": 1.0, \"layer_angle_deg\": -2.5, "
      "\"n_points\": 4, \"receive_time_ns\": 99, \"rssi_bits\": 8, \"rssi_n\": 2, "
      "\"rssi_raw_sum\": "
      "264, \"scan_counter\": 9, \"scan_frequency_hz\": 15.0, \"serial_number\": 12345, "
      "\"start_angle_deg\": -45.0, \"telegram_counter\": 7, \"time_block\": null, "
      "\"time_of_transmission_us\": 1500, \"time_since_startup_us\": 1000}");
}

TEST(ScanJsonLineTest, TimeBlockAndMissingRssi) {
  auto scan = SmallScan();
  scan->channels8.clear();
  scan->has_time = true;
  scan->time = {1970, 1, 1, 0, 50, 14, 136000};
  const std::string line = ScanJsonLine(*scan, 0);
  EXPECT_NE(line.find("\"time_block\": [1970, 1, 1, 0, 50, 14, 136000]"), std::string::npos)
      << line;
  EXPECT_NE(line.find("\"rssi_bits\": 0, \"rssi_n\": 0, \"rssi_raw_sum\": 0"), std::string::npos)
      << line;
}

TEST(DumpCaptureTest, UnreadableFileIsAnErrorNamingTheFile) {
  std::ostringstream out;
  DumpSummary summary;
  std::string error;
  EXPECT_FALSE(DumpCapture("no/such/capture.pcap", DumpOptions{}, &out, &summary, &error));
  EXPECT_NE(error.find("no/such/capture.pcap"), std::string::npos) << error;
  EXPECT_TRUE(out.str().empty());
}

}  // namespace
}  // namespace lrfnet::tools
