#include "gaia/data/config.h"

namespace gaia {

void add_config_fields(DataConfig& d, std::vector<ConfigField>& f) {
  const auto D = ConfigRole::Data;
  f.push_back(config_field("data.height", &d.height, D, closed(8, 8192)));
  f.push_back(config_field("data.width", &d.width, D, closed(8, 8192)));
  f.push_back(config_field("data.native_fps", &d.native_fps, D, above(0, 1000)));
  f.push_back(config_field("data.world_fps", &d.world_fps, D, above(0, 1000)));
  f.push_back(config_field("data.balance_tokenizer", &d.balance_tokenizer, D));
  f.push_back(config_field("data.balance_world", &d.balance_world, D));
  f.push_back(config_field("data.balance_exponent", &d.balance_exponent, D, closed(0, 1)));
  f.push_back(config_field("data.balance_bins", &d.balance_bins, D, closed(1, 10000)));
}

}  // namespace gaia
