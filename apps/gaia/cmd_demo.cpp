// gaia demo: the README's first command. Shows what the system does with what is built so far: the plan of the
// config, a small procedural driving dataset (with a counterfactual replay steering left), its balancing
// statistics, and a video + contact sheet to look at; with --video, the same summary for a real clip.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/ingest.h"
#include "gaia/data/video_io.h"
#include "gaia/plan/plan.h"
#include "gaia/synth/synth.h"

namespace gaia::app {

namespace {

std::vector<cv::Mat> episode_frames(const data::Episode& ep) {
  std::vector<cv::Mat> f;
  for (int64_t i = 0; i < ep.size(); ++i) f.push_back(ep.frame_bgr(i));
  return f;
}

}  // namespace

void register_demo(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "end-to-end demo: plan, procedural driving data, counterfactual replay, videos");
  auto flags = std::make_shared<SharedFlags>();
  auto video = std::make_shared<std::string>();
  auto episodes = std::make_shared<int>(6);
  auto seconds = std::make_shared<double>(6.0);
  cmd->add_option("--video", *video, "also ingest a real driving clip and summarise it");
  cmd->add_option("--episodes", *episodes, "procedural episodes to render");
  cmd->add_option("--seconds", *seconds, "seconds per episode");
  add_shared_flags(cmd, flags.get(), "output directory (default: demo-out)");
  cmd->callback([=] {
    Config c = resolve_config(*flags);
    apply_threads(c);
    fs::path out = flags->out.empty() ? fs::path("demo-out") : fs::path(flags->out);
    std::printf("== gaia demo ==\n\n-- plan of config '%s' --\n%s", c.name.c_str(),
                plan::format_plan(plan::make_plan(c), c).c_str());

    // 1. Procedural driving data: one episode per weather, at the config's resolution.
    std::printf("\n-- procedural driving world: %d episodes x %.3g s at %dx%d --\n", *episodes, *seconds, c.data.height, c.data.width);
    fs::path ds_dir = out / "synth";
    synth::SynthOptions so;
    so.height = c.data.height;
    so.width = c.data.width;
    so.seconds = *seconds;
    so.seed = c.run.seed;
    so.overwrite = true;
    const char* weathers[] = {"clear", "rain", "fog", "snow", "overcast", "clear"};
    const char* times[] = {"day", "dusk", "night", "day", "day", "night"};
    const int64_t per = static_cast<int64_t>(so.seconds * so.fps);
    ProgressBar bar(per * *episodes, "synth");
    std::vector<cv::Mat> thumbs;
    std::vector<std::string> labels;
    for (int e = 0; e < *episodes; ++e) {
      so.weather = weathers[e % 6];
      so.time_of_day = times[e % 6];
      auto m = synth::write_episode(ds_dir, so, e, [&](int64_t d, int64_t) { bar.update(per * e + d); });
      data::Episode ep(ds_dir / "episodes" / m.id);
      thumbs.push_back(ep.frame_bgr(ep.size() / 2));
      labels.push_back(ep.caption(ep.size() / 2));
    }
    bar.finish();
    data::Dataset ds(ds_dir);
    for (size_t i = 0; i < ds.size(); ++i) {
      data::Episode ep = ds.episode(i);
      std::printf("  %s: %-8s %-5s  speed %4.1f m/s  \"%s\"\n", ep.meta().id.c_str(), ep.meta().weather.c_str(),
                  ep.meta().time_of_day.c_str(), ep.speed(ep.size() / 2), ep.caption(ep.size() / 2).c_str());
    }
    data::write_png(out / "contact_sheet.png", synth::contact_sheet(thumbs, labels, 3, 320));

    // 2. Counterfactual replay: the first episode again, steering left from 2 s on (ground truth for action control).
    data::Episode first = ds.episode(0);
    const int64_t from = std::min<int64_t>(50, first.size() - 1);
    std::vector<synth::ActionStep> left;
    for (int64_t i = from; i < first.size(); ++i) left.push_back({std::max(5.0f, first.speed(i)), 0.02});
    auto rm = synth::replay(first, from, left, out / "replay", first.meta().id + "-steer-left", true);
    data::Episode replayed(out / "replay" / "episodes" / rm.id);
    std::vector<cv::Mat> side;
    for (int64_t i = 0; i < replayed.size(); ++i) {
      cv::Mat s;
      cv::hconcat(first.frame_bgr(from + i), replayed.frame_bgr(i), s);
      side.push_back(s);
    }
    data::write_video(out / "replay_steer_left.mp4", side, first.meta().fps);
    data::write_video(out / "episode0.mp4", episode_frames(first), first.meta().fps);
    std::printf("\n-- counterfactual replay: %s steering left (curvature +0.02 1/m) from frame %lld --\n",
                first.meta().id.c_str(), (long long)from);
    std::printf("  recorded | replayed side by side: %s\n", (out / "replay_steer_left.mp4").c_str());

    // 3. Balancing statistics of the little dataset (paper §3).
    std::printf("\n  try: gaia data stats %s --balance weather,speed,curvature\n", ds_dir.c_str());

    if (!video->empty()) {
      data::IngestOptions o;
      o.height = c.data.height;
      o.width = c.data.width;
      o.overwrite = true;
      auto m = data::ingest_video(*video, out / "real", o);
      double dur = m.num_frames / m.fps;
      std::printf("\n-- dataset summary of %s --\n", video->c_str());
      std::printf("  episode %s: %lld frames at %.4g fps (%.2f s), stored as %dx%d %s in %s\n", m.id.c_str(),
                  (long long)m.num_frames, m.fps, dur, m.height, m.width, m.frame_codec.c_str(), (out / "real").c_str());
      int64_t steps = static_cast<int64_t>(dur * c.data.world_fps);
      std::printf("  at the world model's %.4g Hz: %lld steps = %lld image tokens (n = %d per frame)\n", c.data.world_fps,
                  (long long)steps, (long long)(steps * c.image_tokens()), c.image_tokens());
    }
    std::printf("\nwrote %s: contact_sheet.png, episode0.mp4, replay_steer_left.mp4, synth/ (dataset)\n", out.c_str());
  });
}

}  // namespace gaia::app
