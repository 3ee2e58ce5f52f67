#pragma once
// The GPT body of the world model (§2.3, nanoGPT-style): pre-LN blocks of causal self-attention and a 4d MLP.
// Attention keeps an optional key/value cache so that sampling runs one token at a time (§5.1) without
// recomputing the context.
#include <vector>

#include <torch/torch.h>

namespace gaia::world {

// Keys and values of every layer for the tokens seen so far, preallocated to a capacity (the context length), so
// appending a token writes in place instead of copying the cache.
struct KVCache {
  // Per layer: keys transposed [B, H, hd, capacity], so that one query's scores against every cached key are
  // contiguous multiply-adds (no horizontal sums); values [B, H, capacity, hd].
  std::vector<torch::Tensor> k, v;
  int64_t capacity() const { return k.empty() ? 0 : k[0].size(3); }
  int64_t length = 0;               // tokens cached
  // One token per row on a float32 or bf16 CPU cache takes the fused path (attention on raw memory); false forces
  // the general LibTorch path, which tests and benchmarks use as the reference.
  bool fused_single_token = true;
  void reset() { length = 0; }
};

// Sampling's case on raw memory: one new token per row, qkv [B, 3d] float32 (per row q | k | v, each H x hd), its
// key and value written at `offset` of one layer's CPU cache (K [B, H, hd, cap], V [B, H, cap, hd], contiguous,
// float32 or bf16) -> [B, d], the token attending to the cache's first offset + 1 positions.
torch::Tensor attend_one_cached(const torch::Tensor& qkv, torch::Tensor& K, torch::Tensor& V, int64_t offset,
                                int64_t heads);
// The same on raw memory (the fused token step's): qkv [B, 3d], y [B, d], `scores` room for B * H * (offset + 1)
// floats. The cache may also be bf16 (RolloutOptions::precision): its keys and values are read widened to float32.
void attend_one_cached(const float* qkv, int64_t B, int64_t d, int64_t heads, torch::Tensor& K, torch::Tensor& V,
                       int64_t offset, float* scores, float* y);
bool fused_cache(const torch::Tensor& K, const torch::Tensor& V);  // contiguous float32 or bf16 on the CPU

// Softmax of each of `rows` rows of n floats, in place (the cached attention's): exp as a vectorised polynomial,
// within a few units in the last place of std::exp.
void softmax_rows(float* s, int64_t rows, int64_t n);

struct CausalSelfAttentionImpl : torch::nn::Module {
  CausalSelfAttentionImpl(int64_t d, int64_t heads);
  // x [B, L, d] -> [B, L, d]. Without a cache the L tokens attend causally among themselves. With a cache they
  // are appended after cache.length tokens and attend to all of those plus causally among themselves.
  torch::Tensor forward(const torch::Tensor& x, KVCache* cache = nullptr, int layer = 0);
  // Only the keys and values of x [B, L, d], written to the cache after cache.length (what a layer's outputs are
  // not needed for: the last layer when the cache is being filled).
  void append_kv(const torch::Tensor& x, KVCache& cache, int layer);
  int64_t heads, d;
  torch::nn::Linear qkv{nullptr}, proj{nullptr};
};
TORCH_MODULE(CausalSelfAttention);

struct BlockImpl : torch::nn::Module {
  BlockImpl(int64_t d, int64_t heads);
  torch::Tensor forward(const torch::Tensor& x, KVCache* cache = nullptr, int layer = 0);  // [B, L, d] -> same
  void append_kv(const torch::Tensor& x, KVCache& cache, int layer) { attn->append_kv(ln1->forward(x), cache, layer); }
  torch::nn::LayerNorm ln1{nullptr}, ln2{nullptr};
  CausalSelfAttention attn{nullptr};
  torch::nn::Linear fc{nullptr}, fc_proj{nullptr};
};
TORCH_MODULE(Block);

// Activation checkpointing (§4.2): runs the block without keeping its intermediate activations and recomputes them
// in the backward pass, trading ~1/3 more compute for memory that no longer grows with the block's internals.
// Gradients equal the plain forward's (a test checks this).
torch::Tensor checkpointed(Block& block, const torch::Tensor& x);

}  // namespace gaia::world
