// gaia sim: closed-loop driving inside the world model (sim/hub.h, docs/sim.md). --stdio: one JSON request a line
// on stdin, one JSON answer a line on stdout, for a policy in any language.
#include <cstdio>
#include <deque>
#include <map>
#include <iostream>
#include <mutex>

#include <nlohmann/json.hpp>

#include "common.h"
#include "episode_prompt.h"
#include "gaia/core/error.h"
#include "gaia/sim/hub.h"
#include "gaia/world/prompt_text.h"
#include "gaia/sim/server.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/io.h"
#include "gaia/world/token_dataset.h"
#ifndef GAIA_NO_VIDEO
#include <opencv2/imgcodecs.hpp>

#include "gaia/data/video_io.h"

#include "gaia/emerging/common.h"
#include "gaia/probe/trainer.h"
#include "gaia/report/report.h"
#include "gaia/tokenizer/io.h"
#endif

namespace gaia::app {

namespace {

struct SimFlags {
  std::string tokens, world, tokenizer, probe, t5;
  std::vector<std::string> videos;
  int video_frames = 64;
  bool stdio = false;
  int max_sessions = 8, max_queue = 4;
  double idle_s = 600;
  TokenFormatFlags format;
};

constexpr size_t kMaxLine = 1 << 20;  // bytes of one request

// The flags both modes take.
void add_sim_flags(CLI::App* cmd, SimFlags* g, SharedFlags* flags) {
  cmd->add_option("TOKENS", g->tokens, "token dataset or file whose episodes are video prompts ({\"episode\": ID})");
  add_token_format_flags(cmd, &g->format);
  cmd->add_option("--video", g->videos,
                  "video files tokenized at start (needs --tokenizer), each a prompt named by its file name without "
                  "the extension ({\"episode\": \"highway\"}); repeatable")
      ->check(CLI::ExistingFile);
  cmd->add_option("--video-frames", g->video_frames, "frames of each --video kept, at the world model's rate")
      ->check(number_in({1, 4096}));
  add_weights_flag(cmd, Weights::World, &g->world);
  add_weights_flag(cmd, Weights::Tokenizer, &g->tokenizer, "decodes frames to PNG for steps that ask ({\"frame\": true})");
  add_weights_flag(cmd, Weights::Probe, &g->probe,
                   "dynamics probe: each step answers what its frames show (read_back: speed, curvature); needs "
                   "--tokenizer");
  add_weights_flag(cmd, Weights::T5, &g->t5, "encodes text prompts for a world model trained on its embeddings");
  cmd->add_option("--max-sessions", g->max_sessions, "sessions open at once")->check(number_in({1, 1024}));
  cmd->add_option("--max-queue", g->max_queue, "requests that may wait while a session answers another")
      ->check(number_in({0, 1024}));
  cmd->add_option("--idle", g->idle_s, "seconds after which an untouched session is closed")->check(number_in({1, 1e7}));
  add_shared_flags(cmd, flags, "unused");
}

// The world model, the prompts from TOKENS and the frame encoder (the tokenizer), then `serve` with the hub.
void with_hub(const SimFlags& g, const SharedFlags& flags, const std::function<void(sim::SessionHub&)>& serve) {
  Config run = resolve_config(flags);
  // One intra-op thread per session unless told otherwise: a session's frame then samples on one core while the
  // next window's history is encoded on another (world/rollout.h, lookahead), and sessions sharing the cores do not
  // spin against each other.
  if (flags.threads < 0 && run.run.threads == 0) run.run.threads = 1;
  apply_threads(run);
  const auto dev = parse_device(run.run.device);
  world::WorldInfo info;
  auto model = world::load_world(g.world, dev, &info);
  std::unique_ptr<world::TokenDataset> ds;
  if (!g.tokens.empty()) {
    ds = std::make_unique<world::TokenDataset>(g.tokens, token_format(g.format, run, false, &info));
    if (ds->grid_h() != info.grid_h || ds->grid_w() != info.grid_w)
      fail("{}: a {}x{} token grid, the world model {} takes {}x{}", g.tokens, ds->grid_h(), ds->grid_w(), g.world,
           info.grid_h, info.grid_w);
  }
  const int64_t T = model->layout.T;
  std::mutex ds_lock;  // the dataset's episode cache is not shared between threads
  // --video prompts by name: tokens [frames, n], no actions (filled below, once the tokenizer is loaded).
  std::vector<std::pair<std::string, torch::Tensor>> videos;
  // {"episode": ID or index, "start": step, "frames": P}: P frames of a --video or of TOKENS, with their actions.
  sim::PromptSource prompts;
  if (ds || !g.videos.empty())
    prompts = [&, T](const nlohmann::json& q) {
      for (const auto& [k, v] : q.items())
        if (k != "episode" && k != "start" && k != "frames") fail("unknown field 'prompt.{}'", k);
      if (!q.contains("episode") || !(q["episode"].is_string() || q["episode"].is_number_unsigned()))
        fail("'prompt.episode' must be the name of a --video or an episode id or index of the server's TOKENS");
      const std::string id = q["episode"].is_string() ? q["episode"].get<std::string>()
                                                      : std::to_string(q["episode"].get<uint64_t>());
      auto whole = [&](const char* k, int64_t fallback, int64_t lo, int64_t hi) {
        if (!q.contains(k)) return fallback;
        if (!q[k].is_number_integer() || q[k].get<int64_t>() < lo || q[k].get<int64_t>() > hi)
          fail("'prompt.{}' must be a whole number in [{}, {}]", k, lo, hi);
        return q[k].get<int64_t>();
      };
      auto frames_from = [&](int64_t steps, int64_t* start) {
        *start = whole("start", 0, 0, steps - 1);
        return std::min(whole("frames", std::min<int64_t>(T - 1, 4), 0, T - 1), steps - *start);
      };
      for (const auto& [name, tokens] : videos)
        if (name == id) {
          int64_t start = 0;
          const int64_t P = frames_from(tokens.size(0), &start);
          return sim::Prompt{tokens.narrow(0, start, P).clone(), {}};
        }
      if (!ds) {
        std::string names;
        for (const auto& v : videos) names += (names.empty() ? "" : ", ") + v.first;
        fail("no prompt '{}': this server's video prompts are {}", id, names);
      }
      std::lock_guard<std::mutex> g_(ds_lock);
      const size_t e = ds->find(id);
      int64_t start = 0;
      const int64_t P = frames_from(ds->steps(e), &start);
      auto ep = episode_prompt(*ds, e, start, P);
      return sim::Prompt{ep.tokens, ep.actions};
    };
  sim::FrameEncoder frames;
  sim::ReadBack read_back;
#ifdef GAIA_NO_VIDEO
  if (!g.tokenizer.empty() || !g.probe.empty() || !g.videos.empty())
    fail("--tokenizer, --probe and --video need a build with video support (this one has none)");
#else
  emerging::Models m;  // the read-back's models: the tokenizer's decoder and the dynamics probe
  if (!g.probe.empty() && g.tokenizer.empty()) fail("--probe reads decoded frames: it needs --tokenizer");
  tokenizer::ImageTokenizer tok{nullptr};
  // Decoded frames by their tokens: a step's frame and its read-back share one decoding, and the read-back's other
  // frames were decoded at the steps before (so a step decodes one frame, not the probe's four).
  struct Decoded {
    std::mutex lock;
    std::map<std::vector<int64_t>, cv::Mat> frames;
    std::deque<std::vector<int64_t>> order;  // oldest first
  };
  auto cache = std::make_shared<Decoded>();
  const size_t cache_size = size_t(8 * g.max_sessions);
  auto decoded = [&, cache, cache_size](const torch::Tensor& t) {
    auto c = t.to(torch::kCPU).to(torch::kLong).contiguous();
    std::vector<int64_t> key(c.data_ptr<int64_t>(), c.data_ptr<int64_t>() + c.numel());
    {
      std::lock_guard<std::mutex> l(cache->lock);
      auto it = cache->frames.find(key);
      if (it != cache->frames.end()) return it->second;
    }
    cv::Mat img = tokenizer::decode_tokens(tok, c.view({1, info.grid_h, info.grid_w}), dev).at(0);
    std::lock_guard<std::mutex> l(cache->lock);
    if (cache->frames.emplace(key, img).second) cache->order.push_back(key);
    while (cache->order.size() > cache_size) {
      cache->frames.erase(cache->order.front());
      cache->order.pop_front();
    }
    return img;
  };
  if (!g.videos.empty() && g.tokenizer.empty()) fail("--video needs --tokenizer to turn the frames into tokens");
  if (!g.tokenizer.empty()) {
    Config tok_cfg;
    tok = tokenizer::load_tokenizer(g.tokenizer, dev, &tok_cfg);
    emerging::check_tokenizer_fits(info, g.world, tok, g.tokenizer);
    for (const auto& path : g.videos) {  // as gaia generate --video reads its prompt
      const std::string name = fs::path(path).stem().string();
      for (const auto& v : videos)
        if (v.first == name) fail("--video {}: a second prompt named '{}' (prompts are named by file name)", path, name);
      auto tokens = tokenizer::video_prompt_tokens(tok, tok_cfg, path, g.video_frames, model->layout.n, dev);
      std::fprintf(stderr, "gaia sim: video prompt '%s': %ld frames\n", name.c_str(), long(tokens.size(0)));
      videos.emplace_back(name, tokens);
    }
    frames = [&, decoded](const torch::Tensor& t, const std::string& format) -> nlohmann::json {
      auto img = decoded(t);
      std::vector<uchar> bytes;
      cv::imencode(format == "jpeg" ? ".jpg" : ".png", img, bytes, {cv::IMWRITE_JPEG_QUALITY, 90});
      return "data:image/" + format + ";base64," +
             report::base64_encode({reinterpret_cast<const char*>(bytes.data()), bytes.size()});
    };
  }
  if (!g.probe.empty()) {
    m.world = model;
    m.info = info;
    m.tok = tok;
    m.dev = dev;
    m.dynamics = probe::load_probe(g.probe, dev);
    if (m.dynamics->kind != probe::ProbeKind::kDynamics) fail("{}: not a dynamics probe", g.probe);
    read_back.frames = m.dynamics->frames;
    read_back.read = [&, decoded](const torch::Tensor& recent) -> nlohmann::json {
      std::vector<cv::Mat> last;
      for (int64_t i = 0; i < recent.size(0); ++i) last.push_back(decoded(recent[i]));
      auto y = emerging::read_dynamics(m, last);  // [1, 2]
      return {{"speed", y[0][0].item<double>()}, {"curvature", y[0][1].item<double>()}};
    };
  }
#endif
  // A model that reads T5 embeddings takes text only through its T5 (sessions without text need none).
  std::shared_ptr<text::TextEncoder> text;
  if (!info.embeds_text() || !g.t5.empty()) text = world::prompt_encoder(info, g.world, g.t5, dev);
  const Precision precision = run_precision(run, dev, "sim");
  sim::SessionHub hub(model, info, {g.max_sessions, g.max_queue, g.idle_s, precision}, prompts, frames, read_back, text);
  serve(hub);
}

// One JSON request a line on stdin, one JSON answer a line on stdout.
void serve_stdio(sim::SessionHub& hub) {
  std::string line;
  int64_t number = 0;
  while (std::getline(std::cin, line)) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    sim::HubReply reply;
    if (line.size() > kMaxLine) {
      reply = {413, {{"error", fmt::format("line {}: a request of {} bytes; at most {}", number, line.size(), kMaxLine)}}};
    } else {
      nlohmann::json req = nlohmann::json::parse(line, nullptr, false);
      if (req.is_discarded() || !req.is_object())
        reply = {400, {{"error", fmt::format("line {}: not a JSON object", number)}}};
      else if (!req.contains("op") || !req["op"].is_string())
        reply = {400, {{"error", fmt::format("line {}: no \"op\" (create, step, command, drive, fork, reset, close, status)", number)}}};
      else {
        const auto op = req["op"].get<std::string>();
        req.erase("op");
        reply = hub.handle(op, req);
      }
    }
    reply.body["status"] = reply.status;
    std::fputs((reply.body.dump() + "\n").c_str(), stdout);
    std::fflush(stdout);
  }
}

}  // namespace

void register_sim(CLI::App& app) {
  auto* cmd = app.add_subcommand("sim", "closed-loop driving in the world model: sessions stepped one action at a time "
                                        "(--stdio: JSON lines; serve: HTTP with a page to drive; docs/sim.md)");
  auto flags = std::make_shared<SharedFlags>();
  auto g = std::make_shared<SimFlags>();
  add_sim_flags(cmd, g.get(), flags.get());
  cmd->add_flag("--stdio", g->stdio, "read one JSON request a line from stdin, answer one JSON line on stdout");
  auto* serve = cmd->add_subcommand("serve", "answer the session protocol over HTTP on loopback, with a page at / to "
                                             "drive from the browser");
  auto sflags = std::make_shared<SharedFlags>();
  auto sg = std::make_shared<SimFlags>();
  add_sim_flags(serve, sg.get(), sflags.get());
  auto so = std::make_shared<sim::ServerOptions>();
  serve->add_option("--host", so->host, "address to listen on (default 127.0.0.1: this machine only)");
  serve->add_option("--port", so->port, "port (0: any free one)")->check(number_in({0, 65535}));
  serve->callback([=] {
    if (sg->world.empty()) fail("gaia sim serve: --world is required");
#ifndef GAIA_WITH_HTTP
    fail("gaia sim serve: this build has no HTTP server (cpp-httplib was not found); use gaia sim --stdio, or "
         "install libcpp-httplib-dev and rebuild");
#else
    with_hub(*sg, *sflags, [&](sim::SessionHub& hub) {
      sim::SimServer server(hub, *so);
      const int port = server.bind();
      std::printf("gaia sim: serving on http://%s:%d/ (Ctrl-C stops)\n", so->host.c_str(), port);
      std::fflush(stdout);
      server.run();
    });
#endif
  });
  cmd->callback([=] {
    if (serve->parsed()) return;
    if (!g->stdio) fail("gaia sim: say --stdio (JSON requests on stdin, answers on stdout) or serve (HTTP; docs/sim.md)");
    if (g->world.empty()) fail("gaia sim: --world is required");
    with_hub(*g, *flags, serve_stdio);
  });
}

}  // namespace gaia::app
