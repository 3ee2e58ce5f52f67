#include "gaia/core/npy.h"

#include <cstring>
#include <regex>

#include "gaia/core/error.h"

namespace gaia {

namespace {

std::string descr_of(DType t) {
  switch (t) {
    case DType::F64: return "<f8";
    case DType::F32: return "<f4";
    case DType::F16: return "<f2";
    case DType::I64: return "<i8";
    case DType::I32: return "<i4";
    case DType::I16: return "<i2";
    case DType::I8: return "|i1";
    case DType::U8: return "|u1";
    case DType::BOOL: return "|b1";
    case DType::BF16: break;
  }
  fail("npy: dtype {} cannot be stored in .npy", safetensors_name(t));
}

bool dtype_of(const std::string& d, DType* out) {
  static const std::pair<const char*, DType> table[] = {
      {"<f8", DType::F64}, {"<f4", DType::F32}, {"<f2", DType::F16}, {"<i8", DType::I64}, {"<i4", DType::I32},
      {"<i2", DType::I16}, {"|i1", DType::I8},  {"|u1", DType::U8},  {"|b1", DType::BOOL}, {"<u1", DType::U8},
      {"<i1", DType::I8}};
  for (auto& [s, t] : table)
    if (d == s) { *out = t; return true; }
  return false;
}

}  // namespace

NpyArray npy_read(const fs::path& path) {
  if (!fs::exists(path)) fail("{}: no such file", path.string());
  const std::string p = path.string();
  std::string raw = read_file(path);
  if (raw.size() < 10 || std::memcmp(raw.data(), "\x93NUMPY", 6) != 0) fail("{}: not a .npy file (bad magic)", p);
  int major = static_cast<uint8_t>(raw[6]);
  size_t hlen = 0, hstart = 0;
  if (major == 1) {
    hlen = static_cast<uint8_t>(raw[8]) | (static_cast<uint8_t>(raw[9]) << 8);
    hstart = 10;
  } else if (major == 2 || major == 3) {
    if (raw.size() < 12) fail("{}: truncated .npy header", p);
    for (int i = 3; i >= 0; --i) hlen = (hlen << 8) | static_cast<uint8_t>(raw[8 + i]);
    hstart = 12;
  } else {
    fail("{}: unsupported .npy version {}", p, major);
  }
  if (hstart + hlen > raw.size()) fail("{}: truncated .npy header", p);
  std::string header = raw.substr(hstart, hlen);
  std::smatch m;
  static const std::regex descr_re("'descr'\\s*:\\s*'([^']+)'");
  static const std::regex order_re("'fortran_order'\\s*:\\s*(True|False)");
  static const std::regex shape_re("'shape'\\s*:\\s*\\(([^)]*)\\)");
  NpyArray a;
  if (!std::regex_search(header, m, descr_re)) fail("{}: .npy header has no descr", p);
  if (!dtype_of(m[1].str(), &a.dtype))
    fail("{}: unsupported .npy dtype '{}' (want int16/32/64, uint8, float32/64)", p, m[1].str());
  if (!std::regex_search(header, m, order_re)) fail("{}: .npy header has no fortran_order", p);
  if (m[1].str() == "True") fail("{}: Fortran-order .npy arrays are not supported; save with C order", p);
  if (!std::regex_search(header, m, shape_re)) fail("{}: .npy header has no shape", p);
  std::string dims = m[1].str();
  static const std::regex int_re("(\\d+)");
  for (auto it = std::sregex_iterator(dims.begin(), dims.end(), int_re); it != std::sregex_iterator(); ++it)
    a.shape.push_back(std::stoll((*it)[1].str()));
  size_t need = static_cast<size_t>(a.size()) * dtype_size(a.dtype);
  size_t have = raw.size() - hstart - hlen;
  if (have < need) fail("{}: truncated .npy data ({} bytes, shape {} needs {})", p, have, shape_str(a.shape), need);
  if (have > need) fail("{}: .npy has {} trailing bytes after shape {}", p, have - need, shape_str(a.shape));
  a.bytes.assign(raw.begin() + static_cast<std::ptrdiff_t>(hstart + hlen), raw.end());
  return a;
}

void npy_write(const fs::path& path, const NpyArray& a) {
  if (a.bytes.size() != static_cast<size_t>(a.size()) * dtype_size(a.dtype))
    fail("{}: array bytes do not match shape {}", path.string(), shape_str(a.shape));
  // Python tuple syntax: () for scalars, (n,) for 1-D, (a, b, c) otherwise.
  std::string shape = fmt::format("{}", fmt::join(a.shape, ", "));
  if (a.shape.size() == 1) shape += ",";
  std::string header = "{'descr': '" + descr_of(a.dtype) + "', 'fortran_order': False, 'shape': (" + shape + "), }";
  size_t total = 10 + header.size() + 1;
  size_t pad = (64 - total % 64) % 64;  // numpy aligns the data to 64 bytes
  header += std::string(pad, ' ') + "\n";
  std::string out = "\x93NUMPY";
  out.push_back(1);
  out.push_back(0);
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>((header.size() >> 8) & 0xff));
  out += header;
  out.append(reinterpret_cast<const char*>(a.bytes.data()), a.bytes.size());
  write_file_atomic(path, out);
}

std::vector<int64_t> NpyArray::to_int64() const {
  std::vector<int64_t> out(static_cast<size_t>(size()));
  for (size_t i = 0; i < out.size(); ++i) {
    switch (dtype) {
      case DType::I64: out[i] = as<int64_t>()[i]; break;
      case DType::I32: out[i] = as<int32_t>()[i]; break;
      case DType::I16: out[i] = as<int16_t>()[i]; break;
      case DType::I8: out[i] = as<int8_t>()[i]; break;
      case DType::U8: case DType::BOOL: out[i] = as<uint8_t>()[i]; break;
      default: fail("npy: array of {} is not an integer array", safetensors_name(dtype));
    }
  }
  return out;
}

std::vector<double> NpyArray::to_double() const {
  if (dtype != DType::F64 && dtype != DType::F32 && dtype != DType::F16) {
    std::vector<int64_t> ints = to_int64();
    return std::vector<double>(ints.begin(), ints.end());
  }
  std::vector<double> out(static_cast<size_t>(size()));
  for (size_t i = 0; i < out.size(); ++i) {
    if (dtype == DType::F64) out[i] = as<double>()[i];
    else if (dtype == DType::F32) out[i] = as<float>()[i];
    else out[i] = half_to_float(as<uint16_t>()[i]);
  }
  return out;
}

}  // namespace gaia
