// docs/your-drives.md cannot rot: its "whole way" block is read from the page and every command in it is run, in
// order, on the real clips it names (from ../shared/data/real/), at the tiny test size with short training.
#include <string>
#include <vector>

#include "gaia/core/fs.h"
#include "test_util.h"

using namespace gaia;

namespace {

// The commands of the fenced block after the "<!-- guide: ... -->" marker, continuation lines joined.
std::vector<std::string> guide_commands(const std::string& page) {
  const auto marker = page.find("<!-- guide:");
  if (marker == std::string::npos) return {};
  const auto open = page.find("```sh\n", marker), close = page.find("```\n", open + 6);
  if (open == std::string::npos || close == std::string::npos) return {};
  std::vector<std::string> out;
  std::string cmd, line;
  for (size_t i = open + 6; i < close; ++i) {
    if (page[i] != '\n') {
      line += page[i];
      continue;
    }
    const bool more = !line.empty() && line.back() == '\\';
    if (more) line.pop_back();
    cmd += line;
    line.clear();
    if (!more) {
      if (!cmd.empty()) out.push_back(cmd);
      cmd.clear();
    }
  }
  return out;
}

}  // namespace

TEST(GuideSlow, YourDrivesWholeWayRunsOnRealClips) {
  const fs::path page = test::source_dir() / "docs" / "your-drives.md";
  const auto commands = guide_commands(read_file(page));
  ASSERT_GE(commands.size(), 6u) << "no guide block in " << page;
  const fs::path real = test::real_data_dir();
  if (real.empty() || !fs::exists(real / "highway-sunny-720p25.mp4") || !fs::exists(real / "night-rural-1080p30.mp4"))
    GTEST_SKIP() << "shared real clips not found";
  test::TempDir dir;
  for (const char* clip : {"highway-sunny-720p25.mp4", "night-rural-1080p30.mp4"})
    fs::create_symlink(real / clip, dir / clip);
  // Tiny size and short training; everything else as written.
  const std::string tiny = " --config " + test::q(test::source_dir() / "configs" / "tiny.yaml") + " --threads 1";
  for (const auto& c : commands) {
    ASSERT_EQ(c.rfind("gaia ", 0), 0u) << "not a gaia command: " << c;
    const bool trains = c.rfind("gaia tokenizer train", 0) == 0 || c.rfind("gaia world train", 0) == 0;
    auto r = test::run_shell("cd " + test::q(dir.path) + " && " +
                             test::gaia_command(c.substr(5) + tiny + (trains ? " --steps 20" : "")) + " 2>&1");
    ASSERT_EQ(r.status, 0) << c << "\n" << r.output;
    if (c.rfind("gaia ingest", 0) == 0) {  // the estimate gave the clip actions to learn from
      EXPECT_NE(r.output.find("signals: estimated"), std::string::npos) << r.output;
    }
  }
  EXPECT_TRUE(fs::exists(dir / "runs" / "gen" / "video.mp4"));
}
