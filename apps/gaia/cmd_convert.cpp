// gaia convert: re-store a weights file (tokenizer, world model, decoder, probe) with F32 tensors as F16.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"

namespace gaia::app {

void register_convert(CLI::App& app) {
  auto* cmd = app.add_subcommand("convert", "store a safetensors weights file in fp16 (half the size; loaders convert back)");
  auto in = std::make_shared<std::string>(), out = std::make_shared<std::string>();
  auto half = std::make_shared<bool>(false);
  cmd->add_option("WEIGHTS", *in, "safetensors file")->required();
  cmd->add_flag("--half", *half, "store F32 tensors as F16 (the only conversion so far)");
  cmd->add_option("--out", *out, "output file (may be WEIGHTS itself)")->required();
  cmd->callback([=] {
    if (!*half) fail("gaia convert: say --half (storing F32 tensors as F16 is the only conversion)");
    const double err = convert_to_half(*in, *out);
    std::printf("%s -> %s (F16; largest rounding error %.3g)\n", in->c_str(), out->c_str(), err);
  });
}

}  // namespace gaia::app
