// gaia sim serve with the shipped models, used from outside as people use it: its page driven as a person drives it
// (headless Chromium through the DevTools protocol, tests/browser/drive_page.py, holds the arrow keys, and the
// frames that arrive turn the way the keys say, as the dynamics probe reads them back), and the example policy
// (examples/lane_keeper.py) driving a session closed loop.
#include <chrono>
#include <cmath>
#include <csignal>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "test_util.h"

using namespace gaia;
using test::q;

namespace {

double mean_of_last(const nlohmann::json& values, size_t n) {
  std::vector<double> v;
  for (const auto& x : values)
    if (!x.is_null()) v.push_back(x.get<double>());
  if (v.size() > n) v.erase(v.begin(), v.end() - long(n));
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? std::nan("") : s / double(v.size());
}

}  // namespace

// `gaia sim serve` with the shipped world model, tokenizer and dynamics probe on a free port, stopped at the end.
struct ServedShipped {
  test::TempDir d;
  int pid = 0;
  std::string url;
  ServedShipped() {
    const auto models = test::source_dir() / "models", log = d / "serve.log";
    auto started = test::run_shell(test::gaia_command("sim serve --world " + q(models / "world.safetensors") +
                                                      " --tokenizer " + q(models / "tokenizer.safetensors") +
                                                      " --probe " + q(models / "probe-dynamics.safetensors") +
                                                      " --port 0") +
                                   " > " + q(log) + " 2>&1 & echo $!");
    pid = std::atoi(started.output.c_str());
    for (int i = 0; i < 600 && pid > 0 && url.empty(); ++i) {  // "gaia sim: serving on http://127.0.0.1:PORT/ ..."
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      const auto text = fs::exists(log) ? read_file(log) : "";
      const auto at = text.find("http://");
      if (at != std::string::npos) url = text.substr(at, text.find(' ', at) - at);
    }
    if (url.empty()) ADD_FAILURE() << "gaia sim serve did not start: " << (fs::exists(log) ? read_file(log) : "");
  }
  ~ServedShipped() {
    if (pid > 0) kill(pid, SIGTERM);
  }
};

TEST(SimPageCli, KeysPressedThroughDevToolsSteerTheShippedModel) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/setup.sh installs it)";
  if (std::system("command -v python3 > /dev/null 2>&1") != 0) GTEST_SKIP() << "python3 not installed";
  ServedShipped s;
  ASSERT_FALSE(s.url.empty());
  const auto& url = s.url;
  const auto& d = s.d;
  // Action guidance 16 against the mirrored command, as gaia generate and gaia eval steer.
  auto r = test::run_shell("timeout 300 python3 " + q(test::source_dir() / "tests" / "browser" / "drive_page.py") +
                           " " + q(url + "?guidance=16") + " " + q(d / "profile") +
                           " none:2 Shift+ArrowLeft:20 none:4 Shift+ArrowRight:20 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  const auto out = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  const auto& phases = out.at("phases");
  ASSERT_EQ(phases.size(), 4u) << r.output;
  std::vector<double> commanded, read;  // every frame shown, in order: its command (1/km) and its read-back
  for (const auto& p : phases) {
    EXPECT_GE(p["frames"].get<int>(), 2) << p.dump();
    EXPECT_TRUE(p["image"].get<bool>()) << "frames arrive as images";
    for (size_t i = 0; i < p["curvature"].size(); ++i) {
      commanded.push_back(p["curvature"][i].get<double>());
      read.push_back(p["read_back"][i].is_null() ? std::nan("") : p["read_back"][i].get<double>());
    }
  }
  // The keys steer: the command of each key phase's last frames is the held key's (Shift: 30 1/km; + = left).
  EXPECT_DOUBLE_EQ(mean_of_last(phases[1]["curvature"], 8), 30.0) << phases[1].dump();
  EXPECT_DOUBLE_EQ(mean_of_last(phases[3]["curvature"], 8), -30.0) << phases[3].dump();
  // And the frames turn that way: the read-back of the 4 frames the probe reads, where all 4 were driven left, and
  // where all 4 were driven right (the stream runs ahead of the page, so the phases are not the commands).
  double left = 0, right = 0;
  int nl = 0, nr = 0;
  for (size_t j = 3; j < commanded.size(); ++j) {
    if (std::isnan(read[j])) continue;
    bool all_left = true, all_right = true;
    for (size_t i = j - 3; i <= j; ++i) all_left = all_left && commanded[i] > 0, all_right = all_right && commanded[i] < 0;
    if (all_left) left += read[j], ++nl;
    if (all_right) right += read[j], ++nr;
  }
  ASSERT_GE(nl, 6);
  ASSERT_GE(nr, 6);
  left /= nl, right /= nr;
  std::printf("read back %.1f 1/km driven left (%d frames), %.1f driven right (%d)\n", left, nl, right, nr);
  EXPECT_GT(left, 2.0) << r.output;
  EXPECT_GT(left - right, 2.0) << "read back " << left << " 1/km driven left, " << right << " driven right";
}

// The example policy: a few seconds of closed-loop driving through the server, its summary and its drive record.
TEST(SimPageCli, TheLaneKeeperExampleDrivesASessionClosedLoop) {
  if (std::system("command -v python3 > /dev/null 2>&1") != 0) GTEST_SKIP() << "python3 not installed";
  ServedShipped s;
  ASSERT_FALSE(s.url.empty());
  const auto out = s.d / "drive.json";
  auto r = test::run_shell("timeout 300 python3 " + q(test::source_dir() / "examples" / "lane_keeper.py") +
                           " --server " + q(s.url) + " --seconds 4 --period 4 --out " + q(out) + " 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("read-back against the plan over"), std::string::npos) << r.output;
  const auto drive = nlohmann::json::parse(read_file(out));
  ASSERT_EQ(drive["steps"].size(), 25u);  // 4 s at 6.25 Hz
  const auto& last = drive["steps"].back();
  EXPECT_EQ(last["tokens"].size(), 144u);
  EXPECT_TRUE(last["read_back"].is_object()) << last.dump();
  EXPECT_TRUE(drive["summary"]["curvature_spearman"].is_number()) << drive["summary"].dump();
  // A server that is not there: one line, a non-zero exit.
  r = test::run_shell("python3 " + q(test::source_dir() / "examples" / "lane_keeper.py") +
                      " --server http://127.0.0.1:9 --seconds 1 2>&1");
  EXPECT_NE(r.status, 0);
  EXPECT_NE(r.output.find("cannot reach"), std::string::npos) << r.output;
}
