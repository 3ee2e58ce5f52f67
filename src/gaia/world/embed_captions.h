#pragma once
// `gaia text embed` (§2.1): every step's caption of a token dataset through a frozen text encoder (T5), once,
// stored with the dataset as its text embeddings (text_embeddings.h) for `gaia world train` to read.
#include <cstdint>
#include <functional>

#include "gaia/core/fs.h"
#include "gaia/text/encoder.h"

namespace gaia::world {

struct EmbedResult {
  int64_t episodes = 0;   // in the dataset
  int64_t embedded = 0;   // written by this call (0: already there from this encoder)
  int64_t captions = 0;   // distinct captions encoded by this call
};

// Writes TOKENS/episodes/<id>/text_emb.npy ([steps, m, dim]; a step without a caption encodes "") and
// TOKENS/text_emb.json naming the encoder. Embeddings of another encoder or m are replaced. Resumable: while it
// runs, TOKENS/.text_emb.partial.json names the encoder, the dataset reads as having no embeddings, and a second
// call keeps the episodes already written by the same encoder.
EmbedResult embed_captions(const fs::path& tokens, text::TextEncoder& encoder, int64_t m,
                           const std::function<void(int64_t done, int64_t total)>& progress = {});

}  // namespace gaia::world
