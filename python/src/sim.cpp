// gaia.Sim: closed-loop sessions as `gaia sim` has them (sim/session.h), each step's frame decoded to an array and
// read back by the dynamics probe, in-process.
#include <algorithm>
#include <chrono>
#include <cstring>
#include <deque>
#include <optional>

#include <fmt/format.h>
#include <opencv2/core.hpp>
#include <pybind11/stl.h>

#include "arrays.h"
#include "gaia/emerging/common.h"
#include "gaia/probe/trainer.h"
#include "gaia/sim/session.h"
#include "gaia/tokenizer/io.h"
#include "handles.h"

namespace gaia::python {

namespace {

struct SimHandle {
  std::shared_ptr<WorldHandle> world;
  std::shared_ptr<TokenizerHandle> tok;  // may be null: tokens only
  probe::ProbeNet dynamics{nullptr};     // may be null: no read-back
};

// One session with the frames it decoded lately (the read-back's window, by step), so a step decodes one frame.
struct SessionHandle {
  std::shared_ptr<SimHandle> sim;
  std::unique_ptr<sim::SimSession> s;
  std::deque<std::pair<int64_t, cv::Mat>> recent;  // (step, BGR frame), oldest first
  std::mutex busy;  // one call at a time (the GIL is released while it steps)
};

std::shared_ptr<SessionHandle> wrap(const std::shared_ptr<SimHandle>& sim, sim::SimSession s,
                                    const std::deque<std::pair<int64_t, cv::Mat>>& recent = {}) {
  auto h = std::make_shared<SessionHandle>();
  h->sim = sim;
  h->s = std::make_unique<sim::SimSession>(std::move(s));
  h->recent = recent;
  return h;
}

sim::Action action_of(double speed, double curvature) {
  sim::Action a{speed, curvature};
  sim::check_action(a);
  return a;
}

cv::Mat bgr_of(const torch::Tensor& rgb) {
  auto bgr = rgb.flip({2}).contiguous();
  cv::Mat m(int(bgr.size(0)), int(bgr.size(1)), CV_8UC3);
  std::memcpy(m.data, bgr.data_ptr(), size_t(bgr.numel()));
  return m;
}

// What step `k` answers, as `gaia sim` does: its tokens [h, w], its frame (RGB [H, W, 3]) when asked and a
// tokenizer is there, and the probe's read-back of the last K frames (prompt frames too) once there are K.
py::dict answer(SessionHandle& h, int64_t k, const torch::Tensor& tokens, bool frame) {
  const auto& info = h.sim->world->info;
  py::dict out;
  out["step"] = k;
  out["tokens"] = array_of(tokens.to(torch::kShort).view({info.grid_h, info.grid_w}));
  out["frame"] = py::none();
  out["read_back"] = py::none();
  if (!h.sim->tok || (!frame && !h.sim->dynamics)) return out;
  torch::Tensor rgb;
  std::optional<std::pair<double, double>> read;
  {
    py::gil_scoped_release free;
    auto& t = *h.sim->tok;
    auto decode = [&](const torch::Tensor& z) {
      return tokenizer::decode_rgb(t.tok, z.to(torch::kLong).view({1, info.grid_h, info.grid_w}), t.dev)[0];
    };
    rgb = decode(tokens);
    const int64_t K = h.sim->dynamics ? int64_t(h.sim->dynamics->frames) : 0;
    if (K > 0 && k + 1 >= K) {
      torch::Tensor all;
      std::vector<cv::Mat> window;
      for (int64_t j = k - K + 1; j < k; ++j) {
        auto it = std::find_if(h.recent.begin(), h.recent.end(), [&](const auto& r) { return r.first == j; });
        if (it != h.recent.end()) { window.push_back(it->second); continue; }
        if (!all.defined()) all = h.s->tokens();
        window.push_back(bgr_of(decode(all[j])));
      }
      window.push_back(bgr_of(rgb));
      h.recent.clear();
      for (int64_t j = k - K + 2, i = 1; j <= k; ++j, ++i) h.recent.emplace_back(j, window[size_t(i)]);
      emerging::Models m_;
      m_.tok = t.tok;
      m_.dev = t.dev;
      m_.dynamics = h.sim->dynamics;
      auto y = emerging::read_dynamics(m_, window);
      read = std::pair{y[0][0].item<double>(), y[0][1].item<double>()};
    }
  }
  if (frame) out["frame"] = array_of(rgb);
  if (read) {
    py::dict rb;
    rb["speed"] = read->first;
    rb["curvature"] = read->second;
    out["read_back"] = rb;
  }
  return out;
}

}  // namespace

void bind_sim(py::module_& m) {
  py::class_<SimHandle, std::shared_ptr<SimHandle>>(m, "Sim", R"(Closed-loop driving in the world model, in-process.

Sim(world, tokenizer=None, probe=None, device="cpu", t5=""): world and tokenizer are paths or loaded
gaia.WorldModel / gaia.Tokenizer objects (shared, not copied); probe a dynamics probe's weights, which reads
each step's frames back as speed and curvature. create() opens a session.)")
      .def(py::init([](py::object world, py::object tokenizer, const std::string& probe, const std::string& device,
                       const std::string& t5) {
        auto h = std::make_shared<SimHandle>();
        if (py::isinstance<py::str>(world)) h->world = load_world_handle(world.cast<std::string>(), device, t5);
        else h->world = world.cast<std::shared_ptr<WorldHandle>>();
        if (py::isinstance<py::str>(tokenizer)) h->tok = load_tokenizer_handle(tokenizer.cast<std::string>(), device);
        else if (!tokenizer.is_none()) h->tok = tokenizer.cast<std::shared_ptr<TokenizerHandle>>();
        if (h->tok) emerging::check_tokenizer_fits(h->world->info, h->world->path, h->tok->tok, h->tok->path);
        if (!probe.empty()) {
          if (!h->tok) throw py::value_error("probe: reads decoded frames, so it needs a tokenizer");
          require_path(probe, "probe");
          h->dynamics = probe::load_probe(probe, h->tok->dev);
          if (h->dynamics->kind != probe::ProbeKind::kDynamics)
            throw py::value_error(fmt::format("probe: {} is not a dynamics probe", probe));
        }
        return h;
      }), py::arg("world"), py::arg("tokenizer") = py::none(), py::arg("probe") = "", py::arg("device") = "cpu",
      py::arg("t5") = "")
      .def("create", [](std::shared_ptr<SimHandle> h, std::optional<py::array> prompt,
                        std::optional<py::array> prompt_actions, const std::string& text, uint64_t seed,
                        std::optional<double> guidance, const std::string& sampling, std::optional<int> top_k,
                        std::optional<double> temperature, int window_stride, const std::string& action_negative,
                        const std::string& precision) {
        auto& w = *h->world;
        sim::SessionSettings s;
        s.seed = seed;
        s.guidance_scale = guidance ? *guidance : -1;
        s.sampling = sampling;
        s.top_k = top_k ? *top_k : -1;
        s.temperature = temperature ? *temperature : -1;
        s.window_stride = window_stride;
        s.precision = precision_arg(precision, w.dev);
        if (action_negative != "mirror" && action_negative != "turn" && action_negative != "null")
          throw py::value_error("action_negative: \"mirror\", \"turn\" or \"null\" expected, got \"" + action_negative + "\"");
        s.mirror_negative = action_negative != "null";
        s.negative_keeps_speed = action_negative == "turn";
        torch::Tensor z, a;
        if (prompt) {
          auto t = view_of(*prompt, Kind::kTokens, {{-1, w.info.grid_h, w.info.grid_w}, {-1, w.info.n()}}, "prompt");
          z = t.to(torch::kLong).reshape({t.size(0), w.info.n()});
        }
        if (prompt_actions) {
          if (!prompt) throw py::value_error("prompt_actions: given without a prompt");
          a = view_of(*prompt_actions, Kind::kSignals, {z.size(0), 2}, "prompt_actions").to(torch::kFloat);
        }
        std::shared_ptr<text::TextEncoder> enc;
        if (w.info.embeds_text() && !w.t5.empty()) enc = w.text();
        auto session = std::make_unique<sim::SimSession>(w.model, w.info, s, enc);
        {
          py::gil_scoped_release free;
          session->start(z, a, text);
        }
        auto out = std::make_shared<SessionHandle>();
        out->sim = h;
        out->s = std::move(session);
        return out;
      },
      py::arg("prompt") = py::none(), py::arg("prompt_actions") = py::none(), py::arg("text") = "",
      py::arg("seed") = 0, py::arg("guidance") = py::none(), py::arg("sampling") = "top-k",
      py::arg("top_k") = py::none(), py::arg("temperature") = py::none(), py::arg("window_stride") = 1,
      py::arg("action_negative") = "mirror", py::arg("precision") = "fp32",
      R"(A session from a video prompt: int16 tokens [P, h, w] with their actions [P, 2] (speed m/s, curvature
1/m, NaN unknown), a text prompt and the sampling settings of `gaia sim`'s create; precision as `gaia sim
--precision` ("fp32" or "bf16").)")
      .def_property_readonly("world", [](const SimHandle& h) { return h.world; })
      .def_property_readonly("tokenizer", [](const SimHandle& h) { return h.tok; });

  py::class_<SessionHandle, std::shared_ptr<SessionHandle>>(m, "Session", "One closed-loop session (gaia.Sim.create).")
      .def("step", [](SessionHandle& h, double speed, double curvature, std::optional<std::string> text, bool frame) {
        std::lock_guard<std::mutex> g(h.busy);
        const auto a = action_of(speed, curvature);
        const auto t0 = std::chrono::steady_clock::now();
        torch::Tensor tokens;
        {
          py::gil_scoped_release free;
          tokens = h.s->step(a, text);
        }
        auto out = answer(h, h.s->steps() - 1, tokens, frame);
        out["ms"] = 1000 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        return out;
      }, py::arg("speed"), py::arg("curvature"), py::arg("text") = py::none(), py::arg("frame") = true,
      R"(The next frame under the command (speed m/s, curvature 1/m, + = left; NaN: none); text replaces the text
prompt from this step on. Returns {"step", "tokens": int16 [h, w], "frame": RGB uint8 [H, W, 3] or None,
"read_back": {"speed", "curvature"} or None, "ms": the time of the step in the library}.)")
      .def("fork", [](SessionHandle& h) {
        std::lock_guard<std::mutex> g(h.busy);
        return wrap(h.sim, h.s->fork(), h.recent);
      }, "An independent copy of the whole state (cache, history, random stream).")
      .def("fork", [](SessionHandle& h, const std::vector<std::vector<std::pair<double, double>>>& plans,
                      std::optional<std::string> text, bool frame) {
        std::lock_guard<std::mutex> g(h.busy);
        std::vector<std::vector<sim::Action>> p;
        for (const auto& plan : plans) {
          p.emplace_back();
          for (const auto& [v, c] : plan) p.back().push_back(action_of(v, c));
        }
        std::vector<sim::SimSession> copies;
        {
          py::gil_scoped_release free;
          copies = h.s->fork(p, text);
        }
        py::list out;
        for (auto& c : copies) {
          auto s = wrap(h.sim, std::move(c), h.recent);
          py::list frames;
          auto all = s->s->tokens();
          const int64_t steps = int64_t(p[0].size()), S = all.size(0);
          // Replays the plan's frames through the read-back window, so each copy continues as if stepped.
          for (int64_t k = S - steps; k < S; ++k) frames.append(answer(*s, k, all[k], frame));
          out.append(py::make_tuple(s, frames));
        }
        return out;
      }, py::arg("plans"), py::arg("text") = py::none(), py::arg("frame") = true,
      R"(A planner's candidates: one copy per plan (a list of (speed, curvature) steps, all plans of one length),
each stepped along its plan in one batch; this session is unchanged. Returns [(session, [answers...]), ...].)")
      .def("reset", [](SessionHandle& h) {
        std::lock_guard<std::mutex> g(h.busy);
        h.s->reset();
        h.recent.clear();
      }, "Back to the state create() left (the same random stream again).")
      .def_property_readonly("steps", [](SessionHandle& h) { return h.s->steps(); }, "prompt + generated frames")
      .def_property_readonly("prompt_frames", [](SessionHandle& h) { return h.s->prompt_frames(); })
      .def_property_readonly("text", [](SessionHandle& h) { return h.s->text(); })
      .def_property_readonly("tokens", [](SessionHandle& h) {
        const auto& info = h.sim->world->info;
        auto t = h.s->tokens();
        return array_of(t.to(torch::kShort).view({t.size(0), info.grid_h, info.grid_w}));
      }, "int16 [steps, h, w]: every frame so far, prompt first");
}

}  // namespace gaia::python
