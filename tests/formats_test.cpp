// safetensors and .npy: round trips, the Hugging Face layout, and corrupt inputs with clear errors.
#include <cstring>
#include <fstream>

#include "gaia/core/error.h"
#include "gaia/core/interpolate.h"
#include "gaia/core/json_file.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "test_util.h"

using namespace gaia;
using test::error_of;

namespace {

void write_raw(const fs::path& p, const std::string& bytes) {
  std::ofstream o(p, std::ios::binary);
  o << bytes;
}
}  // namespace

TEST(Safetensors, RoundTripAllDtypes) {
  test::TempDir dir;
  SafetensorsWriter w;
  std::vector<float> f32{1.5f, -2.25f, 3.0f, 0.0f, 1e-3f, 7.0f};
  w.add_f32("a.weight", {2, 3}, f32);
  std::vector<uint16_t> f16, bf16;
  for (float v : f32) { f16.push_back(float_to_half(v)); bf16.push_back(float_to_bf16(v)); }
  w.add("b.f16", DType::F16, {6}, f16.data(), 12);
  w.add("c.bf16", DType::BF16, {3, 2}, bf16.data(), 12);
  std::vector<int64_t> i64{1, -2, 1LL << 40};
  std::vector<int32_t> i32{7, -8};
  std::vector<int16_t> i16{-300, 300, 5, 6};
  std::vector<uint8_t> u8{0, 255, 128};
  w.add("d.i64", DType::I64, {3}, i64.data(), 24);
  w.add("e.i32", DType::I32, {2}, i32.data(), 8);
  w.add("f.i16", DType::I16, {2, 2}, i16.data(), 8);
  w.add("g.u8", DType::U8, {3}, u8.data(), 3);
  w.set_metadata("format", "pt");
  w.write(dir / "t.safetensors");

  SafetensorsFile f(dir / "t.safetensors");
  EXPECT_EQ(f.names().size(), 7u);
  EXPECT_EQ(f.metadata().at("format"), "pt");
  EXPECT_EQ(f.get("a.weight").shape, (std::vector<int64_t>{2, 3}));
  EXPECT_EQ(f.to_float("a.weight"), f32);
  auto h = f.to_float("b.f16"), b = f.to_float("c.bf16");
  for (size_t i = 0; i < f32.size(); ++i) {
    EXPECT_NEAR(h[i], f32[i], std::abs(f32[i]) * 1e-3 + 1e-6);
    EXPECT_NEAR(b[i], f32[i], std::abs(f32[i]) * 1e-2 + 1e-6);
  }
  EXPECT_EQ(std::memcmp(f.get("d.i64").data, i64.data(), 24), 0);
  EXPECT_EQ(std::memcmp(f.get("f.i16").data, i16.data(), 8), 0);
  EXPECT_EQ(f.get("g.u8").data[1], 255);
  // Data section starts 8-byte aligned as in the reference implementation.
  uint64_t n = 0;
  std::memcpy(&n, read_file(dir / "t.safetensors").data(), 8);
  EXPECT_EQ((8 + n) % 8, 0u);
}

TEST(Safetensors, HalfConversionsAreExact) {
  for (float v : {0.0f, 1.0f, -2.0f, 65504.0f, 6.103515625e-05f, 5.960464477539063e-08f})
    EXPECT_EQ(half_to_float(float_to_half(v)), v) << v;
  EXPECT_EQ(float_to_half(1.0f), 0x3c00);
  EXPECT_EQ(float_to_bf16(1.0f), 0x3f80);
  EXPECT_TRUE(std::isinf(half_to_float(float_to_half(1e6f))));
}

TEST(Safetensors, CorruptFilesFailWithClearErrors) {
  test::TempDir dir;
  SafetensorsWriter w;
  w.add_f32("x", {4}, {1, 2, 3, 4});
  std::string good = w.serialize();

  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "missing.safetensors"); }).find("no such file"), std::string::npos);

  write_raw(dir / "trunc.safetensors", good.substr(0, good.size() - 3));
  std::string e = error_of([&] { SafetensorsFile f(dir / "trunc.safetensors"); });
  EXPECT_NE(e.find("trunc.safetensors"), std::string::npos) << e;
  EXPECT_NE(e.find("'x'"), std::string::npos) << e;

  write_raw(dir / "short.safetensors", "abc");
  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "short.safetensors"); }).find("truncated"), std::string::npos);

  std::string bad_json = good;
  bad_json[9] = '!';
  write_raw(dir / "json.safetensors", bad_json);
  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "json.safetensors"); }).find("not valid JSON"), std::string::npos);

  auto with_header = [&](const std::string& h, size_t data_bytes) {
    std::string out(8, '\0');
    uint64_t n = h.size();
    std::memcpy(out.data(), &n, 8);
    return out + h + std::string(data_bytes, '\0');
  };
  write_raw(dir / "dtype.safetensors", with_header(R"({"x":{"dtype":"F13","shape":[1],"data_offsets":[0,4]}})", 4));
  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "dtype.safetensors"); }).find("unsupported dtype"), std::string::npos);
  write_raw(dir / "size.safetensors", with_header(R"({"x":{"dtype":"F32","shape":[2],"data_offsets":[0,4]}})", 4));
  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "size.safetensors"); }).find("needs 8"), std::string::npos);
  write_raw(dir / "overlap.safetensors",
            with_header(R"({"x":{"dtype":"F32","shape":[1],"data_offsets":[0,4]},"y":{"dtype":"F32","shape":[1],"data_offsets":[2,6]}})", 8));
  EXPECT_NE(error_of([&] { SafetensorsFile f(dir / "overlap.safetensors"); }).find("overlaps"), std::string::npos);

  w.write(dir / "ok.safetensors");
  SafetensorsFile ok(dir / "ok.safetensors");
  EXPECT_NE(error_of([&] { ok.get("nope"); }).find("no tensor named 'nope'"), std::string::npos);
}

TEST(Npy, RoundTripAndTokenArrays) {
  test::TempDir dir;
  std::vector<int16_t> tokens(5 * 8 * 16);
  for (size_t i = 0; i < tokens.size(); ++i) tokens[i] = static_cast<int16_t>(i % 1024);
  npy_write(dir / "tokens.npy", npy_make(DType::I16, {5, 8, 16}, tokens));
  NpyArray a = npy_read(dir / "tokens.npy");
  EXPECT_EQ(a.dtype, DType::I16);
  EXPECT_EQ(a.shape, (std::vector<int64_t>{5, 8, 16}));
  auto v = a.to_int64();
  for (size_t i = 0; i < tokens.size(); ++i) ASSERT_EQ(v[i], tokens[i]);
  // header padded so the data starts 64-byte aligned, as numpy writes it
  EXPECT_EQ(read_file(dir / "tokens.npy").size() % 64, (tokens.size() * 2) % 64);

  for (DType t : {DType::I32, DType::I64, DType::U8, DType::F32, DType::F64}) {
    std::vector<uint8_t> raw(3 * dtype_size(t), 1);
    NpyArray b = npy_make(t, {3}, raw);
    npy_write(dir / "b.npy", b);
    NpyArray c = npy_read(dir / "b.npy");
    EXPECT_EQ(c.dtype, t);
    EXPECT_EQ(c.shape, (std::vector<int64_t>{3}));
    EXPECT_EQ(c.bytes, b.bytes);
  }
}

TEST(Npy, CorruptFilesFailWithClearErrors) {
  test::TempDir dir;
  npy_write(dir / "a.npy", npy_make(DType::F32, {4}, std::vector<float>{1, 2, 3, 4}));
  std::string good = read_file(dir / "a.npy");
  write_raw(dir / "trunc.npy", good.substr(0, good.size() - 2));
  std::string e = error_of([&] { npy_read(dir / "trunc.npy"); });
  EXPECT_NE(e.find("trunc.npy"), std::string::npos);
  EXPECT_NE(e.find("truncated"), std::string::npos);
  write_raw(dir / "magic.npy", "PK\x03\x04 not numpy");
  EXPECT_NE(error_of([&] { npy_read(dir / "magic.npy"); }).find("bad magic"), std::string::npos);
  std::string fortran = good;
  auto pos = fortran.find("False");
  fortran.replace(pos, 5, "True ");
  write_raw(dir / "f.npy", fortran);
  EXPECT_NE(error_of([&] { npy_read(dir / "f.npy"); }).find("Fortran"), std::string::npos);
  std::string cplx = good;
  cplx.replace(cplx.find("<f4"), 3, "<c8");
  write_raw(dir / "c.npy", cplx);
  EXPECT_NE(error_of([&] { npy_read(dir / "c.npy"); }).find("unsupported .npy dtype"), std::string::npos);
}

TEST(JsonFile, ParsesOrNamesTheFile) {
  test::TempDir dir;
  write_raw(dir / "ok.json", "{\"step\": 7, \"ids\": [\"a\", \"b\"]}");
  const auto j = read_json(dir / "ok.json");
  EXPECT_EQ(j.at("step").get<int>(), 7);
  EXPECT_EQ(j.at("ids").size(), 2u);
  write_raw(dir / "torn.json", "{\"step\": 7, \"ids\": [\"a\"");
  const std::string e = error_of([&] { read_json(dir / "torn.json"); });
  EXPECT_EQ(e.rfind((dir / "torn.json").string() + ": invalid JSON (", 0), 0u) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos) << "one line";
  EXPECT_NE(error_of([&] { read_json(dir / "missing.json"); }).find("missing.json: cannot open file"), std::string::npos);
}

// Cross-checks against a peer: files written by numpy and by torch (tools/make_format_fixtures.py).
TEST(PeerFixtures, NumpyArraysReadExactly) {
  fs::path fx = test::source_dir() / "tests" / "fixtures";
  NpyArray t = npy_read(fx / "tokens_6x8x16_int16.npy");
  EXPECT_EQ(t.dtype, DType::I16);
  EXPECT_EQ(t.shape, (std::vector<int64_t>{6, 8, 16}));
  auto v = t.to_int64();
  for (int64_t i = 0; i < 6 * 8 * 16; ++i) ASSERT_EQ(v[static_cast<size_t>(i)], (i * 7 + 3) % 1024);
  NpyArray f = npy_read(fx / "ramp_f32.npy");
  EXPECT_EQ(f.shape, (std::vector<int64_t>{2, 5}));
  for (int i = 0; i < 10; ++i) EXPECT_EQ(f.as<float>()[i], i / 4.0f - 1);
  NpyArray u = npy_read(fx / "ramp_u8.npy");
  EXPECT_EQ(u.shape, (std::vector<int64_t>{17}));
  EXPECT_EQ(u.as<uint8_t>()[16], 16);
  // Our writer produces the same bytes numpy does for the same array.
  test::TempDir dir;
  npy_write(dir / "again.npy", t);
  EXPECT_EQ(read_file(dir / "again.npy"), read_file(fx / "tokens_6x8x16_int16.npy"));
}

TEST(PeerFixtures, TorchSafetensorsReadExactly) {
  SafetensorsFile f(test::source_dir() / "tests" / "fixtures" / "peer.safetensors");
  EXPECT_EQ(f.metadata().at("format"), "pt");
  auto w = f.to_float("encoder.weight");
  ASSERT_EQ(w.size(), 12u);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(w[static_cast<size_t>(i)], i / 8.0f - 0.5f);
  auto h = f.to_float("encoder.half");
  for (int i = 0; i < 6; ++i) EXPECT_EQ(h[static_cast<size_t>(i)], half_to_float(float_to_half(i / 3.0f)));
  auto b = f.to_float("encoder.bf16");
  for (int i = 0; i < 6; ++i) EXPECT_EQ(b[static_cast<size_t>(i)], i - 2.5f);
  const auto& c = f.get("codes");
  EXPECT_EQ(c.dtype, DType::I64);
  EXPECT_EQ(reinterpret_cast<const int64_t*>(c.data)[4], 4000);
}

TEST(Safetensors, ConvertToHalfKeepsNamesMetadataAndOtherDtypes) {
  test::TempDir d;
  SafetensorsWriter w;
  std::vector<float> f{0.1f, -2.5f, 1000.0f, 3.14159f};
  std::vector<int64_t> i{1, -2, 3};
  w.add_f32("w", {2, 2}, f);
  w.add("ids", DType::I64, {3}, i.data(), i.size() * sizeof(int64_t));
  w.set_metadata("gaia.component", "probe");
  w.write(d / "a.safetensors");
  const double err = convert_to_half(d / "a.safetensors", d / "a.safetensors");  // in place
  SafetensorsFile r(d / "a.safetensors");
  EXPECT_EQ(r.get("w").dtype, DType::F16);
  EXPECT_EQ(r.get("ids").dtype, DType::I64);
  EXPECT_EQ(r.metadata().at("gaia.component"), "probe");
  auto back = r.to_float("w");
  for (size_t k = 0; k < f.size(); ++k) EXPECT_NEAR(back[k], f[k], std::abs(f[k]) * 1e-3);
  EXPECT_GT(err, 0.0);
  EXPECT_LT(err, 0.5);  // 1000 rounds to a multiple of 0.5 in half precision
  // A NaN is an error that names the tensor, and the input stays as it was.
  SafetensorsWriter bad;
  bad.add_f32("nan_here", {1}, {std::nanf("")});
  bad.write(d / "b.safetensors");
  EXPECT_NE(test::error_of([&] { convert_to_half(d / "b.safetensors", d / "b.safetensors"); }).find("nan_here"),
            std::string::npos);
  EXPECT_EQ(SafetensorsFile(d / "b.safetensors").get("nan_here").dtype, DType::F32);
}

// WiSE-FT interpolation: every float tensor on the straight line between the two files (F16 read back to float),
// other dtypes and the metadata from the fine-tuned file; mismatched tensor sets or shapes name the tensor, and the
// output is not written.
TEST(Safetensors, InterpolationLiesOnTheLineBetweenTwoTrainings) {
  test::TempDir d;
  SafetensorsWriter a, b;
  std::vector<int64_t> i{7, 8};
  a.add_f32("w", {2, 2}, {0, 1, -2, 4});
  b.add_f32("w", {2, 2}, {2, 1, 2, -4});
  std::vector<uint16_t> ha{float_to_half(1.0f)}, hb{float_to_half(3.0f)};
  a.add("h", DType::F16, {1}, ha.data(), 2);
  b.add("h", DType::F16, {1}, hb.data(), 2);
  a.add("ids", DType::I64, {2}, i.data(), 16);
  b.add("ids", DType::I64, {2}, i.data(), 16);
  a.set_metadata("gaia.component", "before");
  b.set_metadata("gaia.component", "after");
  a.write(d / "a.safetensors");
  b.write(d / "b.safetensors");
  interpolate_weights(d / "a.safetensors", d / "b.safetensors", 0.25, d / "m.safetensors");
  SafetensorsFile m(d / "m.safetensors");
  EXPECT_EQ(m.to_float("w"), (std::vector<float>{0.5f, 1, -1, 2}));
  EXPECT_EQ(m.to_float("h"), (std::vector<float>{1.5f}));
  EXPECT_EQ(m.get("ids").dtype, DType::I64);
  EXPECT_EQ(m.metadata().at("gaia.component"), "after");
  interpolate_weights(d / "a.safetensors", d / "b.safetensors", 0, d / "zero.safetensors");
  EXPECT_EQ(SafetensorsFile(d / "zero.safetensors").to_float("w"), (std::vector<float>{0, 1, -2, 4}));
  SafetensorsWriter c;
  c.add_f32("w", {4}, {0, 1, 2, 3});
  c.write(d / "c.safetensors");
  EXPECT_NE(error_of([&] { interpolate_weights(d / "c.safetensors", d / "b.safetensors", 0.5, d / "x.safetensors"); })
                .find("'h'"),
            std::string::npos);
  c.add_f32("h", {1}, {0});
  c.add("ids", DType::I64, {2}, i.data(), 16);
  c.write(d / "c.safetensors");
  EXPECT_NE(error_of([&] { interpolate_weights(d / "c.safetensors", d / "b.safetensors", 0.5, d / "x.safetensors"); })
                .find("tensor 'w' has another shape"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(d / "x.safetensors"));
}
