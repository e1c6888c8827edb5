// What the standalone C++ test drivers (tests/cpp/test_*.cpp) share: the count of checks, the
// closing line "N passed, N failed" and the timing of their benchmarks.
#pragma once
#include <time.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <cstring>
#include <string>
#include <vector>

#include "pool.hpp"

namespace check_detail {
inline int g_pass = 0, g_fail = 0;
}  // namespace check_detail

// "1.23e-04"
inline std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2e", v);
  return buf;
}

// count one check; a failed one is printed
inline void check(bool ok, const std::string& what) {
  if (ok) {
    ++check_detail::g_pass;
  } else {
    ++check_detail::g_fail;
    std::printf("FAILED: %s\n", what.c_str());
  }
}

// the closing line; the exit code (nonzero when a check failed)
inline int report() {
  std::printf("%d passed, %d failed\n", check_detail::g_pass, check_detail::g_fail);
  return check_detail::g_fail ? 1 : 0;
}

// CPU time of the calling thread (the machine may be shared: wall-clock time would count the
// time the thread waits for a core), in seconds.
inline double thread_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Minimum over `rounds` of the mean thread CPU time of `inner` calls, in seconds.
inline double timeit(const std::function<void()>& f, int inner, int rounds) {
  double best = INFINITY;
  for (int r = 0; r < rounds; ++r) {
    const double t0 = thread_seconds();
    for (int k = 0; k < inner; ++k) f();
    best = std::min(best, (thread_seconds() - t0) / inner);
  }
  return best;
}

// factor() then solve(y) on a copy y of b (n values), on 1, 2 and 3 threads of the engine's
// pool, `rounds` times each: true when factor() always returned 0 and every solution equals
// the first to the last bit (the parts of a dissection run the same operations whatever
// thread runs them; issue 28). The pool's thread count is restored.
template <class Factor, class Solve>
bool same_bits_on_any_threads(int n, const double* b, Factor&& factor, Solve&& solve,
                              int rounds = 10) {
  se3dyn::Pool& pool = se3dyn::Pool::get();
  const int before = pool.threads();
  std::vector<double> ref, y;
  bool same = true;
  for (int r = 0; r < rounds; ++r)
    for (int th : {1, 2, 3}) {
      pool.set_threads(th);
      same = same && factor() == 0;
      y.assign(b, b + n);
      solve(y.data());
      if (ref.empty()) ref = y;
      same = same && std::memcmp(y.data(), ref.data(), sizeof(double) * size_t(n)) == 0;
    }
  pool.set_threads(before);
  return same;
}
