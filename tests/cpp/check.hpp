// What the standalone C++ test drivers (tests/cpp/test_*.cpp) share: the count of checks and
// the closing line "N passed, N failed".
#pragma once
#include <cstdio>
#include <string>

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
