#pragma once
// The module's edge: NumPy arrays <-> LibTorch tensors, checked (dtype, shape, strides) with a ValueError that
// names what was expected, and without copies where the layout allows; and gaia's errors as Python exceptions.
#include <string>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <torch/torch.h>

namespace gaia::python {

namespace py = pybind11;

// What an argument may hold: uint8 frames, integer token ids, float signals.
enum class Kind { kFrames, kTokens, kSignals };

// A view of `a` as a tensor (no copy; `a` must outlive it): frames stay uint8, token ids of any integer dtype and
// signals of float32 or float64 keep theirs. `shape` gives each dimension's size, -1 for any; a shape or dtype
// that does not fit is a ValueError naming `what` and what was expected.
torch::Tensor view_of(const py::array& a, Kind kind, const std::vector<int64_t>& shape, const std::string& what);
// As view_of, with any of several ranks: the one of `shapes` whose rank is a's.
torch::Tensor view_of(const py::array& a, Kind kind, const std::vector<std::vector<int64_t>>& shapes,
                      const std::string& what);

// A NumPy array over `t`'s memory (CPU, made contiguous where it is not), which keeps the tensor alive: no copy.
py::array array_of(torch::Tensor t);

// FileNotFoundError naming `path` unless it exists (weights, datasets and videos are checked before loading).
void require_path(const std::string& path, const std::string& what);

// gaia::Error -> ValueError, c10::Error -> RuntimeError (its first line), as exceptions of the module.
void register_errors(py::module_& m);

}  // namespace gaia::python
