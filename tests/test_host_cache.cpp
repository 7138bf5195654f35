// SPDX-License-Identifier: MIT
// HostBlockCache (src/core/host_cache.hpp): large freed host blocks kept for
// the next frame's arrays, and NoInitAllocator's use of it.
#include <gtest/gtest.h>

#include "../src/core/params.hpp"

#include <cstdint>
#include <cstdlib>
#include <thread>
#include <vector>

namespace {
constexpr std::size_t MiB = std::size_t(1) << 20;
using nbmc::HostBlockCache;
}  // namespace

TEST(HostCache, AFreedBlockServesANearRequestOnly) {
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  void* a = c.allocate(20 * MiB);
  static_cast<char*>(a)[20 * MiB - 1] = 1;
  c.deallocate(a);
  EXPECT_EQ(c.kept_bytes(), 20 * MiB);
  void* b = c.allocate(10 * MiB);  // 20 MiB is more than a quarter larger: a new block
  EXPECT_NE(b, a);
  EXPECT_EQ(c.kept_bytes(), 20 * MiB);
  void* d = c.allocate(17 * MiB);  // within a quarter: the kept block, all of it
  EXPECT_EQ(d, a);
  EXPECT_EQ(c.kept_bytes(), 0u);
  c.deallocate(d);
  EXPECT_EQ(c.kept_bytes(), 20 * MiB);  // its real size comes back, not the request's
  c.deallocate(b);
  EXPECT_EQ(c.kept_bytes(), 30 * MiB);
  void* e = c.allocate(19 * MiB);  // the smallest that holds it: the 20 MiB block
  EXPECT_EQ(e, a);
  c.deallocate(e);
  c.release();
  EXPECT_EQ(c.kept_bytes(), 0u);
}

TEST(HostCache, KeepsAtMostItsCapacityOldestFirst) {
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  const std::size_t block = 64 * MiB, n = HostBlockCache::kCapacity / block + 3;
  std::vector<void*> blocks;
  for (std::size_t i = 0; i < n; ++i) blocks.push_back(c.allocate(block));  // untouched: address space only
  for (void* p : blocks) c.deallocate(p);
  EXPECT_EQ(c.kept_bytes(), (HostBlockCache::kCapacity / block) * block);
  // The first three went: the oldest are freed first.
  void* again = c.allocate(block);
  EXPECT_NE(again, blocks[0]);
  EXPECT_NE(again, blocks[1]);
  EXPECT_NE(again, blocks[2]);
  c.deallocate(again);
  // A block larger than the capacity is never kept.
  void* huge = c.allocate(HostBlockCache::kCapacity + MiB);
  c.deallocate(huge);
  EXPECT_LE(c.kept_bytes(), HostBlockCache::kCapacity);
  c.release();
}

TEST(HostCache, ABlockItDidNotHandOutIsFreed) {
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  void* p = std::malloc(20 * MiB);  // as another shared object's copy of the cache hands out
  ASSERT_NE(p, nullptr);
  c.deallocate(p);  // not kept: freed
  EXPECT_EQ(c.kept_bytes(), 0u);
}

TEST(HostCache, ThreadsShareItSafely) {
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&c, t] {
      for (int i = 0; i < 200; ++i) {
        const std::size_t bytes = (16 + std::size_t((t * 7 + i) % 9)) * MiB;
        char* p = static_cast<char*>(c.allocate(bytes));
        p[0] = char(i);
        p[bytes - 1] = char(t);
        c.deallocate(p);
      }
    });
  for (auto& th : threads) th.join();
  EXPECT_LE(c.kept_bytes(), HostBlockCache::kCapacity);
  c.release();
  EXPECT_EQ(c.kept_bytes(), 0u);
}

TEST(HostCache, NoInitVectorsOfANextFrameReuseTheBlock) {
  if (!HostBlockCache::enabled()) GTEST_SKIP() << "cache off (AddressSanitizer or NBMC_HOST_CACHE=0)";
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  const float* first = nullptr;
  {
    std::vector<float, nbmc::NoInitAllocator<float>> frame(6 * MiB);  // 24 MiB
    frame.back() = 1.f;
    first = frame.data();
  }
  EXPECT_EQ(c.kept_bytes(), 24 * MiB);
  std::vector<float, nbmc::NoInitAllocator<float>> next(5 * MiB + 12345);  // a little smaller
  EXPECT_EQ(next.data(), first);
  std::vector<float, nbmc::NoInitAllocator<float>> small(1000);  // below 4 MiB: the plain allocator
  EXPECT_NE(small.data(), first);
  next.clear();
  next.shrink_to_fit();
  c.release();
}

namespace {
// Fake page-locking for the cache's pinning (the CUDA backend passes
// cudaHostRegister and cudaHostUnregister).
std::vector<void*> g_pinned, g_unpinned;
bool g_pin_works = true;
bool fake_pin(void* p, std::size_t) {
  if (!g_pin_works) return false;
  g_pinned.push_back(p);
  return true;
}
void fake_unpin(void* p) { g_unpinned.push_back(p); }
}  // namespace

TEST(HostCache, BlocksArePageLockedFromTheirSecondUseAndUnlockedBeforeTheyAreFreed) {
  if (!HostBlockCache::pinning_enabled()) GTEST_SKIP() << "cache or pinning off";
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  g_pinned.clear();
  g_unpinned.clear();
  g_pin_works = true;
  char* a = static_cast<char*>(c.allocate(20 * MiB));
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(a) % 4096, 0u);  // whole pages
  a[0] = 1;
  // A fresh block: not locked (its pages may not be there yet).
  EXPECT_FALSE(c.pin_for_device(a, 20 * MiB, fake_pin, fake_unpin));
  EXPECT_TRUE(g_pinned.empty());
  c.deallocate(a);
  char* b = static_cast<char*>(c.allocate(20 * MiB));  // its second use
  ASSERT_EQ(b, a);
  // Not for a range it does not hold, nor for a pointer it did not hand out.
  EXPECT_FALSE(c.pin_for_device(b, 20 * MiB + 4096, fake_pin, fake_unpin));
  EXPECT_FALSE(c.pin_for_device(b + 4096, MiB, fake_pin, fake_unpin));
  EXPECT_TRUE(g_pinned.empty());
  EXPECT_TRUE(c.pin_for_device(b, 20 * MiB, fake_pin, fake_unpin));
  EXPECT_TRUE(c.pin_for_device(b, 10 * MiB, fake_pin, fake_unpin));  // locked already: not again
  ASSERT_EQ(g_pinned.size(), 1u);
  EXPECT_EQ(g_pinned[0], static_cast<void*>(b));
  EXPECT_EQ(c.pinned_bytes(), 20 * MiB);
  // Kept locked in the cache, and still locked when handed out again.
  c.deallocate(b);
  EXPECT_TRUE(g_unpinned.empty());
  char* d = static_cast<char*>(c.allocate(18 * MiB));
  ASSERT_EQ(d, a);
  EXPECT_TRUE(c.pin_for_device(d, 18 * MiB, fake_pin, fake_unpin));
  EXPECT_EQ(g_pinned.size(), 1u);
  c.deallocate(d);
  // release() unlocks it before freeing it.
  c.release();
  ASSERT_EQ(g_unpinned.size(), 1u);
  EXPECT_EQ(g_unpinned[0], static_cast<void*>(a));
  EXPECT_EQ(c.pinned_bytes(), 0u);
}

TEST(HostCache, ALockedBlockLeavingAFullCacheIsUnlockedAndAFailedLockIsNoLock) {
  if (!HostBlockCache::pinning_enabled()) GTEST_SKIP() << "cache or pinning off";
  HostBlockCache& c = HostBlockCache::instance();
  c.release();
  g_pinned.clear();
  g_unpinned.clear();
  const std::size_t block = 64 * MiB;
  g_pin_works = false;
  void* f = c.allocate(block);
  c.deallocate(f);
  f = c.allocate(block);
  EXPECT_FALSE(c.pin_for_device(f, block, fake_pin, fake_unpin));  // the lock failed: the ring's copies
  EXPECT_EQ(c.pinned_bytes(), 0u);
  c.deallocate(f);
  g_pin_works = true;
  void* p = c.allocate(block);
  ASSERT_EQ(p, f);
  EXPECT_TRUE(c.pin_for_device(p, block, fake_pin, fake_unpin));
  c.deallocate(p);  // the oldest kept block now
  // Fill the cache with other blocks (address space only): the locked one
  // leaves first, unlocked before it is freed.
  std::vector<void*> others;
  for (std::size_t i = 0; i < HostBlockCache::kCapacity / block; ++i) others.push_back(c.allocate(block + 4096 * (i + 1)));
  EXPECT_TRUE(g_unpinned.empty());  // (the requests took no kept block: each a little larger)
  for (void* o : others) c.deallocate(o);
  ASSERT_EQ(g_unpinned.size(), 1u);
  EXPECT_EQ(g_unpinned[0], p);
  EXPECT_EQ(c.pinned_bytes(), 0u);
  c.release();
  EXPECT_EQ(g_unpinned.size(), 1u);
}
