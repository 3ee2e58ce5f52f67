#include "gaia/world/io.h"

#include "gaia/core/error.h"
#include "gaia/core/safetensors.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::world {

void save_world(WorldModel& m, const WorldInfo& info, const fs::path& path) {
  Config c = info.config;
  nlohmann::json grid = {{"h", info.grid_h}, {"w", info.grid_w}, {"K", info.K}};
  std::map<std::string, std::string> md{{"gaia.component", "world"}, {"gaia.config", c.to_yaml()},
                                        {"gaia.grid", grid.dump()}, {"gaia.vocab", info.vocab.to_json().dump()}};
  if (info.action_share >= 0) md["gaia.action_share"] = fmt::format("{}", info.action_share);
  if (info.embeds_text()) md["gaia.text_encoder"] = info.text_encoder;
  save_module(*m, path, md);
}

WorldInfo read_world_info(const fs::path& path) {
  WorldInfo info;
  {
    SafetensorsFile f(path);
    auto md = f.metadata();
    if (!md.count("gaia.config") || !md.count("gaia.component") || md.at("gaia.component") != "world")
      fail("{}: not a gaia world model weights file (no gaia.component = world metadata)", path.string());
    info.config.apply_yaml(md.at("gaia.config"), path.string() + " [metadata]");
    info.config.validate();
    try {
      auto g = nlohmann::json::parse(md.at("gaia.grid"));
      info.grid_h = g.at("h").get<int64_t>();
      info.grid_w = g.at("w").get<int64_t>();
      info.K = g.at("K").get<int64_t>();
      info.vocab = text::Vocab::from_json(nlohmann::json::parse(md.at("gaia.vocab")), path.string() + " [gaia.vocab]");
      if (md.count("gaia.text_encoder")) info.text_encoder = md.at("gaia.text_encoder");
      if (md.count("gaia.action_share")) {
        const double a = std::stod(md.at("gaia.action_share"));
        if (!(a >= 0 && a <= 1)) fail("{}: gaia.action_share must be in [0, 1], got {}", path.string(), a);
        info.action_share = a;
      }
    } catch (const nlohmann::json::exception& e) {
      fail("{}: bad gaia.grid / gaia.vocab metadata ({})", path.string(), e.what());
    } catch (const std::out_of_range&) {
      fail("{}: missing gaia.grid / gaia.vocab metadata", path.string());
    } catch (const std::invalid_argument&) {
      fail("{}: gaia.action_share is not a number", path.string());
    }
  }
  return info;
}

WorldModel load_world(const fs::path& path, const torch::Device& device, WorldInfo* info_out) {
  const WorldInfo info = read_world_info(path);
  WorldModel m(info.config.world, info.n(), info.K);
  load_module(*m, path);
  m->to(device);
  m->eval();
  if (info_out) *info_out = info;
  return m;
}

}  // namespace gaia::world
