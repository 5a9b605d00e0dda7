#include "common/memory.h"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "common/errors.h"

namespace flagsim {

namespace {

// A number from the first line of `path` ("max" and unreadable files give 0).
std::uint64_t read_number(const char* path) {
  std::ifstream f(path);
  std::string s;
  if (!(f >> s) || s == "max") return 0;
  try {
    return std::stoull(s);
  } catch (...) {
    return 0;
  }
}

std::string gigabytes(double bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f GB", bytes / 1e9);
  return buf;
}

}  // namespace

namespace {
std::atomic<std::int64_t> g_aligned_bytes{0};
}

std::int64_t aligned_bytes_live() { return g_aligned_bytes.load(std::memory_order_relaxed); }

void count_aligned_bytes(std::int64_t delta) {
  g_aligned_bytes.fetch_add(delta, std::memory_order_relaxed);
}

std::uint64_t available_memory() {
  std::uint64_t avail = 0;
  std::ifstream info("/proc/meminfo");
  std::string key;
  std::uint64_t kb = 0;
  std::string unit;
  while (info >> key >> kb) {
    std::getline(info, unit);
    if (key == "MemAvailable:") {
      avail = kb * 1024;
      break;
    }
  }
  // cgroup v2: the limit minus what the group already uses
  const std::uint64_t limit = read_number("/sys/fs/cgroup/memory.max");
  const std::uint64_t used = read_number("/sys/fs/cgroup/memory.current");
  if (limit > 0 && limit > used) avail = avail > 0 ? std::min(avail, limit - used) : limit - used;
  // FLAGSIM_MEMORY_LIMIT (bytes): a lower ceiling a user sets to leave room for other work.
  if (const char* env = std::getenv("FLAGSIM_MEMORY_LIMIT")) {
    char* end = nullptr;
    const double v = std::strtod(env, &end);
    if (end != env && v > 0)
      avail = avail > 0 ? std::min(avail, std::uint64_t(v)) : std::uint64_t(v);
  }
  return avail;
}

void check_memory(const std::string& what, double bytes, const std::string& advice) {
  const std::uint64_t avail = available_memory();
  if (avail == 0 || bytes <= double(avail)) return;
  throw InvalidArgument(what + " needs about " + gigabytes(bytes) + " of memory, more than the " +
                        gigabytes(double(avail)) + " this machine has available; " + advice);
}

}  // namespace flagsim
