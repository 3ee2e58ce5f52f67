#include "gaia/core/config_registry.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "gaia/core/error.h"

namespace gaia {

namespace {

template <typename T> std::string type_name();
template <> std::string type_name<int>() { return "int"; }
template <> std::string type_name<uint64_t>() { return "uint"; }
template <> std::string type_name<double>() { return "float"; }
template <> std::string type_name<bool>() { return "bool"; }
template <> std::string type_name<std::string>() { return "string"; }
template <> std::string type_name<std::vector<int>>() { return "int list"; }
template <> std::string type_name<std::vector<std::string>>() { return "string list"; }

template <typename T> std::string emit(const T& v) {
  YAML::Emitter e;
  e << YAML::Flow << v;
  return e.c_str();
}

// "[+-]digits" (a loop: std::regex recurses per character and a long scalar would overflow the stack).
bool is_decimal_integer(const std::string& s) {
  const size_t start = !s.empty() && (s[0] == '+' || s[0] == '-') ? 1 : 0;
  return s.size() > start && s.size() < 40 &&
         std::all_of(s.begin() + long(start), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A number's check against its key's range; lists check every element.
template <typename T> void check_range(const std::string& key, const T& v, const Range& r) {
  if constexpr (std::is_same_v<T, int> || std::is_same_v<T, double> || std::is_same_v<T, uint64_t>) {
    if (!r.contains(static_cast<double>(v)))
      fail("config key '{}' = {} is out of range: allowed {}", key, emit(v), r.str());
  } else if constexpr (std::is_same_v<T, std::vector<int>>) {
    for (int x : v)
      if (!r.contains(x)) fail("config key '{}' has entry {} out of range: each entry allowed {}", key, x, r.str());
  }
}

template <typename T> ConfigField field(const std::string& key, T* p, ConfigRole role, Range r = {}) {
  ConfigField f;
  f.key = key;
  f.type = type_name<T>();
  f.role = role;
  f.range = r;
  f.get = [p] { return emit(*p); };
  f.check = [p, key, r] { check_range(key, *p, r); };
  f.set = [p, key, r](const std::string& text) {
    T v;
    try {
      YAML::Node n = YAML::Load(text);
      if (n.IsNull()) fail("config key '{}' has no value", key);
      if constexpr (std::is_same_v<T, uint64_t> || std::is_same_v<T, int>) {
        // yaml-cpp reads "0x10" as 16 and wraps "-1" into a huge unsigned; a config number is plain decimal.
        if (!n.IsScalar() || !is_decimal_integer(n.Scalar())) throw YAML::Exception(YAML::Mark(), "");
        if (std::is_same_v<T, uint64_t> && n.Scalar()[0] == '-') throw YAML::Exception(YAML::Mark(), "");
      }
      v = n.as<T>();
      if constexpr (std::is_same_v<T, std::string> || std::is_same_v<T, std::vector<std::string>>) {
        // A control character (a stray "\r") would not survive the YAML this config is saved as.
        const std::vector<std::string> items = [&] {
          if constexpr (std::is_same_v<T, std::string>) return std::vector<std::string>{v};
          else return v;
        }();
        for (auto& item : items)
          for (unsigned char ch : item)
            if (ch < 0x20 || ch == 0x7f) fail("config key '{}' has a control character in '{}'", key, item);
      }
      if constexpr (std::is_same_v<T, double>) {
        if (!(v == v)) fail("config key '{}' is NaN", key);
        if (!std::isfinite(v)) fail("config key '{}' = {} is not finite", key, text);
      }
    } catch (const YAML::Exception&) {
      fail("config key '{}' expects {} but got '{}'", key, type_name<T>(), text);
    }
    check_range(key, v, r);
    *p = v;  // only a value that parsed and is in range replaces the old one
  };
  return f;
}

// Keys are "section.key" at most, so anything deeper is an unknown key; the depth bound also ends a YAML alias that
// refers to itself (`a: &a {b: *a}`) instead of recursing forever.
void flatten(const YAML::Node& node, const std::string& prefix, std::vector<std::pair<std::string, YAML::Node>>* out,
             const std::string& where, int depth = 0) {
  if (node.IsMap() && depth < 3) {
    for (auto it = node.begin(); it != node.end(); ++it) {
      if (!it->first.IsScalar())
        fail("{}:{}: a config key must be a name, not a {}", where, it->first.Mark().line + 1,
             it->first.IsMap() ? "mapping" : "list");
      const std::string k = it->first.Scalar();
      flatten(it->second, prefix.empty() ? k : prefix + "." + k, out, where, depth + 1);
    }
  } else {
    out->emplace_back(prefix, node);
  }
}

}  // namespace

std::string Range::str() const {
  auto num = [](double v) {
    if (std::isinf(v)) return std::string(v < 0 ? "-inf" : "inf");
    return v == std::floor(v) && std::abs(v) < 1e15 ? fmt::format("{:.0f}", v) : fmt::format("{:g}", v);
  };
  return fmt::format("{}{}, {}{}", lo_open || std::isinf(lo) ? "(" : "[", num(lo), num(hi),
                     hi_open || std::isinf(hi) ? ")" : "]");
}

const char* role_name(ConfigRole r) {
  switch (r) {
    case ConfigRole::Architecture: return "architecture";
    case ConfigRole::Training: return "training";
    case ConfigRole::Sampling: return "sampling";
    case ConfigRole::Data: return "data";
    case ConfigRole::Run: return "run";
  }
  return "?";
}

ConfigField config_field(const std::string& key, int* v, ConfigRole role, Range r) { return field(key, v, role, r); }
ConfigField config_field(const std::string& key, uint64_t* v, ConfigRole role, Range r) { return field(key, v, role, r); }
ConfigField config_field(const std::string& key, double* v, ConfigRole role, Range r) { return field(key, v, role, r); }
ConfigField config_field(const std::string& key, bool* v, ConfigRole role) { return field(key, v, role); }
ConfigField config_field(const std::string& key, std::string* v, ConfigRole role) { return field(key, v, role); }
ConfigField config_field(const std::string& key, std::vector<int>* v, ConfigRole role, Range r) {
  return field(key, v, role, r);
}
ConfigField config_field(const std::string& key, std::vector<std::string>* v, ConfigRole role) {
  return field(key, v, role);
}

void apply_config_yaml(std::vector<ConfigField>& fields, const std::string& text, const std::string& where) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    fail("{}:{}: YAML syntax error ({})", where, e.mark.line + 1, e.msg);
  }
  if (root.IsNull()) return;
  if (!root.IsMap()) fail("{}: top level must be a mapping of config keys", where);
  std::vector<std::pair<std::string, YAML::Node>> flat;
  flatten(root, "", &flat, where);
  std::map<std::string, ConfigField*> by_key;
  for (auto& f : fields) by_key[f.key] = &f;
  for (auto& [key, node] : flat) {
    auto it = by_key.find(key);
    int line = node.Mark().line + 1;
    if (it == by_key.end()) fail("{}:{}: unknown config key '{}'", where, line, key);
    try {
      it->second->set(YAML::Dump(node));
    } catch (const Error& e) {
      fail("{}:{}: {}", where, line, e.what());
    } catch (const YAML::Exception& e) {
      fail("{}:{}: config key '{}': {}", where, line, key, e.msg);
    }
  }
}

void set_config_key(std::vector<ConfigField>& fields, const std::string& kv) {
  auto eq = kv.find('=');
  if (eq == std::string::npos) fail("--set '{}': expected key=value", kv);
  std::string key = kv.substr(0, eq), value = kv.substr(eq + 1);
  for (auto& f : fields)
    if (f.key == key) {
      try {
        f.set(value);
      } catch (const Error& e) {
        fail("--set {}: {}", kv, e.what());
      }
      return;
    }
  fail("--set: unknown config key '{}'", key);
}

std::string config_yaml(const std::vector<ConfigField>& fields) {
  // Keys are at most two levels deep ("section.key"), so the YAML is written directly.
  std::string out, section;
  for (auto& f : fields) {
    auto dot = f.key.find('.');
    if (dot == std::string::npos) {
      out += f.key + ": " + f.get() + "\n";
      continue;
    }
    std::string s = f.key.substr(0, dot);
    if (s != section) out += s + ":\n";
    section = s;
    out += "  " + f.key.substr(dot + 1) + ": " + f.get() + "\n";
  }
  return out;
}

std::string replace_yaml_key(const std::string& text, const std::string& key, const std::string& value) {
  YAML::Node root = YAML::Load(text);
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  const auto dot = key.find('.');
  if (dot == std::string::npos)
    root[key] = YAML::Load(value);
  else
    root[key.substr(0, dot)][key.substr(dot + 1)] = YAML::Load(value);
  return YAML::Dump(root) + "\n";
}

}  // namespace gaia
