// The `gaia` Python module's native part (gaia._gaia): the library in-process, NumPy arrays in and out
// (docs/python.md). Each class is a thin layer over the calls the `gaia` binary makes.
#include <torch/torch.h>

#include "arrays.h"

namespace gaia::python {
void bind_models(py::module_& m);
void bind_sim(py::module_& m);
void bind_dataset(py::module_& m);
}  // namespace gaia::python

PYBIND11_MODULE(_gaia, m) {
  namespace gp = gaia::python;
  m.doc() = "gaia: a generative world model for autonomous driving (GAIA-1), in-process";
  gp::register_errors(m);
  m.def("set_threads", [](int n) {
    if (n < 1) throw pybind11::value_error("threads: at least 1 expected");
    torch::set_num_threads(n);
  }, pybind11::arg("n"), "Intra-op threads of LibTorch in this process (closed loop: 1 is fastest; see docs/python.md)");
  m.def("threads", [] { return torch::get_num_threads(); });
  gp::bind_models(m);
  gp::bind_sim(m);
  gp::bind_dataset(m);
}
