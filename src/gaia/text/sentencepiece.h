#pragma once
// SentencePiece (T5's tokenizer, §2.1) from Debian's library, loaded apart from the rest of the program
// (spm_module.cpp says why): the module libgaia_spm.so sits beside the gaia binary.
#include <cstdint>
#include <string>
#include <vector>

#include "gaia/core/fs.h"

namespace gaia::text {

class SentencePiece {
 public:
  explicit SentencePiece(const fs::path& model);  // errors name the file
  ~SentencePiece();
  SentencePiece(const SentencePiece&) = delete;
  SentencePiece& operator=(const SentencePiece&) = delete;

  std::vector<int64_t> encode(const std::string& text) const;  // the pieces' ids
  int64_t size() const { return size_; }
  int64_t pad_id() const { return pad_; }
  int64_t eos_id() const { return eos_; }
  int64_t unk_id() const { return unk_; }

  // Trains a model as spm_train does, from its flags ("--input=F --model_prefix=P --vocab_size=N ...").
  static void train(const std::string& flags);

 private:
  void* handle_ = nullptr;
  fs::path path_;
  int64_t size_ = 0, pad_ = -1, eos_ = -1, unk_ = -1;
};

}  // namespace gaia::text
