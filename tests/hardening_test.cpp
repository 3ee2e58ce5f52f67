// Reliability: every bad input is one error line and a non-zero exit, a run's output directory belongs to one run,
// and a kill or a full disk never loses a checkpoint or leaves temporaries behind.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include <algorithm>
#include <random>
#include <regex>

#include "gaia/config.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/train/checkpoint.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {

std::string tiny_flags() { return " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1"; }


// A bare token file of the tiny config's grid (4 x 8, K = 256): world training without a tokenizer.
fs::path bare_tokens(const fs::path& dir, int frames = 40, int max_id = 255) {
  std::mt19937 rng(7);
  std::vector<int16_t> v(size_t(frames) * 32);
  for (auto& x : v) x = int16_t(rng() % uint32_t(max_id + 1));
  const fs::path p = dir / "tokens.npy";
  npy_write(p, npy_make(DType::I16, {frames, 4, 8}, v));
  return p;
}

// A pid that no process has: a child that has exited and been reaped.
long dead_pid() {
  const pid_t pid = fork();
  if (pid == 0) _exit(0);
  waitpid(pid, nullptr, 0);
  return pid;
}

int read_json_step(const fs::path& ckpt) { return nlohmann::json::parse(read_file(ckpt / "state.json")).at("step"); }

std::map<std::string, torch::Tensor> weights_of(const fs::path& p) {
  SafetensorsFile f(p);
  std::map<std::string, torch::Tensor> out;
  for (auto& n : f.names()) out[n] = tensor_from_view(f.get(n));
  return out;
}

// Runs `gaia ARGS` under a file-size limit of `kib` KiB (a full disk, as far as the process can tell).
test::RunResult run_gaia_with_file_limit(int kib, const std::string& args) {
  return test::run_shell("bash -c \"ulimit -f " + std::to_string(kib) + "; exec " + test::gaia_command(args) + "\" 2>&1");
}

}  // namespace

// Head counts of 0 used to divide by zero (SIGFPE); each way in now names the key and its range.
TEST(HardeningCli, ZeroHeadsAreRefusedFromEveryWayIn) {
  test::TempDir dir;
  test::expect_one_error_line(test::run_gaia("plan" + tiny_flags() + " --set world.n_heads=0"), "world.n_heads");
  test::expect_one_error_line(test::run_gaia("plan" + tiny_flags() + " --set decoder.heads=0"), "[1, 1024]");
  write_file_atomic(dir / "heads.yaml", "world:\n  n_heads: 0\n");
  test::expect_one_error_line(test::run_gaia("plan " + q(dir / "heads.yaml")), "heads.yaml:2");
  test::expect_one_error_line(test::run_gaia("plan" + tiny_flags() + " --set decoder.res_blocks=1000000000"), "decoder.res_blocks");
  // The ranges are listed for users: one line per key, with the value in this config.
  auto keys = test::run_gaia("plan" + tiny_flags() + " --keys");
  ASSERT_EQ(keys.status, 0) << keys.output;
  EXPECT_TRUE(std::regex_search(keys.output, std::regex("\nworld\\.n_heads +int +architecture +4 +\\[1, 1024\\]\n"))) << keys.output;
  test::expect_one_error_line(test::run_gaia("plan" + tiny_flags() + " --set world.d_model=-48"), "world.d_model");
  test::expect_one_error_line(test::run_gaia("plan" + tiny_flags() + " --set tokenizer.batch_size=-1"), "tokenizer.batch_size");
  const fs::path tokens = bare_tokens(dir.path);
  test::expect_one_error_line(test::run_gaia("world train " + q(tokens) + tiny_flags() + " --set world.n_heads=0 --out " + q(dir / "w")),
                        "world.n_heads");
  EXPECT_FALSE(fs::exists(dir / "w"));

  // A weights file whose stored config says n_heads: 0.
  auto r = test::run_gaia("world train " + q(tokens) + tiny_flags() + " --steps 1 --out " + q(dir / "ok"));
  ASSERT_EQ(r.status, 0) << r.output;
  SafetensorsFile good(dir / "ok" / "world.safetensors");
  SafetensorsWriter bad;
  for (auto& n : good.names()) {
    const auto& v = good.get(n);
    bad.add(n, v.dtype, v.shape, v.data, v.nbytes);
  }
  for (auto& [k, v] : good.metadata()) bad.set_metadata(k, k == "gaia.config" ? std::regex_replace(v, std::regex("n_heads: 4"), "n_heads: 0") : v);
  ASSERT_NE(good.metadata().at("gaia.config").find("n_heads: 4"), std::string::npos);
  bad.write(dir / "bad.safetensors");
  r = test::run_gaia("generate --world " + q(dir / "bad.safetensors") + " --frames 1 --out " + q(dir / "gen"));
  test::expect_one_error_line(r, "bad.safetensors");
  EXPECT_NE(r.output.find("world.n_heads"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "gen"));
}

// Numbers on the command line: NaN, infinities, negatives and values outside a flag's range are one usage line
// (exit 2), and so are flags that exclude each other.
TEST(HardeningCli, CommandLineNumbersAndExclusiveFlags) {
  test::TempDir dir;
  const std::string world = " --world " + q(test::source_dir() / "models" / "world.safetensors");
  const std::string out = " --out " + q(dir / "o");
  for (auto [args, what] : std::vector<std::pair<std::string, std::string>>{
           {"generate" + world + " --temperature 0" + out, "--temperature"},
           {"generate" + world + " --temperature -1" + out, "--temperature"},
           {"generate" + world + " --temperature nan" + out, "--temperature"},
           {"generate" + world + " --top-k 0" + out, "--top-k"},
           {"generate" + world + " --top-k -1" + out, "--top-k"},
           {"generate" + world + " --guidance nan" + out, "--guidance"},
           {"generate" + world + " --guidance -1" + out, "--guidance"},
           {"generate" + world + " --guidance 1e30" + out, "--guidance"},
           {"generate" + world + " --speed inf" + out, "--speed"},
           {"generate" + world + " --speed -1e9" + out, "--speed"},
           {"generate" + world + " --start -1" + out, "--start"},
           {"generate" + world + " --futures 0" + out, "--futures"},
           {"generate" + world + " --threads -3" + out, "--threads"},
           {"world train x.npy --steps 0" + out, "--steps"},
           {"world train x.npy --steps -5" + out, "--steps"},
           {"world train x.npy --val-every -1" + out, "--val-every"},
           {"decode x.npy --tokenizer t --fast --ddim-steps 0" + out, "--ddim-steps"},
           {"decode x.npy --tokenizer t --decoder d --ddim-steps -3" + out, "--ddim-steps"},
           {"generate t" + world + " --video v.mp4" + out, "--video"},
           {"generate" + world + " --tokens t --video v.mp4" + out, "--video"},  // the old spelling too
           {"decode x.npy --tokenizer t --fast --decoder d" + out, "--fast"},
           {"train-all data", "data"},
           {"world", "subcommand"},
       }) {
    SCOPED_TRACE(args);
    test::expect_one_error_line(test::run_gaia(args), what, 2);
  }
  EXPECT_FALSE(fs::exists(dir / "o"));
  // --help still prints help and exits 0.
  auto r = test::run_gaia("generate --help");
  EXPECT_EQ(r.status, 0);
  EXPECT_NE(r.output.find("--temperature"), std::string::npos);
}

// --start far outside the episode used to crash inside LibTorch; a K = 256 token file with a larger id is an error
// naming the first bad position, not a bigger codebook.
TEST(HardeningCli, PromptStartAndTokenIdsAreChecked) {
  test::TempDir dir;
  const fs::path tokens = bare_tokens(dir.path);
  auto r = test::run_gaia("world train " + q(tokens) + tiny_flags() + " --steps 1 --out " + q(dir / "w"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string gen = "generate " + q(tokens) + " --world " + q(dir / "w" / "world.safetensors") +
                          " --episode 0 --frames 2 --threads 1";
  test::expect_one_error_line(test::run_gaia(gen + " --start 100000000 --out " + q(dir / "g")), "--start");
  EXPECT_FALSE(fs::exists(dir / "g"));
  r = test::run_gaia(gen + " --start 3 --out " + q(dir / "g"));
  EXPECT_EQ(r.status, 0) << r.output;
  // A tokenizer of another grid and codebook (the shipped 9 x 16, K = 1024, against this 4 x 8, K = 256) is refused
  // before anything is generated or written, not decoded into a garbage preview.
  r = test::run_gaia(gen + " --tokenizer " + q(test::source_dir() / "models" / "tokenizer.safetensors") + " --out " +
                     q(dir / "mixed"));
  test::expect_one_error_line(r, "tokenizer.safetensors: the tokenizer makes 9x16 tokens of K = 1024");
  EXPECT_FALSE(fs::exists(dir / "mixed"));
  // A million futures do not fit in memory: refused up front with what they would need, nothing written.
  r = test::run_gaia(gen + " --futures 1000000 --out " + q(dir / "many"));
  test::expect_one_error_line(r, "futures = 1000000");
  EXPECT_TRUE(std::regex_search(r.output, std::regex("would need about [0-9.]+ GB of memory, but [0-9.]+ GB are available")))
      << r.output;
  EXPECT_FALSE(fs::exists(dir / "many"));
  // So is a world model too large to train here (each key within its range, the product not).
  r = test::run_gaia("world train " + q(tokens) + tiny_flags() +
                     " --set world.d_model=65536 --set world.n_layers=1024 --set world.n_heads=1024 --out " + q(dir / "huge"));
  test::expect_one_error_line(r, "training this world model");
  EXPECT_NE(r.output.find("would need about"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(dir / "huge"));

  test::TempDir big;
  std::vector<int16_t> v(40 * 32, 3);
  v[5 * 32 + 7] = 301;  // step 5, position 7
  npy_write(big / "tokens.npy", npy_make(DType::I16, {40, 4, 8}, v));
  r = test::run_gaia("world train " + q(big / "tokens.npy") + tiny_flags() + " --steps 1 --out " + q(big / "w"));
  test::expect_one_error_line(r, "tokens.npy");
  EXPECT_NE(r.output.find("301"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("256"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(big / "w" / "world.safetensors"));
}

// A kill between the two renames of a checkpoint swap left no checkpoint/ although complete copies were on disk.
// Recovery puts the newest complete one back and removes the rest; a live process's staging is left alone.
TEST(Hardening, RecoverCheckpointTakesTheNewestCompleteCopy) {
  test::TempDir dir;
  auto fake = [&](const fs::path& p, int step, bool complete) {
    fs::create_directories(p);
    write_file_atomic(p / "world.safetensors", "x");
    if (complete) write_file_atomic(p / "state.json", fmt::format("{{\"step\": {}, \"extra\": {{}}}}\n", step));
  };
  const long dead = dead_pid();
  const fs::path ckpt = dir / "checkpoint";
  fake(dir / fmt::format("checkpoint.old-{}-0", dead), 200, true);
  fake(dir / fmt::format(".tmp-checkpoint-{}-1", dead), 400, true);
  fake(dir / fmt::format(".tmp-checkpoint-{}-2", dead), 600, false);  // torn: no state.json
  fake(dir / fmt::format(".tmp-checkpoint-{}-3", long(getpid())), 800, true);  // a live writer's: not ours to take
  write_file_atomic(dir / fmt::format("latest.safetensors.tmp-{}-4", dead), "torn");
  const std::string said = train::recover_checkpoint(ckpt);
  EXPECT_NE(said.find("step 400"), std::string::npos) << said;
  EXPECT_EQ(read_json_step(ckpt), 400);
  std::vector<std::string> left;
  for (auto& e : fs::directory_iterator(dir.path)) left.push_back(e.path().filename().string());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{fmt::format(".tmp-checkpoint-{}-3", long(getpid())), "checkpoint"}));
  // With a complete checkpoint in place nothing is replaced.
  EXPECT_EQ(train::recover_checkpoint(ckpt), "");
  EXPECT_EQ(read_json_step(ckpt), 400);
}

// One run per output directory: a second one fails at once with one line naming the first's pid, and the lock
// dies with its process.
TEST(HardeningCli, RunDirectoryIsLockedForOneRun) {
  test::TempDir dir;
  const fs::path tokens = bare_tokens(dir.path);
  {
    DirLock held(dir / "w");
    EXPECT_NE(test::error_of([&] { DirLock again(dir / "w"); }).find(std::to_string(getpid())), std::string::npos);
    auto r = test::run_gaia("world train " + q(tokens) + tiny_flags() + " --steps 1 --out " + q(dir / "w"));
    test::expect_one_error_line(r, "another gaia run (pid " + std::to_string(getpid()) + ")");
    EXPECT_FALSE(fs::exists(dir / "w" / "checkpoint"));
  }
  // A lock that created its directory and left nothing in it takes the directory with it.
  EXPECT_FALSE(fs::exists(dir / "w"));
  const pid_t child = fork();
  if (child == 0) {
    DirLock l(dir / "k");
    _exit(0);  // no destructor: as if killed
  }
  waitpid(child, nullptr, 0);
  EXPECT_EQ(test::error_of([&] { DirLock after(dir / "k"); }), "");
}

// World-model training resumes bit for bit, from a checkpoint that a kill broke as well.
TEST(HardeningCli, WorldTrainResumesExactlyAfterAKill) {
  test::TempDir dir;
  const fs::path tokens = bare_tokens(dir.path);
  const std::string train = "world train " + q(tokens) + tiny_flags() + " --set run.checkpoint_every=2 --steps 6 --val-every 3";
  auto r = test::run_gaia(train + " --out " + q(dir / "straight"));
  ASSERT_EQ(r.status, 0) << r.output;
  r = test::run_gaia(train + " --stop-after 4 --out " + q(dir / "resumed"));
  ASSERT_EQ(r.status, 0) << r.output;
  // The kill between the two renames: the checkpoint moved aside, nothing in its place.
  fs::rename(dir / "resumed" / "checkpoint", dir / "resumed" / fmt::format("checkpoint.old-{}-0", dead_pid()));
  r = test::run_gaia(train + " --out " + q(dir / "resumed"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("recovered the checkpoint of step 4"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("at step 4"), std::string::npos) << r.output;
  auto a = weights_of(dir / "straight" / "world.safetensors"), b = weights_of(dir / "resumed" / "world.safetensors");
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 10u);
  for (auto& [name, t] : a) EXPECT_TRUE(torch::equal(t, b.at(name))) << name;
  for (auto& e : fs::directory_iterator(dir / "resumed"))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
}

// A full disk while the optimiser state is written used to abort the process and leave a torn file behind. Here a
// file-size limit stands in for the full disk: the run fails with one line, the last checkpoint stays whole.
TEST(HardeningCli, FullDiskDuringACheckpointIsOneErrorAndKeepsTheLastOne) {
  test::TempDir dir;
  const fs::path tokens = bare_tokens(dir.path);
  const std::string train = "world train " + q(tokens) + tiny_flags() + " --set run.checkpoint_every=1 --val-every 100";
  auto r = test::run_gaia(train + " --steps 1 --out " + q(dir / "w"));
  ASSERT_EQ(r.status, 0) << r.output;
  const auto before = weights_of(dir / "w" / "checkpoint" / "world.safetensors");
  const auto optim_bytes = fs::file_size(dir / "w" / "checkpoint" / "world.optim.pt");
  const auto weight_bytes = fs::file_size(dir / "w" / "checkpoint" / "world.safetensors");
  ASSERT_GT(optim_bytes, weight_bytes + 8192);
  // ulimit -f counts 1024-byte blocks: the weights fit, the optimiser state does not.
  const auto limit = (optim_bytes + weight_bytes) / 2 / 1024;
  const auto full = run_gaia_with_file_limit(int(limit), train + " --steps 3 --out " + q(dir / "w"));
  EXPECT_EQ(full.status, 1) << full.output;  // an exit, not a signal (-1)
  const auto last = full.output.substr(full.output.rfind("gaia: error: ") == std::string::npos ? 0 : full.output.rfind("gaia: error: "));
  EXPECT_EQ(last.rfind("gaia: error: ", 0), 0u) << full.output;
  EXPECT_NE(last.find("optim.pt"), std::string::npos) << full.output;
  EXPECT_EQ(std::count(last.begin(), last.end(), '\n'), 1) << full.output;
  EXPECT_EQ(full.output.find("terminate"), std::string::npos) << full.output;
  // The checkpoint is still the step-1 one, whole, and nothing torn is left beside it.
  EXPECT_TRUE(train::has_checkpoint(dir / "w" / "checkpoint"));
  const auto after = weights_of(dir / "w" / "checkpoint" / "world.safetensors");
  for (auto& [name, t] : before) EXPECT_TRUE(torch::equal(t, after.at(name))) << name;
  for (auto& e : fs::directory_iterator(dir / "w"))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  // And the run resumes from it once there is room again.
  r = test::run_gaia(train + " --steps 3 --out " + q(dir / "w"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("at step 1"), std::string::npos) << r.output;
}

// decode's MP4, GIF and PNG are one output: a full disk at the GIF leaves none of them, not an MP4 on its own.
TEST(HardeningCli, DecodeOnAFullDiskLeavesNoPartialOutput) {
  test::TempDir dir;
  std::vector<int16_t> v(10 * 9 * 16);
  for (size_t i = 0; i < v.size(); ++i) v[i] = int16_t((i * 37) % 1024);
  npy_write(dir / "tokens.npy", npy_make(DType::I16, {10, 9, 16}, v));
  const std::string args = "decode " + q(dir / "tokens.npy") + " --tokenizer " +
                           q(test::source_dir() / "models" / "tokenizer.safetensors") + " --fast --threads 1 --out " +
                           q(dir / "out" / "v.mp4");
  auto r = test::run_gaia(args);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto mp4 = fs::file_size(dir / "out" / "v.mp4"), gif = fs::file_size(dir / "out" / "v.gif");
  ASSERT_LT(mp4 + 2048, gif) << "the test needs an MP4 smaller than the GIF";
  fs::remove_all(dir / "out");
  r = run_gaia_with_file_limit(int((mp4 + gif) / 2 / 1024), args);
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_NE(r.output.find("gaia: error: "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("v.gif"), std::string::npos) << r.output;
  std::vector<std::string> left;
  if (fs::exists(dir / "out"))
    for (auto& e : fs::directory_iterator(dir / "out")) left.push_back(e.path().filename().string());
  EXPECT_TRUE(left.empty()) << left.front();
}

// An output directory on a read-only file system is one error line naming it, not the encoder's "no video encoder
// available". Root (CI runs as root) passes every permission check, so the directory is a tmpfs mounted read-only
// in a private mount namespace that ends with the command.
TEST(HardeningCli, DecodeIntoAReadOnlyDirectoryNamesIt) {
  if (test::run_shell("unshare -m true 2>&1").status != 0)
    GTEST_SKIP() << "a read-only directory needs a private mount namespace (unshare -m, as root)";
  test::TempDir dir;
  std::vector<int16_t> v(4 * 9 * 16, 7);
  npy_write(dir / "tokens.npy", npy_make(DType::I16, {4, 9, 16}, v));
  fs::create_directories(dir / "ro");
  const std::string decode = "decode " + q(dir / "tokens.npy") + " --tokenizer " +
                             q(test::source_dir() / "models" / "tokenizer.safetensors") + " --fast --threads 1 --out " +
                             q(dir / "ro" / "v.mp4");
  auto r = test::run_shell("unshare -m bash -c \"mount -t tmpfs -o ro,size=1m tmpfs " + q(dir / "ro") + " && exec " +
                           test::gaia_command(decode) + "\" 2>&1");
  EXPECT_EQ(r.status, 1) << r.output;
  EXPECT_EQ(r.output.rfind("gaia: error: ", 0), 0u) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find((dir / "ro").string()), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("Read-only file system"), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("encoder"), std::string::npos) << r.output;
}
