#pragma once
// OpenBLAS, which does LibTorch's float32 matrix products in Debian's build, picks its kernels by the CPU model it
// recognises; on a CPU newer than the library it falls back to its oldest x86-64 kernels (SSE3, "Prescott"),
// several times slower than the AVX2 or AVX-512 ones the CPU runs (docs/benchmarks.md).
#include <string>

namespace gaia {

// The OpenBLAS core type whose kernels this CPU runs ("SkylakeX", "Haswell"), or nullptr (no AVX2, not x86-64).
const char* openblas_core_for_this_cpu();

// The core type OpenBLAS runs now, as it names it ("skylakex"), or "" without OpenBLAS in the process.
std::string openblas_core();

// Where OpenBLAS fell back to kernels older than AVX2 on a CPU with AVX2, switches it to this CPU's core type
// (and sets OPENBLAS_CORETYPE for child processes); a core type the user set in OPENBLAS_CORETYPE stands. Runs
// once as the library loads (tensor_io.cpp), before any product; true when it switched.
bool use_openblas_kernels_of_this_cpu();

// A symbol of the OpenBLAS in this process, or nullptr (looked up, not linked: the reference BLAS has none).
void* openblas_symbol(const char* name);

}  // namespace gaia
