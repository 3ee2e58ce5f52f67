#pragma once
// Reading video for ingestion: any file OpenCV's FFmpeg backend decodes, or a directory of images
// (PNG/JPEG, sorted by name) at a given frame rate. Frames come with timestamps in seconds.
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "gaia/core/fs.h"

namespace cv { class VideoCapture; }

namespace gaia::data {

struct VideoFrame {
  cv::Mat bgr;        // CV_8UC3 (greyscale sources are expanded to 3 channels)
  double time_s = 0;  // presentation time from the container, or index / fps
};

class VideoSource {
 public:
  // fps_override > 0 replaces the container's frame rate (required for image directories); it must agree with a
  // rate the video states, unless `retime`, which times every frame by its index at fps_override instead of the
  // container's timestamps (a stated rate known to be right where the container's is wrong).
  explicit VideoSource(const fs::path& path, double fps_override = 0, bool retime = false);
  ~VideoSource();
  bool next(VideoFrame* out);  // false at the end
  double fps() const { return fps_; }
  // The frame count the container states (0 when it states none); may be off by a frame or two.
  int64_t frame_count_hint() const { return count_hint_; }
  int width() const { return width_; }
  int height() const { return height_; }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
  std::unique_ptr<cv::VideoCapture> cap_;
  std::vector<fs::path> images_;
  size_t next_image_ = 0;
  int64_t index_ = 0;
  double fps_ = 0, last_time_ = -1;
  bool retime_ = false;
  int64_t count_hint_ = 0;
  int width_ = 0, height_ = 0;
};

// Scales so the image covers HxW, then crops the centre (keeps the aspect ratio; no letterboxing).
cv::Mat resize_center_crop(const cv::Mat& bgr, int height, int width);

// Up to `count` frames of a video subsampled to `rate` Hz (frame k is the source frame nearest k * fps / rate; a
// file without a frame rate counts as 25 Hz), resized and centre-cropped: a video prompt at the world-model rate.
std::vector<cv::Mat> read_frames_at_rate(const fs::path& path, double rate, int64_t count, int height, int width);

// Writes a PNG atomically.
void write_png(const fs::path& path, const cv::Mat& bgr);

// Writes frames to a video file (MP4/H.264 where FFmpeg has it, else MPEG-4 Part 2), atomically.
void write_video(const fs::path& path, const std::vector<cv::Mat>& frames, double fps);

}  // namespace gaia::data
