#pragma once
// Containers with a compile-time capacity and no heap allocation. Overflow is never silent: a push that
// does not fit returns false and is counted in overflow_count(), and the container stays unchanged.

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>

namespace lrfnet::common {

template <typename T, std::size_t N>
class FixedVector {
  static_assert(std::is_default_constructible_v<T>, "FixedVector stores default-constructed slots");

 public:
  using value_type = T;
  static constexpr std::size_t kCapacity = N;

  std::size_t size() const { return size_; }
  static constexpr std::size_t capacity() { return N; }
  bool empty() const { return size_ == 0; }
  bool full() const { return size_ == N; }
  std::uint64_t overflow_count() const { return overflow_count_; }

  [[nodiscard]] bool push_back(const T& v) {
    if (size_ == N) {
      ++overflow_count_;
      return false;
    }
    data_[size_++] = v;
    return true;
  }
  // Appends a default-valued element and returns it, or nullptr (counted) when full.
  T* emplace_slot() {
    if (size_ == N) {
      ++overflow_count_;
      return nullptr;
    }
    data_[size_] = T{};
    return &data_[size_++];
  }
  void pop_back() {
    assert(size_ > 0);
    --size_;
  }
  void clear() { size_ = 0; }
  // Resizes within capacity; returns false (counted) and leaves the size unchanged if n > N.
  [[nodiscard]] bool resize(std::size_t n) {
    if (n > N) {
      ++overflow_count_;
      return false;
    }
    for (std::size_t i = size_; i < n; ++i) data_[i] = T{};
    size_ = n;
    return true;
  }
  // Removes element i by moving the last one into its place (order not kept).
  void swap_remove(std::size_t i) {
    assert(i < size_);
    data_[i] = data_[size_ - 1];
    --size_;
  }

  T& operator[](std::size_t i) {
    assert(i < size_);
    return data_[i];
  }
  const T& operator[](std::size_t i) const {
    assert(i < size_);
    return data_[i];
  }
  T& back() { return (*this)[size_ - 1]; }
  const T& back() const { return (*this)[size_ - 1]; }

  T* begin() { return data_.data(); }
  T* end() { return data_.data() + size_; }
  const T* begin() const { return data_.data(); }
  const T* end() const { return data_.data() + size_; }
  T* data() { return data_.data(); }
  const T* data() const { return data_.data(); }
  std::span<T> span() { return {data_.data(), size_}; }
  std::span<const T> span() const { return {data_.data(), size_}; }

 private:
  std::array<T, N> data_{};
  std::size_t size_ = 0;
  std::uint64_t overflow_count_ = 0;
};

// A ring buffer that keeps the newest N elements. Pushing into a full ring drops the oldest element and
// counts it in dropped_count(); callers that must not lose data check full() first.
template <typename T, std::size_t N>
class RingBuffer {
  static_assert(N > 0);

 public:
  static constexpr std::size_t kCapacity = N;

  std::size_t size() const { return size_; }
  static constexpr std::size_t capacity() { return N; }
  bool empty() const { return size_ == 0; }
  bool full() const { return size_ == N; }
  std::uint64_t dropped_count() const { return dropped_count_; }

  void push_back(const T& v) {
    if (size_ == N) {
      data_[head_] = v;
      head_ = (head_ + 1) % N;
      ++dropped_count_;
      return;
    }
    data_[(head_ + size_) % N] = v;
    ++size_;
  }
  void pop_front() {
    assert(size_ > 0);
    head_ = (head_ + 1) % N;
    --size_;
  }
  void clear() {
    head_ = 0;
    size_ = 0;
  }
  // i = 0 is the oldest element.
  T& operator[](std::size_t i) {
    assert(i < size_);
    return data_[(head_ + i) % N];
  }
  const T& operator[](std::size_t i) const {
    assert(i < size_);
    return data_[(head_ + i) % N];
  }
  T& front() { return (*this)[0]; }
  T& back() { return (*this)[size_ - 1]; }
  const T& front() const { return (*this)[0]; }
  const T& back() const { return (*this)[size_ - 1]; }

 private:
  std::array<T, N> data_{};
  std::size_t head_ = 0;
  std::size_t size_ = 0;
  std::uint64_t dropped_count_ = 0;
};

}  // namespace lrfnet::common
