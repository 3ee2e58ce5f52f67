#pragma once
// The data side's configuration (§3): YAML section `data:`. Part of gaia::Config (gaia/config.h).
#include <string>
#include <vector>

#include "gaia/core/config_registry.h"

namespace gaia {

struct DataConfig {
  int height = 72;               // paper §4.1: 288 (default is 4x smaller for the CPU)
  int width = 128;               // paper §4.1: 512 (9/16 ratio)
  double native_fps = 25.0;      // paper §3: data at 25 Hz
  double world_fps = 6.25;       // paper §2.3: world model runs at 6.25 Hz
  std::vector<std::string> balance_tokenizer{"latitude", "longitude", "weather"};  // paper §3
  std::vector<std::string> balance_world{"latitude", "longitude", "weather", "steering", "speed"};  // paper §3
  double balance_exponent = 0.5;  // paper §3: 0 = empirical, 1 = uniform; 0.5 used for all features
  int balance_bins = 10;          // bins for continuous features
};

// The section's keys ("data.height", ...) with their roles and ranges, appended to `out`.
void add_config_fields(DataConfig& c, std::vector<ConfigField>& out);

}  // namespace gaia
