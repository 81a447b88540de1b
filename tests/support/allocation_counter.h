#pragma once

// Counts heap allocations made through the global operator new (every form),
// for tests that prove a code path does not allocate. A test binary that
// needs it lists allocation_counter.cpp among its sources: that file replaces
// the global allocation functions for the whole binary.

#include <cstdint>

namespace scaled::test {

// Number of successful operator new calls (any form) so far in this process.
std::int64_t allocationCount();

// The same, made by the calling thread only. For code that hands work to
// OpenCV's thread pool: its worker threads do one-time bookkeeping (their
// thread-local data) the first time they take part in a job, which may be
// any call, not only the first one.
std::int64_t allocationCountThisThread();

}  // namespace scaled::test
