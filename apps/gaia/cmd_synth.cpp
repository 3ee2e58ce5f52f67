// gaia synth: procedural driving episodes with ground-truth actions, captions and labels; gaia synth replay.
#include <cstdio>
#include <regex>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/core/progress.h"
#include "gaia/data/geofence.h"
#include "gaia/synth/counterfactual.h"
#include "gaia/synth/synth.h"

namespace gaia::app {

namespace {
void parse_size(const std::string& s, int* h, int* w) {
  std::smatch m;
  static const std::regex re("(\\d+)x(\\d+)");
  if (!std::regex_match(s, m, re)) fail("--size '{}': expected HxW, e.g. 72x128", s);
  *h = std::stoi(m[1].str());
  *w = std::stoi(m[2].str());
  if (*h < 16 || *w < 16 || *h > 4096 || *w > 4096) fail("--size '{}': sides must be in [16, 4096]", s);
}
}  // namespace

void register_synth(CLI::App& app) {
  auto* cmd = app.add_subcommand("synth", "render procedural driving episodes (ground truth for evaluation)");
  auto flags = std::make_shared<SharedFlags>();
  auto o = std::make_shared<synth::SynthOptions>();
  auto episodes = std::make_shared<int>(4);
  auto first = std::make_shared<int>(0);
  auto size = std::make_shared<std::string>();
  cmd->add_option("--episodes", *episodes, "number of episodes");
  cmd->add_option("--first", *first, "index of the first episode (to extend a dataset)");
  cmd->add_option("--seconds", o->seconds, "seconds per episode");
  cmd->add_option("--size", *size, "frame size HxW (default: config data.height x data.width)");
  cmd->add_option("--fps", o->fps, "frame rate (paper §3: 25 Hz)");
  cmd->add_option("--weather", o->weather, "clear | overcast | rain | fog | snow (default: each district's climate)");
  cmd->add_option("--time", o->time_of_day, "day | dusk | night (default: random)");
  cmd->add_option("--scene", o->scene, "random | bend | red_light | lead_vehicle | straight");
  cmd->add_option("--district", o->district, "virtual district (default: random)");
  cmd->add_option("--wander", o->wander,
                  "the driver's lateral wander in its lane, m (0 = lane keeping; steering then carries information "
                  "the road does not, see docs/synth.md)");
  cmd->add_option("--swerve", o->swerve,
                  "the largest curvature of the driver's open-loop swerves, 1/m (0 = none; every 1.5-5 s it steers "
                  "off its lane for 0.4-1.6 s, then returns; see docs/synth.md)");
  cmd->add_option("--change-at", o->change_at,
                  "seconds into each drive at which its weather and/or time of day change (0 = never; the world, its "
                  "motion and its traffic stay the same; see docs/synth.md, \"Changes\")");
  cmd->add_option("--change-weather", o->change_weather,
                  "the weather from --change-at: clear | overcast | rain | fog | snow | random (another than the drive's)");
  cmd->add_option("--change-time", o->change_time_of_day,
                  "the time of day from --change-at: day | dusk | night | random (another than the drive's)");
  cmd->add_option("--change-lead", o->change_lead,
                  "seconds before --change-at from which the captions name the new conditions (the words lead the "
                  "scene, as a text prompt leads a rollout)");
  cmd->add_option("--codec", o->frame_codec, "frame storage: raw | png | jpg")->check(CLI::IsMember({"raw", "png", "jpg"}));
  cmd->add_flag("--overwrite", o->overwrite, "replace existing episodes with the same ids");
  add_shared_flags(cmd, flags.get(), "dataset directory", WithPrecision::kNo);
  cmd->callback([=] {
    if (cmd->got_subcommand("replay") || cmd->got_subcommand("counterfactuals")) return;
    Config c = resolve_config(*flags);
    apply_threads(c);
    if (flags->out.empty()) fail("gaia synth: --out DATASET is required");
    if (*episodes < 1) fail("--episodes must be >= 1");
    if (!(o->seconds > 0)) fail("--seconds must be positive");
    synth::SynthOptions opt = *o;
    opt.seed = c.run.seed;
    opt.height = c.data.height;
    opt.width = c.data.width;
    if (!size->empty()) parse_size(*size, &opt.height, &opt.width);
    const int64_t per = static_cast<int64_t>(opt.seconds * opt.fps);
    ProgressBar bar(per * *episodes, "synth");
    for (int e = 0; e < *episodes; ++e)
      synth::write_episode(flags->out, opt, *first + e, [&](int64_t done, int64_t) { bar.update(per * e + done); });
    bar.finish();
    std::printf("wrote %d episodes of %.3g s at %dx%d, %.3g fps -> %s\n", *episodes, opt.seconds, opt.height, opt.width,
                opt.fps, flags->out.c_str());
  });

  auto* rep = cmd->add_subcommand("replay", "counterfactual replay of an episode under other actions");
  auto rflags = std::make_shared<SharedFlags>();
  auto episode = std::make_shared<std::string>(), actions = std::make_shared<std::string>(), id = std::make_shared<std::string>();
  auto from = std::make_shared<int64_t>(0);
  auto overwrite = std::make_shared<bool>(false);
  rep->add_option("EPISODE", *episode, "episode directory (DATASET/episodes/<id>) of a synth dataset")->required();
  rep->add_option("--from", *from, "first frame driven with the new actions");
  rep->add_option("--actions", *actions, "CSV with columns speed,curvature: one row per frame at the episode fps")->required();
  rep->add_option("--id", *id, "id of the replayed episode (default: <episode>-replay-<from>)");
  rep->add_flag("--overwrite", *overwrite, "replace an existing replay");
  add_shared_flags(rep, rflags.get(), "dataset directory for the replayed episode", WithPrecision::kNo);
  rep->callback([=] {
    Config c = resolve_config(*rflags);
    if (rflags->out.empty()) fail("gaia synth replay: --out DATASET is required");
    data::Episode ep(*episode);
    auto acts = synth::read_actions_csv(*actions);
    std::string out_id = id->empty() ? fmt::format("{}-replay-{}", ep.meta().id, *from) : *id;
    auto m = synth::replay(ep, *from, acts, rflags->out, out_id, *overwrite);
    std::printf("replayed %s from frame %lld with %zu actions -> %s/episodes/%s\n", ep.meta().id.c_str(),
                (long long)*from, acts.size(), rflags->out.c_str(), m.id.c_str());
  });

  auto* cfc = cmd->add_subcommand(
      "counterfactuals",
      "replays of a dataset's training drives that hold a random steering command after a stretch of the recorded "
      "driving (training data for action control; docs/synth.md)");
  auto cflags = std::make_shared<SharedFlags>();
  auto co = std::make_shared<synth::CounterfactualOptions>();
  auto source = std::make_shared<std::string>();
  cfc->add_option("DATASET", *source, "synth dataset whose training-split drives are replayed")->required();
  cfc->add_option("--per-episode", co->per_episode, "replays of each drive, each from its own random start");
  cfc->add_option("--lead", co->lead_seconds, "seconds of the recorded driving before the command");
  cfc->add_option("--hold", co->hold_seconds, "seconds the command is held");
  cfc->add_option("--max-curvature", co->max_curvature, "the command's curvature is uniform in [-max, max], 1/m");
  cfc->add_option("--min-speed", co->min_speed, "the command keeps the recorded speed, at least this, m/s");
  auto without = std::make_shared<std::vector<std::string>>();
  cfc->add_option("--without-meta", *without,
                  "leave out drives whose metadata has this key, e.g. synth_wander keeps the lane-keeping drives "
                  "(repeatable)");
  add_shared_flags(cfc, cflags.get(), "dataset directory for the replays (resumes: replays already there are kept)",
                   WithPrecision::kNo);
  cfc->callback([=] {
    Config c = resolve_config(*cflags);
    apply_threads(c);
    if (cflags->out.empty()) fail("gaia synth counterfactuals: --out DATASET is required");
    if (fs::weakly_canonical(cflags->out) == fs::weakly_canonical(*source))
      fail("gaia synth counterfactuals: --out must not be the source dataset {}", *source);
    data::Dataset ds(*source);
    // Held-out drives are never replayed: their prompts are what gaia eval and validation measure.
    const data::Split split = data::load_or_default_split(ds, data::kDefaultValFraction, c.run.seed);
    std::vector<std::string> ids;
    size_t recorded = 0;  // real drives of a mixed dataset: only a rendered drive can be rendered again
    for (size_t e : data::episode_indices(ds, split.train))
      if (!ds.meta(e).is_procedural()) ++recorded;
      else if (!ds.meta(e).has_any_extra(*without)) ids.push_back(ds.ids()[e]);
    if (ids.empty()) fail("{}: no training drive to replay{}", *source, without->empty() ? "" : " without " + fmt::format("{}", fmt::join(*without, ", ")));
    synth::CounterfactualOptions opt = *co;
    opt.seed = c.run.seed;
    ProgressBar bar(static_cast<int64_t>(ids.size()) * opt.per_episode, "counterfactuals");
    const int64_t n = synth::write_counterfactuals(ds, ids, opt, cflags->out, [&](int64_t done, int64_t) { bar.update(done); });
    bar.finish();
    if (!fs::exists(fs::path(cflags->out) / "dataset.json"))
      fail("{}: no training drive is {} s long (--lead + --hold), nothing to replay", *source, opt.lead_seconds + opt.hold_seconds);
    std::printf("wrote %lld replays of %zu training drives (%zu held out, %zu recorded, %zu left out by --without-meta) -> %s\n",
                (long long)n, ids.size(), split.held_out().size(), recorded, split.train.size() - ids.size() - recorded,
                cflags->out.c_str());
  });
}

}  // namespace gaia::app
