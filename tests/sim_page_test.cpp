// gaia sim serve's page, driven as a person drives it: headless Chromium through the DevTools protocol
// (tests/browser/drive_page.py) holds the arrow keys against the shipped models, and the frames that arrive turn
// the way the keys say, as the dynamics probe reads them back.
#include <chrono>
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

TEST(SimPageCli, KeysPressedThroughDevToolsSteerTheShippedModel) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/setup.sh installs it)";
  if (std::system("command -v python3 > /dev/null 2>&1") != 0) GTEST_SKIP() << "python3 not installed";
  const auto models = test::source_dir() / "models";
  test::TempDir d;
  const auto log = d / "serve.log";
  auto started = test::run_shell(test::gaia_command("sim serve --world " + q(models / "world.safetensors") +
                                                    " --tokenizer " + q(models / "tokenizer.safetensors") +
                                                    " --probe " + q(models / "probe-dynamics.safetensors") +
                                                    " --port 0") +
                                 " > " + q(log) + " 2>&1 & echo $!");
  const int pid = std::atoi(started.output.c_str());
  ASSERT_GT(pid, 0) << started.output;
  struct Stop {
    int pid;
    ~Stop() { kill(pid, SIGTERM); }
  } stop{pid};
  std::string url;
  for (int i = 0; i < 600 && url.empty(); ++i) {  // "gaia sim: serving on http://127.0.0.1:PORT/ ..."
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    const auto text = fs::exists(log) ? read_file(log) : "";
    const auto at = text.find("http://");
    if (at != std::string::npos) url = text.substr(at, text.find(' ', at) - at);
  }
  ASSERT_FALSE(url.empty()) << read_file(log);
  auto r = test::run_shell("timeout 300 python3 " + q(test::source_dir() / "tests" / "browser" / "drive_page.py") +
                           " " + q(url) + " " + q(d / "profile") +
                           " none:2 Shift+ArrowLeft:16 none:6 Shift+ArrowRight:16 2>&1");
  ASSERT_EQ(r.status, 0) << r.output;
  const auto out = nlohmann::json::parse(r.output.substr(r.output.find('{')));
  const auto& phases = out.at("phases");
  ASSERT_EQ(phases.size(), 4u) << r.output;
  for (const auto& p : phases) {
    EXPECT_GE(p["frames"].get<int>(), 2) << p.dump();
    EXPECT_TRUE(p["image"].get<bool>()) << "frames arrive as images";
  }
  const auto &left = phases[1], &right = phases[3];
  // The keys steer: the command of the phase's last frames is the held key's (Shift: 30 1/km; + = left).
  EXPECT_DOUBLE_EQ(mean_of_last(left["curvature"], 8), 30.0) << left.dump();
  EXPECT_DOUBLE_EQ(mean_of_last(right["curvature"], 8), -30.0) << right.dump();
  // And the frames turn that way: what the probe reads from the last frames of each phase.
  const double read_left = mean_of_last(left["read_back"], 8), read_right = mean_of_last(right["read_back"], 8);
  std::printf("read back %.1f 1/km pressing left, %.1f pressing right\n", read_left, read_right);
  EXPECT_GT(read_left, 2.0) << r.output;
  EXPECT_GT(read_left - read_right, 2.0) << "read back " << read_left << " 1/km pressing left, " << read_right
                                         << " pressing right";
}
