#include "firmware_tracker/io/request_decoder.h"

#include <gtest/gtest.h>
#include <pb_encode.h>

#include <array>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace lrfnet::io {
namespace {

constexpr char kId[] = "gate-3";

std::vector<std::uint8_t> Request(std::string_view sensor_id, bool info, bool background,
                                  std::uint64_t sequence = 17) {
  RequestMessage m;
  m.sensor_id = sensor_id;
  m.sequence = sequence;
  m.sent_ns = 1'700'000'000'000'000'000;
  m.session_id = 99;
  m.send_sensor_info = info;
  m.send_background = background;
  std::vector<std::uint8_t> out(kMaxDatagramBytes);
  out.resize(EncodeRequest(m, out));
  EXPECT_FALSE(out.empty());
  return out;
}

// Hand-written protobuf for datagrams the encoders cannot produce.
struct Writer {
  std::vector<std::uint8_t> bytes;
  void Varint(std::uint64_t v) {
    while (v >= 0x80) {
      bytes.push_back(static_cast<std::uint8_t>(v | 0x80));
      v >>= 7;
    }
    bytes.push_back(static_cast<std::uint8_t>(v));
  }
  void Tag(std::uint32_t field, std::uint32_t wire) { Varint((field << 3) | wire); }
  void Field(std::uint32_t field, std::uint64_t v) {
    Tag(field, 0);
    Varint(v);
  }
  void Bytes(std::uint32_t field, const std::vector<std::uint8_t>& b) {
    Tag(field, 2);
    Varint(b.size());
    bytes.insert(bytes.end(), b.begin(), b.end());
  }
  void String(std::uint32_t field, const std::string& s) {
    Bytes(field, std::vector<std::uint8_t>(s.begin(), s.end()));
  }
};

std::vector<std::uint8_t> RequestPayload(bool info, bool background) {
  Writer r;
  if (info) r.Field(1, 1);
  if (background) r.Field(2, 1);
  return r.bytes;
}

TEST(RequestDecoderTest, AcceptsRequestsForThisSensorOrForAll) {
  RequestDecoder decoder(kId);
  DecodedRequest r = decoder.Decode(Request(kId, true, false, 5));
  EXPECT_EQ(r.reject, RequestReject::kNone);
  EXPECT_TRUE(r.send_sensor_info);
  EXPECT_FALSE(r.send_background);
  EXPECT_EQ(r.sequence, 5u);
  EXPECT_EQ(r.session_id, 99u);
  r = decoder.Decode(Request("", false, true));
  EXPECT_EQ(r.reject, RequestReject::kNone);
  EXPECT_FALSE(r.send_sensor_info);
  EXPECT_TRUE(r.send_background);
  EXPECT_EQ(decoder.counters().accepted, 2u);
}

TEST(RequestDecoderTest, RejectsRequestsForOtherSensors) {
  RequestDecoder decoder(kId);
  EXPECT_EQ(decoder.Decode(Request("gate-4", true, true)).reject, RequestReject::kOtherSensor);
  EXPECT_EQ(decoder.Decode(Request("gate-30", true, true)).reject, RequestReject::kOtherSensor);
  EXPECT_EQ(decoder.Decode(Request("gate", true, true)).reject, RequestReject::kOtherSensor);
  // Our id followed by a NUL and more: not our id.
  Writer w;
  w.Field(1, 1);
  w.String(2, std::string(kId) + std::string(1, '\0') + "x");
  w.Bytes(14, RequestPayload(true, false));
  const DecodedRequest r = decoder.Decode(w.bytes);
  EXPECT_EQ(r.reject, RequestReject::kOtherSensor);
  EXPECT_FALSE(r.send_sensor_info);
  EXPECT_EQ(decoder.counters().Rejected(RequestReject::kOtherSensor), 4u);
  EXPECT_EQ(decoder.counters().accepted, 0u);
}

TEST(RequestDecoderTest, RejectsUnknownVersionsAndOtherPayloads) {
  RequestDecoder decoder(kId);
  for (std::uint64_t version : {0ull, 2ull, 1000ull}) {
    Writer w;
    if (version != 0) w.Field(1, version);
    w.String(2, kId);
    w.Bytes(14, RequestPayload(true, true));
    EXPECT_EQ(decoder.Decode(w.bytes).reject, RequestReject::kUnknownVersion) << version;
  }
  // A tracker's own track frame reflected back, and a datagram with no payload at all.
  DatagramEncoderOptions options;
  options.sensor_id = kId;
  DatagramEncoder encoder(options);
  struct Last final : DatagramSink {
    std::vector<std::uint8_t> bytes;
    void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
      bytes.assign(d.begin(), d.end());
    }
  } sink;
  encoder.EncodeTracks(tracking::ScanTracks{}, 1, sink);
  EXPECT_EQ(decoder.Decode(sink.bytes).reject, RequestReject::kNotARequest);
  Writer bare;
  bare.Field(1, 1);
  bare.String(2, kId);
  EXPECT_EQ(decoder.Decode(bare.bytes).reject, RequestReject::kNotARequest);
  EXPECT_EQ(decoder.counters().Rejected(RequestReject::kUnknownVersion), 3u);
  EXPECT_EQ(decoder.counters().Rejected(RequestReject::kNotARequest), 2u);
}

TEST(RequestDecoderTest, UnknownFieldsAreSkipped) {
  RequestDecoder decoder(kId);
  Writer w;
  w.Field(1, 1);
  w.Field(99, 12345);  // a field a newer daemon might add
  w.String(100, "future");
  w.String(2, kId);
  Writer req;
  req.Field(1, 1);
  req.Field(7, 3);  // unknown inside the request too
  w.Bytes(14, req.bytes);
  const DecodedRequest r = decoder.Decode(w.bytes);
  EXPECT_EQ(r.reject, RequestReject::kNone);
  EXPECT_TRUE(r.send_sensor_info);
}

TEST(RequestDecoderTest, EveryTruncationIsRejected) {
  RequestDecoder decoder(kId);
  const std::vector<std::uint8_t> full = Request(kId, true, true);
  for (std::size_t n = 0; n < full.size(); ++n) {
    const DecodedRequest r = decoder.Decode(std::span<const std::uint8_t>(full.data(), n));
    EXPECT_NE(r.reject, RequestReject::kNone) << "prefix of " << n << " bytes";
    EXPECT_FALSE(r.send_sensor_info || r.send_background);
  }
  EXPECT_EQ(decoder.counters().Rejected(RequestReject::kEmpty), 1u);
  EXPECT_EQ(decoder.Decode(full).reject, RequestReject::kNone);
}

TEST(RequestDecoderTest, HostileBytesAreRejectedWithAReason) {
  RequestDecoder decoder(kId);
  // Too large, even if it starts like a request.
  std::vector<std::uint8_t> big = Request(kId, true, true);
  big.resize(kMaxDatagramBytes + 1, 0);
  EXPECT_EQ(decoder.Decode(big).reject, RequestReject::kTooLarge);
  // A length far beyond the datagram.
  {
    Writer w;
    w.Field(1, 1);
    w.Tag(2, 2);
    w.Varint(0xFFFFFFFFull);
    w.bytes.push_back('a');
    EXPECT_EQ(decoder.Decode(w.bytes).reject, RequestReject::kMalformed);
  }
  // A sensor id longer than the static field.
  {
    Writer w;
    w.Field(1, 1);
    w.String(2, std::string(33, 'a'));
    w.Bytes(14, RequestPayload(true, true));
    EXPECT_EQ(decoder.Decode(w.bytes).reject, RequestReject::kMalformed);
  }
  // More tracks than a part may hold: the static array bound is a decode error, not an overflow.
  {
    Writer frame;
    for (int i = 0; i < 15; ++i) frame.Bytes(6, {0x08, 0x01});
    Writer w;
    w.Field(1, 1);
    w.Bytes(10, frame.bytes);
    EXPECT_EQ(decoder.Decode(w.bytes).reject, RequestReject::kMalformed);
  }
  // A varint of 11 bytes, an unknown wire type, a group tag.
  EXPECT_EQ(decoder
                .Decode(std::vector<std::uint8_t>{0x08, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff,
                                                  0xff, 0xff, 0xff, 0x01})
                .reject,
            RequestReject::kMalformed);
  EXPECT_EQ(decoder.Decode(std::vector<std::uint8_t>{0x0f, 0x01}).reject,
            RequestReject::kMalformed);
  EXPECT_EQ(decoder.Decode(std::vector<std::uint8_t>{0x0b, 0x0c}).reject,
            RequestReject::kMalformed);
  EXPECT_EQ(decoder.counters().accepted, 0u);
}

TEST(RequestDecoderTest, EveryBitFlipAndRandomBytesAreHandled) {
  RequestDecoder decoder(kId);
  const std::vector<std::uint8_t> good = Request(kId, true, false);
  std::uint64_t calls = 0;
  for (std::size_t bit = 0; bit < good.size() * 8; ++bit) {
    std::vector<std::uint8_t> b = good;
    b[bit / 8] ^= static_cast<std::uint8_t>(1u << (bit % 8));
    const DecodedRequest r = decoder.Decode(b);
    ++calls;
    if (r.reject != RequestReject::kNone) {
      EXPECT_FALSE(r.send_sensor_info || r.send_background);
    }
  }
  std::mt19937_64 rng(3);
  for (int i = 0; i < 20'000; ++i) {
    std::vector<std::uint8_t> b(rng() % 64);
    for (auto& x : b) x = static_cast<std::uint8_t>(rng());
    decoder.Decode(b);
    ++calls;
  }
  std::uint64_t total = decoder.counters().accepted;
  for (const std::uint64_t n : decoder.counters().rejected) total += n;
  EXPECT_EQ(total, calls);
  EXPECT_GT(decoder.counters().Rejected(RequestReject::kMalformed), 0u);
  // The decoder is still good after all that.
  EXPECT_EQ(decoder.Decode(good).reject, RequestReject::kNone);
}

TEST(RequestDecoderTest, EncodeRequestRefusesWhatCannotBeSent) {
  std::array<std::uint8_t, 4> tiny{};
  RequestMessage m;
  m.sensor_id = kId;
  m.send_background = true;
  EXPECT_EQ(EncodeRequest(m, tiny), 0u);
  const std::string long_id(33, 'a');
  m.sensor_id = long_id;
  std::array<std::uint8_t, 256> big{};
  EXPECT_EQ(EncodeRequest(m, big), 0u);
}

TEST(RequestDecoderTest, ReasonsHaveNames) {
  for (int i = 0; i < static_cast<int>(RequestReject::kCount); ++i) {
    EXPECT_STRNE(ToString(static_cast<RequestReject>(i)), "unknown");
  }
}

}  // namespace
}  // namespace lrfnet::io
