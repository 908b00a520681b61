#pragma once
// Appending whole records to a file that readers parse record by record (the recordings): either
// all of `bytes` reach the file, or the file is cut back to what it held before, so a reader never
// meets a torn record and records written after a recovered disk stay readable.

#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>

namespace lrfnet::common {

// Writes bytes[0, size) at the end of `fd`, whose first `file_bytes` bytes are whole records.
// Returns 0 on success, else the errno of the failed write(2) (EIO for a write of 0 bytes) after
// cutting the file back to `file_bytes` (regular files; other files keep the partial write).
inline int AppendWhole(int fd, const std::uint8_t* bytes, std::size_t size,
                       std::uint64_t file_bytes) {
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::write(fd, bytes + done, size - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = n < 0 ? errno : EIO;
      if (done > 0 && ::lseek(fd, static_cast<off_t>(file_bytes), SEEK_SET) >= 0) {
        [[maybe_unused]] const int rc = ::ftruncate(fd, static_cast<off_t>(file_bytes));
      }
      return error;
    }
    done += static_cast<std::size_t>(n);
  }
  return 0;
}

}  // namespace lrfnet::common
