// SideBySide: the helper thread that runs the air's step beside the cloth's (issue 28).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <thread>

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

}  // namespace
}  // namespace flagsim
