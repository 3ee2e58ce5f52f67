// gaia train-all on the tiny config with a handful of steps per stage: every stage runs as its own gaia process,
// the fp16 copies land in --ship, and a second run finds every stage done and skips it (resumable recipe).
#include <algorithm>

#include <nlohmann/json.hpp>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <torch/torch.h>

#include "gaia/core/safetensors.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/data/episode.h"
#include "gaia/data/geofence.h"
#include "gaia/world/io.h"
#include "test_util.h"

using namespace gaia;
using test::q;

namespace {
}  // namespace

TEST(TrainAllSlow, RunsEveryStageShipsAndResumes) {
  test::TempDir d;
  const std::string cmd = "train-all --config " + q(test::source_dir() / "configs" / "tiny.yaml") +
                          " --threads 1 --episodes 3 --wander-episodes 2 --swerve-episodes 1 --seconds 4 --tokenizer-steps 6 --finetune-steps 3 --refine-steps 2"
                          " --world-steps 4 --world-cf-steps 2 --decoder-steps 2 --probe-steps 3 --dynamics-probe-steps 3 --skip-eval" +
                          " --ship " + q(d / "models") + " --out " + q(d / "runs");
  auto r = test::run_gaia(cmd);
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"tokenizer.safetensors", "world.safetensors", "decoder.safetensors", "probe-scene.safetensors",
                        "probe-dynamics.safetensors"}) {
    ASSERT_TRUE(fs::exists(d / "models" / f)) << f;
    SafetensorsFile st(d / "models" / f);
    int f16 = 0, f32 = 0;
    for (const auto& n : st.names()) f16 += st.get(n).dtype == DType::F16, f32 += st.get(n).dtype == DType::F32;
    EXPECT_GT(f16, 0) << f;  // shipped as fp16
    EXPECT_EQ(f32, 0) << f;
  }
  auto log = nlohmann::json::parse(read_file(d / "runs" / "train-all.json"));
  ASSERT_EQ(log.size(), 16u + 5u);  // 16 training stages + 5 ship copies
  EXPECT_NE(log[5]["command"].get<std::string>().find("--decoder-only"), std::string::npos);  // tokenizer-refine
  EXPECT_NE(log[5]["command"].get<std::string>().find("tokenizer.token_blocks=2"), std::string::npos);
  EXPECT_NE(log[5]["command"].get<std::string>().find("tokenizer.ema_decay=0.999"), std::string::npos);
  EXPECT_NE(log[6]["command"].get<std::string>().find("tokenizer-refine"), std::string::npos);  // tokens use its codes
  // ... and every drive again in mirror image, held out with its source.
  EXPECT_TRUE(nlohmann::json::parse(read_file(d / "runs" / "tokens" / "dataset.json"))["mirror"].get<bool>());
  // The tokens also hold 6 counterfactual replays of each lane-keeping training drive (docs/synth.md), in mirror
  // image too, every one of them a training episode like its source.
  data::Dataset synth(d / "runs" / "synth");
  const data::Split split = data::load_or_default_split(synth, 0.1, 0);
  size_t lane_keeping_train = 0;
  for (size_t e : data::episode_indices(synth, split.train)) lane_keeping_train += !synth.meta(e).extra.count("synth_wander");
  ASSERT_GT(lane_keeping_train, 0u);
  int mirrored = 0, plain = 0, replays = 0;
  for (auto& e : fs::directory_iterator(d / "runs" / "tokens" / "episodes")) {
    const std::string id = e.path().filename().string();
    (id.find("-mirror") != std::string::npos ? mirrored : plain)++;
    if (id.find("-cf") != std::string::npos) {
      ++replays;
      EXPECT_FALSE(data::held_out_at_random(id, 0.1, 0)) << id;
    }
  }
  EXPECT_EQ(replays, static_cast<int>(2 * 6 * lane_keeping_train));
  EXPECT_EQ(plain, 6 + replays / 2);
  EXPECT_EQ(mirrored, 6 + replays / 2);
  EXPECT_NE(log[7]["command"].get<std::string>().find("world train"), std::string::npos);
  EXPECT_NE(log[7]["command"].get<std::string>().find("--steps 4"), std::string::npos);
  EXPECT_NE(log[8]["command"].get<std::string>().find("synth counterfactuals"), std::string::npos);
  EXPECT_NE(log[10]["command"].get<std::string>().find("--init"), std::string::npos);  // world-cf: the fine-tune
  EXPECT_NE(log[10]["command"].get<std::string>().find("--steps 2"), std::string::npos);
  // ... at half the rate, its text-only and unconditional predictions held to the first phase's (the shipped recipe).
  EXPECT_NE(log[10]["command"].get<std::string>().find("--distill-from"), std::string::npos);
  EXPECT_NE(log[10]["command"].get<std::string>().find("world.lr=1.5e-4"), std::string::npos);
  EXPECT_NE(log[10]["command"].get<std::string>().find("world.p_action=0.6"), std::string::npos);
  // Its second round starts from the first round's weights and is still held to the first phase's predictions.
  const std::string round2 = log[11]["command"].get<std::string>();
  EXPECT_EQ(log[11]["stage"], "world-cf2");
  EXPECT_NE(round2.find("--init " + (d / "runs" / "world-cf" / "world.safetensors").string()), std::string::npos) << round2;
  EXPECT_NE(round2.find("--distill-from " + (d / "runs" / "world" / "world.safetensors").string()), std::string::npos) << round2;
  EXPECT_NE(round2.find("--out " + (d / "runs" / "world-cf2").string()), std::string::npos) << round2;
  // The shipped world model is the calibrated last round, fitted on the lane-keeping drives (not on their replays).
  EXPECT_NE(log[12]["command"].get<std::string>().find("world calibrate"), std::string::npos);
  EXPECT_NE(log[12]["command"].get<std::string>().find("world-cf2"), std::string::npos);
  EXPECT_NE(log[12]["command"].get<std::string>().find("--without-meta synth_wander --without-meta replay_of"), std::string::npos);
  // The scene probe reads half of its frames through the final tokenizer (the refined one), as gaia eval does.
  const auto probe_stage = std::find_if(log.begin(), log.end(), [](const nlohmann::json& e) { return e["stage"] == "probe-scene"; });
  ASSERT_NE(probe_stage, log.end());
  const std::string probe_cmd = (*probe_stage)["command"].get<std::string>();
  EXPECT_NE(probe_cmd.find("--tokenizer " + (d / "runs" / "tokenizer-refine" / "tokenizer.safetensors").string()),
            std::string::npos) << probe_cmd;
  EXPECT_NE(probe_cmd.find("--decoded-share 0.5"), std::string::npos) << probe_cmd;
  EXPECT_EQ(SafetensorsFile(d / "models" / "probe-scene.safetensors").metadata().at("gaia.probe.decoded_share"), "0.5");
  world::WorldInfo shipped;
  world::load_world(d / "models" / "world.safetensors", torch::kCPU, &shipped);
  EXPECT_NE(shipped.config.world.copy_bias, 0.0);
  // The procedural data: 3 lane-keeping episodes, 2 more whose driver wanders and 1 whose driver also swerves
  // (docs/synth.md).
  int keep = 0, wander = 0, swerve = 0;
  for (auto& e : fs::directory_iterator(d / "runs" / "synth" / "episodes")) {
    auto m = nlohmann::json::parse(read_file(e.path() / "episode.json"));
    (m["extra"].contains("synth_swerve") ? swerve : m["extra"].contains("synth_wander") ? wander : keep)++;
  }
  EXPECT_EQ(keep, 3);
  EXPECT_EQ(wander, 2);
  EXPECT_EQ(swerve, 1);
  // Again: nothing left to do.
  r = test::run_gaia(cmd);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(test::occurrences(r.output, "skipped"), 21) << r.output;
  // A bad config key fails before any stage starts, naming the key.
  r = test::run_gaia("train-all --set world.bogus=1 --out " + q(d / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("world.bogus"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "x"));
  r = test::run_gaia("train-all --world-cf-rounds 0 --out " + q(d / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("--world-cf-rounds"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "x"));
}

TEST(TrainAllSlow, RunsOnYourOwnDrivesMixedWithProceduralOnes) {
  test::TempDir d;
  const std::string tiny = " --config " + q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  // Stand-ins for ingested drives: any gaia dataset of the config's frame size.
  auto r = test::run_gaia("synth --episodes 2 --seconds 3 --size 32x64 --seed 9 --threads 1 --out " + q(d / "mine"));
  ASSERT_EQ(r.status, 0) << r.output;
  const std::string cmd = "train-all --data " + q(d / "mine") + " --synth 1 --seconds 3" + tiny +
                          " --tokenizer-steps 4 --world-steps 3 --decoder-steps 2 --skip-eval --ship " + q(d / "models") +
                          " --out " + q(d / "runs");
  r = test::run_gaia(cmd);
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"tokenizer.safetensors", "world.safetensors", "decoder.safetensors"})
    EXPECT_TRUE(fs::exists(d / "models" / f)) << f;
  EXPECT_FALSE(fs::exists(d / "models" / "probe-scene.safetensors"));  // probes need labelled drives
  // Your episodes are linked, not copied or changed, beside the procedural one.
  data::Dataset mixed(d / "runs" / "data");
  EXPECT_EQ(mixed.size(), 3u);
  EXPECT_TRUE(fs::is_symlink(d / "runs" / "data" / "episodes" / "synth-s9-e00000"));
  EXPECT_TRUE(fs::exists(d / "runs" / "data" / "episodes" / "synth-s1-e00000" / "episode.json"));
  r = test::run_gaia(cmd);
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(test::occurrences(r.output, "skipped"), 10) << r.output;  // data, synth, five trainers and steps, three copies
  // Fine-tuning the models just shipped with --new-codes: the tokenizer's encoder and codebook learn too (without
  // it, --decoder-only keeps every code; a warm-up's first steps move them little, but they move).
  r = test::run_gaia("train-all --data " + q(d / "mine") + " --from " + q(d / "models") + " --new-codes --synth 1" +
                     " --seconds 3" + tiny + " --tokenizer-steps 2 --world-steps 1 --decoder-steps 1 --skip-eval --out " +
                     q(d / "tuned"));
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.find("--decoder-only"), std::string::npos) << r.output;
  {
    // The world model starts from the shipped one but is not held to its predictions: those are of the old codes.
    const auto log = nlohmann::json::parse(read_file(d / "tuned" / "train-all.json"));
    std::string world;
    for (const auto& stage : log)
      if (stage["command"].get<std::string>().find("world train") != std::string::npos) world = stage["command"];
    EXPECT_NE(world.find("--init"), std::string::npos) << world;
    EXPECT_EQ(world.find("--distill-from"), std::string::npos) << world;
  }
  {
    SafetensorsFile before(d / "models" / "tokenizer.safetensors"),
        after(d / "tuned" / "tokenizer" / "tokenizer.safetensors");
    int encoder = 0, moved = 0;
    for (const auto& n : before.names())
      if (n.rfind("encoder.", 0) == 0 || n.rfind("quantizer.", 0) == 0) {
        ++encoder;
        const auto a = tensor_from_view(before.get(n)).to(torch::kFloat), b = tensor_from_view(after.get(n)).to(torch::kFloat);
        moved += !torch::equal(a, b);  // --decoder-only writes back the shipped fp16 values exactly
      }
    EXPECT_GT(encoder, 0);
    EXPECT_GT(moved, encoder / 2) << moved << " of " << encoder;
  }
  r = test::run_gaia("train-all --data " + q(d / "mine") + " --new-codes" + tiny + " --out " + q(d / "x"));
  EXPECT_NE(r.output.find("--new-codes goes with --from"), std::string::npos) << r.output;
  // Bad input before any stage: not a dataset, another frame size, --from without the models, --synth alone.
  r = test::run_gaia("train-all --data " + q(d / "nope") + tiny + " --out " + q(d / "x"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("nope"), std::string::npos) << r.output;
  r = test::run_gaia("train-all --data " + q(d / "mine") + " --threads 1 --out " + q(d / "x"));
  EXPECT_NE(r.output.find("episodes are 32x64, the config's data size is 72x128"), std::string::npos) << r.output;
  r = test::run_gaia("train-all --data " + q(d / "mine") + " --from " + q(d / "empty") + tiny + " --out " + q(d / "x"));
  EXPECT_NE(r.output.find("no tokenizer.safetensors there"), std::string::npos) << r.output;
  r = test::run_gaia("train-all --synth 3" + tiny + " --out " + q(d / "x"));
  EXPECT_NE(r.output.find("go with --data"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "x"));

  // The real-footage release: a folder of clips with its manifest, fine-tuned from the models just shipped, with
  // procedural drives mixed in, clips held out by source, the realism probe trained and shipped beside them.
  fs::create_directories(d / "clips");
  for (const char* name : {"a.avi", "b.avi", "c.avi"}) {
    cv::VideoWriter vw((d / "clips" / name).string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 20,
                       cv::Size(128, 72));
    ASSERT_TRUE(vw.isOpened());
    cv::RNG rng(name[0]);
    for (int i = 0; i < 40; ++i) {
      cv::Mat f(72, 128, CV_8UC3, cv::Scalar(90, 100, 110));
      for (int k = 0; k < 30; ++k)
        cv::circle(f, {(rng.uniform(0, 128) + 5 * i) % 128, rng.uniform(0, 72)}, 4, cv::Scalar(rng.uniform(0, 255), 80, 200), cv::FILLED);
      vw.write(f);
    }
  }
  write_file_atomic(d / "clips" / "clips.csv",
                    "file,weather,time_of_day,road,source_repo,place\n"
                    "a.avi,clear,day,city,one/a,Berlin\nb.avi,clear,day,city,two/b,Paris\nc.avi,rain,night,rural,three/c,Rome\n");
  const std::string release = "train-all --data " + q(d / "clips") + " --manifest clips.csv --from " + q(d / "models") +
                              " --synth 3 --wander-episodes 0 --swerve-episodes 0 --seconds 3 --world-cf-steps 0" + tiny +
                              " --tokenizer-steps 3 --world-steps 2 --realism-probe-steps 2 --dynamics-probe-steps 2"
                              " --skip-eval"
                              " --ship " + q(d / "release") + " --out " + q(d / "real");
  r = test::run_gaia(release);
  ASSERT_EQ(r.status, 0) << r.output;
  for (const char* f : {"tokenizer.safetensors", "world.safetensors", "decoder.safetensors", "probe-realism.safetensors",
                        "probe-dynamics.safetensors"})
    EXPECT_TRUE(fs::exists(d / "release" / f)) << f;
  data::Dataset real(d / "real" / "data");
  EXPECT_EQ(real.size(), 6u);  // three clips, three procedural drives
  const auto split = data::read_split(d / "real" / "data" / "split.json");
  EXPECT_EQ(split.held_out().size() > 0, true);
  auto stages = nlohmann::json::parse(read_file(d / "real" / "train-all.json"));
  std::string commands;
  for (auto& s : stages) commands += s["command"].get<std::string>() + "\n";
  EXPECT_NE(commands.find("--decoder-only"), std::string::npos) << commands;  // the codes the world model knows
  EXPECT_NE(commands.find("--distill-procedural-only"), std::string::npos) << commands;
  EXPECT_NE(commands.find("data.balance_tokenizer=[footage]"), std::string::npos) << commands;
  EXPECT_NE(commands.find("--hold-out-by source_repo,place"), std::string::npos) << commands;
  EXPECT_NE(commands.find("probe train dynamics " + (d / "real" / "data").string() + " --steps 2 --mirror"),
            std::string::npos) << commands;  // real roads' motion beside the procedural world's
  // The codes stayed, so the video decoder is the --from one, kept byte for byte rather than trained again.
  EXPECT_EQ(commands.find("decoder train"), std::string::npos) << commands;
  EXPECT_EQ(read_file(d / "real" / "decoder" / "decoder.safetensors"), read_file(d / "models" / "decoder.safetensors"));
  // A manifest with a value it may not hold: one line before any stage, nothing made.
  write_file_atomic(d / "clips" / "bad.csv", "file,weather\na.avi,sunny\n");
  r = test::run_gaia("train-all --data " + q(d / "clips") + " --manifest bad.csv" + tiny + " --out " + q(d / "y"));
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("column 'weather' is 'sunny'"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(d / "y"));
}
