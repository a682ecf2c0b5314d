// Large arrays on transparent huge pages. A fresh array's first touch takes one page fault
// per 4 KB page, which on a virtual machine costs more than filling the page: a 4096² sky
// map's set-up (the PFM's texels, the map's texels and its two distributions, about 1 GB)
// spent three quarters of its 3.7 s in page faults and the zero-filling that makes them.
// Linux backs an address range with 2 MB pages when asked (madvise MADV_HUGEPAGE: Debian's
// default mode for transparent huge pages is "madvise"), 512 times fewer faults; where the
// kernel has none, nothing changes.
#pragma once
#include <sys/mman.h>

#include <cstddef>
#include <cstdint>

namespace tuile {

// Asks for huge pages over the 2 MB-aligned part of [p, p + bytes) (untouched memory: pages
// already faulted in stay as they are). No error where the kernel does not offer them.
inline void advise_huge_pages(void* p, size_t bytes) noexcept {
  constexpr uintptr_t huge = uintptr_t(2) << 20;
  const uintptr_t a = reinterpret_cast<uintptr_t>(p);
  const uintptr_t b = (a + huge - 1) & ~(huge - 1), e = (a + bytes) & ~(huge - 1);
  if (e > b) madvise(reinterpret_cast<void*>(b), e - b, MADV_HUGEPAGE);
}

// v.assign(n, value), a large v's new storage advised to huge pages before it is filled
// (the storage comes from reserve, which glibc maps without touching it).
template <class V> void assign_huge(V& v, size_t n, const typename V::value_type& value) {
  constexpr size_t large = size_t(8) << 20;
  if (n * sizeof(typename V::value_type) >= large && v.capacity() < n) {
    V().swap(v);
    v.reserve(n);
    advise_huge_pages(v.data(), n * sizeof(typename V::value_type));
  }
  v.assign(n, value);
}

}  // namespace tuile
