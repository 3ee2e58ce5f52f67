// gaia: the command users run. It sets OMP_WAIT_POLICY=PASSIVE (unless set: a value the user gives wins) and runs
// the program beside it, gaia-core, with the same arguments. libgomp reads the variable once, as LibTorch loads
// it, and idle OpenMP threads that spin take the cores from the threads with work (docs/benchmarks.md): setting it
// here, in a process that loads nothing, spares gaia-core starting itself again after loading LibTorch once.
#include <cerrno>
#include <climits>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include <unistd.h>

int main(int, char** argv) {
  ::setenv("OMP_WAIT_POLICY", "PASSIVE", /*overwrite=*/0);
  char self[PATH_MAX];
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof(self) - 1);
  std::string core = "gaia-core";
  if (n > 0) {
    self[n] = '\0';
    std::string dir(self);
    core = dir.substr(0, dir.rfind('/') + 1) + core;
  }
  argv[0] = const_cast<char*>(core.c_str());
  ::execv(core.c_str(), argv);
  std::fprintf(stderr, "gaia: error: cannot run %s: %s\n", core.c_str(), std::strerror(errno));
  return 127;
}
