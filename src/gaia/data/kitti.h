#pragma once
// KITTI raw drives read directly (docs/formats.md, "KITTI raw"): DRIVE/image_02/data/*.png (or image_03, image_00,
// image_01) with timestamps.txt, DRIVE/oxts/data/*.txt (30 GPS/IMU values a frame, named in oxts/dataformat.txt)
// with timestamps.txt, and the date folder's calib_cam_to_cam.txt.
//   speed      vf, forward velocity (m/s)
//   curvature  wu / vf, yaw rate over speed (1/m, + = left); missing below kKittiMinSpeed
#include <string>
#include <vector>

#include "gaia/core/fs.h"
#include "gaia/data/signals.h"

namespace gaia::data {

inline constexpr double kKittiMinSpeed = 0.5;  // m/s: below this a yaw rate says little about the path's bend

struct KittiDrive {
  fs::path dir, images;             // the drive and its image folder (the first of image_02, 03, 00, 01)
  std::vector<double> image_time_s;  // each image's time, seconds after the first
  double fps = 0;                   // from the mean gap between image timestamps
  Signals oxts;                     // on the images' clock (record i = image i when the counts match, as in
                                    // synced drives); empty when the drive has no oxts/
  double latitude = 0, longitude = 0;  // of the first OXTS record (the episode's location for the geofence)
  // Rectified intrinsics of the chosen camera (P_rect_0N) at its stored size; 0 when no calib file was found.
  double focal_px = 0, cx = 0, cy = 0;
  int image_width = 0, image_height = 0;
  bool has_oxts() const { return !oxts.time_s.empty(); }
};

bool is_kitti_drive(const fs::path& dir);  // a folder with image_0N/data/
// Fails naming the file at fault; a drive without oxts/ is read without signals (the caller decides).
KittiDrive read_kitti_drive(const fs::path& dir);

// Camera poses as signals (KITTI odometry's poses.txt, or any SLAM trajectory in that layout): one row of 12
// numbers per frame, the 3x4 camera-to-world matrix [R | c] in camera axes (x right, y down, z forward). Frame i
// is at time i / fps; its speed is |c[i+1] - c[i]| * fps and its curvature the yaw of R[i]^T R[i+1] per metre
// (+ = left), so frame i carries the motion to frame i + 1 as a recorded action does.
Signals pose_signals(const fs::path& poses, double fps);

// "2011-09-26 13:02:44.335092332" -> seconds since 1970 (UTC; KITTI's clock), nanosecond digits kept.
double kitti_timestamp(const std::string& s, const std::string& where);

}  // namespace gaia::data
