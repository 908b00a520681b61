#include "central_daemon/io/recording_writer.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "central_daemon/io/recording_decoder.h"
#include "central_daemon/io/recording_test_util.h"

namespace lrfnet::daemon {
namespace {

using test_util::MakeDatagram;
using test_util::ReadResult;
using test_util::ReadToEnd;
using test_util::TempPath;

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
constexpr common::DurationNs kMs = common::kNsPerMs;

class RecordingWriterTest : public ::testing::Test {
 protected:
  static void TearDownTestSuite() { std::filesystem::remove_all(test_util::TempDir()); }
};

RecordingWriterOptions Options(const std::string& path) {
  RecordingWriterOptions o;
  o.path = path;
  o.writer = "lrfnetd 0.1.0";
  return o;
}

struct Sent {
  std::vector<std::uint8_t> bytes;
  std::string source;
  common::UtcNs receive_ns;
};

Sent MakeSent(std::uint32_t i, std::size_t size) {
  static const char* const kSources[] = {"192.168.10.21:40001", "[fe80::1:2]:40002",
                                         "tracker:gate-3"};
  return {MakeDatagram(size, i), kSources[i % 3], kT0 + static_cast<common::UtcNs>(i) * 7 * kMs};
}

ReadResult ReadRecording(const std::string& path) {
  std::string error;
  auto source = OpenDatagramFile(path, {}, &error);
  EXPECT_NE(source, nullptr) << error;
  if (source == nullptr) return {};
  EXPECT_EQ(source->kind(), DatagramFileKind::kRecording);
  return ReadToEnd(*source);
}

void ExpectSame(const std::vector<ReceivedDatagram>& got, const std::vector<Sent>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got[i].bytes, want[i].bytes) << i;
    EXPECT_EQ(got[i].source, want[i].source) << i;
    EXPECT_EQ(got[i].receive_ns, want[i].receive_ns) << i;
  }
}

// The header entries at the start of every part, read part by part with the decoder.
std::vector<RecordingHeader> PartHeaders(const std::vector<std::string>& files) {
  std::vector<RecordingHeader> headers;
  for (const std::string& file : files) {
    const auto bytes = test_util::ReadBytes(file);
    RecordingDecoder decoder;
    std::size_t consumed = 0;
    if (decoder.Feed(bytes, &consumed) == RecordingDecodeStatus::kEntry &&
        decoder.entry().has_header) {
      headers.push_back(decoder.entry().header);
    } else {
      ADD_FAILURE() << file << ": no header: " << decoder.error();
    }
  }
  return headers;
}

TEST_F(RecordingWriterTest, OptionsAreValidated) {
  EXPECT_EQ(Validate(Options("x.rec")), std::nullopt);
  RecordingWriterOptions o = Options("");
  EXPECT_TRUE(Validate(o).has_value());
  o = Options("x.rec");
  o.max_file_bytes = 1000;
  EXPECT_TRUE(Validate(o).has_value());
  o.max_file_bytes = 0;
  EXPECT_EQ(Validate(o), std::nullopt);
  o = Options("x.rec");
  o.flush_interval_s = 0.0;
  EXPECT_TRUE(Validate(o).has_value());
  o = Options("x.rec");
  o.buffer_bytes = 4096;
  EXPECT_TRUE(Validate(o).has_value());
  o = Options("x.rec");
  o.writer = std::string(300, 'w');
  EXPECT_TRUE(Validate(o).has_value());
  RecordingWriter writer(o);
  EXPECT_TRUE(writer.Open(kT0).has_value());  // invalid options: an error, not an abort
  EXPECT_FALSE(writer.is_open());
}

TEST_F(RecordingWriterTest, EntriesReadBackIdentical) {
  const std::string path = TempPath("round_trip.rec");
  std::vector<Sent> sent;
  RecordingWriter writer(Options(path));
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  EXPECT_TRUE(writer.is_open());
  EXPECT_EQ(writer.current_path(), path);
  for (std::uint32_t i = 0; i < 500; ++i) {
    sent.push_back(MakeSent(i, i * 37 % 1401));
    ASSERT_TRUE(writer.Append(sent.back().bytes, sent.back().source, sent.back().receive_ns));
  }
  EXPECT_EQ(writer.Close(), std::nullopt);
  EXPECT_FALSE(writer.is_open());
  const RecordingWriterCounters& c = writer.counters();
  EXPECT_EQ(c.entries, 500u);
  EXPECT_EQ(c.entries_written, 500u);
  EXPECT_EQ(c.files, 1u);
  EXPECT_EQ(c.write_errors, 0u);
  EXPECT_EQ(c.dropped_entries, 0u);
  EXPECT_EQ(c.bytes_written, std::filesystem::file_size(path));

  std::string error;
  auto source = OpenDatagramFile(path, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  EXPECT_EQ(source->format_version(), 1u);
  EXPECT_EQ(source->created_ns(), kT0);
  EXPECT_EQ(source->writer(), "lrfnetd 0.1.0");
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ExpectSame(r.datagrams, sent);
  EXPECT_EQ(source->counters().datagrams, 500u);
  EXPECT_EQ(source->counters().files, 1u);
  ReceivedDatagram d;
  EXPECT_EQ(source->Next(&d), SourceStatus::kEnd);  // stays at the end
}

TEST_F(RecordingWriterTest, RotationWritesPartsEachWithAHeaderAndReadsBackAsOne) {
  const std::string path = TempPath("rotated.rec");
  RecordingWriterOptions options = Options(path);
  options.max_file_bytes = 64 * 1024;
  RecordingWriter writer(options);
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  std::vector<Sent> sent;
  std::vector<common::UtcNs> part_starts = {kT0};
  for (std::uint32_t i = 0; i < 220; ++i) {
    sent.push_back(MakeSent(i, 1000));
    const std::uint64_t files_before = writer.counters().files;
    ASSERT_TRUE(writer.Append(sent.back().bytes, sent.back().source, sent.back().receive_ns));
    if (writer.counters().files != files_before) part_starts.push_back(sent.back().receive_ns);
  }
  ASSERT_EQ(writer.Close(), std::nullopt);

  const std::vector<std::string> files = RecordingFiles(path);
  ASSERT_EQ(files.size(), 4u);  // 220 entries of ~1030 bytes, 63 per 64 KiB part
  EXPECT_EQ(files, (std::vector<std::string>{path, path + ".1", path + ".2", path + ".3"}));
  EXPECT_EQ(writer.counters().files, 4u);
  EXPECT_EQ(writer.current_path(), path + ".3");
  std::uint64_t total_bytes = 0;
  for (const std::string& file : files) {
    EXPECT_LE(std::filesystem::file_size(file), options.max_file_bytes) << file;
    if (file != files.back()) {  // full: the next entry would not have fitted
      EXPECT_GT(std::filesystem::file_size(file), options.max_file_bytes - 1100) << file;
    }
    total_bytes += std::filesystem::file_size(file);
  }
  EXPECT_EQ(writer.counters().bytes_written, total_bytes);
  const std::vector<RecordingHeader> headers = PartHeaders(files);
  ASSERT_EQ(headers.size(), 4u);
  for (std::size_t k = 0; k < headers.size(); ++k) {
    EXPECT_EQ(headers[k].format_version, 1u);
    EXPECT_EQ(headers[k].writer, "lrfnetd 0.1.0");
    EXPECT_EQ(headers[k].created_ns, part_starts[k]) << "part " << k;
  }

  std::string error;
  auto source = OpenDatagramFile(path, {}, &error);
  ASSERT_NE(source, nullptr) << error;
  const ReadResult r = ReadToEnd(*source);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ExpectSame(r.datagrams, sent);
  EXPECT_EQ(source->counters().files, 4u);
  EXPECT_EQ(source->created_ns(), kT0);  // the first file's header
}

TEST_F(RecordingWriterTest, OpenRemovesStalePartsOfAnEarlierRecording) {
  const std::string path = TempPath("reused.rec");
  RecordingWriterOptions options = Options(path);
  options.max_file_bytes = 64 * 1024;
  {
    RecordingWriter earlier(options);
    ASSERT_EQ(earlier.Open(kT0), std::nullopt);
    for (std::uint32_t i = 0; i < 200; ++i) {
      const Sent s = MakeSent(i, 1000);
      earlier.Append(s.bytes, s.source, s.receive_ns);
    }
  }
  ASSERT_EQ(RecordingFiles(path).size(), 4u);
  // A part beyond a gap is not part of the set and is left alone.
  test_util::WriteBytes(path + ".9", {1, 2, 3});

  RecordingWriter writer(options);
  ASSERT_EQ(writer.Open(kT0 + common::kNsPerS), std::nullopt);
  const Sent s = MakeSent(1000, 10);
  writer.Append(s.bytes, s.source, s.receive_ns);
  ASSERT_EQ(writer.Close(), std::nullopt);
  EXPECT_EQ(RecordingFiles(path), std::vector<std::string>{path});
  EXPECT_TRUE(std::filesystem::exists(path + ".9"));
  const ReadResult r = ReadRecording(path);
  EXPECT_EQ(r.end, SourceStatus::kEnd);
  ExpectSame(r.datagrams, {s});
}

TEST_F(RecordingWriterTest, EntriesReachTheFileOneFlushIntervalAfterTheLastWrite) {
  const std::string path = TempPath("interval.rec");
  RecordingWriter writer(Options(path));
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  const auto header_bytes = std::filesystem::file_size(path);
  EXPECT_GT(header_bytes, 0u);  // written at once
  EXPECT_EQ(ReadRecording(path).end, SourceStatus::kEnd);

  const common::UtcNs t = kT0 + 200 * kMs;
  const Sent a{MakeDatagram(300, 1), "10.0.0.1:1", t};
  const Sent b{MakeDatagram(300, 2), "10.0.0.1:1", t + 300 * kMs};
  writer.Append(a.bytes, a.source, a.receive_ns);
  writer.Append(b.bytes, b.source, b.receive_ns);
  writer.FlushIfDue(t + 700 * kMs);
  EXPECT_EQ(std::filesystem::file_size(path), header_bytes);  // still buffered
  writer.FlushIfDue(t + 1000 * kMs);
  // Read without Close, as after a kill: both entries are there, whole.
  const ReadResult r = ReadRecording(path);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ExpectSame(r.datagrams, {a, b});
  EXPECT_EQ(writer.counters().entries_written, 2u);
}

TEST_F(RecordingWriterTest, AKillLosesAtMostTheLastFlushInterval) {
  const std::string path = TempPath("killed.rec");
  constexpr int kEntries = 45;  // one every 100 ms for 4.5 s
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // The daemon's shape: an entry every 100 ms, FlushIfDue from a 250 ms timer, then SIGKILL.
    RecordingWriter writer(Options(path));
    if (writer.Open(kT0)) ::_exit(3);
    for (int step = 0; step < 2 * kEntries; ++step) {
      const common::UtcNs t = kT0 + step * 50 * kMs;
      if (step % 2 == 0) {
        const auto bytes = MakeDatagram(200, static_cast<std::uint32_t>(step / 2));
        writer.Append(bytes, "10.0.0.9:5000", t);
      }
      if (step % 5 == 0) writer.FlushIfDue(t);
    }
    ::raise(SIGKILL);
    ::_exit(4);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL) << status;

  const common::UtcNs killed_ns = kT0 + (2 * kEntries - 1) * 50 * kMs;
  const ReadResult r = ReadRecording(path);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;  // whole entries only
  int older_than_interval = 0;
  for (int k = 0; k < kEntries; ++k) {
    if (kT0 + k * 100 * kMs <= killed_ns - common::kNsPerS) ++older_than_interval;
  }
  EXPECT_GE(static_cast<int>(r.datagrams.size()), older_than_interval);
  EXPECT_LT(static_cast<int>(r.datagrams.size()), kEntries);  // the newest were buffered
  for (std::size_t k = 0; k < r.datagrams.size(); ++k) {
    EXPECT_EQ(r.datagrams[k].bytes, MakeDatagram(200, static_cast<std::uint32_t>(k))) << k;
  }
}

TEST_F(RecordingWriterTest, ClockSteppingBackWritesAtOnce) {
  const std::string path = TempPath("clock_step.rec");
  RecordingWriter writer(Options(path));
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  const Sent a{MakeDatagram(100, 1), "10.0.0.1:1", kT0 + 100 * kMs};
  writer.Append(a.bytes, a.source, a.receive_ns);
  writer.FlushIfDue(kT0 - 60 * common::kNsPerS);
  ExpectSame(ReadRecording(path).datagrams, {a});
}

TEST_F(RecordingWriterTest, WriteErrorsAreCountedAndTheFileStaysReadable) {
  const std::string path = TempPath("fsize.rec");
  constexpr std::uint32_t kBefore = 400;
  constexpr std::uint32_t kAfter = 50;
  struct ChildReport {
    RecordingWriterCounters counters;
    bool close_reported = false;
  };
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    // A file size limit stands in for a full disk: writes past it fail with EFBIG.
    ::close(fds[0]);
    ::signal(SIGXFSZ, SIG_IGN);
    rlimit old_limit{};
    ::getrlimit(RLIMIT_FSIZE, &old_limit);
    rlimit limit = old_limit;
    limit.rlim_cur = 200 * 1024;
    if (::setrlimit(RLIMIT_FSIZE, &limit) != 0) ::_exit(3);
    RecordingWriterOptions options = Options(path);
    options.buffer_bytes = 64 * 1024;
    RecordingWriter writer(options);
    if (writer.Open(kT0)) ::_exit(4);
    for (std::uint32_t i = 0; i < kBefore; ++i) {
      const Sent s = MakeSent(i, 1000);
      writer.Append(s.bytes, s.source, s.receive_ns);
    }
    ::setrlimit(RLIMIT_FSIZE, &old_limit);  // space again
    for (std::uint32_t i = kBefore; i < kBefore + kAfter; ++i) {
      const Sent s = MakeSent(i, 1000);
      writer.Append(s.bytes, s.source, s.receive_ns);
    }
    ChildReport report;
    report.close_reported = writer.Close().has_value();
    report.counters = writer.counters();
    const ssize_t n = ::write(fds[1], &report, sizeof(report));
    ::_exit(n == static_cast<ssize_t>(sizeof(report)) ? 0 : 5);
  }
  ::close(fds[1]);
  ChildReport report;
  const ssize_t n = ::read(fds[0], &report, sizeof(report));
  ::close(fds[0]);
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  ASSERT_EQ(n, static_cast<ssize_t>(sizeof(report)));

  const RecordingWriterCounters& c = report.counters;
  EXPECT_TRUE(report.close_reported) << "Close() reports the write errors";
  EXPECT_EQ(c.entries, kBefore + kAfter);
  EXPECT_GE(c.write_errors, 1u);
  EXPECT_EQ(c.last_errno, EFBIG);
  EXPECT_GT(c.dropped_entries, 0u);
  EXPECT_EQ(c.entries_written + c.dropped_entries, c.entries);
  EXPECT_EQ(c.bytes_written, std::filesystem::file_size(path));

  // The file holds only whole entries: those written before the limit and those after it.
  const ReadResult r = ReadRecording(path);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ASSERT_EQ(r.datagrams.size(), c.entries_written);
  EXPECT_EQ(r.datagrams.back().bytes, MakeSent(kBefore + kAfter - 1, 1000).bytes);
  std::uint32_t next = 0;  // the survivors are a subsequence of what was appended, in order
  for (const ReceivedDatagram& d : r.datagrams) {
    while (next < kBefore + kAfter && MakeSent(next, 1000).bytes != d.bytes) ++next;
    ASSERT_LT(next, kBefore + kAfter);
    ++next;
  }
}

TEST_F(RecordingWriterTest, UnwritableFilesGiveErrorsNotCrashes) {
  RecordingWriter missing_dir(Options(TempPath("no/such/dir/x.rec")));
  const auto error = missing_dir.Open(kT0);
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("no/such/dir/x.rec"), std::string::npos) << *error;
  EXPECT_FALSE(missing_dir.Append(MakeDatagram(10, 1), "10.0.0.1:1", kT0));
  EXPECT_EQ(missing_dir.counters().dropped_entries, 1u);
  EXPECT_FALSE(missing_dir.Flush());

  if (std::filesystem::exists("/dev/full")) {
    RecordingWriter full(Options("/dev/full"));
    const auto full_error = full.Open(kT0);
    ASSERT_TRUE(full_error.has_value());
    EXPECT_NE(full_error->find(std::strerror(ENOSPC)), std::string::npos) << *full_error;
  }
}

TEST_F(RecordingWriterTest, OversizeEntryIsRefusedAndCounted) {
  const std::string path = TempPath("oversize.rec");
  RecordingWriter writer(Options(path));
  ASSERT_EQ(writer.Open(kT0), std::nullopt);
  const Sent a = MakeSent(1, 100);
  const Sent largest = MakeSent(2, kMaxRecordEntryBytes - 256);
  EXPECT_TRUE(writer.Append(a.bytes, a.source, a.receive_ns));
  EXPECT_FALSE(writer.Append(MakeDatagram(kMaxRecordEntryBytes, 3), "10.0.0.1:1", kT0));
  EXPECT_TRUE(writer.Append(largest.bytes, largest.source, largest.receive_ns));
  ASSERT_EQ(writer.Close(), std::nullopt);
  EXPECT_EQ(writer.counters().entries, 2u);
  EXPECT_EQ(writer.counters().dropped_entries, 1u);
  const ReadResult r = ReadRecording(path);
  EXPECT_EQ(r.end, SourceStatus::kEnd) << r.error;
  ExpectSame(r.datagrams, {a, largest});
}

}  // namespace
}  // namespace lrfnet::daemon
