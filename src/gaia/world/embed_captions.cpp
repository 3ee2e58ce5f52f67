#include "gaia/world/embed_captions.h"

#include <set>

#include <nlohmann/json.hpp>

#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/world/text_embeddings.h"
#include "gaia/world/token_dataset.h"

namespace gaia::world {

EmbedResult embed_captions(const fs::path& tokens, text::TextEncoder& encoder, int64_t m,
                           const std::function<void(int64_t, int64_t)>& progress) {
  if (!encoder.embeds()) fail("gaia text embed: the {} encoder gives word ids, not embeddings", encoder.identity());
  if (m < 1) fail("text tokens per step (world.text_tokens) must be >= 1, got {}", m);
  if (!fs::exists(tokens / "dataset.json"))
    fail("{}: not a token dataset of gaia tokenize (text embeddings are made from its episodes' captions)",
         tokens.string());
  const std::string id = encoder.identity();
  const fs::path partial = tokens / kTextEmbPartialFile;
  EmbedResult r;
  if (!fs::exists(partial)) {
    const TextEmbInfo have = read_text_emb_info(tokens);
    if (have.defined() && have.encoder == id && have.m == m) {
      r.episodes = int64_t(TokenDataset(tokens).size());
      return r;  // already there
    }
  }
  // Resuming: the episodes an interrupted run of the same encoder wrote are kept.
  bool resume = false;
  if (fs::exists(partial)) {
    const auto j = read_json(partial);
    resume = j.value("encoder", "") == id && j.value("m", int64_t{0}) == m;
  }
  write_file_atomic(partial, nlohmann::json({{"encoder", id}, {"m", m}}).dump() + "\n");
  fs::remove(tokens / kTextEmbInfoFile);
  TokenDataset ds(tokens);  // reads as having no embeddings while the partial record is there
  r.episodes = int64_t(ds.size());
  if (ds.size() == 0) fail("{}: has no episodes to embed the captions of", tokens.string());
  std::set<std::string> distinct;
  int64_t dim = 0;
  for (size_t e = 0; e < ds.size(); ++e) {
    const fs::path dir = ds.episode_dir(e), old = text_emb_file(dir);
    if (resume && old == dir / "text_emb.npy") {  // written atomically, so whole
      if (progress) progress(int64_t(e) + 1, r.episodes);
      continue;
    }
    if (!old.empty()) fs::remove(old);
    auto captions = ds.episode(e)->captions;
    if (captions.empty()) captions.assign(size_t(ds.steps(e)), "");  // no captions: the empty text at every step
    auto emb = encoder.encode_all(captions, m);  // [steps, m, dim]
    dim = emb.size(2);
    write_text_embeddings(dir, emb);
    distinct.insert(captions.begin(), captions.end());
    ++r.embedded;
    if (progress) progress(int64_t(e) + 1, r.episodes);
  }
  if (dim == 0 && ds.size() > 0) dim = encoder.encode("", m).size(1);  // every episode came from the earlier run
  write_text_emb_info(tokens, TextEmbInfo{id, m, dim});
  fs::remove(partial);
  r.captions = int64_t(distinct.size());
  return r;
}

}  // namespace gaia::world
