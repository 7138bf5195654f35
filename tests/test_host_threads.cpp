// SPDX-License-Identifier: MIT
// The host thread limit (src/core/parallel.hpp) that the C API sets from a
// context's thread count: the host steps' loops start no more threads. And
// the team of host threads that the fairing flips' steps share.
#include <gtest/gtest.h>

#include "../src/core/parallel.hpp"

#include <algorithm>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

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

// The team of host threads (the fairing flips' steps): every index once per
// step, on no more threads than its size, step after step; an exception in
// any part comes back to the caller, and the team goes on after it.
TEST(HostThreads, TeamRunsEveryIndexOnceAndRethrows) {
  nbmc::HostTeam team(4);
  for (std::size_t n : {0u, 1u, 3u, 4u, 11u}) {
    std::vector<int> hits(n, 0);
    std::set<std::thread::id> ids;
    std::mutex m;
    for (int step = 0; step < 50; ++step)
      team.run(n, [&](std::size_t t) {
        std::lock_guard<std::mutex> lock(m);
        ++hits[t];
        ids.insert(std::this_thread::get_id());
      });
    for (int h : hits) EXPECT_EQ(h, 50);
    EXPECT_LE(ids.size(), std::min<std::size_t>(4, n));
  }
  std::vector<int> sums(10, 0);
  team.chunks(100, 10, [&](std::size_t k, std::size_t b, std::size_t e) { sums[k] = int(e - b); });
  for (int s : sums) EXPECT_EQ(s, 10);
  EXPECT_THROW(team.run(4, [](std::size_t t) {
    if (t == 2) throw std::runtime_error("part 2");
  }),
               std::runtime_error);
  EXPECT_THROW(team.run(4, [](std::size_t t) {
    if (t == 0) throw std::runtime_error("part 0");
  }),
               std::runtime_error);
  int after = 0;
  team.run(1, [&](std::size_t) { ++after; });
  EXPECT_EQ(after, 1);
}
