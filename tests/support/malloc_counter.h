#pragma once

// Counts calls of the C allocation functions (malloc, calloc, realloc and the
// aligned forms), for tests that prove a code path does not allocate at all.
// allocation_counter.h sees only the global operator new; Eigen's dynamic
// matrices and cv::fastMalloc call malloc directly, so a path that is quiet
// there can still allocate. A test binary that needs it lists
// malloc_counter.cpp among its sources: that file interposes the malloc
// family for the whole binary, forwarding to glibc's implementation.
//
// Under AddressSanitizer the sanitizer owns malloc; the interposition is then
// compiled out and mallocCountingEnabled() is false (mallocCount() stays 0).

#include <cstdint>

namespace scaled::test {

// Whether this binary counts the malloc family (false under the sanitizers).
bool mallocCountingEnabled();

// Number of successful malloc / calloc / realloc (to a nonzero size) /
// memalign / aligned_alloc / posix_memalign / valloc / pvalloc calls so far in
// this process, from every thread. The global operator new of
// allocation_counter.cpp allocates with malloc, so it is counted here too.
std::int64_t mallocCount();

}  // namespace scaled::test
