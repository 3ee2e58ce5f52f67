// gaia demo: the README's first command (demo/demo.h does the work). --from-scratch first runs the whole training
// recipe (`gaia train-all`) as a child process and uses what it made.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/demo/demo.h"
#include "gaia/torch/tensor_io.h"

namespace gaia::app {

void register_demo(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "demo", "end-to-end demo with the shipped models: video prompt -> futures, steering, text, decoded, HTML report");
  auto flags = std::make_shared<SharedFlags>();
  auto d = std::make_shared<demo::DemoOptions>();
  auto models = std::make_shared<std::string>("models");
  auto from_scratch = std::make_shared<bool>(false);
  cmd->add_option("--models", *models, "directory with the shipped weights (tokenizer, world, decoder, probes)");
  cmd->add_option("--video", d->video, "a driving video as the prompt instead of a procedural drive (e.g. a real clip)");
  cmd->add_option("--prompt-frames", d->prompt_frames, "video prompt frames (6.25 Hz)")->check(number_in({1, 1e6}));
  cmd->add_option("--frames", d->frames, "frames to generate (6.25 Hz)")->check(number_in({1, 1e6}));
  cmd->add_option("--ddim-steps", d->ddim_steps, "DDIM steps of the video decoder (paper: 50; 10 keeps the demo short)")
      ->check(key_range("decoder.ddim_steps"));
  cmd->add_option("--fps", d->fps, "output rate of the video decoder: 6.25, 12.5 or 25 Hz");
  cmd->add_option("--text-guidance", d->text_guidance,
                  "classifier-free guidance scale of the scenes generated from text alone")
      ->check(key_range("world.guidance_scale"));
  cmd->add_option("--guidance", d->text_guidance, "old spelling of --text-guidance")
      ->check(key_range("world.guidance_scale"))
      ->group("");
  cmd->add_option("--action-guidance", d->action_guidance,
                  "classifier-free guidance scale on the steering commands (the mirrored command as unconditional; "
                  "0 = off)")
      ->check(key_range("world.guidance_scale"));
  cmd->add_option("--steer-guidance", d->action_guidance, "old spelling of --action-guidance")
      ->check(key_range("world.guidance_scale"))
      ->group("");
  cmd->add_flag("--from-scratch", *from_scratch, "first train every model with `gaia train-all` (hours on a CPU)");
  add_shared_flags(cmd, flags.get(), "output directory (default: demo-out)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    const fs::path out = flags->out.empty() ? fs::path("demo-out") : fs::path(flags->out);
    demo::DemoOptions o = *d;
    o.models = *models;
    if (*from_scratch) {
      // The recipe as a child process, so its stages resume exactly as `gaia train-all` would.
      o.models = out / "models";
      std::vector<std::string> args{"train-all", "--ship", o.models.string(), "--out", (out / "runs").string()};
      if (!flags->config.empty()) args.insert(args.end(), {"--config", flags->config});
      if (run_gaia_child(args) != 0) fail("gaia demo --from-scratch: the training recipe failed (see above)");
    }
    o.seed = uint64_t(c.run.seed);
    o.device = c.run.device;
    o.precision = run_precision(c, parse_device(c.run.device), "demo");
    o.command_line = g_command_line;
    auto r = demo::run_demo(o, out, [](const std::string& line) { std::printf("%s\n", line.c_str()); });
    std::printf("read-back: %s\n", r.readback.dump().c_str());
    std::printf("wrote %s (videos in %s) in %.0f s\n", r.report.c_str(), (out / "videos").c_str(), r.seconds);
  });
}

}  // namespace gaia::app
