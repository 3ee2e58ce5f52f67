// OpenBLAS's kernels (torch/openblas.h): where OpenBLAS does not recognise the CPU it falls back to SSE3 kernels;
// every program of gaia switches it to the AVX2 or AVX-512 ones the CPU runs, unless the user chose a core type.
#include <gtest/gtest.h>

#include <cstdlib>
#include <set>

#include "gaia/torch/openblas.h"
#include "test_util.h"

using namespace gaia;

namespace {

const std::set<std::string> kVectorCores{"haswell", "zen", "skylakex", "cooperlake", "sapphirerapids"};

// The core type of the last "Core: X" line OpenBLAS printed (OPENBLAS_VERBOSE=2), lower case.
std::string last_core_line(const std::string& out) {
  const auto at = out.rfind("Core: ");
  if (at == std::string::npos) return "";
  std::string s = out.substr(at + 6, out.find('\n', at) - at - 6);
  for (auto& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

TEST(OpenBlas, RunsTheKernelsOfThisCpuOrTheUsersChoice) {
  const std::string now = gaia::openblas_core();
  if (now.empty()) {
    GTEST_SKIP() << "LibTorch's products do not run on OpenBLAS in this build";
  }
  if (const char* env = std::getenv("OPENBLAS_CORETYPE")) {
    std::string want = env;
    for (auto& c : want) c = char(std::tolower(static_cast<unsigned char>(c)));
    EXPECT_EQ(now, want);
    return;
  }
  if (!gaia::openblas_core_for_this_cpu()) {
    GTEST_SKIP() << "no AVX2 on this CPU: OpenBLAS's own choice stands";
  }
  EXPECT_TRUE(kVectorCores.count(now)) << now;
  EXPECT_FALSE(gaia::use_openblas_kernels_of_this_cpu());  // already switched (or already right): nothing to do
}

TEST(OpenBlasCli, TheBinaryRunsTheKernelsOfThisCpuUnlessTheUserChoosesOthers) {
  if (!gaia::openblas_core_for_this_cpu()) {
    GTEST_SKIP() << "no AVX2 on this CPU: OpenBLAS's own choice stands";
  }
  auto r = test::run_shell("env -u OPENBLAS_CORETYPE OPENBLAS_VERBOSE=2 " + test::gaia_command("--version") + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  if (r.output.find("Core: ") == std::string::npos) {
    GTEST_SKIP() << "this OpenBLAS says nothing of its kernels";
  }
  EXPECT_TRUE(kVectorCores.count(last_core_line(r.output))) << r.output;
  r = test::run_shell("OPENBLAS_CORETYPE=Prescott OPENBLAS_VERBOSE=2 " + test::gaia_command("--version") + " 2>&1");
  EXPECT_EQ(last_core_line(r.output), "prescott") << r.output;  // the user's choice stands
}
