// SideBySide: the helper thread that runs the air's step beside the cloth's (issue 28).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "common/parallel.h"

namespace flagsim {
namespace {

struct Threads {  // flagsim's thread count for a scope
  int before = num_threads();
  explicit Threads(int n) { set_num_threads(n); }
  ~Threads() { set_num_threads(before); }
};

// On two threads the helper takes the second job while the first still runs: the first job
// waits (up to 10 s) for the second to have started, which only another thread can do.
TEST(SideBySide, OnTwoThreadsTheJobsRunAtTheSameTimeEachWithItsLoopsOnOneThread) {
  if (!has_openmp()) GTEST_SKIP() << "built without OpenMP: one thread only";
  Threads two(2);
  SideBySide beside;
  for (int round = 0; round < 20; ++round) {
    std::atomic<bool> second_started{false};
    bool overlapped = false;
    int threads_first = 0, threads_second = 0;
    std::thread::id first_id, second_id;
    beside.run(
        [&]() noexcept {
          first_id = std::this_thread::get_id();
          threads_first = num_threads();
          const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
          while (!second_started.load() && std::chrono::steady_clock::now() < until)
            std::this_thread::yield();
          overlapped = second_started.load();
        },
        [&]() noexcept {
          second_id = std::this_thread::get_id();
          threads_second = num_threads();
          second_started.store(true);
        });
    EXPECT_TRUE(overlapped) << "round " << round;
    EXPECT_NE(first_id, second_id);
    EXPECT_EQ(first_id, std::this_thread::get_id());
    EXPECT_EQ(threads_first, 1);
    EXPECT_EQ(threads_second, 1);
    EXPECT_EQ(num_threads(), 2);  // the caller's count is back
  }
}

// On one thread: first, then second, both on the calling thread.
TEST(SideBySide, OnOneThreadTheJobsRunInOrderOnTheCallingThread) {
  Threads one(1);
  SideBySide beside;
  int order = 0, first_at = -1, second_at = -1;
  std::thread::id second_id;
  beside.run([&]() noexcept { first_at = order++; },
             [&]() noexcept {
               second_at = order++;
               second_id = std::this_thread::get_id();
             });
  EXPECT_EQ(first_at, 0);
  EXPECT_EQ(second_at, 1);
  EXPECT_EQ(second_id, std::this_thread::get_id());
}

// Many short rounds (the paper scene's ~100 us steps): every job runs exactly once, whichever
// thread takes it, and building and stopping helpers does not hang.
TEST(SideBySide, EveryJobRunsOnceOverManyShortRounds) {
  Threads two(2);
  for (int helper = 0; helper < 5; ++helper) {
    SideBySide beside;
    long firsts = 0, seconds = 0;
    for (int round = 0; round < 2000; ++round)
      beside.run([&]() noexcept { ++firsts; }, [&]() noexcept { ++seconds; });
    EXPECT_EQ(firsts, 2000);
    EXPECT_EQ(seconds, 2000);
  }
}

// Outside a SideBySide, for_each_chunk is a plain loop in chunk order on the calling thread.
TEST(ForEachChunk, OutsideSideBySideAPlainLoopInOrder) {
  Threads two(2);
  std::vector<Index> order;
  std::vector<std::thread::id> who;
  order.reserve(10);
  for_each_chunk(10, [&](Index c) {
    order.push_back(c);
    who.push_back(std::this_thread::get_id());
  });
  ASSERT_EQ(order.size(), 10u);
  for (Index c = 0; c < 10; ++c) {
    EXPECT_EQ(order[size_t(c)], c);
    EXPECT_EQ(who[size_t(c)], std::this_thread::get_id());
  }
}

// Inside the first job, the helper takes chunks once its own job is done (the air's thread
// helping the cloth's): every chunk runs exactly once, its output is the same whoever ran it,
// and over a few rounds the helper takes some (each round's chunks wait 0.2 ms, far longer than
// the helper needs to join unless the machine keeps it off a core throughout).
TEST(ForEachChunk, InsideSideBySideTheHelperTakesChunksOnceItsJobIsDone) {
  if (!has_openmp()) GTEST_SKIP() << "built without OpenMP: one thread only";
  Threads two(2);
  SideBySide beside;
  constexpr Index kChunks = 64;
  long helped = 0;
  for (int round = 0; round < 20 && helped == 0; ++round) {
    std::vector<std::atomic<int>> runs(kChunks);
    std::vector<std::thread::id> who(kChunks);
    std::vector<double> out(kChunks, 0.0);
    std::atomic<bool> second_done{false};
    std::thread::id caller;
    beside.run(
        [&]() noexcept {
          caller = std::this_thread::get_id();
          const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
          while (!second_done.load() && std::chrono::steady_clock::now() < until)
            std::this_thread::yield();
          for_each_chunk(kChunks, [&](Index c) {
            ++runs[size_t(c)];
            who[size_t(c)] = std::this_thread::get_id();
            out[size_t(c)] = 1.0 / double(c + 1);
            std::this_thread::sleep_for(std::chrono::microseconds(200));
          });
        },
        [&]() noexcept { second_done.store(true); });
    for (Index c = 0; c < kChunks; ++c) {
      EXPECT_EQ(runs[size_t(c)].load(), 1) << "chunk " << c;
      EXPECT_EQ(out[size_t(c)], 1.0 / double(c + 1));
      helped += who[size_t(c)] != caller;
    }
  }
  EXPECT_GT(helped, 0) << "the helper never took a chunk in 20 rounds";
}

// A for_each_chunk inside a shared chunk (the check's energy sums beside the normals) is a plain
// loop in chunk order on the thread that runs the outer chunk: one chunk set is shared at a time,
// so an inner set can neither take the outer one's place nor be taken by the helper. The first
// outer chunk's inner chunks wait 0.2 ms each, long enough for a helper done with its own job and
// with the other, quick, outer chunk to take one if offered.
TEST(ForEachChunk, AChunkSetInsideASharedChunkIsAPlainLoop) {
  if (!has_openmp()) GTEST_SKIP() << "built without OpenMP: one thread only";
  Threads two(2);
  SideBySide beside;
  constexpr Index kOuter = 2, kInner = 8;
  for (int round = 0; round < 5; ++round) {
    std::vector<std::thread::id> outer_who(kOuter);
    std::vector<std::vector<std::thread::id>> inner_who(kOuter);
    std::vector<std::vector<long>> inner_at(kOuter);  // the inner chunk's place in its loop
    std::vector<std::atomic<long>> next(kOuter);
    std::atomic<bool> second_done{false};
    beside.run(
        [&]() noexcept {
          const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
          while (!second_done.load() && std::chrono::steady_clock::now() < until)
            std::this_thread::yield();
          for_each_chunk(kOuter, [&](Index c) {
            outer_who[size_t(c)] = std::this_thread::get_id();
            inner_who[size_t(c)].assign(kInner, std::thread::id());
            inner_at[size_t(c)].assign(kInner, -1);
            for_each_chunk(kInner, [&](Index k) {
              inner_at[size_t(c)][size_t(k)] = next[size_t(c)].fetch_add(1);
              inner_who[size_t(c)][size_t(k)] = std::this_thread::get_id();
              if (c == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
            });
          });
        },
        [&]() noexcept { second_done.store(true); });
    for (Index c = 0; c < kOuter; ++c) {
      for (Index k = 0; k < kInner; ++k) {
        EXPECT_EQ(inner_at[size_t(c)][size_t(k)], k) << "outer chunk " << c;
        EXPECT_EQ(inner_who[size_t(c)][size_t(k)], outer_who[size_t(c)])
            << "round " << round << ", outer chunk " << c << ", inner chunk " << k;
      }
    }
  }
}

// Many short rounds with shared chunks in each: nothing runs twice or hangs, whether the helper
// is still on its own job, helping, or asleep.
TEST(ForEachChunk, EveryChunkRunsOnceOverManyShortRounds) {
  Threads two(2);
  SideBySide beside;
  long chunks = 0, seconds = 0;
  std::atomic<long> counted{0};
  for (int round = 0; round < 2000; ++round)
    beside.run(
        [&]() noexcept {
          for (int share = 0; share < 3; ++share)
            for_each_chunk(8, [&](Index) { counted.fetch_add(1); });
          chunks += 24;
        },
        [&]() noexcept { ++seconds; });
  EXPECT_EQ(counted.load(), chunks);
  EXPECT_EQ(seconds, 2000);
}

}  // namespace
}  // namespace flagsim
