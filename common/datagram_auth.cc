#include "common/datagram_auth.h"

#include <sodium.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "common/byte_order.h"

namespace lrfnet::auth {
namespace {

static_assert(crypto_aead_chacha20poly1305_ietf_KEYBYTES == kKeyBytes);
static_assert(crypto_aead_chacha20poly1305_ietf_NPUBBYTES == kNonceBytes);
static_assert(crypto_aead_chacha20poly1305_ietf_ABYTES == kTagBytes);
static_assert(crypto_kdf_KEYBYTES == kKeyBytes);
static_assert(crypto_kdf_CONTEXTBYTES == 8);

constexpr std::uint8_t kFlagEncrypted = 0x01;
constexpr std::uint8_t kFlagToTracker = 0x02;
constexpr std::uint8_t kKnownFlags = kFlagEncrypted | kFlagToTracker;

bool IsIdChar(char c) {
  return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
         c == '.' || c == '-';
}

void Derive(std::span<std::uint8_t> out, std::uint64_t subkey_id, const char (&context)[9],
            const Key& key) {
  crypto_kdf_derive_from_key(out.data(), out.size(), subkey_id, context, key.data());
}

constexpr void StoreBe64(std::uint8_t* p, std::uint64_t v) {
  common::StoreBe32(p, static_cast<std::uint32_t>(v >> 32));
  common::StoreBe32(p + 4, static_cast<std::uint32_t>(v));
}
constexpr std::uint64_t LoadBe64(const std::uint8_t* p) {
  return (std::uint64_t{common::LoadBe32(p)} << 32) | common::LoadBe32(p + 4);
}

std::array<std::uint8_t, kNonceBytes> Nonce(std::uint32_t salt, std::uint64_t counter) {
  std::array<std::uint8_t, kNonceBytes> nonce{};
  common::StoreBe32(nonce.data(), salt);
  StoreBe64(nonce.data() + 4, counter);
  return nonce;
}

}  // namespace

bool Init() { return sodium_init() >= 0; }

bool IsValidSensorId(std::string_view id) {
  return !id.empty() && id.size() <= kMaxSensorIdBytes &&
         std::all_of(id.begin(), id.end(), IsIdChar);
}

Key DeriveSensorKey(const Key& site_key, std::string_view sensor_id) {
  if (!IsValidSensorId(sensor_id)) {
    std::fprintf(stderr, "DeriveSensorKey: invalid sensor id\n");
    std::abort();
  }
  Key key = site_key;
  const std::size_t n = sensor_id.size();
  for (std::size_t i = 0; i * 8 < n; ++i) {
    std::uint64_t chunk = 0;  // little-endian: byte j of the chunk is bits 8j..8j+7
    for (std::size_t j = 0; j < 8 && i * 8 + j < n; ++j) {
      chunk |= std::uint64_t{static_cast<unsigned char>(sensor_id[i * 8 + j])} << (8 * j);
    }
    char context[9] = {'l',
                       'r',
                       'f',
                       'n',
                       'S',
                       static_cast<char>('0' + i),
                       static_cast<char>('0' + n / 10),
                       static_cast<char>('0' + n % 10),
                       '\0'};
    Key next{};
    crypto_kdf_derive_from_key(next.data(), next.size(), chunk, context, key.data());
    key = next;
  }
  return key;
}

SensorKeys DeriveSensorKeys(const Key& sensor_key, std::uint32_t epoch) {
  SensorKeys keys;
  keys.epoch = epoch;
  std::array<std::uint8_t, crypto_kdf_BYTES_MIN> id{};
  Derive(id, 0, "lrfnetid", sensor_key);
  keys.key_id = common::LoadBe32(id.data());
  Derive(keys.to_daemon, 1, "lrfnetdg", sensor_key);
  Derive(keys.to_tracker, 2, "lrfnetdg", sensor_key);
  return keys;
}

const char* ToString(HeaderError error) {
  switch (error) {
    case HeaderError::kNone:
      return "ok";
    case HeaderError::kTooShort:
      return "shorter than an envelope";
    case HeaderError::kNotEnvelope:
      return "not an envelope";
    case HeaderError::kVersion:
      return "unknown envelope version";
    case HeaderError::kFlags:
      return "reserved flag bits set";
    case HeaderError::kSensorId:
      return "bad sensor id";
  }
  return "invalid";
}

HeaderError ParseEnvelope(std::span<const std::uint8_t> bytes, Envelope* out) {
  if (bytes.size() < 4)
    return bytes.empty() || bytes[0] == kMagic ? HeaderError::kTooShort : HeaderError::kNotEnvelope;
  if (bytes[0] != kMagic) return HeaderError::kNotEnvelope;
  if (bytes[1] != kEnvelopeVersion) return HeaderError::kVersion;
  const std::uint8_t flags = bytes[2];
  if ((flags & ~kKnownFlags) != 0) return HeaderError::kFlags;
  const std::size_t n = bytes[3];
  if (n == 0 || n > kMaxSensorIdBytes) return HeaderError::kSensorId;
  const std::size_t header_bytes = kFixedHeaderBytes + n;
  if (bytes.size() < header_bytes + kTagBytes) return HeaderError::kTooShort;
  const std::string_view id(reinterpret_cast<const char*>(bytes.data() + 4), n);
  if (!IsValidSensorId(id)) return HeaderError::kSensorId;
  const std::uint8_t* p = bytes.data() + 4 + n;
  Envelope e;
  e.sensor_id = id;
  e.epoch = common::LoadBe32(p);
  e.key_id = common::LoadBe32(p + 4);
  e.salt = common::LoadBe32(p + 8);
  e.counter = LoadBe64(p + 12);
  e.encrypted = (flags & kFlagEncrypted) != 0;
  e.direction = (flags & kFlagToTracker) != 0 ? Direction::kToTracker : Direction::kToDaemon;
  e.header = bytes.first(header_bytes);
  e.payload = bytes.subspan(header_bytes, bytes.size() - header_bytes - kTagBytes);
  e.tag = bytes.last(kTagBytes);
  *out = e;
  return HeaderError::kNone;
}

bool OpenEnvelope(const Envelope& e, const SensorKeys& keys, std::span<std::uint8_t> plain,
                  std::span<const std::uint8_t>* payload) {
  const auto nonce = Nonce(e.salt, e.counter);
  const Key& key = keys.For(e.direction);
  if (!e.encrypted) {
    // Associated data: everything before the tag (header and payload).
    const std::size_t ad_bytes = e.header.size() + e.payload.size();
    // Nothing to decrypt: the message is empty (libsodium still wants valid pointers).
    std::uint8_t none = 0;
    if (crypto_aead_chacha20poly1305_ietf_decrypt_detached(&none, nullptr, &none, 0, e.tag.data(),
                                                           e.header.data(), ad_bytes, nonce.data(),
                                                           key.data()) != 0) {
      return false;
    }
    *payload = e.payload;
    return true;
  }
  if (plain.size() < e.payload.size()) return false;
  if (crypto_aead_chacha20poly1305_ietf_decrypt_detached(
          plain.data(), nullptr, e.payload.data(), e.payload.size(), e.tag.data(), e.header.data(),
          e.header.size(), nonce.data(), key.data()) != 0) {
    return false;
  }
  *payload = plain.first(e.payload.size());
  return true;
}

std::optional<std::string> Validate(const SealerOptions& options) {
  if (!IsValidSensorId(options.sensor_id))
    return "sensor id '" + options.sensor_id + "' must match [A-Za-z0-9_.-]{1,32}";
  return std::nullopt;
}

Sealer::Sealer(const SealerOptions& options) : options_(options), counter_(options.first_counter) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "Sealer: invalid options: %s\n", error->c_str());
    std::abort();
  }
  sensor_id_length_ = options.sensor_id.size();
}

std::size_t Sealer::Seal(std::span<const std::uint8_t> payload, std::span<std::uint8_t> out) {
  const std::size_t n = sensor_id_length_;
  const std::size_t header_bytes = kFixedHeaderBytes + n;
  const std::size_t total = header_bytes + payload.size() + kTagBytes;
  if (out.size() < total) return 0;
  std::uint8_t* p = out.data();
  p[0] = kMagic;
  p[1] = kEnvelopeVersion;
  p[2] =
      static_cast<std::uint8_t>((options_.encrypt ? kFlagEncrypted : 0) |
                                (options_.direction == Direction::kToTracker ? kFlagToTracker : 0));
  p[3] = static_cast<std::uint8_t>(n);
  std::memcpy(p + 4, options_.sensor_id.data(), n);
  common::StoreBe32(p + 4 + n, options_.keys.epoch);
  common::StoreBe32(p + 8 + n, options_.keys.key_id);
  common::StoreBe32(p + 12 + n, options_.salt);
  StoreBe64(p + 16 + n, counter_);
  const auto nonce = Nonce(options_.salt, counter_);
  const Key& key = options_.keys.For(options_.direction);
  std::uint8_t* body = p + header_bytes;
  std::uint8_t* tag = body + payload.size();
  if (options_.encrypt) {
    crypto_aead_chacha20poly1305_ietf_encrypt_detached(body, tag, nullptr, payload.data(),
                                                       payload.size(), p, header_bytes, nullptr,
                                                       nonce.data(), key.data());
  } else {
    if (!payload.empty()) std::memcpy(body, payload.data(), payload.size());
    std::uint8_t none = 0;
    crypto_aead_chacha20poly1305_ietf_encrypt_detached(&none, tag, nullptr, &none, 0, p,
                                                       header_bytes + payload.size(), nullptr,
                                                       nonce.data(), key.data());
  }
  ++counter_;
  return total;
}

ReplayWindow::Verdict ReplayWindow::Check(std::uint64_t counter) const {
  if (has_floor_ && counter <= floor_) return Verdict::kTooOld;
  if (!has_highest_ || counter > highest_) return Verdict::kFresh;
  if (highest_ - counter >= kWindowBits) return Verdict::kTooOld;
  const std::uint64_t block = (counter / kBlockBits) % kBlocks;
  const std::uint64_t bit = std::uint64_t{1} << (counter % kBlockBits);
  return (bitmap_[block] & bit) != 0 ? Verdict::kReplayed : Verdict::kFresh;
}

void ReplayWindow::Commit(std::uint64_t counter) {
  if (has_floor_ && counter <= floor_) return;
  if (!has_highest_) {
    bitmap_.fill(0);
    highest_ = counter;
    has_highest_ = true;
  } else if (counter > highest_) {
    // Slide: clear the blocks between the old highest's block and the new one (RFC 6479 sec. 2).
    const std::uint64_t from = highest_ / kBlockBits;
    const std::uint64_t to = counter / kBlockBits;
    const std::uint64_t steps = std::min<std::uint64_t>(to - from, kBlocks);
    for (std::uint64_t i = 1; i <= steps; ++i) bitmap_[(from + i) % kBlocks] = 0;
    highest_ = counter;
  } else if (highest_ - counter >= kWindowBits) {
    return;  // below the window: nothing to mark (Check refused it)
  }
  bitmap_[(counter / kBlockBits) % kBlocks] |= std::uint64_t{1} << (counter % kBlockBits);
}

void ReplayWindow::SetFloor(std::uint64_t floor) {
  if (!has_floor_ || floor > floor_) floor_ = floor;
  has_floor_ = true;
  if (!has_highest_ || floor > highest_) {
    bitmap_.fill(0);
    highest_ = floor;
    has_highest_ = true;
  }
}

std::string ToHex(std::span<const std::uint8_t> bytes) {
  static constexpr char kDigits[] = "0123456789abcdef";
  std::string out;
  out.reserve(bytes.size() * 2);
  for (const std::uint8_t b : bytes) {
    out.push_back(kDigits[b >> 4]);
    out.push_back(kDigits[b & 15]);
  }
  return out;
}

bool FromHex(std::string_view hex, std::span<std::uint8_t> out) {
  if (hex.size() != out.size() * 2) return false;
  const auto value = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  for (std::size_t i = 0; i < out.size(); ++i) {
    const int hi = value(hex[2 * i]);
    const int lo = value(hex[2 * i + 1]);
    if (hi < 0 || lo < 0) return false;
    out[i] = static_cast<std::uint8_t>(hi * 16 + lo);
  }
  return true;
}

void RandomBytes(std::span<std::uint8_t> out) { randombytes_buf(out.data(), out.size()); }

bool ConstantTimeEquals(std::string_view a, std::string_view b) {
  std::array<std::uint8_t, crypto_generichash_BYTES> ha{}, hb{};
  crypto_generichash(ha.data(), ha.size(), reinterpret_cast<const unsigned char*>(a.data()),
                     a.size(), nullptr, 0);
  crypto_generichash(hb.data(), hb.size(), reinterpret_cast<const unsigned char*>(b.data()),
                     b.size(), nullptr, 0);
  return sodium_memcmp(ha.data(), hb.data(), ha.size()) == 0;
}

}  // namespace lrfnet::auth
