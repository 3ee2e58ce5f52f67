#pragma once
// Shared command-line plumbing: every subcommand takes the same run flags and resolves one Config from them.
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <torch/torch.h>

#include "gaia/config.h"
#include "gaia/torch/precision.h"

namespace gaia::data {
struct MotionOptions;
}  // namespace gaia::data

namespace gaia::train {
class Distributed;
struct Parallel;
}  // namespace gaia::train

namespace gaia::world {
struct TokenFormat;
struct WorldInfo;
}  // namespace gaia::world

namespace gaia::app {

struct SharedFlags {
  std::string config;               // --config FILE (default: built-in defaults = configs/default.yaml)
  std::vector<std::string> sets;    // --set key=value (repeatable)
  std::string device;               // --device cpu|cuda|cuda:N
  std::string precision;            // --precision fp32|bf16|fp16
  int threads = -1;                 // --threads N
  long long seed = -1;              // --seed N
  std::string out;                  // --out DIR or FILE
};

// Adds --config/--set/--device/--precision/--threads/--seed/--out to a subcommand. `out_help` says what --out is.
// A command that does not run its products under run.precision leaves --precision out (WithPrecision::kNo), so
// that a run asking for bf16 there is refused instead of quietly running in float32.
enum class WithPrecision { kYes, kNo };
void add_shared_flags(CLI::App* cmd, SharedFlags* f, const std::string& out_help = "output directory",
                      WithPrecision precision = WithPrecision::kYes);

// The CLI's one rule: data positional, weights by component. Each component's weights flag is declared here, with
// one name and one help text; `use` adds what this command does with them (e.g. "decodes the preview").
enum class Weights { Tokenizer, World, Decoder, Probe, T5 };
std::string weights_flag_name(Weights which);                           // "--tokenizer", ...
std::string weights_flag_help(Weights which, const std::string& use);  // "tokenizer weights (tokenizer.safetensors): USE"
template <typename Path>  // std::string or fs::path
CLI::Option* add_weights_flag(CLI::App* cmd, Weights which, Path* path, const std::string& use = "") {
  return cmd->add_option(weights_flag_name(which), *path, weights_flag_help(which, use));
}

// Which episodes a measure reads (world/footage.h): `name` (--footage, --prompt-footage) takes any, real or
// procedural, default any; `what` says what the choice selects.
CLI::Option* add_footage_flag(CLI::App* cmd, const std::string& name, std::string* into, const std::string& what);

// How to read token files of other tokenizers (world/token_file.h, docs/formats.md): --grid HxW, --codebook-size
// K, --token-fps F, --keep-rate. Commands given world-model weights take the grid and K from them.
struct TokenFormatFlags {
  std::string grid;
  long long codebook_size = 0;
  double token_fps = 0;
  bool keep_rate = false;
};
void add_token_format_flags(CLI::App* cmd, TokenFormatFlags* f);
// The format for `c` (its world rate and, with no --codebook-size, its tokenizer.codebook_size when `k_from_config`);
// with `info` (a trained world model) its grid and K, which stated flags must match.
world::TokenFormat token_format(const TokenFormatFlags& f, const Config& c, bool k_from_config,
                                const world::WorldInfo* info = nullptr);

// --camera-height, --hfov, --motion-smooth: ego-motion from video (data/motion.h), for ingest and data motion.
void add_motion_flags(CLI::App* cmd, data::MotionOptions* m);

// An old spelling of an option kept for a release: hidden from --help, writing the same variable. The callback
// copies it over (old_spelling_into) and says once on stderr which name to use instead.
struct OldSpelling {
  std::string name, use, value;
  CLI::Option* option = nullptr;
};
std::shared_ptr<OldSpelling> add_old_spelling(CLI::App* cmd, const std::string& name, const std::string& use);
void old_spelling_into(const OldSpelling& o, std::string& target);

// Config from --config (or defaults), then --set overrides, then --device/--threads/--seed; validated.
Config resolve_config(const SharedFlags& f);

// A weights file fixes its model's config, except for how the model is sampled: applies the --set overrides of
// `sampling_keys` (e.g. decoder.noise_correlation) to `model_cfg`, the config read from `weights`. Any other --set
// key under `section` (e.g. decoder.channels) is an error naming the file: the weights decide it.
void apply_sampling_sets(const SharedFlags& f, const std::string& section, const std::vector<std::string>& sampling_keys,
                         const std::string& weights, Config& model_cfg);

// The keys that say how a model is sampled rather than what it is (ConfigRole::Sampling in the registry): a weights
// file stores them with its config, a run may override them (apply_sampling_sets), and `gaia convert --set`
// changes the file's own.
extern const std::vector<std::string> kWorldSamplingKeys;    // world.top_k, world.temperature, ...
extern const std::vector<std::string> kDecoderSamplingKeys;  // decoder.ddim_steps, decoder.start_time, ...

// Numbers on the command line: after every subcommand is registered, check_numbers() makes every numeric option
// refuse NaN and infinities, and values below 0 unless the option carries kSignedNumber. Options add their own
// bounds with number_in() or, where a flag overrides a config key, with key_range() (one range for both).
void check_numbers(CLI::App& app);
CLI::Validator number_in(const Range& r);
CLI::Validator key_range(const std::string& config_key);  // e.g. "world.top_k" for --top-k
extern const CLI::Validator kSignedNumber;

// Applies run.threads to the process (OpenCV; LibTorch when linked).
void apply_threads(const Config& c);

// run.precision (--precision) on `dev` for a sampling command: precision_for, its fallback note a stderr line
// "COMMAND: ...".
Precision run_precision(const Config& c, const torch::Device& dev, const std::string& command);

// Runs this gaia binary again as a child process with `args` (after "gaia"), sharing stdout/stderr, and returns
// its exit status: train-all's stages and demo --from-scratch.
int run_gaia_child(const std::vector<std::string>& args);

// Data-parallel training (train/distributed.h): --nproc, --accumulate, --shard-optimizer, --shard-gradients,
// --no-overlap, --dist-timeout.
struct ParallelFlags {
  int nproc = 1;
  int accumulate = 1;
  bool shard_optimizer = false;
  bool shard_gradients = false;
  bool no_overlap = false;
  double timeout_s = 1800;  // as torch.distributed's default
};
void add_parallel_flags(CLI::App* cmd, ParallelFlags* f);
// How a trainer runs in `dist`'s job under these flags.
train::Parallel parallel_of(const ParallelFlags& f, train::Distributed* dist);
// With --nproc N > 1 outside a job: runs N ranks of this same command on this machine and returns true once all
// succeeded (the caller then returns: the ranks did the work); when one fails, stops the others and fails naming it.
// False when there is nothing to launch (one process, or already a rank of a job).
bool launch_local_ranks(const ParallelFlags& f);
// This process's place in the job (a job of one outside any): per-rank device (cuda -> cuda:LOCAL_RANK) and, for
// ranks sharing this machine, a share of its cores; applies the thread count.
std::unique_ptr<train::Distributed> join_job(const ParallelFlags& f, Config& c);

// The arguments of this run, as main got them (launch_local_ranks runs them again).
extern std::vector<std::string> g_args;

// The exact command line of this run (set by main), recorded in reports so that every figure can be remade.
extern std::string g_command_line;

// Fine-tuning from --init weights: the architecture keys of `section` ("tokenizer") that neither --config nor --set
// pins take the values stored in the weights, so their layers are kept rather than dropped. Returns the keys
// adopted, as "key=value" (none for weights without a stored config).
std::vector<std::string> adopt_init_architecture(Config& c, const fs::path& init, const SharedFlags& f,
                                                 const std::string& section);

// Token frames from a rollout (.safetensors "tokens" [F, N, h, w] or [N, h, w]), a .npy [N, h, w], or a token
// dataset episode directory (its tokens.npy) -> int64 [F, N, h, w]. `prompt_frames` (when given) gets the rollout's
// prompt length from its metadata (0 for other files).
torch::Tensor read_tokens(const fs::path& p, int64_t* prompt_frames = nullptr);

// Registration of the subcommands (one file each).
void register_plan(CLI::App& app);
void register_demo(CLI::App& app);
void register_ingest(CLI::App& app);
void register_data(CLI::App& app);
void register_synth(CLI::App& app);
void register_tokenizer(CLI::App& app);  // also registers `gaia tokenize`
void register_world(CLI::App& app);
void register_generate(CLI::App& app);
void register_decoder(CLI::App& app);   // gaia decoder train|eval
void register_decode(CLI::App& app);    // gaia decode
void register_probe(CLI::App& app);     // gaia probe train|eval
void register_convert(CLI::App& app);   // gaia convert --half / --set
void register_eval(CLI::App& app);      // gaia eval (action / text control, futures, long rollouts)
void register_train_all(CLI::App& app); // gaia train-all (the whole recipe)
void register_report(CLI::App& app);    // gaia report RUN_DIR
void register_sim(CLI::App& app);       // gaia sim --stdio (closed-loop sessions)
void register_text(CLI::App& app);      // gaia text embed (T5 embeddings of a dataset's captions)
void register_scaling(CLI::App& app);   // gaia scaling (the scaling-law study, §6)
// A token dataset's captions through the T5 at `t5` into its text embeddings (world/embed_captions.h), with progress.
void embed_dataset_captions(const std::string& tokens, const std::string& t5, int64_t m, const torch::Device& dev);

}  // namespace gaia::app
