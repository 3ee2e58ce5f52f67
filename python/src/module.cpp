// The `gaia` Python module's native part (gaia._gaia): the library in-process, NumPy arrays in and out
// (docs/python.md). Each class is a thin layer over the calls the `gaia` binary makes.
#include <cstdlib>

#include <torch/torch.h>

#include "arrays.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::python {
void bind_models(py::module_& m);
void bind_sim(py::module_& m);
void bind_dataset(py::module_& m);
}  // namespace gaia::python

PYBIND11_MODULE(_gaia, m) {
  namespace gp = gaia::python;
  m.doc() = "gaia: a generative world model for autonomous driving (GAIA-1), in-process";
  gp::register_errors(m);
  // As the gaia binary: freed blocks stay in the process instead of fresh mmap()s each step (torch/tensor_io.h);
  // GAIA_SYSTEM_MALLOC=1 keeps the process's own malloc settings.
  if (!std::getenv("GAIA_SYSTEM_MALLOC")) gaia::configure_allocator();
  m.def("set_threads", [](int n) {
    if (n < 1) throw pybind11::value_error("threads: at least 1 expected");
    gaia::set_torch_threads(n);  // LibTorch's and OpenBLAS's, as the gaia binary sets them
  }, pybind11::arg("n"), "Intra-op threads of LibTorch (and OpenBLAS) in this process (closed loop: 1 is fastest; "
                         "see docs/python.md)");
  m.def("threads", [] { return torch::get_num_threads(); });
  gp::bind_models(m);
  gp::bind_sim(m);
  gp::bind_dataset(m);
}
