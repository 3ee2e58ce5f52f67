#include "gaia/data/mirror.h"

#include <cctype>

#include "gaia/core/text.h"

namespace gaia::data {

std::string mirrored_id(const std::string& id) { return id + kMirrorSuffix; }

std::string mirror_source_id(const std::string& id) {
  const std::string suffix = kMirrorSuffix;
  if (id.size() > suffix.size() && id.compare(id.size() - suffix.size(), suffix.size(), suffix) == 0)
    return id.substr(0, id.size() - suffix.size());
  return id;
}

namespace {
bool is_letter(char c) { return std::isalpha(static_cast<unsigned char>(c)) != 0; }

// The word after position `end` (skipping non-letters), lower-cased; "" at the end of the text.
std::string next_word(const std::string& t, size_t end) {
  size_t a = end;
  while (a < t.size() && !is_letter(t[a])) ++a;
  size_t b = a;
  while (b < t.size() && is_letter(t[b])) ++b;
  return lower(t.substr(a, b - a));
}

// Keeps the source word's capitalisation pattern: "left" / "Left" / "LEFT".
std::string recase(const std::string& like, std::string w) {
  bool all_upper = true;
  for (char c : like) all_upper = all_upper && std::isupper(static_cast<unsigned char>(c));
  for (size_t i = 0; i < w.size(); ++i)
    if (all_upper || (i == 0 && std::isupper(static_cast<unsigned char>(like[0]))))
      w[i] = static_cast<char>(std::toupper(static_cast<unsigned char>(w[i])));
  return w;
}
}  // namespace

std::string mirror_words(const std::string& text) {
  // "right behind" means "directly behind", not a side (synth captions say "right behind a bus"). Only that one:
  // "right ahead" or "right in 50 m" are directions in driving text ("turn right ahead").
  std::string out;
  out.reserve(text.size() + 8);
  size_t i = 0;
  while (i < text.size()) {
    if (!is_letter(text[i])) { out += text[i++]; continue; }
    size_t j = i;
    while (j < text.size() && is_letter(text[j])) ++j;
    const std::string word = text.substr(i, j - i), w = lower(word);
    if (w == "left") {
      out += recase(word, "right");
    } else if (w == "right") {
      out += next_word(text, j) == "behind" ? word : recase(word, "left");
    } else {
      out += word;
    }
    i = j;
  }
  return out;
}

nlohmann::json mirror_labels(const nlohmann::json& labels) {
  nlohmann::json m = labels;
  for (auto it = m.begin(); it != m.end(); ++it) {
    if (it->is_string()) *it = mirror_words(it->get<std::string>());
    else if ((it.key() == "curvature" || it.key() == "lane_offset_m") && it->is_number()) *it = -it->get<double>();
  }
  return m;
}

}  // namespace gaia::data
