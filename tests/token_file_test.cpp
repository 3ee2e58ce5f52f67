// Token files of other tokenizers (world/token_file.h): dtypes, 2-D arrays with a stated grid, K, frame rates,
// safetensors, a single file split in time and a directory of files as episodes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "gaia/core/fs.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/data/geofence.h"
#include "gaia/world/token_dataset.h"
#include "gaia/world/token_file.h"
#include "test_util.h"

using namespace gaia;
using gaia::world::TokenArray;
using gaia::world::TokenDataset;
using gaia::world::TokenFormat;

namespace {

// commaVQ's layout: [frames, 128] for an 8x16 grid, K = 1024, 20 fps. Token (f, j) = (f * 7 + j) % 1024, so each
// kept frame can be checked.
int64_t comma_id(int64_t f, int64_t j) { return (f * 7 + j) % 1024; }

fs::path write_comma(const fs::path& p, int64_t frames, DType t = DType::I64) {
  std::vector<int64_t> v;
  for (int64_t f = 0; f < frames; ++f)
    for (int64_t j = 0; j < 128; ++j) v.push_back(comma_id(f, j));
  if (t == DType::I64) {
    npy_write(p, npy_make(t, {frames, 128}, v));
  } else {  // int16, as commaVQ's README says
    std::vector<int16_t> s(v.begin(), v.end());
    npy_write(p, npy_make(t, {frames, 128}, s));
  }
  return p;
}

TokenFormat comma_format() {
  TokenFormat f;
  f.set_grid("8x16");
  f.codebook_size = 1024;
  f.rate_hz = 20;
  return f;
}

}  // namespace

TEST(TokenFile, CommaVqLayoutIsSubsampledTo6p25Hz) {
  test::TempDir dir;
  for (DType t : {DType::I64, DType::I16}) {
    const auto p = write_comma(dir / "drive.npy", 1200, t);  // one minute at 20 fps
    TokenArray a = world::read_token_file(p, comma_format());
    EXPECT_EQ(a.h, 8);
    EXPECT_EQ(a.w, 16);
    // 20 / 6.25 = 3.2 frames a step: frames 0, 3, 6, 10, 13, ... (rounded), the last below 1200.
    EXPECT_EQ(a.steps, 375);
    ASSERT_EQ(a.ids.size(), size_t(375 * 128));
    for (int64_t k : {0, 1, 2, 3, 374}) {
      const int64_t f = std::llround(double(k) * 3.2);
      EXPECT_EQ(a.ids[size_t(k * 128 + 5)], comma_id(f, 5)) << "step " << k;
    }
  }
}

TEST(TokenFile, StatedRatesAndGrids) {
  test::TempDir dir;
  const auto p = write_comma(dir / "d.npy", 40);
  TokenFormat f = comma_format();
  f.keep_rate = true;  // the file's own rate: every frame
  EXPECT_EQ(world::read_token_file(p, f).steps, 40);
  EXPECT_DOUBLE_EQ(f.dataset_rate_hz(), 20);
  f.keep_rate = false;
  f.rate_hz = 0;  // unstated: already at the world model's rate
  EXPECT_EQ(world::read_token_file(p, f).steps, 40);
  f.rate_hz = 5;  // slower than 6.25 Hz: no way to subsample up
  auto err = test::error_of([&] { world::read_token_file(p, f); });
  EXPECT_NE(err.find("--keep-rate"), std::string::npos) << err;
  EXPECT_NE(err.find("d.npy"), std::string::npos) << err;

  TokenFormat none;  // a 2-D array needs its grid
  err = test::error_of([&] { world::read_token_file(p, none); });
  EXPECT_NE(err.find("--grid"), std::string::npos) << err;
  TokenFormat wrong;
  wrong.set_grid("8x8");
  err = test::error_of([&] { world::read_token_file(p, wrong); });
  EXPECT_NE(err.find("128 tokens a frame"), std::string::npos) << err;
  for (const char* bad : {"8", "8x", "x16", "0x16", "8x16x2", "8 x16", "-8x16", "axb"})
    EXPECT_NE(test::error_of([&] { TokenFormat t; t.set_grid(bad); }).find("HxW"), std::string::npos) << bad;

  // A 3-D array carries its grid; a stated one must agree.
  npy_write(dir / "g.npy", npy_make(DType::I32, {3, 2, 4}, std::vector<int32_t>(24, 1)));
  TokenFormat g;
  EXPECT_EQ(world::read_token_file(dir / "g.npy", g).w, 4);
  g.set_grid("4x2");
  EXPECT_NE(test::error_of([&] { world::read_token_file(dir / "g.npy", g); }).find("2x4 token grid"), std::string::npos);
}

TEST(TokenFile, IdsOutsideTheCodebookNameTheFirstBadIndex) {
  test::TempDir dir;
  std::vector<int64_t> v(6 * 128, 3);
  v[2 * 128 + 17] = 1024;  // = K
  v[4 * 128 + 1] = 5000;
  npy_write(dir / "bad.npy", npy_make(DType::I64, {6, 128}, v));
  TokenFormat f = comma_format();
  f.rate_hz = 0;
  auto err = test::error_of([&] { world::read_token_file(dir / "bad.npy", f); });
  EXPECT_NE(err.find("bad.npy"), std::string::npos) << err;
  EXPECT_NE(err.find("token 1024 at frame 2, position 17 (flat index 273)"), std::string::npos) << err;
  EXPECT_NE(err.find("[0, 1024)"), std::string::npos) << err;
  v[2 * 128 + 17] = -1;
  npy_write(dir / "neg.npy", npy_make(DType::I64, {6, 128}, v));
  err = test::error_of([&] { world::read_token_file(dir / "neg.npy", f); });
  EXPECT_NE(err.find("token -1 at frame 2"), std::string::npos) << err;
  // Floats are not token ids.
  npy_write(dir / "f.npy", npy_make(DType::F32, {2, 128}, std::vector<float>(256, 1.0f)));
  EXPECT_NE(test::error_of([&] { world::read_token_file(dir / "f.npy", f); }).find("must be integers"),
            std::string::npos);
}

TEST(TokenFile, EveryIntegerDtypeAndSafetensorsReadAlike) {
  test::TempDir dir;
  std::vector<uint16_t> u;
  for (int i = 0; i < 4 * 6; ++i) u.push_back(uint16_t(1000 + i));
  npy_write(dir / "u16.npy", npy_make(DType::U16, {4, 2, 3}, u));
  std::vector<uint32_t> u32(u.begin(), u.end());
  npy_write(dir / "u32.npy", npy_make(DType::U32, {4, 2, 3}, u32));
  std::vector<int32_t> i32(u.begin(), u.end());
  SafetensorsWriter w;
  w.add("tokens", DType::I32, {4, 6}, i32.data(), i32.size() * 4);
  w.add_f32("scale", {1}, {1.0f});  // other tensors beside "tokens" are ignored
  w.write(dir / "st.safetensors");
  TokenFormat f;
  f.codebook_size = 1024;
  const auto a = world::read_token_file(dir / "u16.npy", f);
  EXPECT_EQ(world::read_token_file(dir / "u32.npy", f).ids, a.ids);
  f.set_grid("2x3");
  const auto s = world::read_token_file(dir / "st.safetensors", f);
  EXPECT_EQ(s.ids, a.ids);
  EXPECT_EQ(a.ids.back(), 1023);

  SafetensorsWriter two;
  two.add("a", DType::I32, {4, 6}, i32.data(), i32.size() * 4);
  two.add("b", DType::I32, {4, 6}, i32.data(), i32.size() * 4);
  two.write(dir / "two.safetensors");
  EXPECT_NE(test::error_of([&] { world::read_token_file(dir / "two.safetensors", f); }).find("named 'tokens'"),
            std::string::npos);
}

TEST(TokenFile, OneFileIsADriveWithItsLastTenthHeldOut) {
  test::TempDir dir;
  const auto p = write_comma(dir / "minute.npy", 1200);
  TokenDataset ds(p, comma_format());
  EXPECT_TRUE(ds.bare());
  EXPECT_TRUE(ds.foreign());
  EXPECT_EQ(ds.codebook_size(), 1024);
  EXPECT_EQ(ds.tokens_per_step(), 128);
  EXPECT_DOUBLE_EQ(ds.rate_hz(), 6.25);
  ASSERT_EQ(ds.size(), 2u);
  EXPECT_EQ(ds.steps(0), 337);  // 375 steps, 38 (a tenth, rounded) held out at the end
  EXPECT_EQ(ds.steps(1), 38);
  const auto split = ds.split();
  EXPECT_EQ(split.train, (std::vector<std::string>{"minute"}));
  EXPECT_EQ(split.held_out(), (std::vector<std::string>{"minute.held-out"}));
  // The held-out part continues where training stops: step 337 is frame round(337 * 3.2) = 1078.
  EXPECT_EQ(ds.episode(1)->tokens.front(), comma_id(1078, 0));
  EXPECT_TRUE(ds.windows(ds.indices(split.held_out()), 16, 1).size() > 0);
  TokenFormat all = comma_format();
  all.val_fraction = 0;
  EXPECT_EQ(TokenDataset(p, all).size(), 1u);
}

TEST(TokenFile, ADirectoryOfFilesIsADatasetHeldOutByFile) {
  test::TempDir dir;
  fs::create_directories(dir / "drives");
  for (int i = 0; i < 12; ++i) write_comma(dir / "drives" / fmt::format("d{:02d}.npy", i), 80 + i, DType::I16);
  fs::create_directories(dir / "drives" / "notes");  // ignored, as is anything that is not a token file
  write_file_atomic(dir / "drives" / "README.txt", "tokens\n");
  TokenDataset ds(dir / "drives", comma_format());
  EXPECT_FALSE(ds.bare());
  EXPECT_TRUE(ds.foreign());
  ASSERT_EQ(ds.size(), 12u);
  EXPECT_EQ(ds.ids()[3], "d03");
  EXPECT_EQ(ds.steps(0), 25);  // frames 0, 3.2, ..., 76.8 of 80
  EXPECT_EQ(ds.episode(3)->tokens[128 + 9], comma_id(3, 9));  // step 1 = frame 3
  const auto split = ds.split(0.1, 0);
  EXPECT_GE(split.held_out().size(), 1u);
  EXPECT_EQ(split.train.size() + split.held_out().size(), 12u);

  // One grid, one K for all files.
  npy_write(dir / "drives" / "z.npy", npy_make(DType::I32, {30, 4, 32}, std::vector<int32_t>(30 * 128, 1)));
  auto err = test::error_of([&] { TokenDataset(dir / "drives", comma_format()); });
  EXPECT_NE(err.find("z.npy: a 4x32 token grid"), std::string::npos) << err;
  fs::remove(dir / "drives" / "z.npy");
  TokenFormat small = comma_format();
  small.codebook_size = 512;
  err = test::error_of([&] { TokenDataset(dir / "drives", small); });
  EXPECT_NE(err.find("d00.npy"), std::string::npos) << err;
  EXPECT_NE(err.find("outside [0, 512)"), std::string::npos) << err;
  fs::create_directories(dir / "empty");
  EXPECT_NE(test::error_of([&] { TokenDataset(dir / "empty"); }).find("no .npy or .safetensors"), std::string::npos);
}

// A sidecar X.json gives what the file cannot say: the drive's place (for balancing and the geofenced split) and
// its frame rate; a stated rate that disagrees, an unknown key and a bad value are one error naming the sidecar.
TEST(TokenFile, SidecarsGivePlaceAndRateAndAreChecked) {
  test::TempDir dir;
  fs::create_directories(dir / "drives");
  for (int i = 0; i < 4; ++i) write_comma(dir / "drives" / fmt::format("d{}.npy", i), 80, DType::I16);
  write_file_atomic(dir / "drives" / "d1.json", R"({"latitude": 48.1, "longitude": 11.5, "weather": "rain", "fps": 20})");
  write_file_atomic(dir / "drives" / "d2.json", R"({"latitude": 48.9, "longitude": 8.4, "fps": 10})");
  TokenFormat unstated = comma_format();
  unstated.rate_hz = 0;  // the rate comes from each sidecar (files without one are at the world model's rate)
  TokenDataset ds(dir / "drives", unstated);
  EXPECT_EQ(ds.steps(0), 80);  // no sidecar: already at 6.25 Hz
  EXPECT_EQ(ds.steps(1), 25);  // 20 fps: every 3.2th frame
  EXPECT_EQ(ds.steps(2), 50);  // 10 fps: every 1.6th
  EXPECT_EQ(ds.episode(1)->tokens[128 + 9], comma_id(3, 9));
  EXPECT_EQ(ds.meta(1).weather, "rain");
  EXPECT_DOUBLE_EQ(ds.meta(2).longitude, 8.4);
  EXPECT_TRUE(std::isnan(ds.meta(0).latitude));
  // A geofence around d2's position holds it out; d1 trains.
  auto s = data::geofence_split({ds.meta(0), ds.meta(1), ds.meta(2), ds.meta(3)}, {data::parse_geobox("48.5,8,49.5,9")},
                                0.0, 0, {"d3"});
  EXPECT_EQ(s.val_geofence, std::vector<std::string>{"d2"});
  EXPECT_EQ(s.val_named, std::vector<std::string>{"d3"});
  EXPECT_EQ(s.train, (std::vector<std::string>{"d0", "d1"}));

  // --token-fps 20 agrees with d1 but not with d2.
  auto err = test::error_of([&] { TokenDataset(dir / "drives", comma_format()); });
  EXPECT_NE(err.find("d2.npy: --token-fps 20 does not match the 10 fps its sidecar d2.json states"), std::string::npos) << err;
  // --keep-rate trains at one rate: files of 20 and 10 fps cannot share it.
  TokenFormat keep = unstated;
  keep.keep_rate = true;
  err = test::error_of([&] { TokenDataset(dir / "drives", keep); });
  EXPECT_NE(err.find("d0.npy: --keep-rate needs each file's own frame rate"), std::string::npos) << err;  // no sidecar
  write_file_atomic(dir / "drives" / "d0.json", R"({"fps": 20})");
  write_file_atomic(dir / "drives" / "d3.json", R"({"fps": 20})");
  err = test::error_of([&] { TokenDataset(dir / "drives", keep); });
  EXPECT_NE(err.find("d2.npy: 10 fps, but"), std::string::npos) << err;
  EXPECT_NE(err.find("--keep-rate trains at one rate"), std::string::npos) << err;
  write_file_atomic(dir / "drives" / "d2.json", R"({"latitude": 48.9, "longitude": 8.4, "speed": 3})");
  err = test::error_of([&] { TokenDataset(dir / "drives", unstated); });
  EXPECT_NE(err.find("d2.json: unknown key 'speed'"), std::string::npos) << err;
  write_file_atomic(dir / "drives" / "d2.json", R"({"latitude": 148.9, "longitude": 8.4})");
  err = test::error_of([&] { TokenDataset(dir / "drives", unstated); });
  EXPECT_NE(err.find("d2.json: 'latitude' must be a number in [-90, 90]"), std::string::npos) << err;
  write_file_atomic(dir / "drives" / "d2.json", R"({"latitude": 48.9})");
  err = test::error_of([&] { TokenDataset(dir / "drives", unstated); });
  EXPECT_NE(err.find("give latitude and longitude together"), std::string::npos) << err;
  write_file_atomic(dir / "drives" / "d2.json", "[1, 2");
  err = test::error_of([&] { TokenDataset(dir / "drives", unstated); });
  EXPECT_NE(err.find("d2.json"), std::string::npos) << err;
}

// `gaia data split` on a directory of token files: geofenced from the sidecars, --hold-out by stem; world train
// then validates on exactly those files.
TEST(TokenFileCli, DataSplitGeofencesTokenFilesFromTheirSidecars) {
  test::TempDir dir;
  fs::create_directories(dir / "drives");
  for (int i = 0; i < 5; ++i) {
    write_comma(dir / "drives" / fmt::format("d{}.npy", i), 200, DType::I16);
    write_file_atomic(dir / "drives" / fmt::format("d{}.json", i),
                      fmt::format(R"({{"latitude": {}, "longitude": 8.4, "fps": 20}})", 48.0 + 0.5 * i));
  }
  const std::string tiny = " --config " + test::q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("data split " + test::q(dir / "drives") + " --grid 8x16 --geofence 48.9,8,49.6,9 --hold-out d0" + tiny);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto split = data::read_split(dir / "drives" / "split.json");
  EXPECT_EQ(split.val_geofence, (std::vector<std::string>{"d2", "d3"}));
  EXPECT_EQ(split.val_named, std::vector<std::string>{"d0"});
  EXPECT_EQ(split.train, (std::vector<std::string>{"d1", "d4"}));
  r = test::run_gaia("world train " + test::q(dir / "drives") + " --grid 8x16 --codebook-size 1024" + tiny +
                     " --steps 2 --val-every 2 --out " + test::q(dir / "run"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.find("validation skipped"), std::string::npos) << r.output;
  // A name that is no file, and a split that leaves nothing to train on, are one line each; split.json is kept.
  const std::string before = read_file(dir / "drives" / "split.json");
  r = test::run_gaia("data split " + test::q(dir / "drives") + " --grid 8x16 --hold-out d9" + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--hold-out d9"), std::string::npos) << r.output;
  r = test::run_gaia("data split " + test::q(dir / "drives") + " --grid 8x16 --geofence 40,0,50,10" + tiny);
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("leaves no episode to train on"), std::string::npos) << r.output;
  EXPECT_EQ(read_file(dir / "drives" / "split.json"), before);
}

// The validation line's copy bias is fitted on held-out frames, not on the training frames the weights learn: a
// drive whose training part never repeats a frame's code and whose held-out end repeats four codes in five gets a
// large bias and a far lower calibrated score (fitted on its training windows, the bias would stay near 0).
TEST(TokenFileCli, ValidationFitsTheCopyBiasOnHeldOutFrames) {
  test::TempDir dir;
  const int64_t frames = 400;  // at 20 fps, kept: the last 40 frames are the held-out tenth
  std::vector<int64_t> v;
  std::mt19937 rng(5);
  for (int64_t f = 0; f < frames; ++f)
    for (int64_t j = 0; j < 128; ++j)
      v.push_back(f >= 360 && rng() % 5 != 0 ? v[size_t((f - 1) * 128 + j)] : comma_id(f, j));
  npy_write(dir / "drive.npy", npy_make(DType::I64, {frames, 128}, v));
  const std::string tiny = " --config " + test::q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  auto r = test::run_gaia("world train " + test::q(dir / "drive.npy") +
                          " --grid 8x16 --codebook-size 1024 --token-fps 20 --keep-rate" + tiny +
                          " --steps 4 --val-every 4 --out " + test::q(dir / "run"));
  ASSERT_EQ(r.status, 0) << r.output;
  nlohmann::json val;
  std::istringstream in(read_file(dir / "run" / "metrics.jsonl"));
  for (std::string line; std::getline(in, line);)
    if (auto j = nlohmann::json::parse(line); j.contains("val") && !j["val"].is_null()) val = j["val"];
  ASSERT_TRUE(val.contains("copy_bias")) << r.output;
  EXPECT_GT(val["copy_bias"].get<double>(), 2.0) << val.dump();
  EXPECT_LT(val["bits_per_token"].get<double>(), val["bits_per_token_uncalibrated"].get<double>() - 2.0) << val.dump();
  // Without --val-every a set this small is validated every two passes over it (357 training windows of 4 steps,
  // 4 a batch: 44 steps), not every 250 steps, past which it would have overfitted long before.
  r = test::run_gaia("world train " + test::q(dir / "drive.npy") +
                     " --grid 8x16 --codebook-size 1024 --token-fps 20 --keep-rate" + tiny + " --steps 50 --out " +
                     test::q(dir / "auto"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("validating every 44 steps"), std::string::npos) << r.output;
  std::vector<int> validated;
  std::istringstream again(read_file(dir / "auto" / "metrics.jsonl"));
  for (std::string line; std::getline(again, line);)
    if (auto j = nlohmann::json::parse(line); j.contains("val") && !j["val"].is_null()) validated.push_back(j["step"]);
  EXPECT_EQ(validated, (std::vector<int>{44, 50}));
}

TEST(TokenFileCli, CommaVqMinuteTrainsWithValidationAndRefusesSteering) {
  test::TempDir dir;
  const auto file = write_comma(dir / "minute.npy", 400, DType::I16);  // 20 s at 20 fps -> 125 steps at 6.25 Hz
  const std::string tiny = " --config " + test::q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  const std::string fmt = " --grid 8x16 --codebook-size 1024 --token-fps 20";
  auto r = test::run_gaia("world train " + test::q(file) + fmt + tiny + " --steps 4 --val-every 4 --out " +
                          test::q(dir / "run"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("no actions in"), std::string::npos) << r.output;        // said, not silent
  EXPECT_EQ(r.output.find("validation skipped"), std::string::npos) << r.output;  // its held-out end is scored
  EXPECT_NE(r.output.find("bits/token"), std::string::npos) << r.output;
  // Random ids never repeat a frame's: no copy bias to fit, said once, and the run goes on without it.
  EXPECT_NE(r.output.find("copy calibration off: none of the held-out tokens"), std::string::npos) << r.output;
  // The best validation's weights are kept beside the last ones.
  EXPECT_NE(r.output.find("best validation"), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(dir / "run" / "best.safetensors"));
  EXPECT_EQ(nlohmann::json::parse(read_file(dir / "run" / "best.json")).at("step").get<int>(), 4);
  const auto w = " --world " + test::q(dir / "run" / "world.safetensors");
  // The model takes its grid and K from the weights: the flat file needs no --grid now.
  r = test::run_gaia("world eval " + test::q(file) + " --token-fps 20" + w + tiny + " --max-windows 2");
  EXPECT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("generate " + test::q(file) + " --token-fps 20 --episode minute.held-out --frames 2" + w + tiny +
                     " --out " + test::q(dir / "gen"));
  EXPECT_EQ(r.status, 0) << r.output;
  r = test::run_gaia("generate " + test::q(file) + " --token-fps 20 --frames 2 --steer left" + w + tiny + " --out " +
                     test::q(dir / "steer"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("never saw an action"), std::string::npos) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  // A grid that disagrees with the weights, and a rate the world model cannot be subsampled to, are one line each.
  r = test::run_gaia("world eval " + test::q(file) + " --grid 4x32" + w + tiny);
  EXPECT_NE(r.output.find("--grid 4x32: the world model was trained on a 8x16 grid"), std::string::npos) << r.output;
  r = test::run_gaia("world train " + test::q(file) + " --grid 8x16 --codebook-size 1024 --token-fps 4" + tiny + " --steps 1 --out " +
                     test::q(dir / "slow"));
  EXPECT_NE(r.output.find("--keep-rate"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "slow" / "world.safetensors"));
}
