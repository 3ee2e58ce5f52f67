#include "gaia/decoder/io.h"

#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::decoder {

void save_decoder(const VideoUNet& m, const Config& c, const fs::path& path, bool half) {
  Config copy = c;
  save_module(*m, path,
              {{"gaia.component", "decoder"}, {"gaia.config", copy.to_yaml()}, {"gaia.decoder.K", std::to_string(m->K)},
               {"gaia.decoder.D", std::to_string(m->D)}},
              half);
}

VideoUNet load_decoder(const fs::path& path, const torch::Device& device, Config* config_out) {
  Config c;
  int64_t K = 0, D = 0;
  {
    SafetensorsFile f(path);
    auto md = f.metadata();
    if (!md.count("gaia.config") || md["gaia.component"] != "decoder" || !md.count("gaia.decoder.K"))
      fail("{}: not a gaia video decoder weights file (no decoder metadata)", path.string());
    // Decoders saved before decoder.interp_base existed were trained with zero coarse frames between known ones:
    // their metadata has no such key, so the value set here stays; newer files set it themselves.
    c.decoder.interp_base = false;
    // Files saved before decoder.start_time existed have no such key: they take the default start, except a
    // decoder without a coarse frame (the paper's setting), which can only start from pure noise.
    const double default_start = c.decoder.start_time;
    c.decoder.start_time = -1;
    c.apply_yaml(md["gaia.config"], path.string() + " [metadata]");
    if (c.decoder.start_time == -1) c.decoder.start_time = c.decoder.cond_image ? default_start : 1.0;
    c.validate();
    try {
      K = std::stoll(md["gaia.decoder.K"]);
      D = std::stoll(md["gaia.decoder.D"]);
    } catch (const std::exception&) {
      fail("{}: metadata gaia.decoder.K / gaia.decoder.D are not integers", path.string());
    }
  }
  VideoUNet m(c.decoder, K, D);
  load_module(*m, path);
  m->to(device);
  m->eval();
  if (config_out) *config_out = c;
  return m;
}

}  // namespace gaia::decoder
