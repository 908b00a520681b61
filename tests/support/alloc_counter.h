#pragma once
// Test-only: counts heap allocations of the whole process between Start and Stop, to show the
// "nothing allocated per scan" property (DESIGN.md quality bar). Linking lrfnet_alloc_counter
// replaces the global operator new/delete and, in glibc builds without a sanitizer, malloc and its
// family (so C code such as nanopb and libc is counted too). One binary per test that links it.

#include <cstddef>

namespace lrfnet::testing {

void StartCountingAllocations();
// Stops counting; returns the allocations since Start.
std::size_t StopCountingAllocations();
// Whether malloc & co. are counted (false under sanitizers: they bring their own allocator).
bool CountsMalloc();

}  // namespace lrfnet::testing
