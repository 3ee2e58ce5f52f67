#include "common.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>

#include <algorithm>
#include <cmath>
#include <regex>

#include <nlohmann/json.hpp>
#ifndef GAIA_NO_VIDEO
#include <opencv2/core.hpp>
#endif

#include "gaia/core/error.h"
#include "gaia/core/npy.h"
#include "gaia/core/safetensors.h"
#ifndef GAIA_NO_VIDEO
#include "gaia/data/motion.h"
#endif
#include "gaia/torch/tensor_io.h"
#include "gaia/world/io.h"
#include "gaia/world/token_file.h"

namespace gaia::app {

int run_gaia_child(const std::vector<std::string>& args) {
  std::error_code ec;
  const std::string exe = fs::read_symlink("/proc/self/exe", ec).string();
  if (ec) fail("cannot find the gaia binary to run '{}' ({})", args.empty() ? "" : args[0], ec.message());
  std::vector<char*> argv{const_cast<char*>(exe.c_str())};
  for (auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  std::fflush(stdout);
  const pid_t pid = fork();
  if (pid < 0) fail("fork failed");
  if (pid == 0) {
    execv(exe.c_str(), argv.data());
    _exit(127);
  }
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

std::string g_command_line = "gaia";

void add_shared_flags(CLI::App* cmd, SharedFlags* f, const std::string& out_help, WithPrecision precision) {
  cmd->add_option("--config", f->config, "YAML config (configs/tiny.yaml, default.yaml, paper.yaml); default: built-in default");
  cmd->add_option("--set", f->sets, "override a config key, e.g. --set world.d_model=512 (repeatable)");
  cmd->add_option("--device", f->device, "cpu | cuda | cuda:N (default: config run.device)");
  if (precision == WithPrecision::kYes)
    cmd->add_option("--precision", f->precision,
                    "fp32 | bf16 | fp16: mixed precision of training and sampling (default: config run.precision)");
  cmd->add_option("--threads", f->threads, "CPU threads (0 = all cores)");
  cmd->add_option("--seed", f->seed, "random seed (default: config run.seed)");
  cmd->add_option("--out", f->out, out_help);
}

std::string weights_flag_name(Weights which) {
  static const char* names[] = {"--tokenizer", "--world", "--decoder", "--probe", "--t5"};
  return names[static_cast<int>(which)];
}

std::string weights_flag_help(Weights which, const std::string& use) {
  static const char* what[] = {"tokenizer weights (tokenizer.safetensors)", "world model weights (world.safetensors)",
                               "video decoder weights (decoder.safetensors)", "probe weights (probe-KIND.safetensors)",
                               "frozen T5 text encoder (a Hugging Face folder: config.json, model.safetensors, spiece.model)"};
  const std::string w = what[static_cast<int>(which)];
  return use.empty() ? w : w + ": " + use;
}

std::shared_ptr<OldSpelling> add_old_spelling(CLI::App* cmd, const std::string& name, const std::string& use) {
  auto o = std::make_shared<OldSpelling>();
  o->name = name;
  o->use = use;
  o->option = cmd->add_option(name, o->value, "old spelling of " + use)->group("");  // group "" hides it
  return o;
}

void old_spelling_into(const OldSpelling& o, std::string& target) {
  if (o.option->count() == 0) return;
  if (!target.empty()) fail("{} is the old spelling of {}: give one of them", o.name, o.use);
  std::fprintf(stderr, "gaia: note: %s is an old spelling; use %s\n", o.name.c_str(), o.use.c_str());
  target = o.value;
}

Config resolve_config(const SharedFlags& f) {
  Config c = f.config.empty() ? Config{} : Config::load(f.config);
  for (auto& kv : f.sets) c.set(kv);
  if (!f.device.empty()) c.run.device = f.device;
  if (!f.precision.empty()) c.run.precision = f.precision;
  if (f.threads >= 0) c.run.threads = f.threads;
  if (f.seed >= 0) c.run.seed = static_cast<uint64_t>(f.seed);
  static const std::regex dev_re("cpu|cuda(:[0-9]+)?");
  if (!std::regex_match(c.run.device, dev_re)) fail("--device '{}': expected cpu, cuda or cuda:N", c.run.device);
  c.validate();
  return c;
}

const std::vector<std::string> kWorldSamplingKeys = Config::keys("world", ConfigRole::Sampling);
const std::vector<std::string> kDecoderSamplingKeys = Config::keys("decoder", ConfigRole::Sampling);

void apply_sampling_sets(const SharedFlags& f, const std::string& section, const std::vector<std::string>& sampling_keys,
                         const std::string& weights, Config& model_cfg) {
  for (auto& kv : f.sets) {
    const std::string key = kv.substr(0, kv.find('='));
    if (std::find(sampling_keys.begin(), sampling_keys.end(), key) != sampling_keys.end())
      model_cfg.set(kv);
    else if (key.rfind(section + ".", 0) == 0)
      fail("--set {}: {} comes from the weights file {}; {}", kv, key, weights,
           sampling_keys.empty() ? std::string("none of its keys can be set here")
                                 : fmt::format("here only {} can be set", fmt::join(sampling_keys, ", ")));
  }
  model_cfg.validate();
}

#ifndef GAIA_NO_VIDEO
void add_motion_flags(CLI::App* cmd, data::MotionOptions* m) {
  cmd->add_option("--camera-height", m->camera_height, "camera height above the road in metres, the scale of "
                  "estimated speed (default 1.4, a dashcam behind the mirror; KITTI drives: 1.65)")
      ->check(number_in({0.2, 10}))
      ->each([m](const std::string&) { m->camera_height_stated = true; });
  cmd->add_option("--hfov", m->hfov_deg, "the camera's horizontal field of view in degrees, when no calibration "
                  "gives its focal length")->check(number_in({1, 179}))->capture_default_str();
  cmd->add_option("--motion-smooth", m->smooth_s, "seconds of the median filter over the per-frame estimates")
      ->check(number_in({0, 10}))->capture_default_str();
}
#endif

void add_token_format_flags(CLI::App* cmd, TokenFormatFlags* f) {
  cmd->add_option("--grid", f->grid, "another tokenizer's token grid HxW, for [frames, h*w] arrays (e.g. 8x16)");
  cmd->add_option("--codebook-size", f->codebook_size, "another tokenizer's codebook size K (default: the config's "
                  "tokenizer.codebook_size, or the world model's)")->check(number_in({1, 1 << 24}));
  cmd->add_option("--token-fps", f->token_fps, "frame rate of the token files (subsampled to the world model's "
                  "data.world_fps; default: already at it)")->check(number_in({0.1, 1000}));
  cmd->add_flag("--keep-rate", f->keep_rate, "with --token-fps: keep the files' own rate instead of subsampling");
}

world::TokenFormat token_format(const TokenFormatFlags& f, const Config& c, bool k_from_config,
                                const world::WorldInfo* info) {
  world::TokenFormat t;
  if (!f.grid.empty()) t.set_grid(f.grid);
  t.codebook_size = f.codebook_size;
  t.rate_hz = f.token_fps;
  t.keep_rate = f.keep_rate;
  t.world_rate_hz = (info ? info->config : c).data.world_fps;
  if (info) {
    if (t.grid_h > 0 && (t.grid_h != info->grid_h || t.grid_w != info->grid_w))
      fail("--grid {}: the world model was trained on a {}x{} grid", f.grid, info->grid_h, info->grid_w);
    if (t.codebook_size > 0 && t.codebook_size != info->K)
      fail("--codebook-size {}: the world model was trained with K = {}", t.codebook_size, info->K);
    t.grid_h = info->grid_h;
    t.grid_w = info->grid_w;
    t.codebook_size = info->K;
  } else if (t.codebook_size == 0 && k_from_config) {
    t.codebook_size = c.tokenizer.codebook_size;
  }
  return t;
}

CLI::Validator number_in(const Range& r) {
  return CLI::Validator(
      [r](std::string& in) {
        double v = 0;
        if (!CLI::detail::lexical_cast(in, v)) return fmt::format("'{}' is not a number", in);
        if (!r.contains(v)) return fmt::format("{} is out of range: allowed {}", in, r.str());
        return std::string{};
      },
      r.str());
}

CLI::Validator key_range(const std::string& config_key) {
  Config c;
  for (auto& f : c.fields())
    if (f.key == config_key) return number_in(f.range);
  fail("key_range: no config key '{}'", config_key);  // a programming error, found by the CLI tests
}

const CLI::Validator kSignedNumber{[](std::string&) { return std::string{}; }, "", "signed"};

namespace {
void check_numbers_of(CLI::App* app) {
  for (CLI::Option* opt : app->get_options()) {
    const std::string type = opt->get_type_name().substr(0, opt->get_type_name().find(':'));
    if (type != "FLOAT" && type != "INT" && type != "UINT") continue;
    bool is_signed = true;
    try {
      opt->get_validator("signed");
    } catch (const CLI::OptionNotFound&) {
      is_signed = false;
    }
    opt->check(CLI::Validator(
        [is_signed](std::string& in) {
          double v = 0;
          if (!CLI::detail::lexical_cast(in, v) || !std::isfinite(v)) return fmt::format("'{}' is not a finite number", in);
          if (!is_signed && v < 0) return fmt::format("{} is negative", in);
          return std::string{};
        },
        ""));
  }
  for (CLI::App* sub : app->get_subcommands([](CLI::App*) { return true; })) check_numbers_of(sub);
}
}  // namespace

void check_numbers(CLI::App& app) { check_numbers_of(&app); }

void apply_threads(const Config& c) {
#ifndef GAIA_NO_VIDEO
  if (c.run.threads > 0) cv::setNumThreads(c.run.threads);
#endif
  set_torch_threads(c.run.threads);
}

Precision run_precision(const Config& c, const torch::Device& dev, const std::string& command) {
  return precision_for(c.run.precision, dev,
                       [&](const std::string& n) { std::fprintf(stderr, "%s: %s\n", command.c_str(), n.c_str()); });
}

std::vector<std::string> adopt_init_architecture(Config& c, const fs::path& init, const SharedFlags& f,
                                                 const std::string& section) {
  std::vector<std::string> adopted;
  if (!f.config.empty() || !fs::exists(init)) return adopted;  // a config file describes the model; a missing file fails later
  auto md = SafetensorsFile(init).metadata();
  if (!md.count("gaia.config")) return adopted;
  Config stored;
  stored.apply_yaml(md["gaia.config"], init.string() + " [metadata]");
  auto theirs = stored.fields();
  for (auto& field : c.fields()) {
    if (field.role != ConfigRole::Architecture || field.key.rfind(section + ".", 0) != 0) continue;
    bool pinned = false;
    for (const auto& s : f.sets) pinned = pinned || s.rfind(field.key + "=", 0) == 0;
    if (pinned) continue;
    for (auto& t : theirs)
      if (t.key == field.key && t.get() != field.get()) {
        field.set(t.get());
        adopted.push_back(field.key + "=" + t.get());
      }
  }
  c.validate();
  return adopted;
}

torch::Tensor read_tokens(const fs::path& p, int64_t* prompt_frames) {
  torch::Tensor t;
  if (prompt_frames) *prompt_frames = 0;
  if (!fs::exists(p)) fail("{}: no such file or directory", p.string());
  if (fs::is_directory(p)) {
    if (!fs::exists(p / "tokens.npy")) fail("{}: not a token episode (no tokens.npy)", p.string());
    return read_tokens(p / "tokens.npy");
  }
  if (p.extension() == ".npy") {
    NpyArray a = npy_read(p);
    auto v = a.to_int64();
    t = torch::tensor(v, torch::kLong).view(a.shape);
  } else {
    SafetensorsFile f(p);
    if (!f.contains("tokens")) fail("{}: no 'tokens' tensor (expected a gaia generate rollout)", p.string());
    t = tensor_from_view(f.get("tokens")).to(torch::kLong);
    auto md = f.metadata();
    if (prompt_frames && md.count("gaia.rollout")) {
      auto j = nlohmann::json::parse(md["gaia.rollout"], nullptr, false);
      if (j.is_object()) *prompt_frames = j.value("prompt_frames", int64_t(0));
    }
  }
  if (t.dim() == 3) t = t.unsqueeze(0);
  if (t.dim() != 4) fail("{}: tokens must be [frames, h, w] or [futures, frames, h, w], got {} dimensions", p.string(), t.dim());
  if (t.size(1) == 0 || t.size(0) == 0) fail("{}: the token file is empty (0 frames)", p.string());
  return t;
}

CLI::Option* add_footage_flag(CLI::App* cmd, const std::string& name, std::string* into, const std::string& what) {
  *into = "any";
  return cmd->add_option(name, *into, what + ": any (default), real (recorded footage) or procedural")
      ->check(CLI::IsMember({"any", "real", "procedural"}));
}

}  // namespace gaia::app
