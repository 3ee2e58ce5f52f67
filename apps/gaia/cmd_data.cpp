// gaia data info|stats|split|motion: look at a dataset, its balancing and its geofenced validation split; estimate
// ego-motion from the frames of episodes without signals.
#include <cmath>
#include <cstdio>
#include <random>

#include <nlohmann/json.hpp>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/json_file.h"
#include "gaia/data/balance.h"
#include "gaia/data/clip_sampler.h"
#include "gaia/data/geofence.h"
#include "gaia/data/holdout.h"
#include "gaia/data/motion.h"
#include "gaia/data/recorded_motion.h"
#include "gaia/core/progress.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/world/token_dataset.h"

namespace gaia::app {

namespace {

std::vector<size_t> all_episodes(const data::Dataset& ds) {
  std::vector<size_t> v(ds.size());
  for (size_t i = 0; i < v.size(); ++i) v[i] = i;
  return v;
}

std::vector<std::string> split_list(const std::string& s) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= s.size()) {
    size_t c = s.find(',', start);
    if (c == std::string::npos) c = s.size();
    if (c > start) out.push_back(s.substr(start, c - start));
    start = c + 1;
  }
  return out;
}

void info(const std::string& root, const Config& c) {
  data::Dataset ds(root);
  std::printf("dataset %s: %zu episodes\n", root.c_str(), ds.size());
  std::printf("%-28s %7s %7s %8s %9s %6s %6s %-9s %-6s %s\n", "episode", "frames", "fps", "seconds", "size",
              "speed", "curv", "weather", "time", "lat,lon");
  int64_t frames = 0;
  double seconds = 0;
  for (size_t i = 0; i < ds.size(); ++i) {
    data::Episode ep = ds.episode(i);
    const auto& m = ep.meta();
    int sp = 0, cu = 0;
    for (int64_t f = 0; f < ep.size(); ++f) {
      sp += !std::isnan(ep.speed(f));
      cu += !std::isnan(ep.curvature(f));
    }
    double dur = ep.size() > 1 ? ep.time_s(ep.size() - 1) - ep.time_s(0) + 1.0 / m.fps : 1.0 / m.fps;
    frames += ep.size();
    seconds += dur;
    std::printf("%-28s %7lld %7.3g %8.2f %4dx%-4d %5.0f%% %5.0f%% %-9s %-6s %s\n", m.id.c_str(), (long long)ep.size(),
                m.fps, dur, m.height, m.width, 100.0 * sp / double(ep.size()), 100.0 * cu / double(ep.size()),
                m.weather.empty() ? "-" : m.weather.c_str(), m.time_of_day.empty() ? "-" : m.time_of_day.c_str(),
                m.has_location() ? fmt::format("{:.4f},{:.4f}", m.latitude, m.longitude).c_str() : "-");
  }
  auto clips = data::enumerate_clips(ds, all_episodes(ds), c.world.context_steps, c.data.world_fps,
                                     c.world.context_steps / c.data.world_fps);
  std::printf("total: %lld frames, %.1f s; %zu non-overlapping world-model clips of T=%d steps at %.4g Hz\n",
              (long long)frames, seconds, clips.size(), c.world.context_steps, c.data.world_fps);
}

}  // namespace

void register_data(CLI::App& app) {
  auto* data_cmd = app.add_subcommand("data", "inspect datasets: info, balancing statistics, geofenced split");
  data_cmd->require_subcommand(1);

  {
    auto* cmd = data_cmd->add_subcommand("info", "episodes, frames, signals coverage and clip count");
    auto flags = std::make_shared<SharedFlags>();
    auto root = std::make_shared<std::string>();
    cmd->add_option("DATASET", *root, "dataset directory")->required();
    add_shared_flags(cmd, flags.get(), "unused", WithPrecision::kNo);
    cmd->callback([=] { info(*root, resolve_config(*flags)); });
  }

  {
    auto* cmd = data_cmd->add_subcommand("stats", "empirical vs balanced-sampled histograms (paper §3), as text and SVG");
    auto flags = std::make_shared<SharedFlags>();
    auto root = std::make_shared<std::string>();
    auto features = std::make_shared<std::string>("weather,speed,curvature");
    auto exponent = std::make_shared<double>(-1);
    cmd->add_option("DATASET", *root, "dataset directory")->required();
    cmd->add_option("--balance", *features, "comma-separated features: " + fmt::format("{}", fmt::join(data::known_features(), ", ")));
    cmd->add_option("--exponent", *exponent, "balancing exponent in [0, 1] (default: config data.balance_exponent)");
    add_shared_flags(cmd, flags.get(), "directory for balance.svg and balance.json (default: DATASET)",
                     WithPrecision::kNo);
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      data::Dataset ds(*root);
      if (ds.size() == 0) fail("{}: dataset has no episodes", *root);
      double ex = *exponent >= 0 ? *exponent : c.data.balance_exponent;
      data::Balancer bal(split_list(*features), ex, c.data.balance_bins);
      // One example per world-model clip (T steps at the world rate), as training samples them.
      auto clips = data::enumerate_clips(ds, all_episodes(ds), c.world.context_steps, c.data.world_fps, 1.0);
      if (clips.empty()) fail("{}: no episode is long enough for a clip of {} steps at {} Hz", *root, c.world.context_steps, c.data.world_fps);
      std::vector<data::FeatureRow> rows;
      size_t cur = SIZE_MAX;
      std::unique_ptr<data::Episode> ep;
      for (auto& clip : clips) {
        if (clip.episode != cur) { ep = std::make_unique<data::Episode>(ds.episode(clip.episode)); cur = clip.episode; }
        rows.push_back(data::clip_features(*ep, clip.frames));
      }
      bal.fit(rows);
      std::printf("%zu clips, exponent %.2f, acceptance rate %.1f%%\n", rows.size(), ex, 100 * bal.acceptance_rate(rows));
      std::vector<std::string> charts;
      nlohmann::json out = nlohmann::json::object();
      for (auto& f : bal.features()) {
        auto h = bal.histogram(f, rows);
        std::printf("\n%s\n  %-24s %10s %10s\n", f.c_str(), "bin", "empirical", "sampled");
        for (size_t i = 0; i < h.bins.size(); ++i)
          std::printf("  %-24s %9.1f%% %9.1f%%\n", h.bins[i].c_str(), 100 * h.empirical[i], 100 * h.sampled[i]);
        charts.push_back(eval::svg_bars(fmt::format("{} (exponent {:.2f})", f, ex), h.bins,
                                        {{"empirical", h.empirical, ""}, {"sampled", h.sampled, ""}}));
        out[f] = {{"bins", h.bins}, {"empirical", h.empirical}, {"sampled", h.sampled}};
      }
      fs::path dir = flags->out.empty() ? fs::path(*root) : fs::path(flags->out);
      write_file_atomic(dir / "balance.svg", eval::svg_stack(charts));
      write_file_atomic(dir / "balance.json", out.dump(2) + "\n");
      std::printf("\nwrote %s and %s\n", (dir / "balance.svg").c_str(), (dir / "balance.json").c_str());
    });
  }

  {
    auto* cmd = data_cmd->add_subcommand("split", "geofenced validation split (paper §3) written as JSON, for an "
                                         "episode dataset, a token dataset or a directory of token files");
    auto flags = std::make_shared<SharedFlags>();
    auto root = std::make_shared<std::string>();
    auto boxes = std::make_shared<std::vector<std::string>>(), named = std::make_shared<std::vector<std::string>>();
    auto frac = std::make_shared<double>(0.0);
    auto format = std::make_shared<TokenFormatFlags>();
    cmd->add_option("DATASET", *root, "episode dataset, token dataset (gaia tokenize) or directory of token files "
                    "(positions from their sidecar X.json)")->required();
    cmd->add_option("--geofence", *boxes, "strict validation box lat_min,lon_min,lat_max,lon_max (repeatable)");
    cmd->add_option("--hold-out", *named, "hold out this episode (or token file stem) and its mirror images and "
                    "replays (repeatable): e.g. one clip for a leave-one-out measurement");
    cmd->add_option("--val-fraction", *frac, "fraction of the other episodes held out at random (with --hold-out-by: "
                    "the share of frames to hold out, by group; default 0.15)");
    auto by = std::make_shared<std::vector<std::string>>();
    auto cover = std::make_shared<std::vector<std::string>>(std::vector<std::string>{"weather", "time_of_day", "road"});
    cmd->add_option("--hold-out-by", *by, "hold out whole groups of episodes with the same metadata, e.g. "
                    "source_repo,place (clips of one source and place share a drive): every value of --cover that "
                    "two or more groups hold gets a held-out group, then groups up to --val-fraction of the frames; "
                    "procedural drives in the same dataset are held out as the default split holds them out")
        ->delimiter(',');
    cmd->add_option("--cover", *cover, "with --hold-out-by: metadata keys whose values each need a held-out group "
                    "(default weather,time_of_day,road)")->delimiter(',');
    add_token_format_flags(cmd, format.get());
    add_shared_flags(cmd, flags.get(), "split JSON file (default: DATASET/split.json)", WithPrecision::kNo);
    cmd->callback([=] {
      Config c = resolve_config(*flags);
      std::vector<data::GeoBox> gb;
      for (auto& b : *boxes) gb.push_back(data::parse_geobox(b));
      std::vector<data::EpisodeMeta> metas;
      const fs::path header = fs::path(*root) / "dataset.json";
      if (fs::exists(header) && read_json(header).value("format", "") == "gaia-episodes") {
        data::Dataset ds(*root);
        for (size_t i = 0; i < ds.size(); ++i) metas.push_back(ds.meta(i));
      } else {
        world::TokenDataset ds(*root, token_format(*format, c, false));
        if (ds.bare()) fail("{}: a single token file is split in time (its last tenth); split a directory of them", *root);
        for (size_t e = 0; e < ds.size(); ++e) metas.push_back(ds.meta(e));
      }
      std::vector<std::string> held = *named;
      double random_frac = *frac;
      if (!by->empty()) {
        // Groups among the recorded episodes; procedural drives (gaia synth, their mirror images and replays) share
        // no driver or road with anything: they are held out exactly as the default split holds them out.
        const double share = cmd->count("--val-fraction") ? *frac : 0.15;
        std::vector<data::EpisodeMeta> recorded;
        size_t procedural = 0, procedural_held = 0;
        for (const auto& m : metas) {
          if (!m.is_procedural()) {
            recorded.push_back(m);
            continue;
          }
          ++procedural;
          if (data::held_out_at_random(m.id, data::kDefaultValFraction, c.run.seed)) held.push_back(m.id), ++procedural_held;
        }
        if (recorded.empty()) fail("{}: --hold-out-by groups recorded episodes, and this dataset has only procedural ones", *root);
        const auto g = data::hold_out_groups(recorded, *by, *cover, share, c.run.seed);
        held.insert(held.end(), g.episodes.begin(), g.episodes.end());
        if (procedural > 0)
          std::printf("procedural drives: %zu of %zu held out as the default split holds them out\n", procedural_held, procedural);
        random_frac = 0;
        std::string groups;
        for (auto& n : g.groups) groups += (groups.empty() ? "" : "; ") + n;
        std::printf("held out by %s: %zu groups, %lld of %lld frames (%.1f%%): %s\n", fmt::format("{}", fmt::join(*by, ",")).c_str(),
                    g.groups.size(), (long long)g.frames, (long long)g.total_frames,
                    100.0 * double(g.frames) / double(std::max<int64_t>(1, g.total_frames)), groups.c_str());
        if (!g.uncovered.empty())
          std::printf("in training only (held by one group, or their groups must stay): %s\n",
                      fmt::format("{}", fmt::join(g.uncovered, ", ")).c_str());
      }
      auto s = data::geofence_split(metas, gb, random_frac, c.run.seed, held, *root);
      if (s.train.empty()) fail("{}: this split leaves no episode to train on", *root);
      fs::path out = flags->out.empty() ? fs::path(*root) / "split.json" : fs::path(flags->out);
      write_file_atomic(out, s.to_json().dump(2) + "\n");
      std::printf("train %zu, validation %zu inside geofences + %zu named + %zu random -> %s\n", s.train.size(),
                  s.val_geofence.size(), s.val_named.size(), s.val_random.size(), out.c_str());
    });
  }

  {
    auto* cmd = data_cmd->add_subcommand(
        "motion", "estimate speed and curvature from the video (visual odometry) for episodes without signals; "
                  "--compare scores the estimate against the signals episodes have");
    auto flags = std::make_shared<SharedFlags>();
    auto root = std::make_shared<std::string>();
    auto only = std::make_shared<std::vector<std::string>>();
    auto compare = std::make_shared<bool>(false), replace = std::make_shared<bool>(false);
    auto mo = std::make_shared<data::MotionOptions>();
    cmd->add_option("DATASET", *root, "dataset directory")->required();
    cmd->add_option("--episodes", *only, "only these episode ids (comma-separated)")->delimiter(',');
    cmd->add_flag("--compare", *compare, "write nothing: score the estimate against each episode's own signals "
                  "(median speed error, curvature sign, yaw rate) and print the figures");
    cmd->add_flag("--replace", *replace, "also replace signals that were measured (csv, gps, kitti-oxts, synth)");
    add_motion_flags(cmd, mo.get());
    add_shared_flags(cmd, flags.get(), "with --compare: a JSON file for the figures (optional)", WithPrecision::kNo);
    cmd->callback([=] {
      apply_threads(resolve_config(*flags));
      if (*compare && *replace) fail("--compare writes nothing; it cannot --replace");
      data::Dataset ds(*root);
      std::vector<size_t> eps = only->empty() ? all_episodes(ds) : data::episode_indices(ds, *only);
      nlohmann::json report = nlohmann::json::array();
      std::vector<double> est_v, est_k, ref_v, ref_k;
      double ms = 0;
      int done = 0, skipped = 0;
      for (size_t e : eps) {
        data::Episode ep = ds.episode(e);
        const auto& m = ep.meta();
        const bool measured = !m.signals_source.empty() && m.signals_source != "estimated";
        if (!*compare && measured && !*replace) {
          std::printf("%s: keeps its %s signals (--replace to estimate anyway)\n", m.id.c_str(), m.signals_source.c_str());
          ++skipped;
          continue;
        }
        if (*compare && !measured) {
          std::printf("%s: no measured signals to compare with\n", m.id.c_str());
          ++skipped;
          continue;
        }
        ProgressBar bar(ep.size(), m.id);
        const auto est = data::estimate_recorded_motion(ep, *mo, [&](int64_t d, int64_t) { bar.update(d); });
        bar.finish();
        ms += est.ms_per_frame;
        ++done;
        if (*compare) {
          std::vector<double> v(ep.speeds().begin(), ep.speeds().end()), k(ep.curvatures().begin(), ep.curvatures().end());
          const auto g = data::compare_motion(est.speed, est.curvature, v, k);
          std::printf("%s (%s): %s; %.1f ms a frame\n", m.id.c_str(), m.signals_source.c_str(), g.summary().c_str(),
                      est.ms_per_frame);
          report.push_back({{"episode", m.id}, {"reference", m.signals_source}, {"frames", g.frames},
                            {"median_speed_rel_error", g.median_speed_rel_error},
                            {"curvature_frames", g.curvature_frames},
                            {"curvature_sign_agreement", g.curvature_sign_agreement},
                            {"yaw_rate_mae", g.yaw_rate_mae}, {"ms_per_frame", est.ms_per_frame}});
          est_v.insert(est_v.end(), est.speed.begin(), est.speed.end());
          est_k.insert(est_k.end(), est.curvature.begin(), est.curvature.end());
          ref_v.insert(ref_v.end(), v.begin(), v.end());
          ref_k.insert(ref_k.end(), k.begin(), k.end());
        } else {
          data::write_estimated_signals(ep, est);
          std::printf("%s: estimated speed on %lld of %lld frames, curvature on %lld (%.1f ms a frame)\n", m.id.c_str(),
                      (long long)est.frames_with_speed(), (long long)ep.size(), (long long)est.frames_with_curvature(),
                      est.ms_per_frame);
        }
      }
      if (*compare && done > 0) {
        const auto g = data::compare_motion(est_v, est_k, ref_v, ref_k);
        std::printf("all %d episodes: %s; %.1f ms a frame\n", done, g.summary().c_str(), ms / done);
        if (!flags->out.empty()) {
          nlohmann::json j{{"episodes", report},
                           {"all", {{"frames", g.frames}, {"median_speed_rel_error", g.median_speed_rel_error},
                                    {"curvature_frames", g.curvature_frames},
                                    {"curvature_sign_agreement", g.curvature_sign_agreement},
                                    {"yaw_rate_mae", g.yaw_rate_mae}, {"ms_per_frame", ms / done}}}};
          write_file_atomic(flags->out, j.dump(2) + "\n");
        }
      }
      if (done == 0) fail("{}: no episode to {} ({} skipped)", *root, *compare ? "compare" : "estimate", skipped);
    });
  }
}

}  // namespace gaia::app
