// Tests of the procedural driving world (src/gaia/synth): determinism, action/geometry consistency measured
// on rendered images, stopping at red, captions vs labels, counterfactual replay, action CSV parsing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iostream>
#include <random>
#include <set>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "gaia/core/error.h"
#include "gaia/synth/caption.h"
#include "gaia/synth/counterfactual.h"
#include "gaia/synth/rng.h"
#include "gaia/synth/synth.h"

namespace gs = gaia::synth;
namespace fs = std::filesystem;

namespace {

struct TempDir {
  fs::path path;
  TempDir() {
    std::random_device rd;
    path = fs::temp_directory_path() / ("gaia_synth_test_" + std::to_string(rd()) + std::to_string(rd()));
    fs::create_directories(path);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

gs::SynthOptions small(uint64_t seed, double seconds = 1.2) {
  gs::SynthOptions o;
  o.height = 72;
  o.width = 128;
  o.seconds = seconds;
  o.seed = seed;
  return o;
}

double psnr(const cv::Mat& a, const cv::Mat& b) { return cv::PSNR(a, b); }

bool same(const cv::Mat& a, const cv::Mat& b) {
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

// Column centroid of road-coloured (grey asphalt) pixels between the given rows.
double road_centroid(const cv::Mat& img, int row0, int row1) {
  double sum = 0, n = 0;
  for (int y = row0; y < row1; ++y)
    for (int x = 0; x < img.cols; ++x) {
      const cv::Vec3b p = img.at<cv::Vec3b>(y, x);
      const int b = p[0], g = p[1], r = p[2];
      if (std::abs(g - r) < 12 && std::abs(b - r) < 16 && r > 40 && r < 140) sum += x, n += 1;
    }
  return n > 0 ? sum / n : -1;
}

}  // namespace

TEST(Synth, SameSeedSameEpisodeDifferentSeedDifferent) {
  TempDir tmp;
  auto o = small(5);
  auto m1 = gs::write_episode(tmp.path / "a", o, 3);
  auto m2 = gs::write_episode(tmp.path / "b", o, 3);
  auto o2 = small(6);
  auto m3 = gs::write_episode(tmp.path / "c", o2, 3);
  gaia::data::Episode e1(tmp.path / "a" / "episodes" / m1.id), e2(tmp.path / "b" / "episodes" / m2.id),
      e3(tmp.path / "c" / "episodes" / m3.id);
  ASSERT_EQ(e1.size(), 30);
  ASSERT_EQ(e2.size(), 30);
  EXPECT_EQ(m1.weather, m2.weather);
  EXPECT_EQ(m1.latitude, m2.latitude);
  int differ = 0;
  for (int64_t i = 0; i < e1.size(); ++i) {
    EXPECT_TRUE(same(e1.frame_bgr(i), e2.frame_bgr(i))) << "frame " << i;
    EXPECT_EQ(e1.speed(i), e2.speed(i));
    EXPECT_EQ(e1.curvature(i), e2.curvature(i));
    EXPECT_EQ(e1.caption(i), e2.caption(i));
    EXPECT_EQ(e1.labels(i), e2.labels(i));
    differ += !same(e1.frame_bgr(i), e3.frame_bgr(i));
  }
  EXPECT_EQ(differ, 30);
  // Metadata: a district on the virtual London map, a replayable source.
  EXPECT_NEAR(m1.latitude, 51.5, 0.3);
  EXPECT_NEAR(m1.longitude, -0.1, 0.4);
  EXPECT_EQ(m1.source, "synth:seed=5,episode=3");
  EXPECT_EQ(m1.extra.at("synth_seed"), "5");
  EXPECT_FALSE(m1.weather.empty());
  EXPECT_FALSE(m1.time_of_day.empty());
  // Signals are sane.
  for (int64_t i = 0; i < e1.size(); ++i) {
    EXPECT_GE(e1.speed(i), 0.f);
    EXPECT_LT(e1.speed(i), 30.f);
    EXPECT_LT(std::abs(e1.curvature(i)), 0.25f);
  }
}

TEST(Synth, PositiveCurvatureTurnsLeftSoTheRoadMovesRight) {
  // On a straight rural road, steering left (curvature > 0) turns the camera left: the road region shifts to
  // the right in the image; steering right shifts it left.
  double centroid[3];
  const double curv[3] = {0.03, 0.0, -0.03};
  for (int k = 0; k < 3; ++k) {
    auto o = small(11);
    o.height = 144, o.width = 256;
    o.scene = "straight", o.district = "epping", o.weather = "clear", o.time_of_day = "day";
    gs::Simulator sim(o, 0);
    for (int i = 0; i < 25; ++i) sim.step({8.0, curv[k]});
    cv::Mat img = sim.render();
    centroid[k] = road_centroid(img, 80, 125);
  }
  EXPECT_GT(centroid[0], centroid[1] + 10) << centroid[0] << " " << centroid[1];
  EXPECT_LT(centroid[2], centroid[1] - 10) << centroid[2] << " " << centroid[1];
}

TEST(Synth, HigherSpeedMovesLaneMarkingsFurtherPerFrame) {
  // Measure how far the dashed centre line moves between consecutive frames: the white-pixel profile over image
  // rows (right half, where the centre line is for a kerb-lane ego) is mapped to ground distance with the
  // documented camera, and the best-matching shift is found. It should equal speed / fps.
  auto measure = [](double speed) {
    auto o = small(12);
    o.height = 288, o.width = 512;
    o.scene = "straight", o.district = "epping", o.weather = "overcast", o.time_of_day = "day";
    int idx = 0;
    while (gs::Simulator(o, idx).world().layout().centre_solid) ++idx;  // want a dashed centre line
    gs::Simulator sim(o, idx);
    for (int i = 0; i < 40; ++i) sim.step({speed, 0.0});  // settle the body pitch
    const gs::CameraModel cam;
    const double f = 0.5 * o.width / std::tan(cam.hfov_deg * gs::kPi / 360), cx = 0.5 * o.width - 0.5,
                 cy = 0.5 * o.height - 0.5;
    auto profile = [&](const cv::Mat& img) {
      // White pixels around the projected centre line (d = 0, ego.d metres to the right), per 5 cm of ground
      // distance z in [4.5, 14.5] m (just above the bonnet, where rows are finer than 20 cm).
      const double p = cam.base_pitch + sim.world().ego().pitch, right = sim.world().ego().d;
      std::vector<double> prof(200, 0.0);
      for (int i = 0; i < 200; ++i) {
        const double z = 4.5 + 0.05 * i;
        const double y1 = cam.height * std::cos(p) + z * std::sin(p), z1 = z * std::cos(p) - cam.height * std::sin(p);
        const double row = cy + f * y1 / z1, col = cx + f * right / z1, hw = std::max(1.5, f * 0.4 / z1);
        const int r0 = static_cast<int>(std::floor(row));
        const double a = row - r0;
        auto white = [&](int r) {
          double n = 0;
          if (r < 0 || r >= img.rows) return n;
          for (int x = std::max(0, static_cast<int>(col - hw)); x <= std::min(img.cols - 1, static_cast<int>(col + hw)); ++x) {
            const cv::Vec3b px = img.at<cv::Vec3b>(r, x);
            n += (px[0] > 160 && px[1] > 160 && px[2] > 160) ? 1 : 0;
          }
          return n;
        };
        // Coverage of the line (0 = gap, ~1 = dash), independent of its shrinking width in pixels.
        const double line_px = std::max(1.0, f * 0.13 / z1);
        prof[static_cast<size_t>(i)] = std::min(1.0, (white(r0) * (1 - a) + white(r0 + 1) * a) / line_px);
      }
      return prof;
    };
    double total = 0;
    int n = 0;
    for (int k = 0; k < 6; ++k) {
      auto p0 = profile(sim.render());
      sim.step({speed, 0.0});
      auto p1 = profile(sim.render());
      // Markings move towards the camera: p1(z) ~ p0(z + shift). Best shift = least mean squared difference.
      double best = 1e18, best_shift = 0;
      for (int sh = 0; sh <= 30; ++sh) {
        double c = 0;
        for (int i = 0; i + sh < 200; ++i) {
          const double d = p1[static_cast<size_t>(i)] - p0[static_cast<size_t>(i + sh)];
          c += d * d;
        }
        c /= 200 - sh;
        if (c < best) best = c, best_shift = sh * 0.05;
      }
      total += best_shift;
      ++n;
    }
    return total / n;
  };
  const double slow = measure(5.0), fast = measure(15.0);
  std::cout << "marking shift per frame: " << slow << " m at 5 m/s, " << fast << " m at 15 m/s\n";
  EXPECT_NEAR(slow, 5.0 / 25, 0.1);
  EXPECT_NEAR(fast, 15.0 / 25, 0.15);
  EXPECT_GT(fast, 2 * slow);
}

TEST(Synth, EgoStopsAtRedLight) {
  for (int idx = 0; idx < 3; ++idx) {
    auto o = small(21, 9.0);
    o.scene = "red_light";
    gs::Simulator sim(o, idx);
    bool stopped_at_red = false;
    for (int i = 0; i < 225; ++i) {
      const gs::ActionStep a = sim.policy();
      auto rec = sim.record(a, false);
      const auto& j = rec.labels;
      if (j["light_state"] == "red" && j["light_distance_m"].is_number()) {
        const double dist = j["light_distance_m"].get<double>();
        if (dist < 15 && a.speed < 0.3) stopped_at_red = true;
        EXPECT_FALSE(dist < 2.5 && a.speed > 1.0) << "ran the red light at frame " << i;
      }
      sim.step(a);
    }
    EXPECT_TRUE(stopped_at_red) << "episode " << idx;
  }
}

// A wandering driver (SceneSpec::wander) steers away from the road's own curvature at random moments, so the
// recorded steering carries information the road does not; it still stays near its lane.
TEST(Synth, WanderMakesSteeringDepartFromTheRoad) {
  auto departure = [](double wander, double* max_offset) {
    double sq = 0;
    int n = 0;
    *max_offset = 0;
    for (int idx = 0; idx < 3; ++idx) {
      auto o = small(61, 20.0);
      o.wander = wander;
      gs::Simulator sim(o, idx);
      for (int i = 0; i < 500; ++i) {
        const gs::ActionStep a = sim.policy();
        const gs::Ego& e = sim.world().ego();
        const double dk = a.curvature - sim.world().road().at(e.s).k;
        sq += dk * dk;
        ++n;
        *max_offset = std::max(*max_offset, std::abs(e.d - e.d_ref));
        EXPECT_LE(std::abs(a.curvature), 0.2);
        sim.step(a);
      }
    }
    return std::sqrt(sq / n);
  };
  double off0 = 0, off1 = 0;
  const double keep = departure(0, &off0), wander = departure(1.2, &off1);
  std::cout << "rms(curvature - road curvature): lane keeper " << keep << ", wander 1.2 m " << wander
            << " 1/m; max |d - d_ref| " << off0 << " / " << off1 << " m\n";
  EXPECT_GT(wander, 2.5 * keep);
  // The lane keeper itself strays from its reference in tight bends (pure pursuit cuts corners); the wanderer
  // strays further, but by no more than its amplitude on top of that.
  EXPECT_GT(off1, off0 + 0.5);
  EXPECT_LT(off1, off0 + 1.2 + 0.3);

  TempDir tmp;
  auto o = small(61, 0.4);
  o.wander = 1.2;
  EXPECT_EQ(gs::write_episode(tmp.path, o, 0).extra.at("synth_wander"), "1.2");
  o.wander = -1;
  try {
    gs::Simulator bad(o, 0);
    ADD_FAILURE() << "negative wander accepted";
  } catch (const gaia::Error& err) {
    EXPECT_NE(std::string(err.what()).find("wander"), std::string::npos) << err.what();
  }
}

// A swerving driver (SceneSpec::swerve) steers open loop at random moments: strong turns both ways, never beyond
// its limit while swerving, off its lane and back again. The episode records it, and replay rebuilds it.
TEST(Synth, SwervesSteerStronglyBothWaysAndReturnToTheLane) {
  const double limit = 0.035;
  int strong_left = 0, strong_right = 0, frames = 0, back_in_lane = 0;
  double max_offset = 0;
  for (int idx = 0; idx < 3; ++idx) {
    auto o = small(71, 20.0);
    o.swerve = limit;
    gs::Simulator sim(o, idx);
    bool was_off = false;
    for (int i = 0; i < 500; ++i, ++frames) {
      const gs::ActionStep a = sim.policy();
      const gs::Ego& e = sim.world().ego();
      const bool swerving = sim.world().time() >= e.swerve_start && sim.world().time() < e.swerve_end;
      if (swerving) {
        EXPECT_LE(std::abs(a.curvature), limit + 1e-6) << "frame " << i;
      }
      strong_left += a.curvature > 0.02;
      strong_right += a.curvature < -0.02;
      const double off = std::abs(e.d - e.d_ref);
      max_offset = std::max(max_offset, off);
      if (off > 1.0) was_off = true;
      if (was_off && off < 0.3) back_in_lane++, was_off = false;
      sim.step(a);
    }
  }
  std::cout << "strong left " << strong_left << ", strong right " << strong_right << " of " << frames
            << " frames; max |d - d_ref| " << max_offset << " m; returned to the lane " << back_in_lane << " times\n";
  EXPECT_GT(strong_left, frames / 50);
  EXPECT_GT(strong_right, frames / 50);
  EXPECT_GT(max_offset, 1.0);
  EXPECT_GE(back_in_lane, 2);
  // The lane keeper rarely turns that hard on the same roads.
  int keeper_strong = 0;
  for (int idx = 0; idx < 3; ++idx) {
    gs::Simulator lane_keeper(small(71, 20.0), idx);
    for (int i = 0; i < 500; ++i) {
      const gs::ActionStep a = lane_keeper.policy();
      keeper_strong += std::abs(a.curvature) > 0.02;
      lane_keeper.step(a);
    }
  }
  EXPECT_LT(5 * keeper_strong, strong_left + strong_right) << keeper_strong;

  TempDir tmp;
  auto o = small(71, 2.0);
  o.swerve = limit;
  auto m = gs::write_episode(tmp.path / "orig", o, 1);
  EXPECT_EQ(m.extra.at("synth_swerve"), "0.035");
  gaia::data::Episode orig(tmp.path / "orig" / "episodes" / m.id);
  std::vector<gs::ActionStep> rec;
  for (int64_t i = 10; i < orig.size(); ++i) rec.push_back({orig.speed(i), orig.curvature(i)});
  gs::replay(orig, 10, rec, tmp.path / "replay", "same");
  gaia::data::Episode same_ep(tmp.path / "replay" / "episodes" / "same");
  for (int64_t i = 0; i < same_ep.size(); ++i)
    EXPECT_TRUE(same(orig.frame_bgr(10 + i), same_ep.frame_bgr(i)) || psnr(orig.frame_bgr(10 + i), same_ep.frame_bgr(i)) > 40)
        << "frame " << i;
  o.swerve = 0.5;
  try {
    gs::Simulator bad(o, 0);
    ADD_FAILURE() << "swerve 0.5 accepted";
  } catch (const gaia::Error& err) {
    EXPECT_NE(std::string(err.what()).find("swerve"), std::string::npos) << err.what();
  }
}

TEST(Synth, CaptionsAgreeWithLabels) {
  const char* weathers[] = {"clear", "overcast", "rain", "fog", "snow"};
  const char* tods[] = {"day", "dusk", "night"};
  int n = 0;
  for (int w = 0; w < 5; ++w)
    for (int t = 0; t < 3; ++t) {
      auto o = small(31, 3.0);
      o.weather = weathers[w], o.time_of_day = tods[t];
      o.scene = (w + t) % 2 ? "red_light" : "lead_vehicle";
      gs::Simulator sim(o, w * 3 + t);
      std::set<std::string> distinct;
      for (int i = 0; i < 75; ++i) {
        const gs::ActionStep a = sim.policy();
        auto rec = sim.record(a, false);
        const auto& j = rec.labels;
        const std::string& c = rec.caption;
        distinct.insert(c);
        auto has_any = [&](const std::vector<std::string>& words) {
          return std::any_of(words.begin(), words.end(), [&](const std::string& x) { return c.find(x) != std::string::npos; });
        };
        EXPECT_EQ(j["weather"], weathers[w]);
        EXPECT_EQ(j["time_of_day"], tods[t]);
        EXPECT_TRUE(has_any(gs::weather_words(weathers[w]))) << c;
        EXPECT_TRUE(has_any(gs::time_words(tods[t]))) << c;
        if (j["light_state"] == "red") {
          EXPECT_NE(c.find("red"), std::string::npos) << c;
        }
        if (j["lead_distance_m"].is_number() && j["lead_distance_m"].get<double>() < 45) {
          EXPECT_NE(c.find(j["lead_type"].get<std::string>()), std::string::npos) << c;
        }
        for (const char* key : {"weather", "time_of_day", "light_state", "lead_distance_m", "lead_close", "ego_lane",
                                "lane_offset_m", "speed", "curvature"})
          EXPECT_TRUE(j.contains(key)) << key;
        EXPECT_EQ(j["speed"].get<double>(), a.speed);
        ++n;
        sim.step(a);
      }
      EXPECT_GT(distinct.size(), 3u) << "captions should vary in wording";
    }
  EXPECT_EQ(n, 15 * 75);
}

// A change of conditions mid-drive: the same world and driving, drawn under the first conditions before the change
// and exactly as the drive rendered under the new ones after it; labels follow the frames, captions lead them by
// change_lead; "random" draws another value than the drive's own; a replay keeps the change.
TEST(Synth, ConditionsChangeMidDriveWithTheCaptionLeading) {
  auto o = small(53, 3.0);
  o.weather = "clear", o.time_of_day = "day", o.scene = "lead_vehicle";
  auto night = o, changed = o;
  night.time_of_day = "night";
  changed.change_at = 2.0, changed.change_lead = 1.0, changed.change_time_of_day = "night";
  gs::Simulator base_sim(o, 4), night_sim(night, 4), sim(changed, 4);
  int before = 0, after = 0;
  for (int i = 0; i < 75; ++i) {
    const double t = i / 25.0;
    const gs::ActionStep a = base_sim.policy(), an = night_sim.policy(), ac = sim.policy();
    ASSERT_EQ(a.speed, ac.speed) << i;  // the conditions change nothing the driver does
    ASSERT_EQ(a.curvature, ac.curvature) << i;
    ASSERT_EQ(an.curvature, ac.curvature) << i;
    const auto rb = base_sim.record(a), rn = night_sim.record(an), rc = sim.record(ac);
    const bool is_after = t >= 2.0 - 1e-9;
    EXPECT_TRUE(same(rc.bgr, is_after ? rn.bgr : rb.bgr)) << "frame " << i;
    EXPECT_FALSE(same(rb.bgr, rn.bgr)) << "frame " << i;
    EXPECT_EQ(rc.labels["time_of_day"], is_after ? "night" : "day") << i;
    EXPECT_EQ(rc.labels["weather"], "clear") << i;
    if (t < 1.0 - 1e-9) {
      EXPECT_EQ(rc.caption, rb.caption) << i;  // before the lead: the drive's own words
    } else {
      const bool names_night = rc.caption.find("night") != std::string::npos;
      EXPECT_TRUE(names_night) << i << ": " << rc.caption;
    }
    (is_after ? after : before) += 1;
    base_sim.step(a), night_sim.step(an), sim.step(ac);
  }
  EXPECT_EQ(before, 50);
  EXPECT_EQ(after, 25);

  // "random": another weather than the drive's own, the same for the same seed and index, varied over indices.
  auto r = o;
  r.change_at = 1.0, r.change_weather = "random";
  std::set<std::string> drawn;
  for (int i = 0; i < 12; ++i) {
    const std::string w = gs::Simulator(r, i).spec().change_weather;
    EXPECT_NE(w, "clear") << i;
    EXPECT_TRUE(w == "overcast" || w == "rain" || w == "fog" || w == "snow") << w;
    EXPECT_EQ(gs::Simulator(r, i).spec().change_weather, w);
    drawn.insert(w);
  }
  EXPECT_GE(drawn.size(), 3u);

  // Bad changes fail naming the flag.
  auto expect_error = [](const gs::SynthOptions& bad, const std::string& flag) {
    try {
      gs::Simulator s(bad, 0);
      ADD_FAILURE() << "no error for " << flag;
    } catch (const gaia::Error& e) {
      EXPECT_NE(std::string(e.what()).find(flag), std::string::npos) << e.what();
    }
  };
  auto bad = changed;
  bad.change_at = 3.5;
  expect_error(bad, "--change-at");
  bad = changed, bad.change_time_of_day = "";
  expect_error(bad, "--change-at");
  bad = changed, bad.change_weather = "hail";
  expect_error(bad, "--change-weather");
  bad = changed, bad.change_time_of_day = "noon";
  expect_error(bad, "--change-time");
  bad = changed, bad.change_lead = 2.5;
  expect_error(bad, "--change-lead");
  bad = o, bad.change_weather = "rain";
  expect_error(bad, "--change-at");

  // The episode records the change, and a replay after it draws the same frames.
  TempDir tmp;
  auto m = gs::write_episode(tmp.path / "orig", changed, 4);
  EXPECT_EQ(m.time_of_day, "day");  // the episode's conditions are its start's
  EXPECT_EQ(m.extra.at("synth_change_time_of_day"), "night");
  gaia::data::Episode orig(tmp.path / "orig" / "episodes" / m.id);
  EXPECT_EQ(orig.labels(74)["time_of_day"], "night");
  const int64_t from = 40;
  std::vector<gs::ActionStep> rec;
  for (int64_t i = from; i < orig.size(); ++i) rec.push_back({orig.speed(i), orig.curvature(i)});
  gs::replay(orig, from, rec, tmp.path / "replay", "same");
  gaia::data::Episode rep(tmp.path / "replay" / "episodes" / "same");
  for (int64_t i = 0; i < rep.size(); ++i) {
    EXPECT_TRUE(same(orig.frame_bgr(from + i), rep.frame_bgr(i)) || psnr(orig.frame_bgr(from + i), rep.frame_bgr(i)) > 40) << i;
    EXPECT_EQ(orig.caption(from + i), rep.caption(i)) << i;
  }
}

TEST(Synth, ReplayReproducesRecordedActionsAndDivergesUnderOthers) {
  TempDir tmp;
  auto o = small(41, 3.0);
  o.scene = "lead_vehicle";
  auto m = gs::write_episode(tmp.path / "orig", o, 2);
  gaia::data::Episode orig(tmp.path / "orig" / "episodes" / m.id);
  const int64_t from = 25;
  std::vector<gs::ActionStep> rec;
  for (int64_t i = from; i < orig.size(); ++i) rec.push_back({orig.speed(i), orig.curvature(i)});
  auto r1 = gs::replay(orig, from, rec, tmp.path / "replay", "same");
  gaia::data::Episode same_ep(tmp.path / "replay" / "episodes" / "same");
  ASSERT_EQ(same_ep.size(), orig.size() - from);
  EXPECT_EQ(r1.extra.at("replay_of"), m.id);
  for (int64_t i = 0; i < same_ep.size(); ++i) {
    const cv::Mat a = orig.frame_bgr(from + i), b = same_ep.frame_bgr(i);
    EXPECT_TRUE(same(a, b) || psnr(a, b) > 40) << "frame " << i;
    EXPECT_EQ(orig.caption(from + i), same_ep.caption(i));
    EXPECT_DOUBLE_EQ(orig.time_s(from + i), same_ep.time_s(i));
  }
  // Strong left: the frames diverge from the original, more so later on.
  std::vector<gs::ActionStep> left(rec.size(), gs::ActionStep{8.0, 0.08});
  gs::replay(orig, from, left, tmp.path / "replay", "left");
  gaia::data::Episode left_ep(tmp.path / "replay" / "episodes" / "left");
  ASSERT_EQ(left_ep.size(), static_cast<int64_t>(left.size()));
  const int64_t last = left_ep.size() - 1;
  EXPECT_LT(psnr(orig.frame_bgr(from + last), left_ep.frame_bgr(last)), 20.0);
  EXPECT_FLOAT_EQ(left_ep.curvature(3), 0.08f);
  EXPECT_GT(left_ep.labels(last)["lane_offset_m"].get<double>(), orig.labels(from + last)["lane_offset_m"].get<double>() + 1.0);
  // A start frame beyond the episode is a clear error.
  EXPECT_THROW(gs::replay(orig, orig.size() + 1, rec, tmp.path / "replay", "bad"), gaia::Error);
}

// Counterfactual augmentation: each replay follows its source's recorded driving (same frames) for the lead,
// then holds one command within the bounds; it is deterministic, resumes, and a replay cannot be replayed again.
TEST(Synth, CounterfactualsFollowTheRecordingThenHoldACommand) {
  TempDir tmp;
  auto o = small(43, 3.0);
  std::vector<std::string> ids;
  for (int i = 0; i < 2; ++i) ids.push_back(gs::write_episode(tmp.path / "orig", o, i).id);
  gaia::data::Dataset ds(tmp.path / "orig");
  gs::CounterfactualOptions co;
  co.per_episode = 3, co.lead_seconds = 0.5, co.hold_seconds = 1.0, co.max_curvature = 0.04, co.min_speed = 4.0;
  co.seed = 5;
  int64_t last_done = -1;
  EXPECT_EQ(gs::write_counterfactuals(ds, ids, co, tmp.path / "cf", [&](int64_t d, int64_t t) {
              EXPECT_EQ(t, 6);
              EXPECT_GE(d, last_done);
              last_done = d;
            }), 6);
  EXPECT_EQ(last_done, 6);
  gaia::data::Dataset cf(tmp.path / "cf");
  ASSERT_EQ(cf.size(), 6u);
  const int64_t lead = std::llround(0.5 * o.fps), hold = std::llround(1.0 * o.fps);
  std::set<float> curvatures;
  for (size_t e = 0; e < cf.size(); ++e) {
    const gaia::data::Episode r = cf.episode(e);
    const auto& src_id = r.meta().extra.at("replay_of");
    EXPECT_EQ(r.meta().id.substr(0, src_id.size()), src_id);
    const gaia::data::Episode src(tmp.path / "orig" / "episodes" / src_id);
    const int64_t from = std::stoll(r.meta().extra.at("replay_from"));
    ASSERT_EQ(r.size(), lead + hold);
    ASSERT_LE(from + lead + hold, src.size());
    for (int64_t i = 0; i < lead; ++i) {
      EXPECT_EQ(r.speed(i), src.speed(from + i));
      EXPECT_EQ(r.curvature(i), src.curvature(from + i));
      EXPECT_TRUE(same(r.frame_bgr(i), src.frame_bgr(from + i)) || psnr(r.frame_bgr(i), src.frame_bgr(from + i)) > 40) << i;
    }
    const float k = r.curvature(lead);
    EXPECT_LE(std::abs(k), 0.04f);
    EXPECT_GE(r.speed(lead), 4.0f);
    for (int64_t i = lead; i < r.size(); ++i) {
      EXPECT_EQ(r.curvature(i), k);
      EXPECT_EQ(r.speed(i), r.speed(lead));
    }
    curvatures.insert(k);
  }
  EXPECT_EQ(curvatures.size(), 6u);  // every replay draws its own command
  // Deterministic: the same options write the same replays elsewhere; a second run into the same place resumes.
  EXPECT_EQ(gs::write_counterfactuals(ds, ids, co, tmp.path / "cf2"), 6);
  for (auto& id : cf.ids())
    for (auto f : {"frames.bin", "speed.npy", "curvature.npy", "captions.jsonl"})
      EXPECT_EQ(gaia::read_file(tmp.path / "cf" / "episodes" / id / f), gaia::read_file(tmp.path / "cf2" / "episodes" / id / f)) << id << f;
  EXPECT_EQ(gs::write_counterfactuals(ds, ids, co, tmp.path / "cf"), 0);
  // A replay starts mid-drive: it cannot be replayed, and says which episode to replay instead.
  try {
    gs::replay(cf.episode(0), 0, {gs::ActionStep{5, 0}}, tmp.path / "cf3", "x");
    ADD_FAILURE() << "replaying a replay should fail";
  } catch (const gaia::Error& err) {
    EXPECT_NE(std::string(err.what()).find("itself a replay"), std::string::npos) << err.what();
  }
  co.per_episode = 0;
  EXPECT_THROW(gs::write_counterfactuals(ds, ids, co, tmp.path / "cf4"), gaia::Error);
}

TEST(Synth, OncomingVehicleSwervesWhenEgoDriftsIntoItsLane) {
  // Drive straight along the oncoming lane; an approaching vehicle in that lane moves towards its kerb.
  bool swerved = false;
  for (int idx = 0; idx < 6 && !swerved; ++idx) {
    auto o = small(51, 6.0);
    o.district = "city", o.scene = "random";
    gs::Simulator sim(o, idx);
    const double d_target = sim.world().layout().onc_lane_centre(0);
    for (int i = 0; i < 150 && !swerved; ++i) {
      const auto& e = sim.world().ego();
      const double k = std::clamp(0.02 * (d_target - e.d) - 0.3 * std::remainder(e.h - sim.world().road().at(e.s).h, 2 * gs::kPi), -0.05, 0.05);
      sim.step({6.0, k});
      for (const auto& v : sim.world().vehicles())
        if (v.dir == -1 && v.swerving && v.d < v.lane_d - 0.3) swerved = true;
    }
  }
  EXPECT_TRUE(swerved);
}

TEST(Synth, ReadActionsCsv) {
  TempDir tmp;
  auto write = [&](const std::string& name, const std::string& text) {
    std::ofstream(tmp.path / name) << text;
    return tmp.path / name;
  };
  auto a = gs::read_actions_csv(write("ok.csv", "t,curvature,speed\n0,0.01,5\n0.04,-0.02,6.5\n\n"));
  ASSERT_EQ(a.size(), 2u);
  EXPECT_DOUBLE_EQ(a[0].speed, 5);
  EXPECT_DOUBLE_EQ(a[1].curvature, -0.02);
  auto expect_error = [&](const std::string& name, const std::string& text, const std::string& needle) {
    try {
      gs::read_actions_csv(write(name, text));
      ADD_FAILURE() << name << " should fail";
    } catch (const gaia::Error& e) {
      EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
    }
  };
  expect_error("hdr.csv", "speed,steer\n1,2\n", "hdr.csv:1");
  expect_error("nan.csv", "speed,curvature\n1,0\n2,nan\n", "nan.csv:3");
  expect_error("cols.csv", "speed,curvature\n1\n", "cols.csv:2");
  expect_error("txt.csv", "speed,curvature\nfast,0\n", "txt.csv:2");
  expect_error("empty.csv", "speed,curvature\n", "no actions");
}

TEST(Synth, OptionsAreValidatedAndContactSheetTiles) {
  auto o = small(1);
  o.weather = "hail";
  EXPECT_THROW(gs::Simulator(o, 0), gaia::Error);
  o = small(1);
  o.scene = "flying";
  EXPECT_THROW(gs::Simulator(o, 0), gaia::Error);
  o = small(1);
  std::vector<cv::Mat> frames = {gs::preview_frame(o, 0, 0.0), gs::preview_frame(o, 1, 0.4), gs::preview_frame(o, 2, 0.4)};
  EXPECT_EQ(frames[0].rows, 72);
  EXPECT_EQ(frames[0].cols, 128);
  cv::Mat sheet = gs::contact_sheet(frames, {"a", "b", "c"}, 2, 128);
  EXPECT_EQ(sheet.cols, 2 * 128 + 3 * 4);
  EXPECT_GT(sheet.rows, 2 * 72);
}

TEST(Synth, ContactSheetAcrossConditions) {
  // Rows: weathers; columns: times of day; scenes cycle through bend, red light, lead vehicle. Set
  // GAIA_SYNTH_CONTACT_SHEET=docs/synth_contact_sheet.png to write the sheet shown in docs/synth.md.
  const char* weathers[] = {"clear", "overcast", "rain", "fog", "snow"};
  const char* tods[] = {"day", "dusk", "night"};
  const char* scenes[] = {"bend", "red_light", "lead_vehicle"};
  const double at[] = {1.0, 4.5, 2.5};
  std::vector<cv::Mat> frames;
  std::vector<std::string> labels;
  for (int w = 0; w < 5; ++w)
    for (int t = 0; t < 3; ++t) {
      const int sc = (w + t) % 3;
      gs::SynthOptions o;
      o.seed = 2024;
      o.weather = weathers[w], o.time_of_day = tods[t], o.scene = scenes[sc];
      frames.push_back(gs::preview_frame(o, w * 3 + t, at[sc]));
      std::string scene = scenes[sc];
      std::replace(scene.begin(), scene.end(), '_', ' ');
      labels.push_back(std::string(weathers[w]) + ", " + tods[t] + ", " + scene);
    }
  cv::Mat sheet = gs::contact_sheet(frames, labels, 3, 320);
  EXPECT_EQ(sheet.cols, 3 * 320 + 4 * 4);
  // Night frames are darker than day frames of the same weather.
  for (int w = 0; w < 5; ++w) EXPECT_LT(cv::mean(frames[static_cast<size_t>(w * 3 + 2)])[1], cv::mean(frames[static_cast<size_t>(w * 3)])[1]);
  if (const char* out = std::getenv("GAIA_SYNTH_CONTACT_SHEET")) cv::imwrite(out, sheet, {cv::IMWRITE_PNG_COMPRESSION, 9});
}
