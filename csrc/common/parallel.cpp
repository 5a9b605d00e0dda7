#include "common/parallel.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <thread>

#include "common/errors.h"
#ifdef _OPENMP
#include <omp.h>
#endif

namespace flagsim {

int num_threads() {
#ifdef _OPENMP
  return omp_get_max_threads();
#else
  return 1;
#endif
}

void set_num_threads(int n) {
  if (n < 1) fail_param("threads", ">= 1", n);
#ifdef _OPENMP
  omp_set_num_threads(n);
#endif
}

bool has_openmp() {
#ifdef _OPENMP
  return true;
#else
  return false;
#endif
}

namespace {
enum JobState : int { kIdle, kPosted, kTaken, kDone };

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}
}  // namespace

// Chunks shared by the calling thread (detail::share_chunks), on its stack while shared.
struct SharedChunks {
  detail::ChunkFn fn;
  const void* body;
  Index count;
  std::atomic<Index> next{0};  // the next chunk to take
};

struct SideBySide::State {
  std::atomic<int> job{kIdle};  // JobState of the posted job
  std::atomic<bool> stop{false};
  Job fn = nullptr;  // the posted job, written before job = kPosted
  const void* arg = nullptr;
  // Chunks the calling thread shares while it runs its first job: the helper takes them once
  // its own job is done. `helping` counts helpers that may hold the pointer: the caller takes it
  // back (nullptr), then waits for helping == 0 before its chunks leave its stack (both
  // sequentially consistent: a helper that counted itself in after that wait began reads null).
  std::atomic<SharedChunks*> shared{nullptr};
  std::atomic<unsigned> shares{0};  // chunks posted so far (the helper's wake-up)
  std::atomic<int> helping{0};
  std::mutex m;
  std::condition_variable posted, done;
  std::thread helper;

  // The helper's part of shared chunks, once its own job is done; returns the share it served.
  unsigned help() {
    const unsigned seen = shares.load();
    helping.fetch_add(1);
    if (SharedChunks* c = shared.load())
      for (Index k; (k = c->next.fetch_add(1)) < c->count;) c->fn(c->body, k);
    if (helping.fetch_sub(1) == 1) notify(done);
    return seen;
  }

  // Until the caller has seen its job done (job leaves kDone): serve what it shares.
  void help_until_released() {
    unsigned served = shares.load() - 1;
    for (;;) {
      wait(posted, [&] {
        return job.load() != kDone || stop.load() ||
               (shared.load() != nullptr && shares.load() != served);
      });
      if (job.load() != kDone || stop.load()) return;
      served = help();
    }
  }

  // Spins for up to kSpinMicroseconds until ready(), then sleeps on cv until ready(). The
  // notifier changes the atomics, then locks and unlocks m, then notifies: no wake-up is lost.
  template <class Ready>
  void wait(std::condition_variable& cv, const Ready& ready) {
    const auto until =
        std::chrono::steady_clock::now() + std::chrono::microseconds(kSpinMicroseconds);
    for (int k = 1; !ready(); ++k) {
      cpu_relax();
      if (k % 64 == 0 && std::chrono::steady_clock::now() > until) {
        std::unique_lock<std::mutex> lock(m);
        cv.wait(lock, ready);
        return;
      }
    }
  }

  void notify(std::condition_variable& cv) {
    { std::lock_guard<std::mutex> lock(m); }
    cv.notify_one();
  }

  void helper_loop() {
    for (;;) {
      wait(posted, [&] { return job.load(std::memory_order_acquire) == kPosted || stop.load(); });
      if (stop.load()) return;
      int expected = kPosted;
      if (!job.compare_exchange_strong(expected, kTaken, std::memory_order_acq_rel)) continue;
      fn(arg);
      job.store(kDone, std::memory_order_release);
      notify(done);
      help_until_released();
    }
  }
};

namespace {
// The SideBySide whose first job runs on this thread (set by run_jobs around it), or null.
thread_local SideBySide::State* t_sharing = nullptr;
}  // namespace

bool detail::share_chunks(Index chunks, ChunkFn fn, const void* body) {
  SideBySide::State* s = t_sharing;
  if (!s || chunks <= 1) return false;
  // A helper that has not picked its own job up is not running (asleep, or without a core on a
  // loaded machine): posting would only cost a wake-up, and the caller runs the air after this.
  if (s->job.load(std::memory_order_acquire) == kPosted) return false;
  if (s->shared.load() != nullptr) return false;  // a chunk of a shared set: its loops run plainly
  SharedChunks c{fn, body, chunks};
  s->shared.store(&c);
  s->shares.fetch_add(1);
  s->notify(s->posted);
  for (Index k; (k = c.next.fetch_add(1)) < chunks;) fn(body, k);
  s->shared.store(nullptr);
  s->wait(s->done, [&] { return s->helping.load() == 0; });  // a chunk the helper still runs
  return true;
}

SideBySide::SideBySide() : s_(std::make_unique<State>()) {
  // The helper's loops run on its own thread (libgomp gives a thread its own settings on the
  // first change, an allocation: here, before run() is ever called).
  std::promise<void> ready;
  std::future<void> started = ready.get_future();
  s_->helper = std::thread([this, &ready] {
    set_num_threads(1);
    ready.set_value();
    s_->helper_loop();
  });
  started.wait();
}

SideBySide::~SideBySide() {
  s_->stop.store(true);
  s_->notify(s_->posted);
  s_->helper.join();
}

void SideBySide::run_jobs(Job first, const void* first_arg, Job second, const void* second_arg) {
  State& s = *s_;
  s.fn = second;
  s.arg = second_arg;
  s.job.store(kPosted, std::memory_order_release);
  s.notify(s.posted);
  const int threads = num_threads();
  set_num_threads(1);
  t_sharing = &s;
  first(first_arg);
  t_sharing = nullptr;
  int expected = kPosted;
  if (s.job.compare_exchange_strong(expected, kIdle, std::memory_order_acq_rel)) {
    second(second_arg);  // the helper has not started it: no waiting for a thread without a core
  } else {
    s.wait(s.done, [&] { return s.job.load(std::memory_order_acquire) == kDone; });
    s.job.store(kIdle);
    s.notify(s.posted);  // the helper stops serving shared chunks
  }
  set_num_threads(threads);
}

void wait_until_set(const std::atomic<bool>& flag) {
  const auto until =
      std::chrono::steady_clock::now() + std::chrono::microseconds(SideBySide::kSpinMicroseconds);
  for (int k = 1; !flag.load(std::memory_order_acquire); ++k) {
    cpu_relax();
    if (k % 64 == 0 && std::chrono::steady_clock::now() > until) std::this_thread::yield();
  }
}

}  // namespace flagsim
