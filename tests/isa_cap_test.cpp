// The suite's AVX2 pass (CMakeLists.txt: ctest -L avx2, GAIA_TEST_ISA=avx2): LibTorch's kernels capped at AVX2 in
// this process and in every gaia binary it runs, so that a machine with AVX-512 takes the paths a CPU without it
// takes. ATen and oneDNN read their caps at their first kernel, after this initialiser; OpenBLAS reads its core
// type when it loads, so its cap reaches the binaries the tests run (an OPENBLAS_CORETYPE already set is kept).
#include <cstdlib>
#include <string>

#include "gaia/torch/precision.h"
#include "test_util.h"

namespace {

bool capped_at_avx2() {
  const char* isa = std::getenv("GAIA_TEST_ISA");
  return isa && std::string(isa) == "avx2";
}

const bool kCapApplied = [] {
  if (!capped_at_avx2()) return false;
  ::setenv("ATEN_CPU_CAPABILITY", "avx2", 1);
  ::setenv("ONEDNN_MAX_CPU_ISA", "AVX2", 1);
  ::setenv("OPENBLAS_CORETYPE", "Haswell", 0);
  return true;
}();

}  // namespace

// The cap reaches the environment LibTorch reads (ATen's dispatch does not export its choice to check) and the bf16
// check, in this process and in the binaries it starts.
TEST(IsaCapCli, ReachesLibTorchAndTheBinaries) {
  if (!capped_at_avx2()) GTEST_SKIP() << "the normal pass: kernels at what the CPU has (ctest -L avx2 caps them)";
  ASSERT_TRUE(kCapApplied);
  EXPECT_FALSE(gaia::cpu_has_bf16());
  auto r = gaia::test::run_shell("echo $ATEN_CPU_CAPABILITY $ONEDNN_MAX_CPU_ISA");
  EXPECT_EQ(r.output, "avx2 AVX2\n");
}
