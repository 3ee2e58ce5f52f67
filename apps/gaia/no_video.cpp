// A build without video (cmake -DGAIA_WITH_VIDEO=OFF): the commands that read or write frames are registered here
// with their usual names, each ending in one line that says this build has none, so that a script written for a
// full build fails plainly rather than with "unknown subcommand".
#include "common.h"
#include "gaia/core/error.h"

namespace gaia::app {

namespace {

void unavailable(CLI::App& app, const std::string& name, const std::string& what) {
  auto* cmd = app.add_subcommand(name, what + " (not in this build: it has no video support)");
  cmd->allow_extras();
  cmd->callback([name] {
    fail("gaia {}: this build has no video support (built with -DGAIA_WITH_VIDEO=OFF); it trains and samples "
         "world models on token datasets: gaia world, gaia generate, gaia plan, gaia convert", name);
  });
}

}  // namespace

void register_demo(CLI::App& app) { unavailable(app, "demo", "the shipped models end to end"); }
void register_ingest(CLI::App& app) { unavailable(app, "ingest", "a video becomes an episode"); }
void register_data(CLI::App& app) { unavailable(app, "data", "dataset info, stats, splits, motion"); }
void register_synth(CLI::App& app) { unavailable(app, "synth", "procedural driving episodes"); }
void register_tokenizer(CLI::App& app) {
  unavailable(app, "tokenizer", "the image tokenizer");
  unavailable(app, "tokenize", "frames to token episodes");
}
void register_decoder(CLI::App& app) { unavailable(app, "decoder", "the video decoder"); }
void register_decode(CLI::App& app) { unavailable(app, "decode", "tokens to video"); }
void register_probe(CLI::App& app) { unavailable(app, "probe", "probes of frames"); }
void register_eval(CLI::App& app) { unavailable(app, "eval", "action and text control"); }
void register_train_all(CLI::App& app) { unavailable(app, "train-all", "the whole recipe"); }
void register_report(CLI::App& app) { unavailable(app, "report", "HTML reports"); }

}  // namespace gaia::app
