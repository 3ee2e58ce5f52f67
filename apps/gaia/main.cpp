// gaia: a C++ implementation of GAIA-1 (Hu et al. 2023), a generative world model for autonomous driving.
// One binary with git-style subcommands; each file cmd_*.cpp registers one of them.
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/torch/tensor_io.h"

int main(int argc, char** argv) {
  // FFmpeg's own log lines would break the "one clear error line" rule; our errors say what went wrong.
  ::setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", /*overwrite=*/0);
  gaia::configure_allocator();
  for (int i = 1; i < argc; ++i) gaia::app::g_command_line += std::string(" ") + argv[i];
  CLI::App app{"gaia: generative world model for autonomous driving (GAIA-1 in C++)", "gaia"};
  app.set_version_flag("--version", std::string("gaia ") + GAIA_VERSION);
  app.require_subcommand(1);
  gaia::app::register_demo(app);
  gaia::app::register_plan(app);
  gaia::app::register_ingest(app);
  gaia::app::register_data(app);
  gaia::app::register_synth(app);
  gaia::app::register_tokenizer(app);
  gaia::app::register_world(app);
  gaia::app::register_generate(app);
  gaia::app::register_decoder(app);
  gaia::app::register_decode(app);
  gaia::app::register_probe(app);
  gaia::app::register_convert(app);
  gaia::app::register_eval(app);
  gaia::app::register_train_all(app);
  gaia::app::register_report(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const gaia::Error& e) {
    std::fprintf(stderr, "gaia: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gaia: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
