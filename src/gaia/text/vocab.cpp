#include "gaia/text/vocab.h"

#include <algorithm>

#include "gaia/core/error.h"

namespace gaia::text {

namespace {
const char* const kPadWord = "<pad>";
const char* const kUnknownWord = "<unk>";

// Letters and digits of ASCII, plus every byte of a multi-byte UTF-8 sequence.
bool is_word_byte(unsigned char c) {
  return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c >= 0x80;
}
}  // namespace

Vocab::Vocab() {
  add(kPadWord);
  add(kUnknownWord);
}

void Vocab::add(const std::string& w) {
  ids_.emplace(w, static_cast<int64_t>(words_.size()));
  words_.push_back(w);
}

std::vector<std::string> Vocab::words(const std::string& caption) {
  std::vector<std::string> out;
  std::string cur;
  for (unsigned char c : caption) {
    if (is_word_byte(c)) {
      cur.push_back(c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : static_cast<char>(c));
    } else if (!cur.empty()) {
      out.push_back(std::move(cur));
      cur.clear();
    }
  }
  if (!cur.empty()) out.push_back(std::move(cur));
  return out;
}

void Vocab::count(const std::string& caption, std::map<std::string, int64_t>& counts) {
  for (auto& w : words(caption)) ++counts[w];
}

Vocab Vocab::from_counts(const std::map<std::string, int64_t>& counts, int64_t max_size) {
  if (max_size < 2) fail("vocabulary size must be >= 2 (padding and unknown), got {}", max_size);
  std::vector<std::pair<std::string, int64_t>> order(counts.begin(), counts.end());
  // Frequency descending, ties alphabetically: a total order, so the ids never depend on insertion order.
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) {
    return a.second != b.second ? a.second > b.second : a.first < b.first;
  });
  Vocab v;
  for (auto& [w, n] : order) {
    if (v.size() >= max_size) break;
    if (n > 0) v.add(w);
  }
  return v;
}

Vocab Vocab::build(const std::vector<std::string>& captions, int64_t max_size) {
  std::map<std::string, int64_t> counts;
  for (auto& c : captions) count(c, counts);
  return from_counts(counts, max_size);
}

std::vector<int64_t> Vocab::encode(const std::string& caption, int64_t m) const {
  std::vector<int64_t> out(static_cast<size_t>(std::max<int64_t>(m, 0)), kPad);
  size_t i = 0;
  for (auto& w : words(caption)) {
    if (i == out.size()) break;
    out[i++] = id(w);
  }
  return out;
}

int64_t Vocab::id(const std::string& w) const {
  auto it = ids_.find(w);
  return it == ids_.end() ? kUnknown : it->second;
}

const std::string& Vocab::word(int64_t i) const {
  if (i < 0 || i >= size()) fail("vocabulary has no id {} (size {})", i, size());
  return words_[static_cast<size_t>(i)];
}

nlohmann::json Vocab::to_json() const {
  return {{"format", "gaia-vocab"}, {"version", 1}, {"words", words_}};
}

Vocab Vocab::from_json(const nlohmann::json& j, const std::string& where) {
  std::vector<std::string> words;
  try {
    auto format = j.at("format").get<std::string>();
    if (format != "gaia-vocab") fail("{}: not a gaia vocabulary (format '{}')", where, format);
    int version = j.at("version").get<int>();
    if (version != 1) fail("{}: vocabulary version {} is not supported (this gaia reads 1)", where, version);
    words = j.at("words").get<std::vector<std::string>>();
  } catch (const nlohmann::json::exception& e) {
    fail("{}: bad vocabulary ({})", where, e.what());
  }
  if (words.size() < 2 || words[0] != kPadWord || words[1] != kUnknownWord)
    fail("{}: vocabulary must start with \"{}\", \"{}\"", where, kPadWord, kUnknownWord);
  Vocab v;
  for (size_t i = 2; i < words.size(); ++i) {
    const auto& w = words[i];
    // Only words that words() can produce are reachable; anything else means the JSON was not written by us.
    if (Vocab::words(w) != std::vector<std::string>{w})
      fail("{}: vocabulary word {} '{}' is not a lower-case word", where, i, w);
    if (v.ids_.count(w)) fail("{}: vocabulary word '{}' appears twice", where, w);
    v.add(w);
  }
  return v;
}

}  // namespace gaia::text
