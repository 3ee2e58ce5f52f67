#include "gaia/torch/openblas.h"

#include <dlfcn.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>

namespace gaia {

const char* openblas_core_for_this_cpu() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl") &&
      __builtin_cpu_supports("avx512dq"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
#endif
  return nullptr;
}

void* openblas_symbol(const char* name) {
  if (void* f = dlsym(RTLD_DEFAULT, name)) return f;
  // A Python extension's libraries are loaded with local symbols: found through the library itself.
  static void* lib = dlopen("libopenblas.so.0", RTLD_NOW | RTLD_NOLOAD);
  return lib ? dlsym(lib, name) : nullptr;
}

std::string openblas_core() {
  using CoreName = char* (*)();
  auto name = reinterpret_cast<CoreName>(openblas_symbol("openblas_get_corename"));
  std::string s = name ? name() : "";
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return s;
}

bool use_openblas_kernels_of_this_cpu() {
  if (std::getenv("OPENBLAS_CORETYPE")) return false;  // the user's choice, taken as OpenBLAS loaded
  const char* want = openblas_core_for_this_cpu();
  const std::string now = openblas_core();
  using Hook = void (*)();
  // A build with every core's kernels (DYNAMIC_ARCH, as Debian's) chooses them in gotoblas_dynamic_init, which
  // reads OPENBLAS_CORETYPE; gotoblas_dynamic_quit lets it choose again.
  auto quit = reinterpret_cast<Hook>(openblas_symbol("gotoblas_dynamic_quit"));
  auto init = reinterpret_cast<Hook>(openblas_symbol("gotoblas_dynamic_init"));
  if (!want || now.empty() || !quit || !init) return false;
  for (const char* vector_core : {"haswell", "zen", "skylakex", "cooperlake", "sapphirerapids"})
    if (now == vector_core) return false;  // OpenBLAS knows this CPU: its choice stands
  ::setenv("OPENBLAS_CORETYPE", want, /*overwrite=*/0);
  quit();
  init();
  return openblas_core() != now;
}

}  // namespace gaia
