#include "gaia/core/npy.h"

#include <cstring>
#include <cctype>
#include <optional>

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
    case DType::U16: return "<u2";
    case DType::U32: return "<u4";
    case DType::U64: return "<u8";
    case DType::BOOL: return "|b1";
    case DType::BF16: break;
  }
  fail("npy: dtype {} cannot be stored in .npy", safetensors_name(t));
}

bool dtype_of(const std::string& d, DType* out) {
  static const std::pair<const char*, DType> table[] = {
      {"<f8", DType::F64}, {"<f4", DType::F32}, {"<f2", DType::F16}, {"<i8", DType::I64}, {"<i4", DType::I32},
      {"<i2", DType::I16}, {"|i1", DType::I8},  {"|u1", DType::U8},  {"|b1", DType::BOOL}, {"<u1", DType::U8},
      {"<i1", DType::I8},  {"<u2", DType::U16}, {"<u4", DType::U32}, {"<u8", DType::U64}};
  for (auto& [s, t] : table)
    if (d == s) { *out = t; return true; }
  return false;
}

// The value of 'key' in the header's Python dict literal: the text between `open` and `close` right after
// `'key':`, or (open == 0) the rest of the header from there; nullopt when the key or a delimiter is missing.
// Plain string search: std::regex recurses once per character and overflows the stack on a long header.
std::optional<std::string> header_value(const std::string& h, const char* key, char open, char close) {
  const std::string k = std::string("'") + key + "'";
  size_t at = h.find(k);
  if (at == std::string::npos) return std::nullopt;
  auto skip_space = [&] { while (at < h.size() && std::isspace(static_cast<unsigned char>(h[at]))) ++at; };
  at += k.size();
  skip_space();
  if (at >= h.size() || h[at] != ':') return std::nullopt;
  ++at;
  skip_space();
  if (open == 0) return h.substr(at);
  if (at >= h.size() || h[at] != open) return std::nullopt;
  const size_t end = h.find(close, at + 1);
  if (end == std::string::npos) return std::nullopt;
  return h.substr(at + 1, end - at - 1);
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
  NpyArray a;
  const auto descr = header_value(header, "descr", '\'', '\'');
  if (!descr) fail("{}: .npy header has no descr", p);
  if (!dtype_of(*descr, &a.dtype))
    fail("{}: unsupported .npy dtype '{}' (want an integer type, bool, float16/32/64)", p, *descr);
  const std::string order = header_value(header, "fortran_order", 0, 0).value_or("");
  if (order.rfind("True", 0) == 0) fail("{}: Fortran-order .npy arrays are not supported; save with C order", p);
  if (order.rfind("False", 0) != 0) fail("{}: .npy header has no fortran_order", p);
  const auto shape = header_value(header, "shape", '(', ')');
  if (!shape) fail("{}: .npy header has no shape", p);
  const std::string& dims = *shape;
  for (size_t i = 0; i < dims.size();) {
    if (!std::isdigit(static_cast<unsigned char>(dims[i]))) { ++i; continue; }
    size_t j = i;
    while (j < dims.size() && std::isdigit(static_cast<unsigned char>(dims[j]))) ++j;
    try {
      a.shape.push_back(std::stoll(dims.substr(i, j - i)));
    } catch (const std::out_of_range&) {
      fail("{}: .npy shape ({}) has a dimension too large for int64", p, dims);
    }
    i = j;
  }
  size_t need = 0;
  if (__builtin_mul_overflow(static_cast<size_t>(numel(a.shape)), dtype_size(a.dtype), &need))
    fail("{}: .npy shape {} is too large", p, shape_str(a.shape));
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
  if (!is_integer(dtype)) fail("npy: array of {} is not an integer array", safetensors_name(dtype));
  return integer_values(dtype, bytes.data(), static_cast<size_t>(size()));
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
