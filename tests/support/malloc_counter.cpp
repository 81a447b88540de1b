// Interposes glibc's malloc family (see malloc_counter.h). glibc documents
// this replacement ("Replacing malloc"): a program may define malloc, free,
// calloc and realloc (and the aligned forms) itself; every caller in the
// process, shared libraries included, then binds to these definitions. Each
// one forwards to glibc's own allocator through its exported __libc_*
// entry points, so memory from either side may be freed by the other.

#include "malloc_counter.h"

#include <atomic>
#include <cerrno>
#include <cstddef>

#if defined(__SANITIZE_ADDRESS__)
#define SCALED_MALLOC_COUNTER_ENABLED 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SCALED_MALLOC_COUNTER_ENABLED 0
#endif
#endif
#ifndef SCALED_MALLOC_COUNTER_ENABLED
#if defined(__GLIBC__)
#define SCALED_MALLOC_COUNTER_ENABLED 1
#else
#define SCALED_MALLOC_COUNTER_ENABLED 0
#endif
#endif

namespace {

// Constant-initialised: usable by allocations made before main().
std::atomic<std::int64_t> g_mallocs{0};

}  // namespace

namespace scaled::test {

bool mallocCountingEnabled() {
    return SCALED_MALLOC_COUNTER_ENABLED != 0;
}

std::int64_t mallocCount() {
    return g_mallocs.load(std::memory_order_relaxed);
}

}  // namespace scaled::test

#if SCALED_MALLOC_COUNTER_ENABLED

// NOLINTBEGIN(cppcoreguidelines-no-malloc,readability-inconsistent-declaration-parameter-name,bugprone-reserved-identifier,cert-dcl37-c,cert-dcl51-cpp,readability-identifier-naming):
// these are the C allocator's own entry points

extern "C" {

void* __libc_malloc(std::size_t size);
void __libc_free(void* p);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* p, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void* __libc_valloc(std::size_t size);
void* __libc_pvalloc(std::size_t size);

}  // extern "C"

namespace {

void* counted(void* p) noexcept {
    if (p != nullptr) {
        g_mallocs.fetch_add(1, std::memory_order_relaxed);
    }
    return p;
}

}  // namespace

extern "C" {

void* malloc(std::size_t size) noexcept {
    return counted(__libc_malloc(size));
}

void free(void* p) noexcept {
    __libc_free(p);
}

void* calloc(std::size_t count, std::size_t size) noexcept {
    return counted(__libc_calloc(count, size));
}

void* realloc(void* p, std::size_t size) noexcept {
    void* q = __libc_realloc(p, size);
    return size == 0 ? q : counted(q);
}

void* memalign(std::size_t alignment, std::size_t size) noexcept {
    return counted(__libc_memalign(alignment, size));
}

void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
    return counted(__libc_memalign(alignment, size));
}

int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
    // A power of two and a multiple of sizeof(void*), as POSIX requires.
    if (alignment % sizeof(void*) != 0 || (alignment & (alignment - 1)) != 0 || alignment == 0) {
        return EINVAL;
    }
    void* p = __libc_memalign(alignment, size);
    if (p == nullptr) {
        return ENOMEM;
    }
    *out = counted(p);
    return 0;
}

void* valloc(std::size_t size) noexcept {
    return counted(__libc_valloc(size));
}

void* pvalloc(std::size_t size) noexcept {
    return counted(__libc_pvalloc(size));
}

}  // extern "C"

// NOLINTEND(cppcoreguidelines-no-malloc,readability-inconsistent-declaration-parameter-name,bugprone-reserved-identifier,cert-dcl37-c,cert-dcl51-cpp,readability-identifier-naming)

#endif  // SCALED_MALLOC_COUNTER_ENABLED
