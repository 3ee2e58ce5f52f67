// gaia report: the page embeds every input (nothing refers outside the file), escapes text, names the exact field
// of any bad manifest entry, and really shows up in a browser (headless Chromium screenshot and DOM).
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "gaia/data/gif.h"
#include "gaia/eval/svg_plot.h"
#include "gaia/report/report.h"
#include "test_util.h"

using namespace gaia;
using Json = nlohmann::ordered_json;

namespace {

// RFC 4648 decoding, independent of the encoder under test.
std::string base64_decode(const std::string& s) {
  static const std::string kAlphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  uint32_t acc = 0;
  int bits = 0;
  for (char ch : s) {
    if (ch == '=') break;
    acc = acc << 6 | static_cast<uint32_t>(kAlphabet.find(ch));
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out += static_cast<char>((acc >> bits) & 0xff);
    }
  }
  return out;
}

// The bytes behind the first data: URI of this MIME type in `html`.
std::string data_uri_bytes(const std::string& html, const std::string& mime) {
  const std::string tag = "data:" + mime + ";base64,";
  const size_t at = html.find(tag);
  if (at == std::string::npos) return "<no " + mime + " data URI>";
  const size_t start = at + tag.size();
  return base64_decode(html.substr(start, html.find('"', start) - start));
}


// Point counts of every <polyline points="..."> in the page.
std::vector<size_t> polyline_points(const std::string& html) {
  std::vector<size_t> n;
  const std::string tag = "points=\"";
  for (size_t at = html.find(tag); at != std::string::npos; at = html.find(tag, at + 1)) {
    const size_t start = at + tag.size();
    n.push_back(test::occurrences(html.substr(start, html.find('"', start) - start), ","));
  }
  std::sort(n.begin(), n.end());
  return n;
}

// The paths (relative to the run directory) that the manifest of make_run refers to.
const std::vector<std::string> kInputs = {"magenta.png", "videos/prompt.gif", "videos/f1.mp4", "plots/guidance.svg",
                                          "world/metrics.jsonl"};

// A run directory with one of each manifest element. The first section holds only a 64x64 pure magenta image, a
// colour nothing else on the page uses, so the screenshot test can find it near the top.
void make_run(const fs::path& dir) {
  cv::imwrite((dir / "magenta.png").string(), cv::Mat(64, 64, CV_8UC3, cv::Scalar(255, 0, 255)));
  std::vector<cv::Mat> frames = {cv::Mat(24, 32, CV_8UC3, cv::Scalar(40, 160, 90)),
                                 cv::Mat(24, 32, CV_8UC3, cv::Scalar(90, 40, 160))};
  fs::create_directories(dir / "videos");
  data::write_gif(dir / "videos/prompt.gif", frames, 5);
  std::string mp4;  // any bytes: every value once, so the base64 round trip covers them all
  for (int b = 0; b < 256; ++b) mp4 += static_cast<char>(b);
  write_file_atomic(dir / "videos/f1.mp4", mp4);
  write_file_atomic(dir / "plots/guidance.svg",
                    "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n" +
                        eval::svg_lines("guidance", {1, 2, 3, 4, 5}, {{"sign acc.", {0.5, 0.7, 0.8, 0.85, 0.9}, ""}},
                                        "scale", "accuracy"));
  write_file_atomic(dir / "world/metrics.jsonl",
                    "{\"step\":0,\"loss\":3.0}\n"
                    "{\"step\":10,\"loss\":2.5,\"val\":{\"bits_per_token\":8.1}}\n"
                    "{\"step\":20,\"loss\":null}\n"
                    "{\"step\":30,\"loss\":1.9,\"val\":{\"bits_per_token\":7.5}}\n"
                    "{\"step\":40,\"lo");  // torn last line: the trainer is still writing it
  Json m = {
      {"title", "gaia <demo> & co"},
      {"subtitle", "one of each element"},
      {"sections",
       {{{"title", "Colour check"}, {"images", {{{"caption", "a <b>& caption"}, {"path", "magenta.png"}}}}},
        {{"title", "Video prompt, three futures"},
         {"text", "Plain text with <tags> & ampersands."},
         {"videos",
          {{{"caption", "prompt and a future"},
            {"items", {{{"label", "prompt"}, {"path", "videos/prompt.gif"}},
                       {{"label", "future 1"}, {"path", "videos/f1.mp4"}}}}}}},
         {"plots", {{{"caption", "guidance"}, {"path", "plots/guidance.svg"}}}},
         {"tables", {{{"caption", "per command"}, {"columns", {"command", "sign acc."}},
                      {"rows", Json::array({Json::array({"left", 0.934567}), Json::array({"right", "n/a"}),
                                           Json::array({"straight", 42})})}}}},
         {"metrics", {{"any", {{"nested", 1.23456}, {"json", {1, 2}}}}, {"tokens", 1000000}}},
         {"curves",
          {{{"caption", "training"}, {"path", "world/metrics.jsonl"}, {"keys", {"loss", "val.bits_per_token"}}}}},
         {"commands", {"gaia generate --world w --out 'a b' > log"}}}}}};
  write_file_atomic(dir / "report.json", m.dump(2));
}

// A manifest titled "t" whose "sections" value is the JSON text `sections`.
void write_manifest(const fs::path& dir, const std::string& sections) {
  write_file_atomic(dir / "report.json", "{\"title\": \"t\", \"sections\": " + sections + "}");
}

std::string report_error(const fs::path& dir) { return test::error_of([&] { report::render_report(dir); }); }

bool have_chromium() { return std::system("command -v chromium > /dev/null 2>&1") == 0; }

// Runs headless Chromium on a local file with a time limit; stderr (GPU, dbus noise) is dropped.
int chromium(const test::TempDir& d, const std::string& args, const fs::path& html, const fs::path& stdout_file) {
  const std::string cmd = "timeout 60 chromium --headless --no-sandbox --disable-gpu --hide-scrollbars "
                          "--user-data-dir='" + (d / "profile").string() + "' " + args + " 'file://" + html.string() +
                          "' > '" + stdout_file.string() + "' 2>/dev/null";
  return std::system(cmd.c_str());
}

}  // namespace

TEST(Report, Base64MatchesRfc4648) {
  const std::pair<const char*, const char*> vectors[] = {{"", ""},         {"f", "Zg=="},         {"fo", "Zm8="},
                                                         {"foo", "Zm9v"},  {"foob", "Zm9vYg=="},  {"fooba", "Zm9vYmE="},
                                                         {"foobar", "Zm9vYmFy"}};
  for (const auto& [in, want] : vectors) EXPECT_EQ(report::base64_encode(in), want) << in;
  std::string all;
  for (int b = 255; b >= 0; --b) all += static_cast<char>(b);
  EXPECT_EQ(base64_decode(report::base64_encode(all)), all);
}

TEST(Report, NumbersReadWell) {
  EXPECT_EQ(report::format_number(1.23456), "1.235");
  EXPECT_EQ(report::format_number(42.0), "42");
  EXPECT_EQ(report::format_number(-3.0), "-3");
  EXPECT_EQ(report::format_number(-0.0), "0");
  EXPECT_EQ(report::format_number(12345.6), "12346");
  EXPECT_EQ(report::format_number(0.000123456), "0.0001235");
  EXPECT_EQ(report::format_number(6.02e23), "6.02e+23");
  EXPECT_EQ(report::format_number(std::nan("")), "nan");
}

TEST(Report, EmbedsEveryElementAndEscapesText) {
  test::TempDir d;
  make_run(d.path);
  const std::string html = report::render_report(d.path);
  // Data URIs decode back to the very bytes of the inputs.
  EXPECT_EQ(data_uri_bytes(html, "image/png"), read_file(d / "magenta.png"));
  EXPECT_EQ(data_uri_bytes(html, "image/gif"), read_file(d / "videos/prompt.gif"));
  EXPECT_EQ(data_uri_bytes(html, "video/mp4"), read_file(d / "videos/f1.mp4"));
  EXPECT_NE(html.find("<video autoplay loop muted playsinline controls src=\"data:video/mp4;base64,"),
            std::string::npos);
  // Text is escaped wherever it appears.
  EXPECT_NE(html.find("a &lt;b&gt;&amp; caption"), std::string::npos);
  EXPECT_NE(html.find("gaia &lt;demo&gt; &amp; co"), std::string::npos);
  EXPECT_NE(html.find("Plain text with &lt;tags&gt; &amp; ampersands."), std::string::npos);
  EXPECT_NE(html.find("<pre class=\"commands\">gaia generate --world w --out 'a b' &gt; log\n</pre>"),
            std::string::npos);
  EXPECT_EQ(html.find("<b>&"), std::string::npos);
  EXPECT_EQ(html.find("<demo>"), std::string::npos);
  // Metrics flattened, numbers formatted; table cells likewise.
  for (auto s : {">any.nested</td><td class=\"num\">1.235<", ">any.json</td><td>[1, 2]<",
                 ">tokens</td><td class=\"num\">1000000<",
                 "<td>left</td><td class=\"num\">0.9346</td>", "<td>right</td><td>n/a</td>", "<th>sign acc.</th>"})
    EXPECT_NE(html.find(s), std::string::npos) << s;
  // Table of contents links to both sections.
  EXPECT_NE(html.find("<a href=\"#s1\">Colour check</a>"), std::string::npos);
  EXPECT_NE(html.find("<section id=\"s2\">"), std::string::npos);
  // SVG inlined without its prolog; the curves are one chart per key: loss at steps 0, 10, 30 (20 is null, the torn
  // last line is skipped), val.bits_per_token at 10 and 30; the guidance plot has its 5 points.
  EXPECT_EQ(html.find("<?xml"), std::string::npos);
  EXPECT_EQ(test::occurrences(html, "<svg"), 3);
  EXPECT_EQ(polyline_points(html), (std::vector<size_t>{2, 3, 5}));
  EXPECT_NE(html.find(">val.bits_per_token</text>"), std::string::npos);
  // Self-contained: no external references, no input paths.
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);
  EXPECT_EQ(html.find("href=\"http"), std::string::npos);
  EXPECT_EQ(html.find("file:"), std::string::npos);
  EXPECT_EQ(html.find(d.path.string()), std::string::npos);
  for (const auto& p : kInputs) EXPECT_EQ(html.find(p), std::string::npos) << p;
}

TEST(Report, ErrorsNameTheFieldAndFile) {
  test::TempDir d;
  const std::string manifest = (d / "report.json").string();
  EXPECT_EQ(report_error(d.path), manifest + ": does not exist (gaia eval and gaia demo write it)");
  EXPECT_NE(report_error(d / "nope").find("nope: no such run directory"), std::string::npos);

  write_manifest(d.path, "[{}, {\"videos\": [{\"items\": [{\"path\": \"a.gif\"}, {\"path\": \"b.gif\"}, "
                         "{\"path\": \"videos/f3.mp4\"}]}]}]");
  write_file_atomic(d / "a.gif", "GIF89a");
  write_file_atomic(d / "b.gif", "GIF89a");
  write_file_atomic(d / "bad.jsonl", "{\"step\": 1}\nnot json\n");
  EXPECT_EQ(report_error(d.path), manifest + ": sections[1].videos[0].items[2].path: videos/f3.mp4 does not exist");

  const std::pair<std::string, std::string> cases[] = {
      {"{}", ": sections: expected an array, got object"},
      {"[{\"metrics\": [1]}]", ": sections[0].metrics: expected an object, got array"},
      {"[{\"title\": 3}]", ": sections[0].title: expected a string, got number"},
      {"[{\"video\": []}]", ": sections[0]: unknown key 'video' (expected one of: title, text, videos, plots"},
      {"[{\"plots\": [{\"caption\": \"x\"}]}]", ": sections[0].plots[0]: missing 'path'"},
      {"[{\"images\": [{\"path\": \"a.pdf\"}]}]", ": sections[0].images[0].path: a.pdf: unsupported file type"},
      {"[{\"tables\": [{\"columns\": [\"a\"], \"rows\": [[1, 2]]}]}]",
       ": sections[0].tables[0].rows[0]: has 2 cells but there are 1 columns"},
      {"[{\"curves\": [{\"path\": \"bad.jsonl\"}]}]", ": sections[0].curves[0].path: bad.jsonl line 2: invalid JSON"},
      {"[{\"commands\": [\"ok\", 7]}]", ": sections[0].commands[1]: expected a string, got number"},
  };
  for (const auto& [sections, want] : cases) {
    write_manifest(d.path, sections);
    EXPECT_EQ(report_error(d.path).rfind(manifest + want, 0), 0u) << report_error(d.path);
  }
  write_file_atomic(d / "report.json", "{\"sections\": []}");
  EXPECT_EQ(report_error(d.path), manifest + ": missing 'title'");
  write_file_atomic(d / "report.json", "{\"title\": \"t\"}");
  EXPECT_EQ(report_error(d.path), manifest + ": missing 'sections'");
  write_file_atomic(d / "report.json", "{\"title\": \"t\",\n \"sections\": [}");
  EXPECT_EQ(report_error(d.path).rfind(manifest + ": invalid JSON: parse error at line 2", 0), 0u)
      << report_error(d.path);
}

TEST(ReportCli, WritesThePageOrOneErrorLineAndNothing) {
  test::TempDir d;
  make_run(d.path);
  auto ok = test::run_gaia("report '" + d.path.string() + "'");
  EXPECT_EQ(ok.status, 0) << ok.output;
  EXPECT_EQ(read_file(d / "report.html"), report::render_report(d.path));
  auto other = test::run_gaia("report '" + d.path.string() + "' --out '" + (d / "out/page.html").string() + "'");
  EXPECT_EQ(other.status, 0) << other.output;
  EXPECT_TRUE(fs::exists(d / "out/page.html"));

  fs::remove(d / "report.html");
  fs::remove(d / "videos/f1.mp4");
  auto r = test::run_gaia("report '" + d.path.string() + "'");
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(r.output.rfind("gaia: error: ", 0), 0u) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  EXPECT_NE(r.output.find("sections[1].videos[0].items[1].path: videos/f1.mp4 does not exist"), std::string::npos)
      << r.output;
  for (const auto& e : fs::directory_iterator(d.path))  // neither the page nor a temporary file
    EXPECT_EQ(e.path().filename().string().find("report.html"), std::string::npos) << e.path();
  EXPECT_NE(test::run_gaia("report").status, 0);  // RUN_DIR is required
}

TEST(Report, ChromiumShowsThePage) {
  if (!have_chromium()) GTEST_SKIP() << "chromium not installed (scripts/setup.sh installs it)";
  test::TempDir d;
  make_run(d.path);
  report::write_report(d.path, d / "report.html");

  // The DOM Chromium built: the page parses into the elements we wrote.
  ASSERT_EQ(chromium(d, "--dump-dom", d / "report.html", d / "dom.html"), 0);
  const std::string dom = read_file(d / "dom.html");
  EXPECT_EQ(test::occurrences(dom, "<img"), 2);    // magenta.png, prompt.gif
  EXPECT_EQ(test::occurrences(dom, "<video"), 1);  // f1.mp4
  EXPECT_EQ(test::occurrences(dom, "<svg"), 3);    // guidance plot, two curves
  EXPECT_EQ(test::occurrences(dom, "<table"), 2);  // the table, the metrics
  EXPECT_NE(dom.find("gaia &lt;demo&gt; &amp; co"), std::string::npos);

  // The screenshot: window-sized, not blank, and the magenta image is on it.
  const fs::path png = d / "shot.png";
  const std::string shot_args = "--window-size=1200,1600 --screenshot='" + png.string() + "'";
  ASSERT_EQ(chromium(d, shot_args, d / "report.html", d / "log"), 0);
  cv::Mat shot = cv::imread(png.string(), cv::IMREAD_COLOR);
  ASSERT_FALSE(shot.empty()) << "no screenshot at " << png;
  EXPECT_EQ(shot.cols, 1200);
  EXPECT_EQ(shot.rows, 1600);
  cv::Scalar mean, sd;
  cv::meanStdDev(shot.reshape(1), mean, sd);
  EXPECT_GT(sd[0], 20.0);
  cv::Mat magenta;
  cv::inRange(shot, cv::Scalar(230, 0, 230), cv::Scalar(255, 30, 255), magenta);
  EXPECT_GT(cv::countNonZero(magenta), 3000);  // the 64 x 64 image: 4096 pixels
}
