// gaia sim serve (sim/server.h) in process on a loopback port: the protocol over HTTP, bad requests as 4xx, a
// bounded load of clients all answered with memory flat, a client that vanishes mid-request, and the driving page
// in a real headless browser (a scripted drive holding the left arrow).
#ifdef GAIA_WITH_HTTP
#include <atomic>
#include <algorithm>
#include <thread>

#include <httplib.h>
#include <torch/torch.h>

#include <sys/socket.h>
#include <unistd.h>

#include "gaia/config.h"
#include "gaia/sim/server.h"
#include "gaia/sizing/sizing.h"
#include "test_util.h"

using namespace gaia;
using nlohmann::json;

namespace {

// A tiny random world model behind a server on a free port, answered by 4 threads.
struct Served {
  world::WorldInfo info;
  world::WorldModel model{nullptr};
  std::unique_ptr<sim::SessionHub> hub;
  std::unique_ptr<sim::SimServer> server;
  std::thread thread;
  int port = 0;
  explicit Served(int max_sessions = 8) {
    info.config = test::config("tiny.yaml");
    info.grid_h = 2;
    info.grid_w = 3;
    info.K = 32;
    torch::manual_seed(12);
    model = world::WorldModel(info.config.world, 6, 32);
    model->eval();
    // A frame as a 1x1 PNG data: URI (the tokenizer's decoder in the app).
    hub = std::make_unique<sim::SessionHub>(model, info, sim::HubLimits{max_sessions, 4, 600}, sim::PromptSource{},
                                            [](const torch::Tensor&, const std::string&) {
                                              return json("data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAA"
                                                          "fFcSJAAAADUlEQVR42mNkYPhfDwAChwGA60e6kgAAAABJRU5ErkJggg==");
                                            });
    sim::ServerOptions o;
    o.port = 0;
    o.threads = 4;
    o.max_body = 64 * 1024;
    server = std::make_unique<sim::SimServer>(*hub, o);
    port = server->bind();
    thread = std::thread([this] { server->run(); });
  }
  ~Served() {
    server->stop();
    thread.join();
  }
  httplib::Client client() const {
    httplib::Client c("127.0.0.1", port);
    c.set_read_timeout(60, 0);
    return c;
  }
};

std::pair<int, json> post(httplib::Client& c, const std::string& op, const std::string& body) {
  auto r = c.Post(("/api/" + op).c_str(), body, "application/json");
  if (!r) return {0, json()};
  return {r->status, json::parse(r->body, nullptr, false)};
}

}  // namespace

TEST(SimServer, ProtocolOverHttpAndBadRequestsAre4xx) {
  Served s;
  auto c = s.client();
  auto page = c.Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->body.find("<canvas"), std::string::npos);
  auto [status, body] = post(c, "create", R"({"seed": 3, "text": "rain"})");
  ASSERT_EQ(status, 200) << body.dump();
  const auto id = body["session"].get<int64_t>();
  std::tie(status, body) = post(c, "step", json({{"session", id}, {"speed", 8}, {"curvature", 0.01}, {"frame", true}}).dump());
  ASSERT_EQ(status, 200) << body.dump();
  EXPECT_EQ(body["tokens"].size(), 6u);
  EXPECT_EQ(body["frame"].get<std::string>().rfind("data:image/png", 0), 0u);
  const std::vector<std::tuple<std::string, std::string, int>> bad = {
      {"step", "not json", 400},
      {"step", "[1, 2]", 400},
      {"step", R"({"session": 99})", 404},
      {"step", json({{"session", id}, {"curvature", 3}}).dump(), 400},
      {"step", json({{"session", id}, {"speed", "fast"}}).dump(), 400},
      {"warp", "{}", 404},
      {"step", std::string(100 * 1024, ' '), 413},
  };
  for (const auto& [op, req, want] : bad) {
    auto r = c.Post(("/api/" + op).c_str(), req, "application/json");
    ASSERT_TRUE(r) << op;
    EXPECT_EQ(r->status, want) << op << " " << req.substr(0, 60) << ": " << r->body;
    auto j = json::parse(r->body, nullptr, false);
    EXPECT_TRUE(j.is_object() && j.contains("error")) << r->body;
  }
  EXPECT_EQ(c.Get("/etc/passwd")->status, 404);
  EXPECT_EQ(c.Get("/api/../../etc/passwd")->status, 404);
  auto st = c.Get("/api/status");
  ASSERT_TRUE(st);
  EXPECT_EQ(json::parse(st->body)["sessions"].size(), 1u);
  std::tie(status, body) = post(c, "close", json({{"session", id}}).dump());
  EXPECT_EQ(status, 200);
}

// N clients x M steps on their own sessions, all answered, twice: the second round holds no more memory than the
// first; a client that sends half a request and vanishes leaves the others served.
// The stream: server-sent events, one per step of the standing command, changed while it runs; a stream left early
// leaves the session to the next one; bad streams are plain 4xx.
TEST(SimServer, TheStreamSendsAStepPerEventWithTheStandingCommand) {
  Served s;
  auto c = s.client();
  const auto id = post(c, "create", R"({"seed": 5})").second["session"].get<int64_t>();
  ASSERT_EQ(post(c, "command", json({{"session", id}, {"speed", 9}, {"curvature", 0.01}}).dump()).first, 200);
  std::string events;
  int seen = 0;
  auto other = s.client();
  auto r = c.Get(("/api/stream?session=" + std::to_string(id) + "&frames=5&frame=1").c_str(),
                 [&](const char* data, size_t len) {
                   events.append(data, len);
                   const int now = int(std::count(events.begin(), events.end(), '\n')) / 2;
                   if (now >= 2 && seen < 2)  // mid-stream, from another connection: turn right from here
                     post(other, "command", json({{"session", id}, {"speed", 9}, {"curvature", -0.01}}).dump());
                   seen = now;
                   return true;
                 });
  ASSERT_TRUE(r);
  EXPECT_EQ(r->status, 200);
  EXPECT_NE(r->get_header_value("Content-Type").find("text/event-stream"), std::string::npos);
  std::vector<json> got;
  for (size_t at = 0; (at = events.find("data: ", at)) != std::string::npos; at += 6)
    got.push_back(json::parse(events.substr(at + 6, events.find('\n', at) - at - 6)));
  ASSERT_EQ(got.size(), 5u) << events;
  for (size_t k = 0; k < got.size(); ++k) {
    EXPECT_EQ(got[k]["step"], int64_t(k));
    EXPECT_EQ(got[k]["frame"].get<std::string>().rfind("data:image/png", 0), 0u);
  }
  // The change lands wherever the stream has got to (the server does not wait for the reader), and holds from there.
  EXPECT_EQ(got.front()["command"]["curvature"], 0.01);
  bool turned = false;
  for (const auto& g : got) {
    turned = turned || g["command"]["curvature"] == -0.01;
    EXPECT_EQ(g["command"]["curvature"], turned ? -0.01 : 0.01);
  }
  std::string next;
  c.Get(("/api/stream?session=" + std::to_string(id) + "&frames=1").c_str(), [&](const char* data, size_t len) {
    next.append(data, len);
    return true;
  });
  EXPECT_NE(next.find(R"("curvature":-0.01)"), std::string::npos) << next;
  // Left after one event: the session goes on serving the next stream and plain steps.
  int n = 0;
  c.Get(("/api/stream?session=" + std::to_string(id)).c_str(), [&](const char*, size_t) { return ++n < 1; });
  auto [status, body] = post(c, "step", json({{"session", id}}).dump());
  EXPECT_EQ(status, 200) << body.dump();
  EXPECT_GE(body["step"].get<int64_t>(), 7);
  for (const auto& [query, words] : std::vector<std::pair<std::string, std::string>>{
           {"session=99", "no session 99"}, {"", "'session'"}, {"session=x", "whole number"},
           {"session=1&speed=3", "unknown parameter 'speed'"}, {"session=1&frame=yes", "'frame' must be 1 or 0, png or jpeg"}}) {
    auto bad = c.Get(("/api/stream?" + query).c_str());
    ASSERT_TRUE(bad);
    EXPECT_GE(bad->status, 400) << query;
    EXPECT_LT(bad->status, 500) << query;
    EXPECT_NE(bad->body.find(words), std::string::npos) << query << ": " << bad->body;
  }
}

TEST(SimServer, ABoundedLoadIsAnsweredAndAVanishedClientHarmsNoOne) {
  Served s;
  constexpr int kClients = 4, kSteps = 12;
  std::vector<double> latencies;
  std::mutex lock;
  auto round = [&] {
    std::atomic<int> ok{0};
    std::vector<std::thread> clients;
    for (int i = 0; i < kClients; ++i)
      clients.emplace_back([&, i] {
        auto c = s.client();
        auto [status, body] = post(c, "create", json({{"seed", i}}).dump());
        if (status != 200) return;
        const auto id = body["session"];
        for (int k = 0; k < kSteps; ++k) {
          const auto t0 = std::chrono::steady_clock::now();
          auto [st, b] = post(c, "step", json({{"session", id}, {"speed", 8}, {"curvature", 0.005 * (i - 1.5)}}).dump());
          const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
          if (st == 200) {
            ++ok;
            std::lock_guard<std::mutex> g(lock);
            latencies.push_back(ms);
          }
        }
        post(c, "close", json({{"session", id}}).dump());
      });
    for (auto& t : clients) t.join();
    return ok.load();
  };
  EXPECT_EQ(round(), kClients * kSteps);
  const double after_first = sizing::resident_bytes();
  // A client that opens a connection, sends half a request and is gone.
  {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(uint16_t(s.port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    const std::string half = "POST /api/create HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\n{\"seed\"";
    ASSERT_GT(::send(fd, half.data(), half.size(), 0), 0);
    ::close(fd);
  }
  EXPECT_EQ(round(), kClients * kSteps);
  EXPECT_LT(sizing::resident_bytes() - after_first, 64e6);  // flat: sessions closed, nothing kept
  EXPECT_EQ(s.hub->sessions(), 0u);
  std::sort(latencies.begin(), latencies.end());
  ASSERT_EQ(latencies.size(), size_t(2 * kClients * kSteps));
  std::printf("latency over %zu steps: p50 %.1f ms, p99 %.1f ms\n", latencies.size(), latencies[latencies.size() / 2],
              latencies[latencies.size() * 99 / 100]);
}

// The page in headless Chromium: it opens, makes a session, holds the left arrow (?hold=ArrowLeft) for 4 frames,
// and shows them with the commanded left turn.
TEST(SimServer, TheDrivingPageDrivesInAHeadlessBrowser) {
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium not installed (scripts/setup.sh installs it)";
  Served s;
  test::TempDir d;
  const std::string url = "http://127.0.0.1:" + std::to_string(s.port) + "/?frames=4&hold=ArrowLeft&text=night";
  auto r = test::run_shell("timeout 120 chromium --headless --no-sandbox --disable-gpu --user-data-dir=" +
                           test::q(d / "profile") + " --virtual-time-budget=60000 --dump-dom '" + url + "' 2>/dev/null");
  ASSERT_EQ(r.status, 0);
  EXPECT_NE(r.output.find("data-done=\"4\""), std::string::npos) << r.output.substr(0, 2000);
  EXPECT_NE(r.output.find("src=\"data:image/png;base64,"), std::string::npos);
  EXPECT_NE(r.output.find("curvature 10 1/km"), std::string::npos);  // the left arrow: +0.01 1/m
  EXPECT_NE(r.output.find("text \"night\""), std::string::npos);
  EXPECT_NE(r.output.find("step 3 "), std::string::npos);
}
#endif
