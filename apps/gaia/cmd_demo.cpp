// gaia demo: the README's first command. Shows what the system can do with what is built so far.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/data/ingest.h"
#include "gaia/plan/plan.h"

namespace gaia::app {

void register_demo(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "the end-to-end demo (today: the plan of the config and a clip summary)");
  auto flags = std::make_shared<SharedFlags>();
  auto video = std::make_shared<std::string>();
  cmd->add_option("--video", *video, "a driving clip to ingest and summarise");
  add_shared_flags(cmd, flags.get(), "output directory (default: demo-out)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    std::printf("== gaia demo ==\n\n-- plan of config '%s' --\n%s", c.name.c_str(),
                plan::format_plan(plan::make_plan(c), c).c_str());
    if (video->empty()) {
      std::printf("\n(pass --video CLIP to ingest a driving clip and see its dataset summary)\n");
      return;
    }
    fs::path out = flags->out.empty() ? fs::path("demo-out") : fs::path(flags->out);
    data::IngestOptions o;
    o.height = c.data.height;
    o.width = c.data.width;
    o.overwrite = true;
    auto m = data::ingest_video(*video, out / "dataset", o);
    double dur = m.num_frames / m.fps;
    std::printf("\n-- dataset summary of %s --\n", video->c_str());
    std::printf("  episode %s: %lld frames at %.4g fps (%.2f s), stored as %dx%d %s in %s\n", m.id.c_str(),
                (long long)m.num_frames, m.fps, dur, m.height, m.width, m.frame_codec.c_str(), (out / "dataset").c_str());
    int64_t steps = static_cast<int64_t>(dur * c.data.world_fps);
    std::printf("  at the world model's %.4g Hz: %lld steps = %lld image tokens (n = %d per frame)\n", c.data.world_fps,
                (long long)steps, (long long)(steps * c.image_tokens()), c.image_tokens());
  });
}

}  // namespace gaia::app
