// The frozen T5 text encoder (paper §2.1) against its plain-PyTorch peer (tools/t5_peer.py --make-fixture, fixtures
// in tests/fixtures/t5/: a tiny SentencePiece model and two tiny random-weight encoders, T5 with ReLU in F32 and
// T5 v1.1 with gated GELU in BF16), its errors, and a SentencePiece model trained here with the C++ library
// (through text/sentencepiece.h, which keeps it apart from LibTorch's protobuf).
#include <algorithm>
#include <cmath>
#include <functional>

#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include "gaia/core/json_file.h"
#include "gaia/core/safetensors.h"
#include "gaia/text/sentencepiece.h"
#include "gaia/text/t5.h"
#include "gaia/torch/tensor_io.h"
#include "test_util.h"

using namespace gaia;
using text::T5Encoder;

namespace {

fs::path fixture_dir() { return test::source_dir() / "tests" / "fixtures" / "t5"; }

struct PeerIo {
  SafetensorsFile file{fixture_dir() / "t5_io.safetensors"};
  std::vector<std::string> captions = nlohmann::json::parse(file.metadata().at("captions")).get<std::vector<std::string>>();
  int64_t m = std::stoll(file.metadata().at("m"));
  torch::Tensor get(const std::string& name) const { return tensor_from_view(file.get(name)); }
};


// A copy of a fixture encoder in a scratch directory, to break one file of.
fs::path copy_of(const std::string& variant, const test::TempDir& tmp) {
  const fs::path dir = tmp / variant;
  fs::copy(fixture_dir() / variant, dir, fs::copy_options::recursive);
  return dir;
}

// Rewrites dir/model.safetensors with `edit` applied to its tensors.
void edit_weights(const fs::path& dir, const std::function<void(std::map<std::string, torch::Tensor>&)>& edit) {
  std::map<std::string, torch::Tensor> w;
  {
    SafetensorsFile f(dir / "model.safetensors");
    for (const auto& name : f.names()) w[name] = tensor_from_view(f.get(name));
  }
  edit(w);
  save_tensors(w, dir / "model.safetensors");
}

// A tiny random-weight T5 (ReLU) in Hugging Face's naming and config.json.
void write_random_t5(const fs::path& dir, int64_t vocab) {
  const int64_t d = 16, heads = 2, dkv = 8, dff = 32, layers = 2, buckets = 8;
  torch::manual_seed(3);
  auto lin = [](int64_t o, int64_t i) { return torch::randn({o, i}) / std::sqrt(static_cast<double>(i)); };
  std::map<std::string, torch::Tensor> w{
      {"shared.weight", torch::randn({vocab, d})},
      {"encoder.final_layer_norm.weight", torch::ones({d})},
      {"encoder.block.0.layer.0.SelfAttention.relative_attention_bias.weight", torch::randn({buckets, heads})}};
  for (int64_t i = 0; i < layers; ++i) {
    const std::string p = "encoder.block." + std::to_string(i) + ".layer.";
    for (const char* t : {"q", "k", "v"}) w[p + "0.SelfAttention." + t + ".weight"] = lin(heads * dkv, d);
    w[p + "0.SelfAttention.o.weight"] = lin(d, heads * dkv);
    w[p + "0.layer_norm.weight"] = torch::ones({d});
    w[p + "1.layer_norm.weight"] = torch::ones({d});
    w[p + "1.DenseReluDense.wi.weight"] = lin(dff, d);
    w[p + "1.DenseReluDense.wo.weight"] = lin(d, dff);
  }
  save_tensors(w, dir / "model.safetensors");
  const nlohmann::json config = {{"vocab_size", vocab}, {"d_model", d}, {"d_kv", dkv}, {"d_ff", dff},
                                 {"num_layers", layers}, {"num_heads", heads}, {"relative_attention_num_buckets", buckets},
                                 {"feed_forward_proj", "relu"}};
  write_file_atomic(dir / "config.json", config.dump(2));
}

}  // namespace

TEST(T5Peer, TokenizeMatchesThePeer) {
  PeerIo io;
  ASSERT_EQ(io.captions.size(), size_t{5});
  T5Encoder enc(fixture_dir() / "relu");
  const auto ids = io.get("ids"), lengths = io.get("lengths");
  bool unknown = false, longer = false;
  for (size_t i = 0; i < io.captions.size(); ++i) {
    const int64_t n = lengths[i].item<int64_t>();
    const auto want = ids[i].slice(0, 0, n);
    const auto got = enc.tokenize(io.captions[i]);
    EXPECT_EQ(got, std::vector<int64_t>(want.data_ptr<int64_t>(), want.data_ptr<int64_t>() + n)) << io.captions[i];
    EXPECT_EQ(got.back(), T5Encoder::kEos);
    unknown |= std::count(got.begin(), got.end(), int64_t{2}) > 0;  // <unk>: words outside spm's training text
    longer |= n > io.m;
  }
  EXPECT_TRUE(unknown);
  EXPECT_TRUE(longer);
  EXPECT_EQ(enc.tokenize(""), std::vector<int64_t>{T5Encoder::kEos});  // as HF gives; encode() zeros it instead
}

TEST(T5Peer, EncodeMatchesThePeer) {
  PeerIo io;
  const auto mask = io.get("mask").to(torch::kBool);  // [N, m]
  for (const std::string variant : {"relu", "gated"}) {
    T5Encoder enc(fixture_dir() / variant, parse_device(test::device_name()));
    EXPECT_EQ(enc.config().gated_gelu, variant == "gated");
    const auto want = io.get(variant);  // [N, m, d]
    const auto got = enc.encode(io.captions, io.m);
    ASSERT_EQ(got.sizes(), want.sizes()) << variant;
    EXPECT_EQ(got.scalar_type(), torch::kFloat);
    EXPECT_TRUE(got.device().is_cpu());
    EXPECT_EQ(got.size(2), enc.dim());
    EXPECT_LE(test::rel_err(got, want), 1e-5) << variant;
    // Each caption on its own too, so one row's error is not hidden by the others.
    for (int64_t i = 0; i < got.size(0); ++i) {
      if (!mask[i].any().item<bool>()) continue;  // the empty caption: zeros on both sides
      EXPECT_LE(test::rel_err(got[i], want[i]), 1e-5) << variant << " row " << i;
    }
    // Padded positions and the empty caption are exactly zero.
    EXPECT_EQ(got.masked_select(mask.logical_not().unsqueeze(-1)).abs().max().item<float>(), 0.0f);
    EXPECT_EQ(got[2].abs().max().item<float>(), 0.0f);
    EXPECT_GT(got.masked_select(mask.unsqueeze(-1)).abs().min().item<float>(), 0.0f);
  }
}

TEST(T5Text, RowsDoNotDependOnTheBatch) {
  PeerIo io;
  T5Encoder enc(fixture_dir() / "gated", parse_device(test::device_name()));
  const auto all = enc.encode(io.captions, io.m);
  for (size_t i = 0; i < io.captions.size(); ++i) {
    const auto alone = enc.encode({io.captions[i]}, io.m);  // [1, m, d]
    // Equal up to float rounding: matrix products of other batch sizes may sum in another order.
    EXPECT_TRUE(torch::allclose(alone[0], all[static_cast<int64_t>(i)], 1e-5, 1e-5)) << io.captions[i];
  }
  // Reversed order gives the same rows; no captions gives an empty batch.
  std::vector<std::string> rev(io.captions.rbegin(), io.captions.rend());
  EXPECT_TRUE(torch::allclose(enc.encode(rev, io.m).flip(0), all, 1e-5, 1e-5));
  EXPECT_EQ(enc.encode({}, io.m).sizes(), (std::vector<int64_t>{0, io.m, enc.dim()}));
  // m = 1 keeps only </s>.
  EXPECT_EQ(enc.encode({"night"}, 1).sizes(), (std::vector<int64_t>{1, 1, enc.dim()}));
}

TEST(T5Text, IdentityNamesTheCheckpoint) {
  test::TempDir tmp;
  const auto relu = T5Encoder(fixture_dir() / "relu").identity();
  EXPECT_EQ(relu.rfind("t5:relu:", 0), 0u) << relu;
  EXPECT_EQ(relu.size(), std::string("t5:relu:").size() + 12);
  EXPECT_EQ(T5Encoder(fixture_dir() / "relu").identity(), relu);  // stable
  const auto hash = [](const std::string& id) { return id.substr(id.size() - 12); };
  EXPECT_NE(hash(T5Encoder(fixture_dir() / "gated").identity()), hash(relu));
  // Same shapes, other values (a fine-tuned checkpoint): another identity.
  const fs::path dir = copy_of("relu", tmp);
  edit_weights(dir, [](auto& w) { w["encoder.block.1.layer.0.SelfAttention.q.weight"].mul_(-1); });
  EXPECT_NE(T5Encoder(dir).identity(), relu);
}

TEST(T5Text, ErrorsNameTheFileAndField) {
  test::TempDir tmp;
  {
    const fs::path dir = copy_of("relu", tmp);
    fs::remove(dir / "spiece.model");
    const auto e = test::error_of([&] { T5Encoder enc(dir); });
    EXPECT_NE(e.find((dir / "spiece.model").string()), std::string::npos) << e;
    fs::remove_all(dir);
  }
  {
    const fs::path dir = copy_of("relu", tmp);
    const std::string name = "encoder.block.1.layer.1.DenseReluDense.wo.weight";
    edit_weights(dir, [&](auto& w) { w[name] = torch::zeros({32, 63}); });
    const auto e = test::error_of([&] { T5Encoder enc(dir); });
    EXPECT_NE(e.find("model.safetensors"), std::string::npos) << e;
    EXPECT_NE(e.find(name), std::string::npos) << e;
    EXPECT_NE(e.find("[32, 63]"), std::string::npos) << e;
    EXPECT_NE(e.find("[32, 64]"), std::string::npos) << e;
    fs::remove_all(dir);
  }
  {
    const fs::path dir = copy_of("gated", tmp);
    edit_weights(dir, [](auto& w) { w.erase("encoder.block.0.layer.1.DenseReluDense.wi_1.weight"); });
    const auto e = test::error_of([&] { T5Encoder enc(dir); });
    EXPECT_NE(e.find("missing tensor 'encoder.block.0.layer.1.DenseReluDense.wi_1.weight'"), std::string::npos) << e;
    fs::remove_all(dir);
  }
  {
    const fs::path dir = copy_of("relu", tmp);
    auto config = read_json(dir / "config.json");
    config["feed_forward_proj"] = "gated-swish";
    write_file_atomic(dir / "config.json", config.dump());
    const auto e = test::error_of([&] { T5Encoder enc(dir); });
    EXPECT_NE(e.find((dir / "config.json").string()), std::string::npos) << e;
    EXPECT_NE(e.find("feed_forward_proj"), std::string::npos) << e;
    config["feed_forward_proj"] = "relu";
    config.erase("d_kv");
    write_file_atomic(dir / "config.json", config.dump());
    EXPECT_NE(test::error_of([&] { T5Encoder enc(dir); }).find("'d_kv' is missing"), std::string::npos);
  }
  EXPECT_NE(test::error_of([&] { T5Encoder enc(tmp / "nowhere"); }).find("nowhere"), std::string::npos);
}

// The SentencePiece model and the small T5 made here, with the C++ libraries alone.
TEST(T5Text, LoadsASentencePieceModelTrainedHere) {
  test::TempDir tmp;
  const fs::path dir = tmp / "t5-here";
  fs::create_directories(dir);
  std::string text;
  for (const char* time : {"a sunny day", "night", "dusk", "dawn"})
    for (const char* road : {"in the city", "on a country road", "on the motorway"})
      for (const char* move : {"driving straight", "turning left", "turning right", "slowing down"})
        text += std::string(time) + ", " + road + ", " + move + "\n";
  write_file_atomic(tmp / "captions.txt", text);
  text::SentencePiece::train(
      "--input=" + (tmp / "captions.txt").string() + " --model_prefix=" + (dir / "spiece").string() +
      " --vocab_size=60 --hard_vocab_limit=false --model_type=unigram --pad_id=0 --eos_id=1 --unk_id=2 --bos_id=-1"
      " --normalization_rule_name=identity --minloglevel=2");
  ASSERT_TRUE(fs::exists(dir / "spiece.model"));
  text::SentencePiece sp(dir / "spiece.model");
  write_random_t5(dir, sp.size() + 4);

  T5Encoder enc(dir, parse_device(test::device_name()));
  EXPECT_EQ(enc.dim(), 16);
  EXPECT_EQ(enc.config().num_buckets, 8);
  EXPECT_EQ(enc.config().max_distance, 128);  // HF's default where config.json has none
  EXPECT_FALSE(enc.config().gated_gelu);
  EXPECT_EQ(enc.identity().rfind("t5:t5-here:", 0), 0u) << enc.identity();
  const auto ids = enc.tokenize("night, on the motorway, turning left");
  std::vector<int64_t> want = sp.encode("night, on the motorway, turning left");
  want.push_back(T5Encoder::kEos);
  EXPECT_EQ(ids, want);

  const int64_t m = 32;  // longer than every caption: each row ends in padding
  const auto out = enc.encode({"dawn, in the city, turning right", "", "night"}, m);
  ASSERT_EQ(out.sizes(), (std::vector<int64_t>{3, m, 16}));
  EXPECT_TRUE(torch::isfinite(out).all().item<bool>());
  const auto n = static_cast<int64_t>(enc.tokenize("dawn, in the city, turning right").size());
  EXPECT_GT(out[0].slice(0, 0, n).abs().min().item<float>(), 0.0f);
  EXPECT_EQ(out[0].slice(0, n).abs().max().item<float>(), 0.0f);
  EXPECT_EQ(out[1].abs().max().item<float>(), 0.0f);
  EXPECT_FALSE(torch::allclose(out[0][0], out[2][0]));  // different captions, different tokens
}
