#pragma once
// The video decoder's training tasks (§2.4, Fig. 4), each a pattern of frame masks over T' frames: which frames are
// given clean as context, which are noised and predicted, and which predicted frames get their image tokens.
//   image        every frame predicted from its tokens, temporal layers off (frames are independent images)
//   video        every frame predicted from its tokens, jointly
//   forward      the first 2 frames are context (past), the rest predicted from tokens   (§5.2: 2 overlapping frames)
//   backward     the last 2 frames are context (future), the rest predicted from tokens  (§5.2 decodes backwards)
//   interpolate  every other frame is context; the frames between have no tokens (temporal upsampling, §5.2)
#include <random>
#include <string>
#include <vector>

namespace gaia::decoder {

enum class Task { kImage, kVideo, kForward, kBackward, kInterpolate };
constexpr int kNumTasks = 5;
constexpr int kOverlapFrames = 2;  // §5.2: context frames shared by consecutive autoregressive windows

std::string to_string(Task t);

struct FrameMasks {
  std::vector<bool> context;  // [T'] true = clean context frame (no loss)
  std::vector<bool> tokens;   // [T'] true = the frame's image tokens condition the model
  bool temporal = true;       // false: temporal layers off (image task)
};

FrameMasks task_masks(Task task, int frames);

// Frame rates the decoder is trained on (§4.3) and the index fed to its frame-rate embedding.
constexpr double kRates[3] = {6.25, 12.5, 25.0};
int rate_index(double fps);  // error for any other rate

// A task drawn with equal probability (§2.4), and a frame rate: any of the three, except that interpolation
// produces 12.5 or 25 Hz (its context frames are at half that rate, as in the 6.25 -> 12.5 -> 25 Hz upsampling).
struct TaskDraw {
  Task task;
  int rate;  // index into kRates
};
TaskDraw draw_task(std::mt19937_64& rng);

}  // namespace gaia::decoder
