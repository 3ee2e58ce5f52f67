// gaia ingest VIDEO [--signals CSV] [--meta key=value ...] [--allow-partial] --out DATASET
#include <cstdio>
#include <memory>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/ingest.h"

namespace gaia::app {

void register_ingest(CLI::App& app) {
  auto* cmd = app.add_subcommand("ingest", "add a video (file or image directory) as an episode of a dataset");
  auto flags = std::make_shared<SharedFlags>();
  auto video = std::make_shared<std::string>();
  auto opt = std::make_shared<data::IngestOptions>();
  auto signals = std::make_shared<std::string>();
  auto metas = std::make_shared<std::vector<std::string>>();
  cmd->add_option("VIDEO", *video, "video file (anything FFmpeg decodes) or a directory of PNG/JPEG frames")->required();
  cmd->add_option("--signals", *signals, "CSV with columns time_s,speed,curvature[,caption]");
  cmd->add_option("--meta", *metas, "episode metadata key=value: weather, time_of_day, latitude, longitude, source, ...");
  cmd->add_option("--id", opt->id, "episode id (default: the video's file name)");
  cmd->add_option("--fps", opt->fps, "frame rate (required for image directories; overrides the container)")
      ->check(number_in({0, data::kMaxIngestFps, true, false}));
  cmd->add_option("--codec", opt->frame_codec, "frame storage: raw | png | jpg")->check(CLI::IsMember({"raw", "png", "jpg"}));
  cmd->add_option("--max-frames", opt->max_frames, "stop after this many frames (0 = all)");
  cmd->add_flag("--overwrite", opt->overwrite, "replace an existing episode with the same id");
  cmd->add_flag("--allow-partial", opt->allow_partial,
                "keep the frames of a truncated or damaged video (with a warning) instead of failing");
  add_shared_flags(cmd, flags.get(), "dataset directory (created if missing)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    if (flags->out.empty()) fail("gaia ingest: --out DATASET is required");
    data::IngestOptions o = *opt;
    o.height = c.data.height;
    o.width = c.data.width;
    o.signals = *signals;
    for (auto& kv : *metas) {
      auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) fail("--meta '{}': expected key=value", kv);
      o.meta[kv.substr(0, eq)] = kv.substr(eq + 1);
    }
    std::unique_ptr<ProgressBar> bar;  // the frame count is only known once the video is open
    auto res = data::ingest_video(*video, flags->out, o, [&](int64_t done, int64_t total) {
      if (!bar) bar = std::make_unique<ProgressBar>(total, "ingest");
      bar->update(done);
    });
    if (bar) bar->finish();
    for (auto& w : res.warnings) std::fprintf(stderr, "gaia: warning: %s\n", w.c_str());
    const data::EpisodeMeta& m = res.meta;
    std::printf("ingested %s: %lld frames at %.3g fps (%dx%d, %s) -> %s/episodes/%s\n", video->c_str(),
                (long long)m.num_frames, m.fps, m.height, m.width, m.frame_codec.c_str(), flags->out.c_str(), m.id.c_str());
  });
}

}  // namespace gaia::app
