#pragma once
// Word vocabulary of the built-in text encoder (the small stand-in for the paper's T5-large, §2.1): captions are
// lower-cased and split on anything that is not a letter or digit; the most frequent words of the training
// captions get ids, everything else is "unknown". Each step's caption becomes exactly m ids (paper §2.1: m tokens
// per step), which the world model's word embedding turns into text tokens c_t.
//
//   id 0 = padding (also the whole caption when a step has none), id 1 = unknown word, ids 2.. = words ordered by
//   frequency (descending), then alphabetically, so the same captions always give the same ids.
//
// The vocabulary is stored as JSON in the world model's safetensors metadata, so a model carries its own words.
#include <cstdint>
#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include <nlohmann/json.hpp>

namespace gaia::text {

class Vocab {
 public:
  static constexpr int64_t kPad = 0, kUnknown = 1;

  Vocab();  // only padding and unknown

  // Words of a caption: ASCII letters lower-cased; split on every ASCII character that is not a letter or digit.
  // Bytes >= 0x80 count as letters, so UTF-8 words ("café") stay whole instead of being cut into pieces.
  static std::vector<std::string> words(const std::string& caption);
  static void count(const std::string& caption, std::map<std::string, int64_t>& counts);  // adds words(caption)
  // The most frequent words, at most max_size ids in all (padding and unknown included; max_size >= 2).
  static Vocab from_counts(const std::map<std::string, int64_t>& counts, int64_t max_size);
  static Vocab build(const std::vector<std::string>& captions, int64_t max_size);

  // Exactly m ids: the caption's words in order, truncated to m, padded with kPad.
  std::vector<int64_t> encode(const std::string& caption, int64_t m) const;
  int64_t id(const std::string& word) const;  // kUnknown when absent (the word as words() gives it)
  const std::string& word(int64_t id) const;  // "<pad>", "<unk>" for the reserved ids
  int64_t size() const { return static_cast<int64_t>(words_.size()); }

  // {"format": "gaia-vocab", "version": 1, "words": ["<pad>", "<unk>", w2, w3, ...]} (index = id).
  nlohmann::json to_json() const;
  static Vocab from_json(const nlohmann::json& j, const std::string& where);  // errors name `where`

  bool operator==(const Vocab& o) const { return words_ == o.words_; }

 private:
  void add(const std::string& w);
  std::vector<std::string> words_;
  std::unordered_map<std::string, int64_t> ids_;
};

}  // namespace gaia::text
