// The gaia binary: help, exit codes, and one clear error line for each kind of bad input.
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "gaia/config.h"
#include "gaia/core/safetensors.h"
#include "test_util.h"

#include <algorithm>
#include <cstring>
#include <sstream>

using namespace gaia;

namespace {

fs::path plain_video(const fs::path& dir, int n) {
  fs::path p = dir / "drive.avi";
  cv::VideoWriter vw(p.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 25, cv::Size(128, 72));
  for (int i = 0; i < n; ++i) {
    cv::Mat f(72, 128, CV_8UC3, cv::Scalar(i * 2, 100, 50));
    vw.write(f);
  }
  return p;
}
}  // namespace

// The subcommands a help page lists under "Subcommands:", one per line: "  name   description".
static std::vector<std::string> subcommands_in(const std::string& help) {
  std::vector<std::string> out;
  std::istringstream in(help);
  bool inside = false;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("Subcommands:", 0) == 0) inside = true;
    else if (inside && line.rfind("  ", 0) == 0 && line.size() > 2 && line[2] != ' ')
      out.push_back(line.substr(2, line.find(' ', 2) - 2));
    else if (inside && !line.empty()) inside = false;
  }
  return out;
}

// Every subcommand that `gaia --help` lists, and theirs in turn, prints its help with exit 0: the list comes from the
// binary itself, so a new subcommand is covered the day it is registered.
TEST(Cli, HelpForEverySubcommand) {
  std::vector<std::string> todo{""}, seen;
  while (!todo.empty()) {
    const std::string sub = todo.back();
    todo.pop_back();
    auto r = test::run_gaia(sub + " --help");
    EXPECT_EQ(r.status, 0) << sub << r.output;
    EXPECT_NE(r.output.find("Usage"), std::string::npos) << sub;
    seen.push_back(sub);
    for (const auto& child : subcommands_in(r.output)) todo.push_back(sub.empty() ? child : sub + " " + child);
  }
  // A floor, so that a parser that finds nothing cannot pass: the commands the README documents are all there.
  for (const char* sub : {"demo", "plan", "data stats", "synth counterfactuals", "tokenizer pca", "tokenize",
                          "world calibrate", "generate", "decoder eval", "decode", "probe eval", "convert", "eval",
                          "train-all", "report"})
    EXPECT_NE(std::find(seen.begin(), seen.end(), sub), seen.end()) << sub;
  auto r = test::run_gaia("ingest --help");
  for (auto flag : {"--config", "--set", "--device", "--threads", "--seed", "--out", "--signals", "--meta"})
    EXPECT_NE(r.output.find(flag), std::string::npos) << flag;
}

// One flag per component's weights, with one help text, wherever a command takes them; old spellings stay hidden.
TEST(Cli, WeightsFlagsShareOneSpelling) {
  for (const char* sub : {"generate", "eval", "decode", "decoder eval", "tokenizer eval", "world eval", "probe eval"}) {
    auto r = test::run_gaia(std::string(sub) + " --help");
    ASSERT_EQ(r.status, 0) << sub;
    for (const char* hidden : {"--tokens ", "--dataset ", "OLD_DATASET", "--batch "})
      EXPECT_EQ(r.output.find(hidden), std::string::npos) << sub << ": " << hidden;
  }
  auto r = test::run_gaia("generate --help");
  EXPECT_NE(r.output.find("world model weights (world.safetensors)"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("tokenizer weights (tokenizer.safetensors): decodes a preview"), std::string::npos) << r.output;
  r = test::run_gaia("probe eval --help");
  EXPECT_NE(r.output.find("--probe"), std::string::npos) << r.output;
}

TEST(Cli, BadFlagsAndConfigsExitNonZero) {
  test::TempDir dir;
  EXPECT_NE(test::run_gaia("plan --frobnicate").status, 0);
  EXPECT_NE(test::run_gaia("no-such-command").status, 0);
  test::expect_one_error_line(test::run_gaia("plan '" + (dir / "missing.yaml").string() + "'"), "missing.yaml");
  write_file_atomic(dir / "typo.yaml", "data:\n  hieght: 72\n");
  test::expect_one_error_line(test::run_gaia("plan '" + (dir / "typo.yaml").string() + "'"), "data.hieght");
  test::expect_one_error_line(test::run_gaia("plan --set world.d_modle=3"), "world.d_modle");
  test::expect_one_error_line(test::run_gaia("plan --set data.height=nan"), "data.height");
  test::expect_one_error_line(test::run_gaia("plan --device tpu"), "--device");
  // --precision only where the work honours it: elsewhere asking for bf16 is refused, not run in float32.
  for (const char* sub : {"data info d", "tokenizer eval d --tokenizer t",
                          "world calibrate d --world w", "synth --out o", "report r"})
    test::expect_one_error_line(test::run_gaia(std::string(sub) + " --precision bf16"), "--precision");
  for (const char* sub : {"generate", "eval", "world eval", "world train", "decode", "sim", "demo", "train-all"})
    EXPECT_NE(test::run_gaia(std::string(sub) + " --help").output.find("--precision"), std::string::npos) << sub;
}

TEST(Cli, IngestErrorsLeaveNoOutput) {
  test::TempDir dir;
  fs::path ds = dir / "ds";
  test::expect_one_error_line(test::run_gaia("ingest '" + (dir / "none.mp4").string() + "' --out '" + ds.string() + "'"), "none.mp4");
  write_file_atomic(dir / "empty.mp4", "");
  test::expect_one_error_line(test::run_gaia("ingest '" + (dir / "empty.mp4").string() + "' --out '" + ds.string() + "'"), "empty.mp4");
  fs::path video = plain_video(dir.path, 12);
  write_file_atomic(dir / "bad.csv", "time_s,speed,curvature\n0,1,0\n0.2,inf,0\n");
  test::expect_one_error_line(test::run_gaia("ingest '" + video.string() + "' --signals '" + (dir / "bad.csv").string() +
                                       "' --out '" + ds.string() + "'"),
                        "bad.csv:3");
  write_file_atomic(dir / "cols.csv", "t,v\n0,1\n");
  test::expect_one_error_line(test::run_gaia("ingest '" + video.string() + "' --signals '" + (dir / "cols.csv").string() +
                                       "' --out '" + ds.string() + "'"),
                        "cols.csv:1");
  // Nothing half-written: no episode directories, no temporary leftovers.
  if (fs::exists(ds / "episodes")) {
    EXPECT_TRUE(fs::is_empty(ds / "episodes"));
  }
  // A good run works and a second one refuses to overwrite.
  auto ok = test::run_gaia("ingest '" + video.string() + "' --meta weather=rain --out '" + ds.string() + "'");
  EXPECT_EQ(ok.status, 0) << ok.output;
  EXPECT_TRUE(fs::exists(ds / "episodes" / "drive" / "episode.json"));
  test::expect_one_error_line(test::run_gaia("ingest '" + video.string() + "' --out '" + ds.string() + "'"), "already exists");
}

TEST(Cli, DataStatsAndSplit) {
  test::TempDir dir;
  fs::path video = plain_video(dir.path, 60);
  fs::path ds = dir / "ds";
  write_file_atomic(dir / "s.csv", "time_s,speed,curvature\n0,3,0.01\n3,15,-0.01\n");
  for (auto [id, weather, lat] : {std::tuple{"a", "rain", "51.50"}, {"b", "clear", "51.60"}, {"c", "clear", "51.70"}}) {
    auto r = test::run_gaia("ingest '" + video.string() + "' --id " + id + " --signals '" + (dir / "s.csv").string() +
                            "' --meta weather=" + weather + " --meta latitude=" + lat + " --meta longitude=-0.1 --out '" +
                            ds.string() + "' --codec raw");
    ASSERT_EQ(r.status, 0) << r.output;
  }
  auto st = test::run_gaia("data stats '" + ds.string() + "' --balance weather,speed --set world.context_steps=4");
  EXPECT_EQ(st.status, 0) << st.output;
  EXPECT_NE(st.output.find("empirical"), std::string::npos);
  std::string svg = read_file(ds / "balance.svg");
  EXPECT_NE(svg.find("<svg"), std::string::npos);
  EXPECT_NE(svg.find("weather"), std::string::npos);

  auto sp = test::run_gaia("data split '" + ds.string() + "' --geofence 51.55,-0.2,51.65,0.0");
  EXPECT_EQ(sp.status, 0) << sp.output;
  std::string split = read_file(ds / "split.json");
  EXPECT_NE(split.find("\"val_geofence\": [\n    \"b\"\n  ]"), std::string::npos) << split;

  auto info = test::run_gaia("data info '" + ds.string() + "'");
  EXPECT_EQ(info.status, 0) << info.output;
  EXPECT_NE(info.output.find("3 episodes"), std::string::npos) << info.output;
}

TEST(Cli, ConvertToHalf) {
  test::TempDir d;
  auto src = test::source_dir() / "tests" / "fixtures" / "peer.safetensors";
  auto r = test::run_gaia("convert '" + src.string() + "' --out '" + (d / "x.safetensors").string() + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("say --half, --set KEY=VALUE, --interpolate-from FROM, --terms TEXT or a combination"),
            std::string::npos) << r.output;
  r = test::run_gaia("convert '" + src.string() + "' --half --out '" + (d / "half.safetensors").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  // The output path is used exactly as given (a CLI11 required-flag bug once corrupted it).
  EXPECT_TRUE(fs::exists(d / "half.safetensors")) << r.output;
  EXPECT_LT(fs::file_size(d / "half.safetensors"), fs::file_size(src));
  // Interpolated halfway between the file and its own half copy, and stored in half again: within half rounding.
  r = test::run_gaia("convert '" + src.string() + "' --interpolate-from '" + (d / "half.safetensors").string() +
                     "' --alpha 0.5 --half --out '" + (d / "mix.safetensors").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile f32(src), mix(d / "mix.safetensors");
  for (const auto& n : f32.names()) {
    if (f32.get(n).dtype != DType::F32) continue;
    EXPECT_EQ(mix.get(n).dtype, DType::F16) << n;
    const auto a = f32.to_float(n), m = mix.to_float(n);
    for (size_t k = 0; k < a.size(); ++k) ASSERT_NEAR(m[k], a[k], 2e-3 * std::abs(a[k]) + 1e-4) << n;
  }
  r = test::run_gaia("convert '" + src.string() + "' --interpolate-from '" + (d / "half.safetensors").string() +
                     "' --alpha 1.5 --out '" + (d / "bad.safetensors").string() + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--alpha must be in [0, 1]"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "bad.safetensors"));
  // --terms: the training data's terms travel in the file's metadata, the tensors untouched.
  r = test::run_gaia("convert '" + (d / "half.safetensors").string() + "' --terms 'research use only' --out '" +
                     (d / "terms.safetensors").string() + "'");
  ASSERT_EQ(r.status, 0) << r.output;
  {
    SafetensorsFile half(d / "half.safetensors"), t(d / "terms.safetensors");
    EXPECT_EQ(t.metadata().at("gaia.terms"), "research use only");
    for (const auto& n : half.names()) {
      const auto a = half.get(n), b = t.get(n);
      ASSERT_EQ(a.dtype, b.dtype) << n;
      ASSERT_EQ(a.nbytes, b.nbytes) << n;
      EXPECT_EQ(std::memcmp(a.data, b.data, a.nbytes), 0) << n;
    }
  }
  // --alpha alone would be ignored: refused.
  r = test::run_gaia("convert '" + src.string() + "' --half --alpha 0.5 --out '" + (d / "bad.safetensors").string() + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--alpha needs --interpolate-from"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "bad.safetensors"));
}

// convert --set changes one sampling setting in the stored config and nothing else: the tensors are the same bytes,
// the other keys the same values, and keys the file was saved without stay absent. Anything but a sampling key, a
// bad value or a file without gaia metadata is one error line and no output.
TEST(Cli, ConvertSetsAStoredSamplingSetting) {
  test::TempDir d;
  Config c = test::config("tiny.yaml");
  std::string yaml = c.to_yaml();
  const auto cut = yaml.find("  start_time:");  // as if saved before decoder.start_time existed
  ASSERT_NE(cut, std::string::npos);
  yaml.erase(cut, yaml.find('\n', cut) + 1 - cut);
  SafetensorsWriter w;
  w.add_f32("w", {2, 3}, {1, 2, 3, 4, 5, 6.5f});
  w.set_metadata("gaia.component", "world");
  w.set_metadata("gaia.config", yaml);
  w.write(d / "world.safetensors");
  auto r = test::run_gaia("convert " + (d / "world.safetensors").string() +
                          " --set world.temperature=0.7 --set decoder.noise_scale=0.25 --out " + (d / "t.safetensors").string());
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile f(d / "t.safetensors");
  EXPECT_EQ(f.metadata().at("gaia.component"), "world");
  EXPECT_EQ(f.to_float("w"), (std::vector<float>{1, 2, 3, 4, 5, 6.5f}));
  EXPECT_EQ(f.get("w").dtype, DType::F32);
  const std::string stored = f.metadata().at("gaia.config");
  EXPECT_EQ(stored.find("start_time"), std::string::npos) << stored;
  Config back;
  back.apply_yaml(stored, "t.safetensors");
  EXPECT_EQ(back.world.temperature, 0.7);
  EXPECT_EQ(back.decoder.noise_scale, 0.25);
  back.world.temperature = c.world.temperature;
  back.decoder.noise_scale = c.decoder.noise_scale;
  EXPECT_EQ(back.to_yaml(), c.to_yaml());

  const auto bad = d / "bad.safetensors";
  test::expect_one_error_line(test::run_gaia("convert " + (d / "world.safetensors").string() + " --set world.d_model=64 --out " +
                                       bad.string()),
                        "--set world.d_model=64: only sampling settings");
  test::expect_one_error_line(test::run_gaia("convert " + (d / "world.safetensors").string() +
                                       " --set world.temperature=0 --out " + bad.string()),
                        "'world.temperature' = 0 is out of range: allowed (0, 100]");
  test::expect_one_error_line(test::run_gaia("convert " + (d / "world.safetensors").string() +
                                       " --set world.top_k=many --out " + bad.string()),
                        "world.top_k");
  auto peer = test::source_dir() / "tests" / "fixtures" / "peer.safetensors";
  test::expect_one_error_line(test::run_gaia("convert " + peer.string() + " --set world.temperature=0.9 --out " + bad.string()),
                        "no gaia.config metadata");
  EXPECT_FALSE(fs::exists(bad));
}

// The `gaia` launcher runs gaia-core with OMP_WAIT_POLICY=PASSIVE, which libgomp takes as it loads; a value the user
// sets wins; without gaia-core beside it, one error line and exit 127.
TEST(LauncherCli, RunsTheCoreWithPassiveOpenMpUnlessTheUserSaysOtherwise) {
  auto r = test::run_shell("env -u OMP_WAIT_POLICY OMP_DISPLAY_ENV=TRUE " + test::gaia_command("--version") + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("OMP_WAIT_POLICY = 'PASSIVE'"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("gaia 0."), std::string::npos) << r.output;
  r = test::run_shell("OMP_WAIT_POLICY=ACTIVE OMP_DISPLAY_ENV=TRUE " + test::gaia_command("--version") + " 2>&1");
  EXPECT_NE(r.output.find("OMP_WAIT_POLICY = 'ACTIVE'"), std::string::npos) << r.output;
  test::TempDir d;
  fs::copy_file(GAIA_BINARY, d / "gaia");
  fs::permissions(d / "gaia", fs::perms::owner_exec, fs::perm_options::add);
  r = test::run_shell(test::q(d / "gaia") + " --version 2>&1");
  EXPECT_EQ(r.status, 127) << r.output;
  EXPECT_EQ(r.output, "gaia: error: cannot run " + (d / "gaia-core").string() + ": No such file or directory\n");
}
