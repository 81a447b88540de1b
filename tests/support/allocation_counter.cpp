// Replaces every replaceable global allocation function ([new.delete]) so that
// each allocation is counted and each deallocation matches it (malloc /
// aligned_alloc with free). All forms must be replaced together: under
// AddressSanitizer a form left out would come from the sanitizer's runtime,
// and pairing it with this file's delete is an alloc-dealloc mismatch.

#include "allocation_counter.h"

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <new>

namespace {

std::atomic<std::int64_t> g_allocations{0};
// Constant-initialised, trivially destructible: no allocation of its own.
thread_local std::int64_t t_allocations = 0;

void* allocate(std::size_t size, std::size_t alignment) noexcept {
    size = std::max<std::size_t>(size, 1);
    void* p = nullptr;
    if (alignment <= alignof(std::max_align_t)) {
        p = std::malloc(size);  // NOLINT(cppcoreguidelines-no-malloc): this is operator new
    } else {
        size = (size + alignment - 1) / alignment * alignment;
        p = std::aligned_alloc(alignment, size);
    }
    if (p != nullptr) {
        g_allocations.fetch_add(1, std::memory_order_relaxed);
        ++t_allocations;
    }
    return p;
}

void* allocateOrThrow(std::size_t size, std::size_t alignment) {
    void* p = allocate(size, alignment);
    if (p == nullptr) {
        throw std::bad_alloc();
    }
    return p;
}

void release(void* p) noexcept {
    std::free(p);  // NOLINT(cppcoreguidelines-no-malloc): this is operator delete
}

}  // namespace

namespace scaled::test {

std::int64_t allocationCount() {
    return g_allocations.load(std::memory_order_relaxed);
}

std::int64_t allocationCountThisThread() {
    return t_allocations;
}

}  // namespace scaled::test

// GCC 12 warns that free() meets memory from `new` once a `new T` elsewhere is
// inlined next to these functions (-Wmismatched-new-delete); here new is
// malloc, so the pairing is right.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
#endif

void* operator new(std::size_t size) {
    return allocateOrThrow(size, 0);
}
void* operator new[](std::size_t size) {
    return allocateOrThrow(size, 0);
}
void* operator new(std::size_t size, std::align_val_t al) {
    return allocateOrThrow(size, static_cast<std::size_t>(al));
}
void* operator new[](std::size_t size, std::align_val_t al) {
    return allocateOrThrow(size, static_cast<std::size_t>(al));
}
void* operator new(std::size_t size, const std::nothrow_t& /*tag*/) noexcept {
    return allocate(size, 0);
}
void* operator new[](std::size_t size, const std::nothrow_t& /*tag*/) noexcept {
    return allocate(size, 0);
}
void* operator new(std::size_t size, std::align_val_t al, const std::nothrow_t& /*tag*/) noexcept {
    return allocate(size, static_cast<std::size_t>(al));
}
void* operator new[](std::size_t size, std::align_val_t al,
                     const std::nothrow_t& /*tag*/) noexcept {
    return allocate(size, static_cast<std::size_t>(al));
}

void operator delete(void* p) noexcept {
    release(p);
}
void operator delete[](void* p) noexcept {
    release(p);
}
void operator delete(void* p, std::size_t /*size*/) noexcept {
    release(p);
}
void operator delete[](void* p, std::size_t /*size*/) noexcept {
    release(p);
}
void operator delete(void* p, std::align_val_t /*al*/) noexcept {
    release(p);
}
void operator delete[](void* p, std::align_val_t /*al*/) noexcept {
    release(p);
}
void operator delete(void* p, std::size_t /*size*/, std::align_val_t /*al*/) noexcept {
    release(p);
}
void operator delete[](void* p, std::size_t /*size*/, std::align_val_t /*al*/) noexcept {
    release(p);
}
void operator delete(void* p, const std::nothrow_t& /*tag*/) noexcept {
    release(p);
}
void operator delete[](void* p, const std::nothrow_t& /*tag*/) noexcept {
    release(p);
}
void operator delete(void* p, std::align_val_t /*al*/, const std::nothrow_t& /*tag*/) noexcept {
    release(p);
}
void operator delete[](void* p, std::align_val_t /*al*/, const std::nothrow_t& /*tag*/) noexcept {
    release(p);
}

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
