#include "gaia/synth/render.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "gaia/synth/rng.h"

namespace gaia::synth {

namespace {

using V3 = cv::Vec3f;  // BGR, 0..255

V3 rgb(float r, float g, float b) { return V3(b, g, r); }
V3 mix(const V3& a, const V3& b, float t) { return a * (1 - t) + b * t; }
V3 mul(const V3& a, const V3& b) { return V3(a[0] * b[0], a[1] * b[1], a[2] * b[2]); }
V3 from8(const cv::Vec3b& c) { return V3(c[0], c[1], c[2]); }
cv::Scalar sc(const V3& c) {
  return cv::Scalar(std::clamp(c[0], 0.f, 255.f), std::clamp(c[1], 0.f, 255.f), std::clamp(c[2], 0.f, 255.f));
}

// Lighting and material palette of a weather / time-of-day combination.
struct Env {
  V3 sky_top, sky_mid, sky_hor;  // sky_hor doubles as the haze / fog colour
  double vis = 900;               // e-folding distance of the haze, m
  V3 tint{1, 1, 1};               // ambient light colour x intensity
  bool night = false, dusk = false, lights_on = false, wet = false, snow = false, rain = false, clouds = false;
  float headlight = 0, lamp = 0;  // strength of the ego's headlight pool and street lamp pools
  V3 grass, urban_ground, asphalt, pavement, kerb, verge, white, yellow, track;
  float tex_amp = 0.10f;
};

Env make_env(const std::string& weather, const std::string& tod) {
  Env e;
  e.grass = rgb(72, 108, 48);
  e.urban_ground = rgb(132, 130, 124);
  e.asphalt = rgb(88, 88, 92);
  e.pavement = rgb(158, 155, 148);
  e.kerb = rgb(188, 186, 180);
  e.verge = rgb(110, 100, 80);
  e.white = rgb(232, 232, 226);
  e.yellow = rgb(226, 178, 30);
  e.track = e.asphalt;
  float amb = 1.0f;
  if (weather == "clear") {
    e.sky_top = rgb(62, 118, 200), e.sky_mid = rgb(120, 168, 222), e.sky_hor = rgb(196, 214, 230);
    e.vis = 1100, e.clouds = true;
  } else if (weather == "overcast") {
    e.sky_top = rgb(150, 154, 160), e.sky_mid = rgb(178, 181, 186), e.sky_hor = rgb(200, 202, 205);
    e.vis = 600, amb = 0.86f, e.tex_amp = 0.07f;
  } else if (weather == "rain") {
    e.sky_top = rgb(98, 102, 110), e.sky_mid = rgb(128, 132, 138), e.sky_hor = rgb(160, 163, 167);
    e.vis = 260, amb = 0.72f, e.wet = e.rain = true, e.tex_amp = 0.05f;
    e.asphalt = rgb(58, 59, 64), e.pavement = rgb(118, 116, 112), e.grass = rgb(56, 86, 40);
    e.white = rgb(200, 200, 196);
  } else if (weather == "fog") {
    e.sky_top = rgb(186, 188, 190), e.sky_mid = rgb(190, 192, 194), e.sky_hor = rgb(194, 196, 198);
    e.vis = 55, amb = 0.9f, e.tex_amp = 0.06f;
  } else {  // snow
    e.sky_top = rgb(172, 176, 184), e.sky_mid = rgb(196, 199, 205), e.sky_hor = rgb(214, 217, 222);
    e.vis = 170, amb = 0.95f, e.snow = true;
    e.grass = rgb(228, 230, 236), e.urban_ground = rgb(214, 216, 222), e.pavement = rgb(222, 224, 230);
    e.kerb = rgb(236, 238, 242), e.verge = rgb(220, 222, 228);
    e.asphalt = rgb(176, 178, 184), e.track = rgb(142, 144, 150), e.white = rgb(226, 228, 232);
  }
  e.lights_on = e.rain || weather == "fog" || weather == "snow";
  if (tod == "dusk") {
    e.dusk = e.lights_on = true;
    if (weather == "clear") {
      e.sky_top = rgb(38, 52, 112), e.sky_mid = rgb(168, 100, 112), e.sky_hor = rgb(246, 156, 84);
      e.vis = 800;
    } else {
      e.sky_top = e.sky_top * 0.45f, e.sky_mid = e.sky_mid * 0.55f, e.sky_hor = mix(e.sky_hor * 0.65f, rgb(200, 130, 90), 0.25f);
    }
    e.tint = rgb(1.05f, 0.82f, 0.7f) * (amb * 0.62f);
    e.headlight = 0.35f, e.lamp = 0.15f;
  } else if (tod == "night") {
    e.night = e.lights_on = true, e.clouds = false;
    e.sky_top = rgb(4, 6, 14), e.sky_mid = rgb(10, 12, 24), e.sky_hor = rgb(34, 30, 40);
    if (weather == "fog") e.sky_top = e.sky_mid = e.sky_hor = rgb(40, 40, 44);
    if (weather == "snow" || weather == "rain" || weather == "overcast") e.sky_hor = rgb(46, 40, 44);
    e.tint = rgb(0.55f, 0.62f, 0.85f) * (amb * 0.16f);
    e.headlight = 1.0f, e.lamp = 0.7f;
    if (weather == "clear") e.vis = 900;
  } else {
    e.tint = V3(amb, amb, amb);
  }
  if (e.snow) e.headlight *= 0.5f, e.lamp *= 0.6f;  // bright snow would blow out under the same light
  return e;
}

struct Cam {
  double ex, ey, ch, sh, height, cp, sp, cr, sr, f, cx, cy;
  cv::Point3d to_cam(double X, double Y, double Z) const {
    const double dx = X - ex, dy = Y - ey;
    const double fwd = dx * ch + dy * sh, right = dx * sh - dy * ch, down = height - Z;
    const double y1 = down * cp + fwd * sp, z1 = fwd * cp - down * sp;
    return {right * cr + y1 * sr, -right * sr + y1 * cr, z1};
  }
  cv::Point2d project(const cv::Point3d& p) const { return {cx + f * p.x / p.z, cy + f * p.y / p.z}; }
};

struct Lamp2 {
  float x, z;  // ego-level right / forward of a street lamp
};

// Shared drawing state for one frame.
struct Frame {
  cv::Mat& img;
  const Cam& cam;
  const Env& env;
  const Scene& world;
  const cv::Mat& glow;
  bool naive;
  std::vector<Lamp2> lamps;
  std::vector<cv::Point3d> clip;
  std::vector<cv::Point> pix;

  float fog_at(double z) const {
    return z <= 0 ? 0.f : static_cast<float>(1.0 - std::exp(-z / env.vis));
  }
  float light_at(double x, double z) const {
    float g = 0;
    if (env.headlight > 0 && z > 0.5) {
      const double q = x / (0.32 * z + 0.9), q2 = q * q;
      g += static_cast<float>(env.headlight / (1 + q2 * q2) / (1 + (z / 28) * (z / 28)) * std::min(1.0, z / 4));
    }
    for (const Lamp2& l : lamps) {
      const double r2 = (x - l.x) * (x - l.x) + (z - l.z) * (z - l.z);
      g += static_cast<float>(env.lamp / (1 + r2 / 25));
    }
    return g;
  }
  // Colour of a lit, fogged surface at camera point p; `face` darkens faces turned from the light.
  V3 shade(const V3& base, const cv::Point3d& p, float face = 1.f) const {
    V3 lit = mul(base, env.tint) * face;
    if (env.headlight > 0 || env.lamp > 0) lit += mul(base, rgb(1.0f, 0.93f, 0.8f)) * (light_at(p.x, p.z) * face);
    return mix(lit, env.sky_hor, fog_at(p.z));
  }
  V3 emissive(const V3& c, const cv::Point3d& p) const { return mix(c, env.sky_hor, fog_at(p.z) * 0.85f); }

  // Fills a polygon given in camera coordinates (clipped at the near plane).
  void poly(const cv::Point3d* pts, int n, const V3& colour, bool convex = true) {
    const double near = 0.5;
    clip.clear();
    for (int i = 0; i < n; ++i) {
      const cv::Point3d& a = pts[i];
      const cv::Point3d& b = pts[(i + 1) % n];
      const bool ina = a.z >= near, inb = b.z >= near;
      if (ina) clip.push_back(a);
      if (ina != inb) clip.push_back(a + (b - a) * ((near - a.z) / (b.z - a.z)));
    }
    if (clip.size() < 3) return;
    pix.clear();
    int minx = 1 << 30, maxx = -(1 << 30), miny = 1 << 30, maxy = -(1 << 30);
    for (auto& p : clip) {
      const double u = std::clamp(cam.cx + cam.f * p.x / p.z, -20000.0, 20000.0);
      const double v = std::clamp(cam.cy + cam.f * p.y / p.z, -20000.0, 20000.0);
      cv::Point q(static_cast<int>(std::lround(u * 16)), static_cast<int>(std::lround(v * 16)));
      minx = std::min(minx, q.x), maxx = std::max(maxx, q.x), miny = std::min(miny, q.y), maxy = std::max(maxy, q.y);
      pix.push_back(q);
    }
    if (maxx < -16 || maxy < -16 || minx > img.cols * 16 + 16 || miny > img.rows * 16 + 16) return;
    if (convex) {
      cv::fillConvexPoly(img, pix.data(), static_cast<int>(pix.size()), sc(colour), cv::LINE_AA, 4);
    } else {
      const cv::Point* pp = pix.data();
      const int np = static_cast<int>(pix.size());
      cv::fillPoly(img, &pp, &np, 1, sc(colour), cv::LINE_AA, 4);
    }
  }
  void quad(const cv::Point3d& a, const cv::Point3d& b, const cv::Point3d& c, const cv::Point3d& d, const V3& col) {
    const cv::Point3d q[4] = {a, b, c, d};
    poly(q, 4, col);
  }
  void disc(const cv::Point3d& centre, double radius_m, const V3& colour, double aspect = 1.0) {
    if (centre.z < 0.8) return;
    const cv::Point2d p = cam.project(centre);
    const double r = cam.f * radius_m / centre.z;
    if (p.x + r < -2 || p.x - r > img.cols + 2 || p.y + r < -2 || p.y - r > img.rows + 2) return;
    const cv::Point c(static_cast<int>(std::lround(p.x * 16)), static_cast<int>(std::lround(p.y * 16)));
    const int r16 = std::max(1, static_cast<int>(std::lround(r * 16)));
    if (aspect == 1.0)
      cv::circle(img, c, r16, sc(colour), cv::FILLED, cv::LINE_AA, 4);
    else
      cv::ellipse(img, c, cv::Size(r16, std::max(1, static_cast<int>(r16 * aspect))), 0, 0, 360, sc(colour), cv::FILLED,
                  cv::LINE_AA, 4);
  }
  // Additive soft glow around an emissive light.
  void add_glow(const cv::Point3d& centre, double radius_m, const V3& colour, float intensity) {
    if (centre.z < 0.8) return;
    const cv::Point2d p = cam.project(centre);
    const double r = std::min(cam.f * radius_m / centre.z, 0.3 * img.cols);
    if (r < 0.8 || p.x + r < 0 || p.x - r > img.cols || p.y + r < 0 || p.y - r > img.rows) return;
    const int x0 = std::max(0, static_cast<int>(p.x - r)), x1 = std::min(img.cols - 1, static_cast<int>(p.x + r));
    const int y0 = std::max(0, static_cast<int>(p.y - r)), y1 = std::min(img.rows - 1, static_cast<int>(p.y + r));
    const float k = 32.f / static_cast<float>(r);
    const V3 c = colour * (intensity * (1 - fog_at(centre.z) * 0.7f));
    for (int y = y0; y <= y1; ++y) {
      uchar* row = img.ptr<uchar>(y);
      const int gy = std::clamp(static_cast<int>((static_cast<float>(y - p.y)) * k + 32.5f), 0, 64);
      const float* grow = glow.ptr<float>(gy);
      for (int x = x0; x <= x1; ++x) {
        const int gx = std::clamp(static_cast<int>((static_cast<float>(x - p.x)) * k + 32.5f), 0, 64);
        const float g = grow[gx];
        if (g <= 0.002f) continue;
        uchar* px = row + 3 * x;
        for (int ch = 0; ch < 3; ++ch) px[ch] = cv::saturate_cast<uchar>(px[ch] + c[ch] * g);
      }
    }
  }
};

// Road cross-section drawing along sampled centre-line poses.
struct GroundDrawer {
  Frame& F;
  const Road& road;
  std::vector<RoadPose> poses;
  std::vector<cv::Point3d> buf;

  cv::Point3d at(const RoadPose& p, double d) const {
    return F.cam.to_cam(p.x - d * std::sin(p.h), p.y + d * std::cos(p.h), 0);
  }
  cv::Point3d at(double s, double d) const { return at(road.at(s), d); }
  void band(double d0, double d1, const V3& col) {
    const size_t n = poses.size();
    for (size_t c = 0; c + 1 < n; c += 11) {
      const size_t e = std::min(n - 1, c + 12);
      buf.clear();
      for (size_t i = c; i <= e; ++i) buf.push_back(at(poses[i], d0));
      for (size_t i = e + 1; i-- > c;) buf.push_back(at(poses[i], d1));
      F.poly(buf.data(), static_cast<int>(buf.size()), col, false);
    }
  }
  void patch(double s0, double s1, double d0, double d1, const V3& col) {
    const RoadPose a = road.at(s0), b = road.at(s1);
    F.quad(at(a, d0), at(b, d0), at(b, d1), at(a, d1), col);
  }
  void dashes(double d, double width, double dash, double period, double s_from, double s_to, const V3& col) {
    const double first = std::floor(s_from / period) * period;
    for (double s = first; s < s_to; s += period) patch(s, s + dash, d - width / 2, d + width / 2, col);
  }
};

void draw_ground(Frame& F, GroundDrawer& G, double s_far) {
  const Scene& W = F.world;
  const RoadLayout& L = W.layout();
  const Env& e = F.env;
  const double se = W.ego().s;
  const bool urban = W.district().building_density > 0.5;
  F.img.setTo(sc(urban && L.kerbs ? e.urban_ground : e.grass));
  for (int side = 0; side < 2; ++side) {
    const double sg = side == 0 ? 1 : -1;
    const double edge = side == 0 ? L.left_edge() : -L.right_edge();
    if (L.kerbs) {
      G.band(sg * edge, sg * (edge + L.pavement_w), e.pavement);
      G.band(sg * edge, sg * (edge + 0.22), e.kerb);
    } else {
      G.band(sg * edge, sg * (edge + L.pavement_w), e.verge);
    }
  }
  G.band(L.right_edge(), L.left_edge(), e.asphalt);
  const double W_ = L.lane_w;
  const double mark_to = std::min(s_far, se + 140);
  const double s_from = se - 10;
  // Parking strips: slightly different surface, bay lines.
  if (L.parking_fwd > 0) {
    G.band(L.lanes_fwd * W_ + 0.1, L.left_edge(), e.asphalt * 0.93f);
    G.dashes(L.lanes_fwd * W_ + 0.05, 0.1, 1.0, 2.0, s_from, mark_to, e.white);
  }
  if (L.parking_onc > 0) {
    G.band(L.right_edge(), -L.lanes_onc * W_ - 0.1, e.asphalt * 0.93f);
    G.dashes(-L.lanes_onc * W_ - 0.05, 0.1, 1.0, 2.0, s_from, mark_to, e.white);
  }
  if (e.snow) {  // tyre tracks through the slush
    for (int i = 0; i < L.lanes_fwd; ++i)
      for (double o : {-0.8, 0.8}) G.band(L.lane_centre(i) + o - 0.22, L.lane_centre(i) + o + 0.22, e.track);
    for (int i = 0; i < L.lanes_onc; ++i)
      for (double o : {-0.8, 0.8}) G.band(L.onc_lane_centre(i) + o - 0.22, L.onc_lane_centre(i) + o + 0.22, e.track);
  }
  // Centre line, lane lines, edge lines.
  if (L.centre_solid) {
    G.band(0.07, 0.19, e.white);
    G.band(-0.19, -0.07, e.white);
  } else {
    G.dashes(0, 0.13, 4.0, 9.0, s_from, mark_to, e.white);
  }
  for (int i = 1; i < L.lanes_fwd; ++i) G.dashes(i * W_, 0.12, 2.5, 9.0, s_from, mark_to, e.white);
  for (int i = 1; i < L.lanes_onc; ++i) G.dashes(-i * W_, 0.12, 2.5, 9.0, s_from, mark_to, e.white);
  if (L.edge_style == 1) {
    if (L.parking_fwd <= 0) G.band(L.left_edge() - 0.35, L.left_edge() - 0.23, e.white);
    if (L.parking_onc <= 0) G.band(L.right_edge() + 0.23, L.right_edge() + 0.35, e.white);
  } else if (L.edge_style == 2) {
    for (double o : {0.3, 0.5}) {
      if (L.parking_fwd <= 0) G.band(L.left_edge() - o - 0.08, L.left_edge() - o, e.yellow);
      if (L.parking_onc <= 0) G.band(L.right_edge() + o, L.right_edge() + o + 0.08, e.yellow);
    }
  }
  // Stop lines and crossings at the lights; speed bumps.
  for (auto& l : W.lights()) {
    if (l.s < se - 30 || l.s > s_far) continue;
    G.patch(l.s - 0.3, l.s, 0.1, L.lanes_fwd * W_, e.white);
    G.patch(l.s + 6.0, l.s + 6.3, -L.lanes_onc * W_, -0.1, e.white);
    if (l.crossing)
      for (double d = L.right_edge() + 0.3; d < L.left_edge() - 0.3; d += 1.1)
        G.patch(l.s + 1.2, l.s + 4.2, d, d + 0.55, e.white);
  }
  for (double b : W.bumps()) {
    if (b < se - 30 || b > s_far) continue;
    G.patch(b, b + 1.0, L.right_edge(), L.left_edge(), e.asphalt * 1.12f);
    for (double d = L.right_edge() + 0.6; d < L.left_edge() - 0.5; d += 1.3) G.patch(b + 0.1, b + 0.9, d, d + 0.45, e.white);
  }
  // Soft shadows under vehicles.
  const V3 shadow = e.asphalt * 0.45f;
  for (auto& o : W.vehicles()) {
    if (o.s < se - 20 || o.s > s_far) continue;
    G.patch(o.s - o.length / 2 - 0.2, o.s + o.length / 2 + 0.2, o.d - o.width / 2 - 0.15, o.d + o.width / 2 + 0.15, shadow);
  }
}

// ---- 3-D objects -------------------------------------------------------------------------------------

struct Face {
  cv::Point3d p00, p10, p11, p01;  // camera coords; u to the viewer's right, v upwards
  bool visible;
  cv::Point3d at(double u, double v) const {
    return p00 + (p10 - p00) * u + (p01 - p00) * v + (p11 - p10 - p01 + p00) * (u * v);
  }
};
enum { kRear = 0, kFront, kLeft, kRight, kTop };

struct Box {
  Face f[5];
};

// Oriented box: centre (cx, cy) on the ground, heading th; extents along the heading [x0, x1], to its left
// [y0, y1], height [z0, z1]. Faces are culled against the camera position.
Box make_box(const Cam& cam, double cx, double cy, double th, double x0, double x1, double y0, double y1, double z0,
             double z1) {
  const double c = std::cos(th), s = std::sin(th);
  auto P = [&](double x, double y, double z) { return cam.to_cam(cx + x * c - y * s, cy + x * s + y * c, z); };
  // Camera position in the box frame.
  const double dx = cam.ex - cx, dy = cam.ey - cy;
  const double lx = dx * c + dy * s, ly = -dx * s + dy * c, lz = cam.height;
  Box b;
  b.f[kRear] = {P(x0, y1, z0), P(x0, y0, z0), P(x0, y0, z1), P(x0, y1, z1), lx < x0};
  b.f[kFront] = {P(x1, y0, z0), P(x1, y1, z0), P(x1, y1, z1), P(x1, y0, z1), lx > x1};
  b.f[kLeft] = {P(x1, y1, z0), P(x0, y1, z0), P(x0, y1, z1), P(x1, y1, z1), ly > y1};
  b.f[kRight] = {P(x0, y0, z0), P(x1, y0, z0), P(x1, y0, z1), P(x0, y0, z1), ly < y0};
  b.f[kTop] = {P(x0, y1, z1), P(x0, y0, z1), P(x1, y0, z1), P(x1, y1, z1), lz > z1};
  return b;
}

const float kFaceShade[5] = {0.72f, 0.8f, 0.88f, 0.88f, 1.05f};

void fill_face(Frame& F, const Face& f, const V3& base, float shade) {
  F.quad(f.p00, f.p10, f.p11, f.p01, F.shade(base, (f.p00 + f.p11) * 0.5, shade));
}
void face_rect(Frame& F, const Face& f, double u0, double u1, double v0, double v1, const V3& colour) {
  F.quad(f.at(u0, v0), f.at(u1, v0), f.at(u1, v1), f.at(u0, v1), colour);
}
// Draws all visible faces of a box in the body colour; returns the box for details.
Box draw_box(Frame& F, double cx, double cy, double th, double x0, double x1, double y0, double y1, double z0, double z1,
             const V3& base) {
  Box b = make_box(F.cam, cx, cy, th, x0, x1, y0, y1, z0, z1);
  for (int i = 0; i < 5; ++i)
    if (b.f[i].visible) fill_face(F, b.f[i], base, kFaceShade[i]);
  return b;
}

void draw_lamp_pair(Frame& F, const Face& f, double v0, double v1, double w, const V3& col, bool on, float glow,
                    double glow_r) {
  for (double u : {0.03, 0.97 - w}) {
    const cv::Point3d c = f.at(u + w / 2, (v0 + v1) / 2);
    face_rect(F, f, u, u + w, v0, v1, on ? F.emissive(col, c) : F.shade(col * 0.6f, c));
    if (on && glow > 0) F.add_glow(c, glow_r, col, glow);
  }
}

void draw_vehicle(Frame& F, const Vehicle& o) {
  const Scene& W = F.world;
  double x, y;
  W.road().point(o.s, o.d, x, y);
  double th = W.road().at(o.s).h;
  if (o.dir == -1 || (o.dir == 0 && (o.look & 1u))) th += kPi;
  if (o.dir != 0) th += std::atan2(o.d_target - o.d, 8.0) * 0.5 * (o.dir > 0 ? 1 : -1) * (o.swerving ? 1 : 0);
  const V3 body = from8(o.colour);
  const double hl = o.length / 2, hw = o.width / 2;
  const bool lights = F.env.lights_on && o.dir != 0;
  const V3 glass = rgb(38, 46, 58), dark = rgb(22, 22, 24), tyre = rgb(18, 18, 18);
  const V3 tail = rgb(235, 30, 25), tail_off = rgb(150, 30, 30), head = rgb(255, 248, 225);
  const bool night = F.env.night;
  const float tail_glow = o.braking ? (night ? 1.0f : 0.55f) : (lights ? (night ? 0.55f : 0.25f) : 0.f);
  // Undercarriage and wheels.
  draw_box(F, x, y, th, -hl + 0.3, hl - 0.3, -hw + 0.12, hw - 0.12, 0.0, 0.45, tyre);
  double body_top, z0 = 0.32;
  switch (o.kind) {
    case VehicleKind::Car: body_top = 0.3 + 0.48 * (o.height - 0.3); break;
    case VehicleKind::Van: body_top = o.height; break;
    case VehicleKind::Bus: body_top = o.height, z0 = 0.3; break;
    default: body_top = 1.1; break;
  }
  if (o.kind == VehicleKind::Truck) {
    // Box trailer behind, cab at the front, chassis between.
    const double cab = 2.3;
    draw_box(F, x, y, th, -hl, hl - cab - 0.2, -hw + 0.2, hw - 0.2, 0.4, 1.1, dark);
    Box tr = draw_box(F, x, y, th, -hl, hl - cab - 0.3, -hw, hw, 1.1, o.height, body);
    if (tr.f[kRear].visible) {
      face_rect(F, tr.f[kRear], 0.495, 0.505, 0.02, 0.98, F.shade(dark, tr.f[kRear].at(0.5, 0.5)));
      Box bumper = make_box(F.cam, x, y, th, -hl, -hl + 0.2, -hw + 0.05, hw - 0.05, 0.5, 1.05);
      if (bumper.f[kRear].visible) {
        fill_face(F, bumper.f[kRear], dark, 1.f);
        draw_lamp_pair(F, bumper.f[kRear], 0.35, 0.8, 0.14, o.braking || lights ? tail : tail_off, o.braking || lights,
                       tail_glow, 0.5);
        face_rect(F, bumper.f[kRear], 0.4, 0.6, 0.1, 0.5, F.shade(rgb(235, 200, 40), bumper.f[kRear].at(0.5, 0.3)));
      }
    }
    Box cb = draw_box(F, x, y, th, hl - cab, hl, -hw + 0.05, hw - 0.05, 0.45, o.height * 0.8, body * 0.9f);
    if (cb.f[kFront].visible) {
      face_rect(F, cb.f[kFront], 0.06, 0.94, 0.55, 0.92, F.shade(glass, cb.f[kFront].at(0.5, 0.7)));
      draw_lamp_pair(F, cb.f[kFront], 0.08, 0.2, 0.15, head, lights, night ? 1.3f : 0.4f, 1.0);
    }
    for (int sd : {kLeft, kRight})
      if (cb.f[sd].visible) face_rect(F, cb.f[sd], 0.1, 0.6, 0.55, 0.9, F.shade(glass, cb.f[sd].at(0.5, 0.7)));
    return;
  }
  Box b = draw_box(F, x, y, th, -hl, hl, -hw, hw, z0, body_top, body);
  // Wheels on the visible side.
  for (int sd : {kLeft, kRight}) {
    if (!b.f[sd].visible) continue;
    const Face& f = b.f[sd];
    const double wr = 0.34 / o.length;
    const double vz = 0.6 / (body_top - z0);
    for (double ax : {0.18, 0.82}) {
      const cv::Point3d c = f.at(ax, 0.0);
      F.quad(f.at(ax - wr, -z0 / (body_top - z0)), f.at(ax + wr, -z0 / (body_top - z0)), f.at(ax + wr, vz * 0.6),
             f.at(ax - wr, vz * 0.6), F.shade(tyre, c));
    }
  }
  if (o.kind == VehicleKind::Car) {
    const double cl = o.length * 0.52, cb_ = -o.length * 0.06;
    Box c = make_box(F.cam, x, y, th, cb_ - cl / 2, cb_ + cl / 2, -hw + 0.1, hw - 0.1, body_top, o.height);
    for (int i = 0; i < 5; ++i) {
      if (!c.f[i].visible) continue;
      fill_face(F, c.f[i], body, kFaceShade[i]);
      if (i == kTop) continue;
      const cv::Point3d m = c.f[i].at(0.5, 0.5);
      if (i == kRear || i == kFront) face_rect(F, c.f[i], 0.1, 0.9, 0.05, 0.9, F.shade(glass, m));
      else face_rect(F, c.f[i], 0.07, 0.93, 0.08, 0.86, F.shade(glass, m));
    }
  } else {
    const Face& s1 = b.f[kLeft].visible ? b.f[kLeft] : b.f[kRight];
    const bool sv = b.f[kLeft].visible || b.f[kRight].visible;
    if (sv) {
      const cv::Point3d m = s1.at(0.5, 0.7);
      if (o.kind == VehicleKind::Van) {
        const bool front_first = b.f[kLeft].visible;  // u runs front->rear on the left face
        if (front_first) face_rect(F, s1, 0.03, 0.25, 0.55, 0.88, F.shade(glass, m));
        else face_rect(F, s1, 0.75, 0.97, 0.55, 0.88, F.shade(glass, m));
      } else if (o.double_decker) {
        face_rect(F, s1, 0.03, 0.97, 0.25, 0.44, F.shade(glass, m));
        face_rect(F, s1, 0.03, 0.97, 0.62, 0.88, F.shade(glass, m));
      } else {
        face_rect(F, s1, 0.03, 0.97, 0.45, 0.85, F.shade(glass, m));
      }
    }
  }
  const double lamp_v0 = o.kind == VehicleKind::Car ? 0.55 : 0.12, lamp_v1 = o.kind == VehicleKind::Car ? 0.9 : 0.3;
  if (b.f[kRear].visible) {
    const Face& f = b.f[kRear];
    if (o.kind == VehicleKind::Van) {
      face_rect(F, f, 0.07, 0.47, 0.6, 0.88, F.shade(glass, f.at(0.3, 0.7)));
      face_rect(F, f, 0.53, 0.93, 0.6, 0.88, F.shade(glass, f.at(0.7, 0.7)));
    } else if (o.kind == VehicleKind::Bus) {
      face_rect(F, f, 0.1, 0.9, o.double_decker ? 0.68 : 0.55, 0.88, F.shade(glass, f.at(0.5, 0.7)));
    }
    draw_lamp_pair(F, f, lamp_v0, lamp_v1, o.kind == VehicleKind::Car ? 0.2 : 0.1, o.braking || lights ? tail : tail_off,
                   o.braking || lights, tail_glow, o.kind == VehicleKind::Car ? 0.6 : 0.5);
    const double pv = o.kind == VehicleKind::Car ? 0.12 : 0.05;
    face_rect(F, f, 0.38, 0.62, pv, pv + (o.kind == VehicleKind::Car ? 0.25 : 0.08),
              F.shade(rgb(235, 200, 40), f.at(0.5, pv)));
  }
  if (b.f[kFront].visible) {
    const Face& f = b.f[kFront];
    if (o.kind != VehicleKind::Car) face_rect(F, f, 0.05, 0.95, o.kind == VehicleKind::Bus ? 0.35 : 0.55, 0.93, F.shade(glass, f.at(0.5, 0.7)));
    if (o.kind == VehicleKind::Bus) face_rect(F, f, 0.1, 0.9, 0.94, 0.99, lights ? F.emissive(rgb(250, 200, 60), f.at(0.5, 0.96)) : F.shade(dark, f.at(0.5, 0.96)));
    face_rect(F, f, 0.3, 0.7, 0.35, 0.6, F.shade(dark, f.at(0.5, 0.5)));
    draw_lamp_pair(F, f, o.kind == VehicleKind::Car ? 0.5 : 0.1, o.kind == VehicleKind::Car ? 0.75 : 0.2, 0.2, head,
                   lights, night ? 1.4f : 0.45f, night ? 1.3 : 0.6);
  }
}

void draw_pedestrian(Frame& F, const PedPose& q, const Pedestrian& p, double t, uint32_t id) {
  const Scene& W = F.world;
  double x, y;
  W.road().point(q.s, q.d, x, y);
  const double th = W.road().at(q.s).h + q.heading;
  const double ph = q.walking ? std::sin(t * 2 * kPi * 1.8 + id) : 0;
  const V3 legs = from8(p.legs), top = from8(p.top);
  const double c = std::cos(th), s = std::sin(th);
  for (double side : {-1.0, 1.0}) {
    const double off = 0.16 * ph * side;
    draw_box(F, x + off * c - side * 0.1 * s, y + off * s + side * 0.1 * c, th, -0.08, 0.08, -0.07, 0.07, 0, 0.86, legs);
  }
  draw_box(F, x, y, th, -0.13, 0.13, -0.23, 0.23, 0.84, 1.48, top);
  const V3 skin = (id % 3 == 0) ? rgb(120, 80, 55) : (id % 3 == 1) ? rgb(220, 180, 150) : rgb(180, 130, 95);
  const cv::Point3d head = F.cam.to_cam(x, y, 1.6);
  F.disc(head, 0.12, F.shade(skin, head));
  const cv::Point3d hair = F.cam.to_cam(x, y, 1.67);
  F.disc(hair, 0.08, F.shade(rgb(40, 30, 25), hair));
}

void draw_prop(Frame& F, const Prop& p) {
  const Scene& W = F.world;
  const RoadPose rp = W.road().at(p.s);
  double x, y;
  W.road().point(p.s, p.d, x, y);
  const double th = rp.h;
  const V3 col = from8(p.colour);
  switch (p.kind) {
    case PropKind::Tree: {
      draw_box(F, x, y, th, -0.15, 0.15, -0.15, 0.15, 0, p.h * 0.55, rgb(80, 60, 42));
      V3 leaf = F.env.snow ? mix(col, rgb(225, 228, 235), 0.5f) : col;
      const cv::Point3d c = F.cam.to_cam(x, y, p.h * 0.62);
      F.disc(c, p.w, F.shade(leaf * 0.7f, c));
      const double sn = std::sin(th), cs = std::cos(th);
      const cv::Point3d c2 = F.cam.to_cam(x - 0.2 * p.w * sn, y + 0.2 * p.w * cs, p.h * 0.62 + 0.35 * p.w);
      F.disc(c2, p.w * 0.68, F.shade(leaf, c2));
      const cv::Point3d c3 = F.cam.to_cam(x + 0.35 * p.w * sn, y - 0.35 * p.w * cs, p.h * 0.62 - 0.1 * p.w);
      F.disc(c3, p.w * 0.55, F.shade(leaf * 0.85f, c3));
      break;
    }
    case PropKind::Building: {
      const double sg = p.d > 0 ? 1 : -1;
      // Box: along-road [-w/2, w/2], lateral from the front wall (towards the road) to depth away.
      const double yin = sg > 0 ? -5 : 5;  // front wall offset relative to the centre (d is centre)
      const double y0 = sg > 0 ? yin : yin - p.depth, y1 = sg > 0 ? yin + p.depth : yin;
      Box b = draw_box(F, x, y, th, -p.w / 2, p.w / 2, y0, y1, 0, p.h, col);
      const int front = sg > 0 ? kRight : kLeft;
      const Face& f = b.f[front];
      if (!f.visible) break;
      const cv::Point3d mid = f.at(0.5, 0.5);
      const double px_per_m = F.cam.f / std::max(1.0, mid.z);
      const int rows = static_cast<int>(p.h / 3.2), cols = static_cast<int>(p.w / 2.9);
      if (px_per_m * 1.2 < 1.5 || rows < 1 || cols < 1) break;
      const V3 glass = F.env.night ? rgb(20, 22, 30) : rgb(60, 72, 88);
      const V3 lit = rgb(255, 205, 120);
      for (int r = 0; r < rows; ++r)
        for (int c = 0; c < cols; ++c) {
          const double u0 = (c + 0.25) / cols, u1 = (c + 0.75) / cols;
          const double v0 = (r * 3.2 + 1.1) / p.h, v1 = (r * 3.2 + 2.6) / p.h;
          const bool on = (F.env.night || F.env.dusk) && (mix64(p.bits + static_cast<uint64_t>(r * 64 + c)) % 5 < 2);
          face_rect(F, f, u0, u1, v0, v1, on ? F.emissive(lit * (F.env.dusk ? 0.8f : 1.f), mid) : F.shade(glass, mid));
        }
      break;
    }
    case PropKind::Lamp: {
      draw_box(F, x, y, th, -0.08, 0.08, -0.08, 0.08, 0, p.h, col);
      const double sg = p.d > 0 ? -1 : 1;  // arm reaches over the road
      draw_box(F, x, y, th, -0.05, 0.05, std::min(0.0, sg * 1.4), std::max(0.0, sg * 1.4), p.h - 0.12, p.h, col);
      const double ax = x - sg * 1.3 * std::sin(th), ay = y + sg * 1.3 * std::cos(th);
      const bool on = F.env.night || F.env.dusk;
      const V3 lampc = rgb(255, 215, 150);
      Box h = make_box(F.cam, ax, ay, th, -0.3, 0.3, -0.15, 0.15, p.h - 0.25, p.h - 0.08);
      for (int i = 0; i < 5; ++i)
        if (h.f[i].visible) fill_face(F, h.f[i], rgb(70, 70, 70), kFaceShade[i]);
      const cv::Point3d c = F.cam.to_cam(ax, ay, p.h - 0.27);
      F.disc(c, 0.18, on ? F.emissive(lampc, c) : F.shade(rgb(200, 200, 190), c));
      if (on) F.add_glow(c, F.env.night ? 2.0 : 1.0, lampc, F.env.night ? 0.9f : 0.5f);
      break;
    }
    case PropKind::Hedge: {
      const int n = 5;
      for (int i = 0; i < n; ++i) {
        const double s0 = p.s - p.w / 2 + i * p.w / n;
        double hx, hy;
        W.road().point(s0 + p.w / n / 2, p.d, hx, hy);
        draw_box(F, hx, hy, W.road().at(s0 + p.w / n / 2).h, -p.w / n / 2 - 0.3, p.w / n / 2 + 0.3, -p.depth / 2,
                 p.depth / 2, 0, p.h, F.env.snow ? mix(col, rgb(225, 228, 235), 0.6f) : col);
      }
      break;
    }
    case PropKind::Sign: {
      draw_box(F, x, y, th, -0.04, 0.04, -0.04, 0.04, 0, p.h, rgb(120, 120, 120));
      const cv::Point3d c = F.cam.to_cam(x, y, p.h + 0.3);
      if (p.bits % 3 == 0) {
        F.disc(c, 0.38, F.shade(rgb(200, 30, 30), c));
        F.disc(c, 0.3, F.shade(rgb(240, 240, 240), c));
        F.disc(c, 0.1, F.shade(rgb(30, 30, 30), c));
      } else {
        F.disc(c, 0.36, F.shade(rgb(30, 80, 170), c));
        F.disc(c, 0.08, F.shade(rgb(240, 240, 240), c));
      }
      break;
    }
  }
}

void draw_signal(Frame& F, const TrafficLight& l, double s, double d, double t) {
  const Scene& W = F.world;
  double x, y;
  W.road().point(s, d, x, y);
  const double th = W.road().at(s).h;
  draw_box(F, x, y, th, -0.07, 0.07, -0.07, 0.07, 0, 3.5, rgb(40, 42, 40));
  Box plate = make_box(F.cam, x, y, th, -0.2, -0.14, -0.3, 0.3, 2.25, 3.45);
  if (plate.f[kRear].visible) {
    fill_face(F, plate.f[kRear], rgb(235, 235, 235), 1.f);
    face_rect(F, plate.f[kRear], 0.06, 0.94, 0.03, 0.97, F.shade(rgb(14, 14, 14), plate.f[kRear].at(0.5, 0.5)));
  }
  draw_box(F, x, y, th, -0.14, 0.1, -0.18, 0.18, 2.3, 3.4, rgb(18, 18, 18));
  const int st = l.state(t);
  const V3 on_c[3] = {rgb(90, 255, 140), rgb(255, 180, 30), rgb(255, 40, 30)};
  const V3 off_c[3] = {rgb(20, 50, 30), rgb(60, 45, 15), rgb(60, 18, 15)};
  const double zs[3] = {2.5, 2.85, 3.2};
  for (int i = 0; i < 3; ++i) {
    const cv::Point3d c = F.cam.to_cam(x - 0.16 * std::cos(th), y - 0.16 * std::sin(th), zs[i]);
    if (!plate.f[kRear].visible) continue;
    const bool on = (i == 0 && st == 0) || (i == 1 && st == 1) || (i == 2 && st == 2);
    F.disc(c, 0.11, on ? F.emissive(on_c[i], c) : F.shade(off_c[i], c));
    if (on) F.add_glow(c, F.env.night ? 1.4 : 0.6, on_c[i], F.env.night ? 1.0f : 0.6f);
  }
}

// Distant hills / skyline and clouds, fixed in world azimuth so they rotate (but never translate) with the ego.
void draw_backdrop(Frame& F) {
  const Scene& W = F.world;
  const Env& e = F.env;
  const double heading = std::atan2(F.cam.sh, F.cam.ch);
  const double R = 4000;
  const bool urban = W.district().building_density > 0.5;
  const uint64_t key = stream_key(W.spec().seed, static_cast<uint64_t>(W.spec().index), "backdrop");
  Rng r(key);
  const double ph1 = r.uniform(0, 6.3), ph2 = r.uniform(0, 6.3), ph3 = r.uniform(0, 6.3);
  const double amp = urban ? 0 : r.uniform(0.6, 1.6);
  std::vector<cv::Point3d> pts;
  const int n = 48;
  for (int i = 0; i <= n; ++i) {
    const double a = heading + (static_cast<double>(i) / n - 0.5) * 2.0;  // +-57 degrees
    double el;
    if (urban) {
      const double bin = std::floor(a / 0.035);
      const double hsh = static_cast<double>(mix64(key + static_cast<uint64_t>(static_cast<int64_t>(bin) + 100000)) % 1000) / 1000.0;
      el = 0.004 + 0.02 * hsh * hsh;
    } else {
      el = 0.004 + 0.006 * amp * (1.3 + std::sin(3 * a + ph1) + 0.5 * std::sin(7 * a + ph2) + 0.25 * std::sin(17 * a + ph3));
    }
    if (urban) {  // blocky skyline: two points per azimuth bin
      const double a0 = std::floor(a / 0.035) * 0.035;
      pts.push_back(F.cam.to_cam(F.cam.ex + R * std::cos(a0), F.cam.ey + R * std::sin(a0), R * el));
      pts.push_back(F.cam.to_cam(F.cam.ex + R * std::cos(a0 + 0.035), F.cam.ey + R * std::sin(a0 + 0.035), R * el));
    } else {
      pts.push_back(F.cam.to_cam(F.cam.ex + R * std::cos(a), F.cam.ey + R * std::sin(a), R * el));
    }
  }
  for (int i = n; i >= 0; --i) {
    const double a = heading + (static_cast<double>(i) / n - 0.5) * 2.0;
    pts.push_back(F.cam.to_cam(F.cam.ex + R * std::cos(a), F.cam.ey + R * std::sin(a), -R * 0.004));
  }
  const V3 land = urban ? rgb(92, 98, 112) : e.snow ? rgb(200, 205, 214) : rgb(48, 72, 50);
  const float haze = urban ? 0.55f : 0.6f;
  V3 c = mix(mul(land, e.tint), e.sky_hor, std::max(haze, F.fog_at(R / 3)));
  F.poly(pts.data(), static_cast<int>(pts.size()), c, false);
  if (!e.clouds) return;
  const int nc = r.integer(3, 9);
  for (int i = 0; i < nc; ++i) {
    const double a = r.uniform(0, 2 * kPi), el = r.uniform(0.05, 0.3), size = r.uniform(0.04, 0.12);
    const int puffs = r.integer(3, 6);
    const V3 cc = e.dusk ? rgb(250, 190, 170) : rgb(245, 247, 250);
    for (int j = 0; j < puffs; ++j) {
      const double aj = a + (j - puffs / 2.0) * size * 0.6, ej = el + r.uniform(-0.2, 0.2) * size;
      const cv::Point3d p = F.cam.to_cam(F.cam.ex + R * std::cos(aj), F.cam.ey + R * std::sin(aj), R * std::tan(ej));
      F.disc(p, R * size * r.uniform(0.35, 0.6), mix(e.sky_mid, cc, 0.45f + 0.1f * static_cast<float>(j % 2)), 0.5);
    }
  }
}

void draw_hood(Frame& F) {
  cv::Mat& img = F.img;
  const int W = img.cols, H = img.rows;
  std::vector<cv::Point> pts;
  const int n = 24;
  for (int i = 0; i <= n; ++i) {
    const double u = static_cast<double>(i) / n;
    const double x = -0.15 * W + u * 1.3 * W;
    const double y = H * (0.935 + 0.09 * (2 * u - 1) * (2 * u - 1));
    pts.push_back(cv::Point(static_cast<int>(x * 16), static_cast<int>(y * 16)));
  }
  pts.push_back(cv::Point(static_cast<int>(1.15 * W * 16), (H + 4) * 16));
  pts.push_back(cv::Point(static_cast<int>(-0.15 * W * 16), (H + 4) * 16));
  V3 paint = mul(rgb(36, 40, 48), F.env.tint);
  if (F.env.headlight > 0) paint += rgb(10, 10, 10) * F.env.headlight;
  const cv::Point* pp = pts.data();
  const int np = static_cast<int>(pts.size());
  cv::fillPoly(img, &pp, &np, 1, sc(paint), cv::LINE_AA, 4);
  // A soft reflection of the sky along the bonnet's crest.
  std::vector<cv::Point> hl;
  for (int i = 4; i <= n - 4; ++i) {
    const double u = static_cast<double>(i) / n;
    const double x = -0.15 * W + u * 1.3 * W;
    const double y = H * (0.935 + 0.09 * (2 * u - 1) * (2 * u - 1)) + 1.5;
    hl.push_back(cv::Point(static_cast<int>(x * 16), static_cast<int>(y * 16)));
  }
  cv::polylines(img, hl, false, sc(mix(paint, F.env.sky_hor, 0.35f)), std::max(1, W / 256), cv::LINE_AA, 4);
}

void draw_precipitation(Frame& F, double t, int64_t frame) {
  const Env& e = F.env;
  if (!e.rain && !e.snow) return;
  cv::Mat& img = F.img;
  const int W = img.cols, H = img.rows;
  const double scale = W / 512.0;
  const uint64_t key = stream_key(F.world.spec().seed, static_cast<uint64_t>(F.world.spec().index), "precip");
  cv::Mat overlay(img.size(), CV_8UC3, cv::Scalar::all(0));
  if (e.rain) {
    Rng r(mix64(key ^ static_cast<uint64_t>(frame)));
    const int n = static_cast<int>(W * H / 1300);
    const float b = e.night ? 30.f : 45.f;
    for (int i = 0; i < n; ++i) {
      const double x = r.uniform(-20, W + 20), y = r.uniform(-20, H);
      const double len = r.uniform(10, 26) * scale;
      cv::line(overlay, cv::Point(static_cast<int>(x * 16), static_cast<int>(y * 16)),
               cv::Point(static_cast<int>((x - 0.18 * len) * 16), static_cast<int>((y + len) * 16)), cv::Scalar::all(b),
               1, cv::LINE_AA, 4);
    }
  } else {
    // Flakes drift smoothly: position is a function of time.
    Rng r(key);
    const int n = static_cast<int>(W * H / 1400);
    for (int i = 0; i < n; ++i) {
      const double x0 = r.uniform(0, W), y0 = r.uniform(0, H), vy = r.uniform(0.15, 0.45) * H, vx = r.uniform(-0.1, 0.1) * W;
      const double sz = r.uniform(0.5, 1.6) * scale;
      const double wob = std::sin(t * r.uniform(1, 3) + r.uniform(0, 6.3)) * 6 * scale;
      const double x = std::fmod(x0 + vx * t + wob + 10 * W, static_cast<double>(W));
      const double y = std::fmod(y0 + vy * t, static_cast<double>(H));
      cv::circle(overlay, cv::Point(static_cast<int>(x * 16), static_cast<int>(y * 16)),
                 std::max(8, static_cast<int>(sz * 16)), cv::Scalar::all(e.night ? 90 : 130), cv::FILLED, cv::LINE_AA, 4);
    }
  }
  cv::add(img, overlay, img);
}

struct Item {
  double dist;
  int kind;  // 0 vehicle, 1 pedestrian, 2 prop, 3 signal
  size_t idx;
  double s, d;  // signal placement
};

}  // namespace

Renderer::Renderer(int height, int width, CameraModel cam) : h_(height), w_(width), cam_(cam) {
  // Tileable value noise, three octaves.
  const int N = 256;
  noise_.assign(N * N, 0.f);
  Rng r(0x5eed);
  for (int oct = 0; oct < 3; ++oct) {
    const int cells = 16 << oct;
    std::vector<float> g(static_cast<size_t>(cells * cells));
    for (auto& v : g) v = static_cast<float>(r.uniform(-1, 1));
    const float amp = 0.6f / static_cast<float>(1 << oct);
    for (int y = 0; y < N; ++y)
      for (int x = 0; x < N; ++x) {
        const float fx = static_cast<float>(x) * cells / N, fy = static_cast<float>(y) * cells / N;
        const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
        const float ux = fx - x0, uy = fy - y0;
        const float sx = ux * ux * (3 - 2 * ux), sy = uy * uy * (3 - 2 * uy);
        auto G = [&](int xx, int yy) { return g[static_cast<size_t>((yy % cells) * cells + (xx % cells))]; };
        const float v = (G(x0, y0) * (1 - sx) + G(x0 + 1, y0) * sx) * (1 - sy) + (G(x0, y0 + 1) * (1 - sx) + G(x0 + 1, y0 + 1) * sx) * sy;
        noise_[static_cast<size_t>(y * N + x)] += amp * v;
      }
  }
  glow_.create(65, 65, CV_32F);
  for (int y = 0; y < 65; ++y)
    for (int x = 0; x < 65; ++x) {
      const float r2 = static_cast<float>((x - 32) * (x - 32) + (y - 32) * (y - 32)) / (32.f * 32.f);
      glow_.at<float>(y, x) = r2 >= 1 ? 0.f : std::exp(-5.f * r2) * (1 - r2);
    }
}

void Renderer::render(const Scene& world, cv::Mat& out) {
  out.create(h_, w_, CV_8UC3);
  const Env env = make_env(world.weather(), world.time_of_day());  // a change of conditions applies from its time
  const Ego& ego = world.ego();
  Cam cam;
  cam.ex = ego.x, cam.ey = ego.y, cam.ch = std::cos(ego.h), cam.sh = std::sin(ego.h);
  cam.height = cam_.height;
  const double pitch = cam_.base_pitch + ego.pitch, roll = ego.roll;
  cam.cp = std::cos(pitch), cam.sp = std::sin(pitch), cam.cr = std::cos(roll), cam.sr = std::sin(roll);
  cam.f = 0.5 * w_ / std::tan(cam_.hfov_deg * kPi / 360);
  cam.cx = 0.5 * w_ - 0.5, cam.cy = 0.5 * h_ - 0.5;
  Frame F{out, cam, env, world, glow_, naive_, {}, {}, {}};
  const double t = world.time();
  const double se = ego.s;
  const double range = std::min(300.0, std::max(90.0, env.vis * 4));
  const double s_far = se + range;

  // Street lamps near the ego light the ground at night.
  std::vector<Prop> props;
  for (int64_t b = static_cast<int64_t>(std::floor((se - 30) / Scene::kBlock));
       b <= static_cast<int64_t>(std::floor(s_far / Scene::kBlock)); ++b)
    for (const Prop& p : world.props_block(b))
      if (p.s > se - 30 && p.s < s_far) props.push_back(p);
  if (env.lamp > 0)
    for (const Prop& p : props)
      if (p.kind == PropKind::Lamp && p.s > se - 10 && p.s < se + 90 && F.lamps.size() < 8) {
        double x, y;
        world.road().point(p.s, p.d + (p.d > 0 ? -1.3 : 1.3), x, y);
        const double dx = x - cam.ex, dy = y - cam.ey;
        F.lamps.push_back({static_cast<float>(dx * cam.sh - dy * cam.ch), static_cast<float>(dx * cam.ch + dy * cam.sh)});
      }

  // 1. Flat ground layer.
  GroundDrawer G{F, world.road(), {}, {}};
  for (double s = se - 40; s < se + 2; s += 3) G.poses.push_back(world.road().at(s));
  for (double dist = 2; dist < range; dist += std::max(0.75, 0.05 * dist)) G.poses.push_back(world.road().at(se + dist));
  draw_ground(F, G, s_far);

  // 2. Per-pixel lighting, texture, haze on the ground; sky gradient above the horizon.
  const int kFogN = 4096;
  const float kFogScale = 4.f;  // LUT bins per metre
  std::vector<float> fog_lut(kFogN);
  for (int i = 0; i < kFogN; ++i) fog_lut[static_cast<size_t>(i)] = F.fog_at((i + 0.5) / kFogScale);
  const int kSkyN = 512;
  std::vector<V3> sky_lut(kSkyN);
  for (int i = 0; i < kSkyN; ++i) {
    const float e = static_cast<float>(i) / (kSkyN - 1);  // tan(elevation) in [0, 1]
    V3 c = e < 0.1f ? mix(env.sky_hor, env.sky_mid, e / 0.1f) : mix(env.sky_mid, env.sky_top, std::min(1.f, (e - 0.1f) / 0.5f));
    sky_lut[static_cast<size_t>(i)] = c;
  }
  const bool lit = env.headlight > 0 || env.lamp > 0;
  const float H = static_cast<float>(cam.height);
  const V3 warm = rgb(1.0f, 0.93f, 0.8f);
  const int N = 256;
  for (int v = 0; v < h_; ++v) {
    uchar* row = out.ptr<uchar>(v);
    const double yc = (v - cam.cy) / cam.f, xc0 = -cam.cx / cam.f, dxc = 1.0 / cam.f;
    const double r0 = xc0 * cam.cr - yc * cam.sr, dr = dxc * cam.cr;
    const double y10 = xc0 * cam.sr + yc * cam.cr, dy1 = dxc * cam.sr;
    const double dn0 = y10 * cam.cp - cam.sp, ddn = dy1 * cam.cp;
    const double fw0 = y10 * cam.sp + cam.cp, dfw = dy1 * cam.sp;
    for (int u = 0; u < w_; ++u) {
      uchar* px = row + 3 * u;
      const double down = dn0 + ddn * u, fwd = fw0 + dfw * u;
      if (down > 1e-5 && fwd > 0 && H * fwd / down < 6000) {
        const double tt = H / down;
        const double Z = fwd * tt, X = (r0 + dr * u) * tt;
        const double wx = cam.ex + Z * cam.ch + X * cam.sh, wy = cam.ey + Z * cam.sh - X * cam.ch;
        const double tx = wx * 2, ty = wy * 2;
        const double fx = std::floor(tx), fy = std::floor(ty);
        const int ix = static_cast<int>(static_cast<int64_t>(fx) & (N - 1)), iy = static_cast<int>(static_cast<int64_t>(fy) & (N - 1));
        const float ax = static_cast<float>(tx - fx), ay = static_cast<float>(ty - fy);
        const float* n0 = &noise_[static_cast<size_t>(iy * N)];
        const float* n1 = &noise_[static_cast<size_t>(((iy + 1) & (N - 1)) * N)];
        const int ix1 = (ix + 1) & (N - 1);
        const float tex = (n0[ix] * (1 - ax) + n0[ix1] * ax) * (1 - ay) + (n1[ix] * (1 - ax) + n1[ix1] * ax) * ay;
        const float amp = env.tex_amp / (1.f + static_cast<float>(Z) / 30.f);
        const float ff = naive_ ? F.fog_at(Z) : fog_lut[static_cast<size_t>(std::min<double>(kFogN - 1, Z * kFogScale))];
        const float g = 1.f + amp * tex;
        const float l = lit ? F.light_at(X, Z) : 0.f;
        for (int ch = 0; ch < 3; ++ch) {
          const float c = px[ch] * g * (env.tint[ch] + l * warm[ch]);
          px[ch] = cv::saturate_cast<uchar>(c * (1 - ff) + env.sky_hor[ch] * ff);
        }
      } else {
        const double e = fwd > 1e-6 ? std::max(0.0, -down / fwd) : 1.0;
        const V3& c = sky_lut[static_cast<size_t>(std::min<double>(kSkyN - 1, e * (kSkyN - 1)))];
        px[0] = cv::saturate_cast<uchar>(c[0]), px[1] = cv::saturate_cast<uchar>(c[1]), px[2] = cv::saturate_cast<uchar>(c[2]);
      }
    }
  }

  // 3. Backdrop, then objects far to near.
  draw_backdrop(F);
  std::vector<Item> items;
  auto dist_of = [&](double s, double d) {
    double x, y;
    world.road().point(s, d, x, y);
    return std::hypot(x - cam.ex, y - cam.ey);
  };
  const auto& veh = world.vehicles();
  for (size_t i = 0; i < veh.size(); ++i)
    if (veh[i].s > se - 15 && veh[i].s < s_far) items.push_back({dist_of(veh[i].s, veh[i].d), 0, i, 0, 0});
  const auto& peds = world.pedestrians();
  std::vector<PedPose> poses(peds.size());
  for (size_t i = 0; i < peds.size(); ++i) {
    poses[i] = world.pedestrian_pose(peds[i], t);
    if (poses[i].s > se - 10 && poses[i].s < std::min(s_far, se + 150)) items.push_back({dist_of(poses[i].s, poses[i].d), 1, i, 0, 0});
  }
  for (size_t i = 0; i < props.size(); ++i) {
    const Prop& p = props[i];
    const double d_near = p.kind == PropKind::Building ? p.d + (p.d > 0 ? -5 : 5) : p.d;
    items.push_back({dist_of(p.s, d_near), 2, i, 0, 0});
  }
  const RoadLayout& L = world.layout();
  const auto& lights = world.lights();
  for (size_t i = 0; i < lights.size(); ++i) {
    const TrafficLight& l = lights[i];
    if (l.s < se - 10 || l.s > s_far) continue;
    items.push_back({dist_of(l.s - 0.6, L.left_edge() + 0.6), 3, i, l.s - 0.6, L.left_edge() + 0.6});
    items.push_back({dist_of(l.s + 7.5, L.right_edge() - 0.6), 3, i, l.s + 7.5, L.right_edge() - 0.6});
  }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return a.dist != b.dist ? a.dist > b.dist : (a.kind != b.kind ? a.kind < b.kind : a.idx < b.idx);
  });
  for (const Item& it : items) {
    switch (it.kind) {
      case 0: draw_vehicle(F, veh[it.idx]); break;
      case 1: draw_pedestrian(F, poses[it.idx], peds[it.idx], t, static_cast<uint32_t>(it.idx)); break;
      case 2: draw_prop(F, props[it.idx]); break;
      default: draw_signal(F, lights[it.idx], it.s, it.d, t); break;
    }
  }
  draw_hood(F);
  draw_precipitation(F, t, world.frame());
}

}  // namespace gaia::synth
