// The last-resort handler of every program's main().
//
//   int main(int argc, char** argv) { return sandtable::GuardedMain(argc, argv, "sandtable-x",
//   Run); }
//
// Runs `run`; an exception that escapes it (a library's or the standard library's: they are bugs
// to fix at their cause, not a way of reporting bad input) is printed as one line
// "sandtable-x: internal error: <what>" on stderr and the program exits 1 instead of reaching
// std::terminate. Bad input is reported by `run` itself with exit status 2.
#pragma once

#include <cstdio>
#include <exception>
#include <new>

namespace sandtable {

template <typename Run>
int GuardedMain(int argc, char** argv, const char* program, Run run) {
  try {
    return run(argc, argv);
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: internal error: out of memory\n", program);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: internal error: %s\n", program, e.what());
  } catch (...) {
    std::fprintf(stderr, "%s: internal error: unknown exception\n", program);
  }
  return 1;
}

}  // namespace sandtable
