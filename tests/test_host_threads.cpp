// SPDX-License-Identifier: MIT
// The host loops of src/core/parallel.hpp: the thread limit that the C API
// sets from a context's thread count (the host steps' loops start no more
// threads), and the persistent pool they run on (every task once, nested
// and concurrent loops, exceptions, fork).
#include <gtest/gtest.h>

#include "../src/core/parallel.hpp"

#include <atomic>
#include <csignal>
#include <mutex>
#include <set>
#include <stdexcept>
#include <thread>
#include <vector>

#include <sys/wait.h>
#include <unistd.h>

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

TEST(HostPool, EveryTaskRunsOnceOnItsOwnThreadAndTheThreadsStay) {
  constexpr std::size_t n = 8;
  constexpr int calls = 200;
  static thread_local int tasks_here = 0;  // tasks this thread has run (a new thread starts at 0)
  const int before = tasks_here;
  std::vector<int> last(n);
  for (int call = 0; call < calls; ++call) {
    std::vector<std::atomic<int>> runs(n);
    std::vector<std::thread::id> who(n);
    nbmc::on_threads(n, [&](std::size_t t) {
      runs[t].fetch_add(1);
      who[t] = std::this_thread::get_id();
      last[t] = ++tasks_here;
    });
    for (std::size_t t = 0; t < n; ++t) ASSERT_EQ(runs[t].load(), 1) << "call " << call << " task " << t;
    ASSERT_EQ(std::set<std::thread::id>(who.begin(), who.end()).size(), n);
    EXPECT_EQ(who[0], std::this_thread::get_id());  // the caller takes part
  }
  // Task t ran on the same thread in every call: the pool keeps its workers
  // (a thread started per loop would have run one task).
  EXPECT_EQ(last[0], before + calls);
  for (std::size_t t = 1; t < n; ++t) EXPECT_GE(last[t], calls) << "task " << t;
}

TEST(HostPool, NestedAndConcurrentLoopsFinish) {
  // A loop inside a task, and loops from several application threads at
  // once: the pool is busy for all but one, which start their own threads.
  std::atomic<long> sum{0};
  auto work = [&] {
    for (int i = 0; i < 50; ++i)
      nbmc::on_threads(4, [&](std::size_t t) {
        nbmc::on_threads(3, [&](std::size_t u) { sum.fetch_add(long(10 * t + u)); });
      });
  };
  std::vector<std::thread> apps;
  for (int a = 0; a < 3; ++a) apps.emplace_back(work);
  work();
  for (std::thread& th : apps) th.join();
  // per inner loop: 30 t + 3; per outer loop: 30 * 6 + 12 = 192
  EXPECT_EQ(sum.load(), 4L * 50 * 192);
}

TEST(HostPool, ATaskExceptionReachesTheCallerAndThePoolGoesOn) {
  for (std::size_t bad : {std::size_t(0), std::size_t(3)}) {
    EXPECT_THROW(nbmc::on_threads(6,
                                  [&](std::size_t t) {
                                    if (t == bad) throw std::runtime_error("task failed");
                                  }),
                 std::runtime_error);
  }
  std::atomic<int> ran{0};
  nbmc::on_threads(6, [&](std::size_t) { ran.fetch_add(1); });
  EXPECT_EQ(ran.load(), 6);
}

TEST(HostPool, AForkedChildRunsLoops) {
  // The child of a fork() has none of the parent's workers (a Python
  // multiprocessing worker, say): its loops must still run, on a pool of
  // its own, and not wait for threads that do not exist.
  nbmc::on_threads(4, [](std::size_t) {});  // the parent's pool exists
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    alarm(20);  // a hang fails the test instead of stalling it
    std::atomic<long> sum{0};
    for (int i = 0; i < 100; ++i) nbmc::on_threads(4, [&](std::size_t t) { sum.fetch_add(long(t)); });
    _exit(sum.load() == 600 ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "child killed by signal " << (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  EXPECT_EQ(WEXITSTATUS(status), 0);
}
