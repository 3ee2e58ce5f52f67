#pragma once
// Repeated frames: containers that store one camera frame several times (a 20 Hz camera held five times in a
// 100 fps file, 25 fps footage in a 30 or 50 fps container). Kept as they are, every repeat reads as a car that
// stands still for one frame, and the world model would learn that roads stop. Ingest drops them and keeps the
// true timestamps (a kept frame's time is its first showing), so clips sampled by timestamp (§3) are unchanged.
//
// A frame's change is the largest mean absolute difference, over blocks of a small greyscale copy, from the frame
// before: a repeat differs by coding noise everywhere, a new frame changes somewhere. A repeat is a change within
// coding noise, or one far below the changes around it (a re-encoded repeat's noise next to the real motion of
// the frames beside it).
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace gaia::data {

struct RepeatOptions {
  double noise = 1.2;       // grey levels: a change at or below this is coding noise (the camera saw nothing new)
  double relative = 0.15;   // ... or below this share of the largest change within `window` frames either side
  double relative_cap = 3.5;  // grey levels: never a repeat above this, however large the changes around it
  int window = 5;
};

// The small greyscale copy that changes are measured on (160x90 by area averaging, whatever the frame's size).
cv::Mat change_thumbnail(const cv::Mat& bgr);
// The change from thumbnail `a` to `b`: the largest mean absolute difference over 10x9-pixel blocks.
double frame_change(const cv::Mat& a, const cv::Mat& b);

// change[i]: frame i's change from frame i - 1 (change[0] is ignored: the first frame is always kept).
// Returns true for each frame that repeats the one before.
std::vector<bool> find_repeats(const std::vector<double>& change, const RepeatOptions& opt = {});

// The camera's frame rate from the kept frames' times: one over the mean interval, leaving out the gaps longer
// than 2.5 times the 10th-percentile interval (a stop whose still frames were dropped). 0 for fewer than 2 frames.
double kept_frame_rate(const std::vector<double>& times);

}  // namespace gaia::data
