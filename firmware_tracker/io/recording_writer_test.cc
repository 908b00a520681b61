#include "firmware_tracker/io/recording_writer.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <pb_decode.h>
#include <sys/stat.h>
#include <unistd.h>

#include <csignal>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/test_data.h"

namespace lrfnet::io {
namespace {

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;

std::filesystem::path TempDir() {
  return std::filesystem::temp_directory_path() /
         ("lrfnet_recording_test_" + std::to_string(::getpid()));
}

std::string TempPath(const std::string& name) {
  std::filesystem::create_directories(TempDir());
  return (TempDir() / name).string();
}

std::vector<std::uint8_t> Datagram(std::size_t size, std::uint8_t seed) {
  std::vector<std::uint8_t> d(size);
  for (std::size_t i = 0; i < size; ++i) d[i] = static_cast<std::uint8_t>(seed + i * 7);
  return d;
}

// Reads a recording with a hand-written varint reader and nanopb (so the test also runs in the
// tracker-only build); uplink_wire_test reads the same format with libprotobuf.
struct Entry {
  lrfnet_proto_RecordEntry message;
};
std::vector<Entry> ReadRecording(const std::string& path, bool* clean_end) {
  const std::vector<std::uint8_t> bytes = testing::ReadFileBytes(path);
  std::vector<Entry> out;
  std::size_t at = 0;
  *clean_end = true;
  while (at < bytes.size()) {
    std::uint64_t size = 0;
    int shift = 0;
    while (at < bytes.size() && shift < 35) {
      const std::uint8_t b = bytes[at++];
      size |= static_cast<std::uint64_t>(b & 0x7f) << shift;
      shift += 7;
      if ((b & 0x80) == 0) break;
    }
    if (size > bytes.size() - at) {
      *clean_end = false;
      break;
    }
    Entry e{};
    pb_istream_t stream = pb_istream_from_buffer(bytes.data() + at, size);
    if (!pb_decode(&stream, lrfnet_proto_RecordEntry_fields, &e.message)) {
      *clean_end = false;
      break;
    }
    out.push_back(e);
    at += size;
  }
  return out;
}

class RecordingWriterTest : public ::testing::Test {
 protected:
  static void TearDownTestSuite() { std::filesystem::remove_all(TempDir()); }
};

RecordingWriterOptions WriterOptions(const std::string& path) {
  RecordingWriterOptions o;
  o.path = path;
  o.writer = "lrfnet-tracker 0.1.0";
  o.source = TrackerRecordSource("gate-3");
  return o;
}

TEST_F(RecordingWriterTest, OptionsAreValidated) {
  EXPECT_EQ(Validate(WriterOptions("x.rec")), std::nullopt);
  RecordingWriterOptions o = WriterOptions("");
  EXPECT_TRUE(Validate(o).has_value());
  o = WriterOptions("x.rec");
  o.source = std::string(65, 's');
  EXPECT_TRUE(Validate(o).has_value());
  o = WriterOptions("x.rec");
  o.buffer_bytes = 100;
  EXPECT_TRUE(Validate(o).has_value());
  o = WriterOptions("x.rec");
  o.flush_interval_s = 0.0;
  EXPECT_TRUE(Validate(o).has_value());
  EXPECT_EQ(TrackerRecordSource("gate-3"), "tracker:gate-3");
}

TEST_F(RecordingWriterTest, HeaderThenEveryDatagramAsSent) {
  const std::string path = TempPath("round_trip.rec");
  std::vector<std::vector<std::uint8_t>> sent;
  {
    RecordingWriter writer(WriterOptions(path));
    ASSERT_EQ(writer.Open(kT0), std::nullopt);
    for (int i = 0; i < 200; ++i) {
      sent.push_back(
          Datagram(static_cast<std::size_t>(i * 7 % 1401), static_cast<std::uint8_t>(i)));
      writer.Send(sent.back(), kT0 + i * 40 * common::kNsPerMs);
    }
    EXPECT_EQ(writer.Close(), std::nullopt);
    EXPECT_EQ(writer.counters().entries, 200u);
    EXPECT_EQ(writer.counters().entries_written, 200u);
    EXPECT_EQ(writer.counters().write_errors, 0u);
    EXPECT_EQ(writer.counters().bytes_written, std::filesystem::file_size(path));
  }
  bool clean = false;
  const std::vector<Entry> entries = ReadRecording(path, &clean);
  EXPECT_TRUE(clean);
  ASSERT_EQ(entries.size(), 201u);
  const lrfnet_proto_RecordEntry& h = entries[0].message;
  ASSERT_TRUE(h.has_header);
  EXPECT_EQ(h.header.format_version, 1u);
  EXPECT_EQ(h.header.created_ns, kT0);
  EXPECT_STREQ(h.header.writer, "lrfnet-tracker 0.1.0");
  EXPECT_EQ(h.datagram.size, 0);
  for (std::size_t i = 1; i < entries.size(); ++i) {
    const lrfnet_proto_RecordEntry& e = entries[i].message;
    EXPECT_FALSE(e.has_header);
    EXPECT_EQ(e.receive_ns, kT0 + static_cast<common::UtcNs>(i - 1) * 40 * common::kNsPerMs);
    EXPECT_STREQ(e.source, "tracker:gate-3");
    ASSERT_EQ(e.datagram.size, sent[i - 1].size());
    EXPECT_TRUE(std::equal(sent[i - 1].begin(), sent[i - 1].end(), e.datagram.bytes)) << i;
  }
}

TEST_F(RecordingWriterTest, DataReachesTheFileWithinTheFlushInterval) {
  const std::string path = TempPath("interval.rec");
  RecordingWriter writer(WriterOptions(path));
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  const auto header_bytes = std::filesystem::file_size(path);
  EXPECT_GT(header_bytes, 0u);  // the header is written at once
  const auto d = Datagram(300, 1);
  writer.Append(d, kT0 + 100 * common::kNsPerMs);
  writer.Append(d, kT0 + 900 * common::kNsPerMs);
  EXPECT_EQ(std::filesystem::file_size(path), header_bytes);  // buffered
  writer.Append(d, kT0 + 1000 * common::kNsPerMs);            // one second after the last write
  bool clean = false;
  EXPECT_EQ(ReadRecording(path, &clean).size(), 4u);
  EXPECT_TRUE(clean);
  writer.Append(d, kT0 + 1100 * common::kNsPerMs);
  EXPECT_EQ(ReadRecording(path, &clean).size(), 4u);
  ASSERT_TRUE(writer.Flush());  // on demand
  EXPECT_EQ(ReadRecording(path, &clean).size(), 5u);
}

TEST_F(RecordingWriterTest, FullBufferIsWrittenAndTheFileHoldsWholeEntries) {
  const std::string path = TempPath("small_buffer.rec");
  RecordingWriterOptions o = WriterOptions(path);
  o.buffer_bytes = 4096;
  o.flush_interval_s = 3600.0;
  RecordingWriter writer(o);
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  for (int i = 0; i < 10; ++i) writer.Append(Datagram(1400, static_cast<std::uint8_t>(i)), kT0 + i);
  EXPECT_GT(writer.counters().flushes, 3u);
  bool clean = false;
  const auto entries = ReadRecording(path, &clean);
  EXPECT_TRUE(clean);
  EXPECT_GE(entries.size(), 7u);
  EXPECT_LT(entries.size(), 11u);
  EXPECT_EQ(writer.Close(), std::nullopt);
  EXPECT_EQ(ReadRecording(path, &clean).size(), 11u);
}

TEST_F(RecordingWriterTest, RefusesOversizeDatagramsAndWritesBeforeOpen) {
  const std::string path = TempPath("refuse.rec");
  RecordingWriter writer(WriterOptions(path));
  EXPECT_FALSE(writer.Append(Datagram(10, 0), kT0));
  EXPECT_EQ(writer.counters().not_open, 1u);
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  EXPECT_FALSE(writer.Append(Datagram(kMaxDatagramBytes + 1, 0), kT0));
  EXPECT_EQ(writer.counters().oversize, 1u);
  EXPECT_TRUE(writer.Append(Datagram(kMaxDatagramBytes, 0), kT0));
  EXPECT_EQ(writer.Close(), std::nullopt);
  bool clean = false;
  EXPECT_EQ(ReadRecording(path, &clean).size(), 2u);
}

TEST_F(RecordingWriterTest, UnwritablePathsGiveAClearError) {
  RecordingWriter missing_dir(WriterOptions(TempPath("no/such/dir/x.rec")));
  const auto error = missing_dir.Open(kT0);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("no/such/dir/x.rec"), std::string::npos) << *error;
  EXPECT_FALSE(missing_dir.is_open());
  if (std::filesystem::exists("/dev/full")) {
    RecordingWriter full(WriterOptions("/dev/full"));
    const auto full_error = full.Open(kT0);
    ASSERT_TRUE(full_error.has_value());
    EXPECT_NE(full_error->find("No space left"), std::string::npos) << *full_error;
  }
}

// The reader of a pipe goes away mid-recording: the failed writes are counted, the entries they
// held are reported lost, and writing goes on without a crash.
TEST_F(RecordingWriterTest, WriteErrorsAreCountedAndNeverFatal) {
  const std::string path = TempPath("pipe.fifo");
  std::filesystem::remove(path);
  ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0);
  const int reader = ::open(path.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  const auto old_handler = std::signal(SIGPIPE, SIG_IGN);
  {
    RecordingWriter writer(WriterOptions(path));
    ASSERT_EQ(writer.Open(kT0), std::nullopt);
    ::close(reader);
    // The first entry is buffered; each later one is a second after it and triggers a write.
    for (int i = 0; i < 5; ++i) writer.Append(Datagram(100, 0), kT0 + i * common::kNsPerS);
    EXPECT_EQ(writer.counters().write_errors, 4u);
    EXPECT_EQ(writer.counters().dropped_entries, 5u);
    EXPECT_EQ(writer.counters().last_errno, EPIPE);
    const auto error = writer.Close();
    ASSERT_TRUE(error.has_value());
    EXPECT_NE(error->find("4 write error(s)"), std::string::npos) << *error;
    EXPECT_NE(error->find("5 entries lost"), std::string::npos) << *error;
  }
  std::signal(SIGPIPE, old_handler);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace lrfnet::io
