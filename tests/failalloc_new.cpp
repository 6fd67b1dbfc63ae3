// C++'s allocation functions for the allocation-failure injector
// (tests/failalloc.c): operator new counts with malloc and fails by throwing
// std::bad_alloc, as the real one does; the nothrow forms return nullptr.
// They allocate with the real malloc, so operator delete is free (defined
// here too: AddressSanitizer's would see malloc's blocks freed by delete).
// Aligned forms are left to the library (theirs and their deletes match).
#include <cstddef>
#include <cstdlib>
#include <new>

extern "C" int failalloc_should_fail(const void *caller);
extern "C" void *failalloc_real_malloc(std::size_t n);

namespace {
void *allocate(std::size_t n, const void *caller)
{
    if (failalloc_should_fail(caller))
        return nullptr;
    return failalloc_real_malloc(n ? n : 1);
}
}   // namespace

void *operator new(std::size_t n)
{
    void *p = allocate(n, __builtin_return_address(0));
    if (!p)
        throw std::bad_alloc();
    return p;
}

void *operator new[](std::size_t n)
{
    void *p = allocate(n, __builtin_return_address(0));
    if (!p)
        throw std::bad_alloc();
    return p;
}

void *operator new(std::size_t n, const std::nothrow_t &) noexcept { return allocate(n, __builtin_return_address(0)); }
void *operator new[](std::size_t n, const std::nothrow_t &) noexcept { return allocate(n, __builtin_return_address(0)); }

void operator delete(void *p) noexcept { std::free(p); }
void operator delete[](void *p) noexcept { std::free(p); }
void operator delete(void *p, std::size_t) noexcept { std::free(p); }
void operator delete[](void *p, std::size_t) noexcept { std::free(p); }
void operator delete(void *p, const std::nothrow_t &) noexcept { std::free(p); }
void operator delete[](void *p, const std::nothrow_t &) noexcept { std::free(p); }
