#pragma once
// gaia synth: procedural forward-camera driving episodes (docs/synth.md) and counterfactual replay.
//
// Actions: speed in m/s and curvature in 1/m of the ego's path; positive curvature turns left
// (counter-clockwise seen from above). Frame i records the action applied from frame i to frame i+1.
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "gaia/core/fs.h"
#include "gaia/data/episode.h"
#include "gaia/synth/render.h"
#include "gaia/synth/scene.h"

namespace gaia::synth {

struct SynthOptions {
  int height = 288, width = 512;
  double fps = 25, seconds = 10;
  uint64_t seed = 0;
  std::string weather, time_of_day;  // "" = drawn from the district's climate
  std::string scene;                 // "" = random mix; random, bend, red_light, lead_vehicle, straight
  std::string district;              // "" = random; see district.h
  std::string frame_codec = "raw";
  double wander = 0;                 // the driver's lateral wander in its lane, m (SceneSpec::wander)
  double swerve = 0;                 // the largest curvature of the driver's open-loop swerves, 1/m (SceneSpec::swerve)
  double change_at = 0, change_lead = 1.0;           // a change of conditions mid-drive (SceneSpec::change_at)
  std::string change_weather, change_time_of_day;  // its targets: a value, "random" or "" (kept)
  bool overwrite = false;            // replace an existing episode with the same id
};

// Episode id of episode `index` of a seeded run: "synth-s<seed>-e<index, 5 digits>".
std::string episode_id(uint64_t seed, int index);

// One episode's world plus its renderer: the building block of write_episode and replay.
class Simulator {
 public:
  Simulator(const SynthOptions& opt, int index);
  const Scene& world() const { return *world_; }
  const SceneSpec& spec() const { return world_->spec(); }
  data::EpisodeMeta meta() const;  // everything replay needs is in meta.extra and meta.source
  cv::Mat render();                // the current frame, BGR CV_8UC3
  ActionStep policy() { return world_->policy(); }
  void step(const ActionStep& a) { world_->step(a); }
  // Labels and caption of the current frame given the action taken in it.
  data::FrameRecord record(const ActionStep& a, bool with_image = true);
  Renderer& renderer() { return renderer_; }

 private:
  SynthOptions opt_;
  int index_;
  std::unique_ptr<Scene> world_;
  Renderer renderer_;
};

// Generates episode `index` of a seeded run and writes it to DATASET; returns its metadata. Deterministic in
// (options, index) regardless of threads or of which other episodes are generated.
data::EpisodeMeta write_episode(const fs::path& dataset, const SynthOptions& opt, int index,
                                std::function<void(int64_t done, int64_t total)> progress = {});

// Counterfactual replay: rebuilds the world of a synth episode from its metadata, re-simulates frames
// [0, from) with the recorded actions, then drives with `actions` (one per frame at the episode fps) and
// writes frames from .. from+actions.size()-1 as a new episode `out_id` in `out_dataset`. Agents react to the
// new ego path. With the recorded actions the frames are reproduced exactly.
data::EpisodeMeta replay(const data::Episode& original, int64_t from, const std::vector<ActionStep>& actions,
                         const fs::path& out_dataset, const std::string& out_id, bool overwrite = false);

// Reads actions from a CSV file with a header naming columns `speed` and `curvature` (other columns are
// ignored). Errors name file:line.
std::vector<ActionStep> read_actions_csv(const fs::path& csv);

// Renders the frame of episode `index` at time t (simulating the policy up to it), without writing anything.
cv::Mat preview_frame(const SynthOptions& opt, int index, double t_seconds);

// A grid of frames (each scaled to cell_width, keeping the aspect ratio) with an optional caption under each.
cv::Mat contact_sheet(const std::vector<cv::Mat>& frames, const std::vector<std::string>& labels, int cols,
                      int cell_width);

}  // namespace gaia::synth
