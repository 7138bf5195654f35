// SPDX-License-Identifier: MIT
// The host thread limit (src/core/parallel.hpp) that the C API sets from a
// context's thread count: the host steps' loops start no more threads.
#include <gtest/gtest.h>

#include "../src/core/parallel.hpp"

#include <mutex>
#include <set>
#include <thread>

TEST(HostThreads, LimitCapsTheChunksAndIsRestored) {
  const std::size_t hw = nbmc::chunk_count(std::size_t(1) << 30, 1);  // no limit: one per hardware thread
  EXPECT_EQ(hw, std::size_t(std::max(1u, std::thread::hardware_concurrency())));
  {
    const nbmc::ScopedHostThreads one(1);
    EXPECT_EQ(nbmc::chunk_count(std::size_t(1) << 30, 1), 1u);
    {
      const nbmc::ScopedHostThreads three(3);  // a limit above the hardware's is taken as asked
      EXPECT_EQ(nbmc::chunk_count(std::size_t(1) << 30, 1), 3u);
      EXPECT_EQ(nbmc::chunk_count(20, 10), 2u);  // the minimum chunk length still counts
    }
    EXPECT_EQ(nbmc::chunk_count(std::size_t(1) << 30, 1), 1u);
  }
  EXPECT_EQ(nbmc::chunk_count(std::size_t(1) << 30, 1), hw);
}

TEST(HostThreads, LimitHoldsForThisThreadOnly) {
  const nbmc::ScopedHostThreads two(2);
  std::size_t other = 0;
  std::thread([&] { other = nbmc::chunk_count(std::size_t(1) << 30, 1); }).join();
  EXPECT_EQ(other, std::size_t(std::max(1u, std::thread::hardware_concurrency())));
  std::set<std::thread::id> ids;
  std::mutex m;
  nbmc::for_chunks(1000000, nbmc::chunk_count(1000000, 1), [&](std::size_t, std::size_t, std::size_t) {
    std::lock_guard<std::mutex> lock(m);
    ids.insert(std::this_thread::get_id());
  });
  EXPECT_LE(ids.size(), 2u);
}
