// What a fuzz target does with a broken contract (parser_contract.h): print it and abort, which
// libFuzzer reports as a crash and saves the input as crash-<sha1>.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <string>

namespace digitize::fuzz {

inline void AbortUnless(const std::string& broken) {
  if (broken.empty()) return;
  std::fprintf(stderr, "parser contract broken: %s\n", broken.c_str());
  std::abort();
}

}  // namespace digitize::fuzz
