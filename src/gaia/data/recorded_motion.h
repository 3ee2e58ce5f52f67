#pragma once
// `gaia data motion` on an ingested episode: ego-motion estimated from the recording's own frames at their recorded
// resolution, as `gaia ingest --motion video` does, not from the stored frames (72x128 at the default config, far
// too coarse for the road plane and the corners the estimate rests on). The episode names its recording
// (episode.json: "recording", with "recording_fps" where a rate was given); the recording's frames are matched to
// the episode's by time, so repeats that ingest dropped stay dropped. Procedural episodes are their own recording.
#include <functional>

#include "gaia/data/episode.h"
#include "gaia/data/motion.h"

namespace gaia::data {

// Fails with one line naming the episode where its recording is not named or not at hand, or no longer holds the
// episode's frames at their times.
MotionEstimate estimate_recorded_motion(const Episode& ep, const MotionOptions& opt,
                                        const std::function<void(int64_t, int64_t)>& progress = {});

}  // namespace gaia::data
