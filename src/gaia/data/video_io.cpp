#include "gaia/data/video_io.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "gaia/core/error.h"

extern "C" {
#include <libavformat/avformat.h>
}

namespace gaia::data {

namespace {
bool is_image(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), ::tolower);
  return e == ".png" || e == ".jpg" || e == ".jpeg" || e == ".bmp";
}

// The frames an MP4/MOV presents: its video stream's duration from the header (edit lists applied, as players show
// it) times the frame rate. A cut MP4 can hold more packets than it presents (nb_frames counts them all), so the
// packet count alone would read a cut clip as truncated. Other containers (AVI, TS) estimate their duration from
// the data that is there, which would hide a truncation: 0 for them, as when no duration is stated.
int64_t presented_frames(const fs::path& path, double fps) {
  AVFormatContext* ctx = nullptr;
  if (avformat_open_input(&ctx, path.c_str(), nullptr, nullptr) != 0) return 0;
  int64_t n = 0;
  const bool mov = ctx->iformat && std::strstr(ctx->iformat->name, "mp4") != nullptr;  // "mov,mp4,m4a,3gp,3g2,mj2"
  if (mov && avformat_find_stream_info(ctx, nullptr) >= 0 && ctx->duration_estimation_method == AVFMT_DURATION_FROM_STREAM) {
    const int s = av_find_best_stream(ctx, AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
    double seconds = 0;
    if (s >= 0 && ctx->streams[s]->duration > 0)
      seconds = double(ctx->streams[s]->duration) * av_q2d(ctx->streams[s]->time_base);
    else if (ctx->duration > 0)
      seconds = double(ctx->duration) / AV_TIME_BASE;
    if (seconds > 0 && fps > 0) n = std::llround(seconds * fps);
  }
  avformat_close_input(&ctx);
  return n;
}

cv::Mat to_bgr(const cv::Mat& m) {
  if (m.channels() == 3) return m;
  cv::Mat out;
  cv::cvtColor(m, out, m.channels() == 4 ? cv::COLOR_BGRA2BGR : cv::COLOR_GRAY2BGR);
  return out;
}
}  // namespace

VideoSource::VideoSource(const fs::path& path, double fps_override, bool retime)
    : path_(path), retime_(retime && fps_override > 0) {
  if (!fs::exists(path)) fail("{}: no such file or directory", path.string());
  if (fs::is_directory(path)) {
    for (auto& e : fs::directory_iterator(path))
      if (e.is_regular_file() && is_image(e.path())) images_.push_back(e.path());
    std::sort(images_.begin(), images_.end());
    if (images_.empty()) fail("{}: directory holds no PNG/JPEG frames", path.string());
    if (!(fps_override > 0)) fail("{}: an image directory needs its frame rate (--fps)", path.string());
    fps_ = fps_override;
    count_hint_ = static_cast<int64_t>(images_.size());
    cv::Mat first = cv::imread(images_[0].string(), cv::IMREAD_UNCHANGED);
    if (first.empty()) fail("{}: cannot decode image", images_[0].string());
    width_ = first.cols;
    height_ = first.rows;
    return;
  }
  cap_ = std::make_unique<cv::VideoCapture>(path.string(), cv::CAP_FFMPEG);
  if (!cap_->isOpened()) fail("{}: cannot open video (not a format FFmpeg decodes, or truncated or corrupt)", path.string());
  double fps = cap_->get(cv::CAP_PROP_FPS);
  // Frame times come from the container's timestamps where it has them, so a stated rate that disagrees would be
  // half applied: refuse it rather than guess which one is right.
  if (!retime_ && fps_override > 0 && fps > 0 && fps <= 1000 && std::abs(fps_override - fps) > 0.01 * fps)
    fail("{}: --fps {:.4g} does not match the {:.4g} fps the video states; leave --fps out (it is for image "
         "directories and videos that state no rate)", path.string(), fps_override, fps);
  fps_ = fps_override > 0 ? fps_override : fps;
  if (!(fps_ > 0) || fps_ > 1000) fail("{}: video reports no usable frame rate; pass --fps", path.string());
  // Streams without an index report 0, a negative or a garbage count: treat anything implausible as "none".
  const double count = cap_->get(cv::CAP_PROP_FRAME_COUNT);
  count_hint_ = std::isfinite(count) && count > 0 && count < 1e12 ? static_cast<int64_t>(count) : 0;
  const int64_t presented = presented_frames(path, fps);  // the container's own rate, whatever --fps says
  if (presented > 0 && count_hint_ > 0 && presented < count_hint_) count_hint_ = presented;
  width_ = static_cast<int>(cap_->get(cv::CAP_PROP_FRAME_WIDTH));
  height_ = static_cast<int>(cap_->get(cv::CAP_PROP_FRAME_HEIGHT));
}

VideoSource::~VideoSource() = default;

bool VideoSource::next(VideoFrame* out) {
  if (!cap_) {
    if (next_image_ >= images_.size()) return false;
    const fs::path& p = images_[next_image_++];
    cv::Mat m = cv::imread(p.string(), cv::IMREAD_UNCHANGED);
    if (m.empty()) fail("{}: cannot decode image", p.string());
    if (m.depth() != CV_8U) m.convertTo(m, CV_8U, 1.0 / 256);
    out->bgr = to_bgr(m);
    out->time_s = static_cast<double>(index_++) / fps_;
    return true;
  }
  cv::Mat m;
  if (!cap_->read(m) || m.empty()) return false;
  out->bgr = to_bgr(m);
  // Container timestamps keep variable-rate footage honest; fall back to index / fps when they are absent
  // or not increasing (some containers report 0 for every frame).
  double t = cap_->get(cv::CAP_PROP_POS_MSEC) / 1000.0;
  double fallback = static_cast<double>(index_) / fps_;
  if (retime_ || !(t > last_time_) || !std::isfinite(t)) t = fallback;
  if (index_ == 0 && t > 0 && t < 1.0 / fps_) t = 0;  // a few containers start at a small offset
  out->time_s = t;
  last_time_ = t;
  ++index_;
  return true;
}

cv::Mat resize_center_crop(const cv::Mat& bgr, int height, int width) {
  if (bgr.empty()) fail("resize_center_crop: empty image");
  double s = std::max(double(height) / bgr.rows, double(width) / bgr.cols);
  int rh = std::max(height, static_cast<int>(std::lround(bgr.rows * s)));
  int rw = std::max(width, static_cast<int>(std::lround(bgr.cols * s)));
  cv::Mat resized;
  cv::resize(bgr, resized, cv::Size(rw, rh), 0, 0, s < 1 ? cv::INTER_AREA : cv::INTER_LINEAR);
  int y = (rh - height) / 2, x = (rw - width) / 2;
  return resized(cv::Rect(x, y, width, height)).clone();
}

void write_png(const fs::path& path, const cv::Mat& bgr) {
  std::vector<uchar> buf;
  if (!cv::imencode(".png", bgr, buf)) fail("{}: PNG encoding failed", path.string());
  write_file_atomic(path, std::string(buf.begin(), buf.end()));
}

void write_video(const fs::path& path, const std::vector<cv::Mat>& frames, double fps) {
  if (frames.empty()) fail("{}: no frames to write", path.string());
  const fs::path dir = path.has_parent_path() ? path.parent_path() : fs::path(".");
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) fail("{}: cannot create directory {} ({})", path.string(), dir.string(), ec.message());
  // Checked first: an encoder that cannot open its file says only that it failed.
  if (::access(dir.c_str(), W_OK) != 0) fail("{}: cannot write into {} ({})", path.string(), dir.string(), std::strerror(errno));
  // The encoder picks the container by extension, so the temporary name keeps it.
  fs::path tmp = dir / (".tmp-" + path.stem().string() + "-" + unique_suffix() + path.extension().string());
  cv::Size size(frames[0].cols, frames[0].rows);
  cv::VideoWriter w;
  // H.264 first (plays everywhere); Debian's OpenCV/FFmpeg may lack an encoder, then MPEG-4 Part 2.
  for (const char* cc : {"avc1", "H264", "mp4v"}) {
    if (w.open(tmp.string(), cv::CAP_FFMPEG, cv::VideoWriter::fourcc(cc[0], cc[1], cc[2], cc[3]), fps, size)) break;
  }
  if (!w.isOpened()) fail("{}: no video encoder available", path.string());
  for (auto& f : frames) w.write(f);
  w.release();
  // The encoder reports no write errors; an empty file is what a full disk leaves.
  if (fs::file_size(tmp, ec) == 0 || ec) {
    fs::remove(tmp, ec);
    fail("{}: writing the video failed (disk full?)", path.string());
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    const std::string why = ec.message();
    fs::remove(tmp, ec);
    fail("{}: cannot rename the video into place ({})", path.string(), why);
  }
}

std::vector<cv::Mat> read_frames_at_rate(const fs::path& path, double rate, int64_t count, int height, int width) {
  VideoSource v(path);
  const double fps = v.fps() > 0 ? v.fps() : 25.0;
  const double every = fps / rate;
  std::vector<cv::Mat> frames;
  VideoFrame f;
  for (int i = 0; v.next(&f) && int64_t(frames.size()) < count; ++i)
    if (i == int(std::lround(double(frames.size()) * every))) frames.push_back(resize_center_crop(f.bgr, height, width));
  if (frames.empty()) fail("{}: no frames", path.string());
  return frames;
}

}  // namespace gaia::data
