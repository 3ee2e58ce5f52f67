#include "gaia/decoder/tasks.h"

#include <cmath>

#include "gaia/core/error.h"

namespace gaia::decoder {

std::string to_string(Task t) {
  switch (t) {
    case Task::kImage: return "image";
    case Task::kVideo: return "video";
    case Task::kForward: return "forward";
    case Task::kBackward: return "backward";
    case Task::kInterpolate: return "interpolate";
  }
  return "?";
}

FrameMasks task_masks(Task task, int frames) {
  if (frames < 1) fail("decoder: a task needs at least one frame, got {}", frames);
  const size_t T = size_t(frames);
  FrameMasks m{std::vector<bool>(T, false), std::vector<bool>(T, true), true};
  switch (task) {
    case Task::kImage: m.temporal = false; break;
    case Task::kVideo: break;
    case Task::kForward:
      for (size_t i = 0; i < std::min<size_t>(kOverlapFrames, T - 1); ++i) m.context[i] = true, m.tokens[i] = false;
      break;
    case Task::kBackward:
      for (size_t i = 0; i < std::min<size_t>(kOverlapFrames, T - 1); ++i) m.context[T - 1 - i] = true, m.tokens[T - 1 - i] = false;
      break;
    case Task::kInterpolate:
      // Even positions are context, odd positions are predicted from their neighbours alone (no tokens).
      for (size_t i = 0; i < T; ++i) {
        m.context[i] = (i % 2 == 0);
        m.tokens[i] = false;
      }
      break;
  }
  return m;
}

int rate_index(double fps) {
  for (int i = 0; i < 3; ++i)
    if (std::abs(fps - kRates[i]) < 1e-6) return i;
  fail("decoder: frame rate {} Hz is not one the decoder is trained on (6.25, 12.5 or 25)", fps);
}

TaskDraw draw_task(std::mt19937_64& rng) {
  Task task = Task(std::uniform_int_distribution<int>(0, kNumTasks - 1)(rng));
  int rate = task == Task::kInterpolate ? std::uniform_int_distribution<int>(1, 2)(rng)
                                        : std::uniform_int_distribution<int>(0, 2)(rng);
  return {task, rate};
}

}  // namespace gaia::decoder
