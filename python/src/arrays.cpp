#include "arrays.h"

#include <filesystem>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "gaia/core/error.h"

namespace gaia::python {

namespace {

torch::ScalarType scalar_of(const py::dtype& d) {
  switch (d.kind()) {
    case 'u': if (d.itemsize() == 1) return torch::kUInt8; break;
    case 'i':
      if (d.itemsize() == 1) return torch::kInt8;
      if (d.itemsize() == 2) return torch::kShort;
      if (d.itemsize() == 4) return torch::kInt;
      if (d.itemsize() == 8) return torch::kLong;
      break;
    case 'f':
      if (d.itemsize() == 4) return torch::kFloat;
      if (d.itemsize() == 8) return torch::kDouble;
      break;
    case 'b': return torch::kBool;
  }
  return torch::kComplexFloat;  // unsupported: rejected by the caller
}

std::string shape_text(const std::vector<int64_t>& shape) {
  std::vector<std::string> s;
  for (auto d : shape) s.push_back(d < 0 ? "*" : std::to_string(d));
  return "[" + fmt::format("{}", fmt::join(s, ", ")) + "]";
}

const char* kind_text(Kind k) {
  switch (k) {
    case Kind::kFrames: return "uint8";
    case Kind::kTokens: return "an integer dtype (int16, int32 or int64)";
    case Kind::kSignals: return "float32 or float64";
  }
  return "";
}

bool kind_accepts(Kind k, torch::ScalarType s) {
  switch (k) {
    case Kind::kFrames: return s == torch::kUInt8;
    case Kind::kTokens: return s == torch::kShort || s == torch::kInt || s == torch::kLong;
    case Kind::kSignals: return s == torch::kFloat || s == torch::kDouble;
  }
  return false;
}

}  // namespace

torch::Tensor view_of(const py::array& a, Kind kind, const std::vector<std::vector<int64_t>>& shapes,
                      const std::string& what) {
  std::vector<int64_t> got(a.shape(), a.shape() + a.ndim());
  std::vector<std::string> wanted;
  for (const auto& s : shapes) wanted.push_back(shape_text(s));
  const std::string expected = fmt::format("{} of shape {}", kind_text(kind), fmt::join(wanted, " or "));
  const auto type = scalar_of(a.dtype());
  if (!kind_accepts(kind, type))
    throw py::value_error(fmt::format("{}: {} expected, got dtype {}", what, expected, std::string(py::str(a.dtype()))));
  const std::vector<int64_t>* shape = nullptr;
  for (const auto& s : shapes)
    if (int64_t(s.size()) == a.ndim()) shape = &s;
  bool fits = shape != nullptr;
  for (size_t i = 0; fits && i < shape->size(); ++i) fits = (*shape)[i] < 0 || (*shape)[i] == got[i];
  if (!fits) throw py::value_error(fmt::format("{}: {} expected, got shape {}", what, expected, shape_text(got)));
  std::vector<int64_t> strides;
  for (py::ssize_t i = 0; i < a.ndim(); ++i) {
    if (a.strides()[i] < 0 || a.strides()[i] % a.itemsize())
      throw py::value_error(fmt::format("{}: an array with positive, aligned strides expected (np.ascontiguousarray "
                                        "gives one)", what));
    strides.push_back(a.strides()[i] / a.itemsize());
  }
  return torch::from_blob(const_cast<void*>(a.data()), got, strides, torch::TensorOptions().dtype(type));
}

torch::Tensor view_of(const py::array& a, Kind kind, const std::vector<int64_t>& shape, const std::string& what) {
  return view_of(a, kind, std::vector<std::vector<int64_t>>{shape}, what);
}

py::array array_of(torch::Tensor t) {
  t = t.to(torch::kCPU).contiguous();
  py::dtype d;
  switch (t.scalar_type()) {
    case torch::kUInt8: d = py::dtype::of<uint8_t>(); break;
    case torch::kShort: d = py::dtype::of<int16_t>(); break;
    case torch::kInt: d = py::dtype::of<int32_t>(); break;
    case torch::kLong: d = py::dtype::of<int64_t>(); break;
    case torch::kFloat: d = py::dtype::of<float>(); break;
    case torch::kDouble: d = py::dtype::of<double>(); break;
    case torch::kBool: d = py::dtype::of<bool>(); break;
    default: throw std::runtime_error("gaia: no NumPy dtype for " + std::string(c10::toString(t.scalar_type())));
  }
  std::vector<py::ssize_t> shape(t.sizes().begin(), t.sizes().end()), strides;
  for (auto s : t.strides()) strides.push_back(py::ssize_t(s * t.element_size()));
  auto* keep = new torch::Tensor(t);
  py::capsule owner(keep, [](void* p) { delete static_cast<torch::Tensor*>(p); });
  return py::array(d, shape, strides, t.data_ptr(), owner);
}

void require_path(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) {
    PyErr_SetObject(PyExc_FileNotFoundError,
                    py::make_tuple(2, fmt::format("{}: no such file or directory: {}", what, path), path).ptr());
    throw py::error_already_set();
  }
}

void register_errors(py::module_& m) {
  (void)m;
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const gaia::Error& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const c10::Error& e) {
      const std::string msg = e.what_without_backtrace();
      PyErr_SetString(PyExc_RuntimeError, msg.substr(0, msg.find('\n')).c_str());
    }
  });
}

}  // namespace gaia::python
