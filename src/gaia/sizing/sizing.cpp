#include "gaia/sizing/sizing.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>

#include <fmt/format.h>

#include "gaia/core/error.h"
#include "gaia/decoder/tasks.h"
#include "gaia/eval/metrics.h"

namespace gaia::sizing {

namespace {

// Parameter counts of the building blocks (weights + biases), as constructed by the model code.
int64_t conv(int64_t cin, int64_t cout, int64_t k) { return cin * cout * k * k + cout; }
int64_t group_norm(int64_t c) { return 2 * c; }
int64_t linear(int64_t in, int64_t out, bool bias = true) { return in * out + (bias ? out : 0); }
int64_t layer_norm(int64_t d) { return 2 * d; }

// ResNet block: GN, conv3x3, GN, conv3x3, 1x1 skip when widths differ; `emb` > 0 adds a FiLM projection
// of the diffusion-time embedding (scale and shift).
int64_t res_block(int64_t cin, int64_t cout, int64_t emb = 0) {
  int64_t p = group_norm(cin) + conv(cin, cout, 3) + group_norm(cout) + conv(cout, cout, 3);
  if (cin != cout) p += conv(cin, cout, 1);
  if (emb > 0) p += linear(emb, 2 * cout);
  return p;
}

// Multi-head self-attention over channels c with a GroupNorm in front (U-Net style).
int64_t attention(int64_t c) { return group_norm(c) + linear(c, 3 * c) + linear(c, c); }

}  // namespace

ParamCount tokenizer_params(const Config& cfg) {
  const auto& t = cfg.tokenizer;
  const int L = static_cast<int>(t.channel_mult.size());
  int64_t p = 0;
  // Encoder: conv_in, per level res_blocks ResBlocks then a stride-2 conv (not after the last level),
  // two middle ResBlocks, GN + conv_out to z_channels.
  int64_t c = int64_t(t.channels) * t.channel_mult[0];
  p += conv(3, c, 3);
  for (int i = 0; i < L; ++i) {
    int64_t co = int64_t(t.channels) * t.channel_mult[static_cast<size_t>(i)];
    for (int r = 0; r < t.res_blocks; ++r) { p += res_block(c, co); c = co; }
    if (i + 1 < L) p += conv(c, c, 3);
  }
  p += 2 * res_block(c, c) + group_norm(c) + conv(c, t.z_channels, 3);
  // Quantiser (Yu et al. 2022): linear projection to code_dim, codebook K x code_dim, projection back.
  int64_t codebook = int64_t(t.codebook_size) * t.code_dim;
  p += linear(t.z_channels, t.code_dim) + codebook + linear(t.code_dim, t.z_channels);
  // Decoder mirrors the encoder with res_blocks + 1 blocks per level and nearest-upsample + conv.
  p += conv(t.z_channels, c, 3) + (2 + t.token_blocks) * res_block(c, c);
  for (int i = L - 1; i >= 0; --i) {
    int64_t co = int64_t(t.channels) * t.channel_mult[static_cast<size_t>(i)];
    for (int r = 0; r < t.res_blocks + 1; ++r) { p += res_block(c, co); c = co; }
    if (i > 0) p += conv(c, c, 3);
  }
  p += t.refine_blocks * res_block(c, c) + group_norm(c) + conv(c, 3, 3);
  ParamCount out;
  out.total = p;
  out.non_embedding = p - codebook;
  return out;
}

int64_t discriminator_params(const Config& cfg) {
  // PatchGAN (Isola et al.): conv4x4 3->C, then layers of conv4x4 doubling width (capped at 8C) with GN,
  // and a final conv4x4 to one logit per patch.
  const auto& t = cfg.tokenizer;
  int64_t c = t.disc_channels, p = conv(3, c, 4);
  for (int i = 1; i <= t.disc_layers; ++i) {
    int64_t co = int64_t(t.disc_channels) * std::min(1 << i, 8);
    p += (c * co * 16) + group_norm(co);  // convs before a norm carry no bias
    c = co;
  }
  return p + conv(c, 1, 4);
}

ParamCount world_params(const Config& cfg) {
  const auto& w = cfg.world;
  const int64_t d = w.d_model, K = cfg.tokenizer.codebook_size;
  const int64_t n = cfg.image_tokens(), m = w.text_tokens, l = w.action_tokens;
  // Embeddings (paper §2.1): image token embedding, text linear layer (text_dim -> d), one linear layer per
  // action scalar (1 -> d), learned null tokens for dropped text / actions, T temporal + (m + n + l) spatial.
  int64_t emb = K * d + linear(w.text_dim, d) + l * linear(1, d) + (m + l) * d + int64_t(w.context_steps) * d +
                (m + n + l) * d;
  if (w.action_mlp > 0) emb += l * (linear(1, w.action_mlp) + linear(w.action_mlp, d));  // world.action_mlp
  // Pre-LN GPT block: LN, causal self-attention (qkv + proj), LN, 4d MLP.
  int64_t block = layer_norm(d) + linear(d, 3 * d) + linear(d, d) + layer_norm(d) + linear(d, 4 * d) + linear(4 * d, d);
  int64_t body = w.n_layers * block + layer_norm(d);
  int64_t head = linear(d, K, false);
  ParamCount out;
  out.non_embedding = body;  // Kaplan's N excludes embeddings (and the tied-size output head)
  out.total = emb + body + head;
  return out;
}

namespace {

bool at_level(const std::vector<int>& levels, int level) {
  return std::find(levels.begin(), levels.end(), level) != levels.end();
}

// The 3D U-Net of decoder/unet.cpp in build order, the one walk both counts take: `conv(level, cin, cout, k)` for
// each convolution outside a layer (level: the resolution it runs at), `layer(level, cin, cout)` for each residual
// block with the attention its level carries. The output convolution (before it, a GroupNorm) is the last conv.
template <class Conv, class Layer>
void walk_unet(const Config& cfg, Conv conv_at, Layer layer) {
  const auto& v = cfg.decoder;
  const int L = static_cast<int>(v.channel_mult.size());
  const int64_t ch = v.channels, E = v.token_embed_dim;
  auto width = [&](int level) { return ch * v.channel_mult[static_cast<size_t>(level)]; };
  // Input: noisy frame (3) + context mask (1) + upsampled token embedding (E) [+ tokenizer-decoded image (3)].
  int64_t c = width(0);
  conv_at(0, 3 + 1 + E + (v.cond_image ? 3 : 0), c, 3);
  std::vector<int64_t> skips{c};
  for (int i = 0; i < L; ++i) {
    conv_at(i, E, c, 1);  // the token embedding added at the start of each level
    for (int r = 0; r < v.res_blocks; ++r) {
      layer(i, c, width(i));
      c = width(i);
      skips.push_back(c);
    }
    if (i + 1 < L) {
      conv_at(i + 1, c, c, 3);  // stride 2: it runs at the next level's pixels
      skips.push_back(c);
    }
  }
  layer(L - 1, c, c);
  layer(L - 1, c, c);
  for (int i = L - 1; i >= 0; --i) {
    for (int r = 0; r < v.res_blocks + 1; ++r) {
      const int64_t skip = skips.back();
      skips.pop_back();
      layer(i, c + skip, width(i));
      c = width(i);
    }
    if (i > 0) conv_at(i - 1, c, c, 3);  // after a nearest 2x upsampling
  }
  conv_at(0, c, 3, 3);
}

}  // namespace

ParamCount decoder_params(const Config& cfg) {
  // A test checks the count against the built model.
  const auto& v = cfg.decoder;
  const int64_t ch = v.channels, emb = 4 * ch, E = v.token_embed_dim;
  // Factorised attention (Ho et al. 2022): temporal attention across frames at temporal_levels (LayerNorm, qkv,
  // proj, a relative-position bias of 2T'-1 entries per head), spatial attention within a frame at attn_levels.
  auto temporal = [&](int64_t c) { return layer_norm(c) + linear(c, 3 * c) + linear(c, c) + int64_t(2 * v.frames - 1) * v.heads; };
  int64_t p = 0;
  const int64_t token_embedding = int64_t(cfg.tokenizer.codebook_size + 1) * E;  // +1: the "no token" embedding
  p += token_embedding;
  p += linear(ch, emb) + linear(emb, emb);  // diffusion-time MLP on a sinusoidal embedding
  p += 3 * emb;                              // frame-rate embedding: 6.25 / 12.5 / 25 Hz
  walk_unet(
      cfg, [&](int, int64_t cin, int64_t cout, int k) { p += conv(cin, cout, k); },
      [&](int level, int64_t cin, int64_t cout) {
        p += res_block(cin, cout, emb) + (at_level(v.attn_levels, level) ? attention(cout) : 0) +
             (at_level(v.temporal_levels, level) ? temporal(cout) : 0);
      });
  p += group_norm(ch * v.channel_mult[0]);  // before the output convolution
  ParamCount out;
  out.total = p;
  out.non_embedding = p - token_embedding;
  return out;
}

Plan make_plan(const Config& c) {
  Plan p;
  p.tokenizer = tokenizer_params(c);
  p.discriminator = discriminator_params(c);
  p.world = world_params(c);
  p.decoder = decoder_params(c);
  p.image_tokens = c.image_tokens();
  p.sequence_length = c.sequence_length();
  p.bit_compression = eval::bit_compression(c.data.height, c.data.width, p.image_tokens, c.tokenizer.codebook_size);
  const double N = double(p.world.non_embedding), s = double(p.sequence_length), d = c.world.d_model;
  const double L = c.world.n_layers;
  p.world_flops_per_token = 6 * N;
  p.world_flops_per_token_with_attn = 6 * N + 6 * L * s * d;
  const double GB = 1e9;
  p.world_weights_gb = 4.0 * p.world.total / GB;
  p.world_train_state_gb = 16.0 * p.world.total / GB;
  // One sequence in bf16 with fused attention (world_train_memory; close to Korthikanti et al. 2022's 34 s d bytes
  // per layer).
  TrainMemorySettings one;
  one.activation_bytes = 2;
  one.fused_attention = true;
  p.world_act_gb_per_seq = world_train_memory(c, one).activations / GB;
  one.checkpointing = true;
  p.world_act_ckpt_gb_per_seq = world_train_memory(c, one).activations / GB;
  p.tokenizer_weights_gb = 4.0 * p.tokenizer.total / GB;
  p.decoder_weights_gb = 4.0 * p.decoder.total / GB;
  return p;
}

InferenceFlops inference_flops(const Config& c, int rows) {
  InferenceFlops f;
  const auto& w = c.world;
  const double d = w.d_model, K = c.tokenizer.codebook_size, layers = w.n_layers;
  const double m = w.text_tokens, n = c.image_tokens(), l = w.action_tokens, S = m + n + l, T = w.context_steps;
  // A block: qkv 3d^2, proj d^2, MLP 8d^2 multiply-adds a token; attention 2 d a key (scores and values, all heads).
  const double block = 12 * d * d, kv = 2 * d * d;
  auto attend = [&](double keys) { return 2 * d * keys; };
  // Sampling in a full window: the current step sits at T - 1, its token i after (T - 1) S + m + i earlier ones.
  double tokens = 0;
  for (int64_t i = 0; i < int64_t(n); ++i) tokens += layers * (block + attend((T - 1) * S + m + i + 1)) + d * K;
  f.world_token = 2 * tokens / n;
  // The step's text through every block (the last position's logits predict token 0), its actions appended to
  // the cache (the last block's keys and values only, as WorldModel::prefill).
  double text = 0;
  for (int64_t i = 0; i < int64_t(m); ++i) text += layers * (block + attend((T - 1) * S + i + 1));
  const double actions = l * ((layers - 1) * block + kv) + (layers - 1) * l * attend(T * S);
  f.world_frame_sampling = 2 * rows * (tokens + text + d * K + actions);
  // Re-encoding: L = (T - 1) S positions; every block but the last attends causally, the last stores keys and values.
  const double L = (T - 1) * S;
  f.world_frame_reencode = 2 * rows * (L * ((layers - 1) * block + kv) + (layers - 1) * 2 * d * L * (L + 1) / 2);

  // The video decoder, the U-Net walk of decoder_params: per level, its pixels over T' frames.
  const auto& v = c.decoder;
  const double frames = v.frames;
  auto pixels = [&](int level) { return double(c.data.height >> level) * double(c.data.width >> level); };
  const double ch = v.channels, emb = 4 * ch;
  double macs = frames * (ch * emb + emb * emb);  // diffusion-time MLP
  auto conv_at = [&](int level, double cin, double cout, double k) {
    macs += frames * pixels(level) * cin * cout * k * k;
  };
  walk_unet(
      c, [&](int level, int64_t cin, int64_t cout, int k) { conv_at(level, double(cin), double(cout), k); },
      [&](int level, int64_t cin_, int64_t cout_) {
        const double cin = double(cin_), cout = double(cout_), px = pixels(level);
        conv_at(level, cin, cout, 3);
        conv_at(level, cout, cout, 3);
        if (cin != cout) conv_at(level, cin, cout, 1);
        macs += frames * emb * 2 * cout;  // FiLM
        // Attention within a frame (px keys), across frames (T' keys): qkv and proj 4c^2, scores and values 2c a key.
        if (at_level(v.attn_levels, level)) macs += frames * px * (4 * cout * cout + 2 * px * cout);
        if (at_level(v.temporal_levels, level)) macs += frames * px * (4 * cout * cout + 2 * frames * cout);
      });
  f.decoder_window = 2 * macs;
  // Windows a second: backward ones advance T' - 2 frames at the token rate (decoder::kOverlapFrames), upsampling
  // ones T' - 1 frames at 12.5 and at 25 Hz; only the backward windows hold frames with tokens.
  const double fps = c.data.world_fps, per_window = v.ddim_steps * f.decoder_window;
  f.decoder_video_second = per_window * ((1 + v.mix_probability) * fps / (frames - decoder::kOverlapFrames) +
                                         (2 * fps + 4 * fps) / (frames - 1));
  return f;
}

namespace {
std::string flop(double v) {  // SI prefixes: 7.69 MFLOP, 4.79 TFLOP
  const char* prefix[] = {"", "k", "M", "G", "T", "P", "E"};
  int i = 0;
  for (; i < 6 && v >= 1000; ++i) v /= 1000;
  return fmt::format("{:.3g} {}FLOP", v, prefix[i]);
}

std::string human(double v) {
  if (v >= 1e9) return fmt::format("{:.2f}B", v / 1e9);
  if (v >= 1e6) return fmt::format("{:.2f}M", v / 1e6);
  if (v >= 1e3) return fmt::format("{:.1f}K", v / 1e3);
  return fmt::format("{:.0f}", v);
}
}  // namespace

std::string format_plan(const Plan& p, const Config& c) {
  std::string s;
  s += fmt::format("config: {}   image {}x{}, D={}, K={}, n={} tokens/frame ({}x{})\n", c.name, c.data.height,
                   c.data.width, c.tokenizer.downsample, c.tokenizer.codebook_size, p.image_tokens, c.tokens_h(),
                   c.tokens_w());
  s += fmt::format("\n{:<28}{:>14}{:>16}{:>14}\n", "component", "parameters", "non-embedding", "fp32 weights");
  s += fmt::format("{:<28}{:>14}{:>16}{:>11.2f} GB\n", "image tokenizer (enc+dec)", human(p.tokenizer.total),
                   human(p.tokenizer.non_embedding), p.tokenizer_weights_gb);
  s += fmt::format("{:<28}{:>14}{:>16}{:>14}\n", "  discriminator (training)", human(p.discriminator), "", "");
  s += fmt::format("{:<28}{:>14}{:>16}{:>11.2f} GB\n", "world model", human(p.world.total),
                   human(p.world.non_embedding), p.world_weights_gb);
  s += fmt::format("{:<28}{:>14}{:>16}{:>11.2f} GB\n", "video decoder (3D U-Net)", human(p.decoder.total),
                   human(p.decoder.non_embedding), p.decoder_weights_gb);
  s += fmt::format("\nworld model: d={}, layers={}, heads={}, T={} steps at {} Hz\n", c.world.d_model,
                   c.world.n_layers, c.world.n_heads, c.world.context_steps, c.data.world_fps);
  s += fmt::format("  sequence length  T (m + n + l) = {} x ({} + {} + {}) = {}\n", c.world.context_steps,
                   c.world.text_tokens, p.image_tokens, c.world.action_tokens, p.sequence_length);
  s += fmt::format("  FLOPs per token  6N = {:.3g}   (with attention 6N + 6Lsd = {:.3g})\n", p.world_flops_per_token,
                   p.world_flops_per_token_with_attn);
  s += fmt::format("  training state   {:.1f} GB (bf16 weights+grads, fp32 master+Adam m,v: 16 B/param)\n",
                   p.world_train_state_gb);
  s += fmt::format("  activations      {:.2f} GB/sequence (bf16, FlashAttention); {:.2f} GB with checkpointing\n",
                   p.world_act_gb_per_seq, p.world_act_ckpt_gb_per_seq);
  const auto f = inference_flops(c, 2);
  s += fmt::format("  inference        {} a sampled token (one row, full context); a closed-loop frame with\n"
                   "                   guidance (2 rows): {} sampling + {} re-encoding the window (§2.3)\n",
                   flop(f.world_token), flop(f.world_frame_sampling), flop(f.world_frame_reencode));
  s += fmt::format("video decoder: {} a U-Net pass over T' = {} frames; {} a second of {:g} Hz video at {} DDIM\n"
                   "  steps (decoder.ddim_steps)\n",
                   flop(f.decoder_window), c.decoder.frames, flop(f.decoder_video_second), 4 * c.data.world_fps,
                   c.decoder.ddim_steps);
  s += fmt::format("tokenizer bit compression  H W 3 8 / (n log2 K) = {:.1f}\n", p.bit_compression);
  return s;
}

TrainMemorySettings train_memory_settings(const Config& c, int ranks, int accumulate, bool shard_optimizer,
                                          bool fused_attention, bool shard_gradients) {
  TrainMemorySettings m;
  m.ranks = std::max(1, ranks);
  m.micro_batch = std::max<int64_t>(1, c.world.batch_size / (int64_t(m.ranks) * std::max(1, accumulate)));
  m.shard_optimizer = (shard_optimizer || shard_gradients) && m.ranks > 1;
  m.shard_gradients = shard_gradients && m.ranks > 1;
  m.activation_bytes = c.run.precision == "fp32" ? 4 : 2;
  m.fused_attention = fused_attention;
  m.checkpointing = c.world.activation_checkpointing;
  return m;
}

TrainMemory world_train_memory(const Config& c, const TrainMemorySettings& m) {
  TrainMemory t;
  const double N = double(world_params(c).total), f = 4, e = m.activation_bytes;
  const double B = double(m.micro_batch), s = double(c.sequence_length()), d = c.world.d_model;
  const double L = c.world.n_layers, H = c.world.n_heads, K = c.tokenizer.codebook_size;
  t.weights = f * N;  // float32 master weights
  // ZeRO-2 keeps the gradients of this rank's share and their buckets only (train/grad_reducer.h): at the start of
  // the backward pass the others' were freed after the last step.
  const double share = m.shard_gradients ? m.ranks : 1;
  t.grads = f * N / share;
  t.optimizer = 2 * f * N / (m.shard_optimizer ? m.ranks : 1);  // AdamW's m and v
  t.buckets = m.ranks > 1 ? f * N / share : 0;                  // the flat all-reduce buffers (train/grad_reducer.h)
  // Saved for the backward pass per layer (world/transformer.cpp): the float32 residual stream at both norms, the
  // two norms' outputs, q, k, v, the heads' output, the MLP's hidden layer before and after the GELU:
  // s B d (2 f + 14 e); and the attention probabilities, H s^2 B in e bytes (the CPU's causal softmax keeps them in
  // the scores' dtype, torch/causal_softmax.h), which fused attention replaces by one float per query and head.
  const double per_layer_states = s * B * d * (2 * f + 14 * e);
  const double scores = m.fused_attention ? H * s * B * f : H * s * s * B * e;
  const double layer = per_layer_states + scores;
  // Checkpointing keeps each layer's input and recomputes one layer at a time. Unfused attention's backward pass
  // holds two more tensors of the probabilities' size at once (their gradient and the scores') while every earlier
  // layer's activations are still kept.
  const double transient = m.fused_attention ? 0 : 2 * H * s * s * B * e;
  t.activations = (m.checkpointing ? L * s * B * d * f + layer : L * layer) + 3 * s * B * d * f + transient;
  // The image tokens' distribution over K codes: the logits (e), their float32 log-softmax, and in the backward pass
  // the gradients of both.
  const double image_positions = double(c.world.context_steps) * c.image_tokens() * B;
  t.logits = image_positions * K * (e + 3 * f);
  return t;
}

std::string format_train_memory(const TrainMemory& t, const TrainMemorySettings& m) {
  auto bytes = [](double v) {
    if (v >= 1e9) return fmt::format("{:.2f} GB", v / 1e9);
    if (v >= 1e6) return fmt::format("{:.0f} MB", v / 1e6);
    return fmt::format("{:.0f} KB", v / 1e3);
  };
  std::string s = fmt::format(
      "  training memory  per rank at its peak, micro-batch {} x {} rank(s), {}, {} attention{}{}:\n", m.micro_batch,
      m.ranks, m.activation_bytes == 4 ? "fp32" : "16-bit autocast", m.fused_attention ? "fused" : "unfused",
      m.shard_gradients ? ", sharded AdamW and gradients" : m.shard_optimizer ? ", sharded AdamW" : "", m.checkpointing ? ", activation checkpointing" : "");
  s += fmt::format("    weights {} + gradients {} + AdamW {}{} + activations {} + output distribution {} = {}\n",
                   bytes(t.weights), bytes(t.grads), bytes(t.optimizer),
                   t.buckets > 0 ? " + all-reduce buffers " + bytes(t.buckets) : "", bytes(t.activations),
                   bytes(t.logits), bytes(t.total()));
  return s;
}

namespace {
// A field of /proc/self/status in kB, as bytes (0 where the system has none).
double status_bytes(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return std::atof(line.c_str() + field.size() + 1) * 1024.0;
  return 0;
}
}  // namespace

double resident_bytes() { return status_bytes("VmRSS"); }
double peak_resident_bytes() { return status_bytes("VmHWM"); }

double rollout_memory_bytes(const Config& c, int64_t futures, int64_t steps, int passes, bool preview) {
  const double B = double(futures) * std::max(passes, 1);
  const double kv = 2.0 * c.world.n_layers * double(c.sequence_length()) * c.world.d_model * 4.0 * B;
  const double logits = 4.0 * c.tokenizer.codebook_size * B * 4.0;  // a few copies while sampling
  const double tokens = 8.0 * 2 * double(futures) * steps * c.image_tokens();
  const double frames = preview ? 2.0 * double(futures) * steps * c.data.height * c.data.width * 3 : 0;
  return kv + logits + tokens + frames;
}

double available_memory_bytes() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  double kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit)
    if (key == "MemAvailable:") return kb * 1024.0;
  return 0;
}

void check_memory(double bytes, const std::string& what) {
  const double have = available_memory_bytes();
  if (have > 0 && bytes > have)
    fail("{} would need about {:.1f} GB of memory, but {:.1f} GB are available", what, bytes / 1e9, have / 1e9);
}

}  // namespace gaia::sizing
