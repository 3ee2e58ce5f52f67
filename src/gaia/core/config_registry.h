#pragma once
// The machinery behind every config (gaia/config.h): each key is registered once, beside its model
// (tokenizer/config.h, world/config.h, ...), with its dotted key, its role and the values it allows; loading YAML,
// --set overrides, range checks and dumping all go through that one list, so a key cannot be half-supported.
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace gaia {

// The values a numeric key allows (each entry, for a list): [lo, hi], either end open. Checked wherever a value
// arrives: YAML files, --set, a weights file's stored config, and validate() for configs built in code. Upper bounds
// stop a typo from asking for the machine's whole memory.
struct Range {
  double lo = -std::numeric_limits<double>::infinity(), hi = std::numeric_limits<double>::infinity();
  bool lo_open = false, hi_open = false;
  bool contains(double v) const {
    return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi);
  }
  bool bounded() const { return std::isfinite(lo) || std::isfinite(hi); }
  std::string str() const;  // "[1, 1024]", "(0, 1]", "[0, inf)"
};

// Range builders and the ranges many keys share.
constexpr Range closed(double lo, double hi) { return {lo, hi, false, false}; }  // [lo, hi]
constexpr Range above(double lo, double hi) { return {lo, hi, true, false}; }    // (lo, hi]
inline constexpr Range kWeightRange = closed(0, 1e6);           // loss weights
inline constexpr Range kRateRange = closed(0, 10);              // learning rates (0 freezes: fine-tune tests use it)
inline constexpr Range kBetaRange = {0, 1, false, true};        // Adam betas, [0, 1)
inline constexpr Range kDecayRange = {0, 1, false, true};       // EMA decay, dropout, [0, 1)
inline constexpr Range kStepsRange = closed(1, 1e9);
inline constexpr Range kStepsOrZeroRange = closed(0, 1e9);
inline constexpr Range kBatchRange = closed(1, 1 << 20);

// What a key is about. A weights file fixes its model's architecture and records how it was trained; the
// sampling keys say how it is sampled, so a run may override them (--set) and `gaia convert --set` may change the
// file's own.
enum class ConfigRole { Architecture, Training, Sampling, Data, Run };
const char* role_name(ConfigRole r);  // "architecture", ...

struct ConfigField {
  std::string key, type;                        // "world.d_model", "int"
  ConfigRole role = ConfigRole::Run;
  Range range;                                  // allowed values (numbers and int lists; unbounded otherwise)
  std::function<std::string()> get;             // YAML text of the value
  std::function<void(const std::string&)> set;  // parses YAML text; throws gaia::Error on a bad or out-of-range value
  std::function<void()> check;                  // throws gaia::Error if the current value is out of range
};

// One field bound to a value, one overload per value type.
ConfigField config_field(const std::string& key, int* value, ConfigRole role, Range range = {});
ConfigField config_field(const std::string& key, uint64_t* value, ConfigRole role, Range range = {});
ConfigField config_field(const std::string& key, double* value, ConfigRole role, Range range = {});
ConfigField config_field(const std::string& key, bool* value, ConfigRole role);
ConfigField config_field(const std::string& key, std::string* value, ConfigRole role);
ConfigField config_field(const std::string& key, std::vector<int>* value, ConfigRole role, Range range = {});
ConfigField config_field(const std::string& key, std::vector<std::string>* value, ConfigRole role);

// YAML text (a file's, or a weights file's stored config) into the fields; `where` names it in errors, with the
// line: "FILE:3: unknown config key 'a.b'".
void apply_config_yaml(std::vector<ConfigField>& fields, const std::string& text, const std::string& where);
// "--set key=value".
void set_config_key(std::vector<ConfigField>& fields, const std::string& key_eq_value);
// The fields as YAML, one "section:" block per dotted prefix, in registration order.
std::string config_yaml(const std::vector<ConfigField>& fields);
// `text` (YAML) with one key replaced by `value` (YAML text as a field's get() writes it); other keys untouched.
std::string replace_yaml_key(const std::string& text, const std::string& key, const std::string& value);

}  // namespace gaia
