// gaia.Tokenizer, gaia.WorldModel and gaia.VideoDecoder: thin wrappers over the library calls the CLI makes.
#include <optional>

#include <pybind11/stl.h>

#include "arrays.h"
#include "gaia/core/error.h"
#include "gaia/decoder/pipeline.h"
#include "gaia/tokenizer/io.h"
#include "gaia/torch/tensor_io.h"
#include "gaia/world/evaluate.h"
#include "gaia/world/generate.h"
#include "gaia/world/prompt_text.h"
#include "handles.h"

namespace gaia::python {

std::shared_ptr<text::TextEncoder> WorldHandle::text() {
  std::lock_guard<std::mutex> g(lock_);
  if (!text_) text_ = world::prompt_encoder(info, path, t5, dev);
  return text_;
}

Precision precision_arg(const std::string& s, const torch::Device& dev) {
  return precision_for(s, dev, [](const std::string& note) {
    PyErr_WarnEx(PyExc_RuntimeWarning, ("precision: " + note).c_str(), 1);
  });
}

std::shared_ptr<TokenizerHandle> load_tokenizer_handle(const std::string& path, const std::string& device) {
  require_path(path, "tokenizer");
  auto h = std::make_shared<TokenizerHandle>();
  h->dev = parse_device(device);
  h->tok = tokenizer::load_tokenizer(path, h->dev, &h->config);
  h->path = path;
  return h;
}

std::shared_ptr<WorldHandle> load_world_handle(const std::string& path, const std::string& device,
                                               const std::string& t5) {
  require_path(path, "world model");
  if (!t5.empty()) require_path(t5, "t5");
  auto h = std::make_shared<WorldHandle>();
  h->dev = parse_device(device);
  h->model = world::load_world(path, h->dev, &h->info);
  h->path = path;
  h->t5 = t5;
  return h;
}

namespace {

// Token ids [N, h, w] or [N, n] of this grid -> int64 [N, n].
torch::Tensor token_rows(const py::array& a, int64_t h, int64_t w, const std::string& what) {
  auto t = view_of(a, Kind::kTokens, {{-1, h, w}, {-1, h * w}}, what);
  return t.to(torch::kLong).reshape({t.size(0), h * w});
}

// Speed and curvature a row [S, 2] (m/s, 1/m; NaN unknown) as float32.
torch::Tensor action_rows(const py::array& a, int64_t rows, const std::string& what) {
  return view_of(a, Kind::kSignals, {rows, 2}, what).to(torch::kFloat);
}

}  // namespace

void bind_models(py::module_& m) {
  py::class_<TokenizerHandle, std::shared_ptr<TokenizerHandle>>(m, "Tokenizer", R"(The image tokenizer (§2.2).

Tokenizer(path, device="cpu"): frames (RGB uint8 [N, H, W, 3]) <-> tokens (int16 [N, h, w]).)")
      .def(py::init(&load_tokenizer_handle), py::arg("path"), py::arg("device") = "cpu")
      .def_property_readonly("grid", [](const TokenizerHandle& h) {
        return py::make_tuple(h.tok->height / h.tok->cfg.downsample, h.tok->width / h.tok->cfg.downsample); })
      .def_property_readonly("frame_size", [](const TokenizerHandle& h) { return py::make_tuple(h.tok->height, h.tok->width); })
      .def_property_readonly("K", [](const TokenizerHandle& h) { return h.tok->cfg.codebook_size; }, "codebook size")
      .def_property_readonly("path", [](const TokenizerHandle& h) { return h.path; })
      .def("encode", [](TokenizerHandle& h, const py::array& frames) {
        const bool one = frames.ndim() == 3;
        auto x = view_of(frames, Kind::kFrames, {{-1, h.tok->height, h.tok->width, 3}, {h.tok->height, h.tok->width, 3}},
                         "frames");
        torch::Tensor z;
        {
          py::gil_scoped_release free;
          z = tokenizer::encode_rgb(h.tok, one ? x.unsqueeze(0) : x, h.dev).to(torch::kShort);
        }
        return array_of(one ? z[0] : z);
      }, py::arg("frames"), "RGB uint8 frames [N, H, W, 3] (or one [H, W, 3]) -> int16 tokens [N, h, w] (or [h, w])")
      .def("decode", [](TokenizerHandle& h, const py::array& tokens) {
        const int64_t gh = h.tok->height / h.tok->cfg.downsample, gw = h.tok->width / h.tok->cfg.downsample;
        const bool one = tokens.ndim() == 2 && tokens.shape(0) == gh && tokens.shape(1) == gw;
        auto z = view_of(tokens, Kind::kTokens, {{-1, gh, gw}, {gh, gw}}, "tokens").to(torch::kLong);
        if (one) z = z.unsqueeze(0);
        const auto hi = z.numel() ? z.max().item<int64_t>() : 0, lo = z.numel() ? z.min().item<int64_t>() : 0;
        if (lo < 0 || hi >= h.tok->cfg.codebook_size)
          throw py::value_error(fmt::format("tokens: ids in [0, {}) expected, got {}..{}", h.tok->cfg.codebook_size, lo, hi));
        torch::Tensor x;
        {
          py::gil_scoped_release free;
          x = tokenizer::decode_rgb(h.tok, z, h.dev);
        }
        return array_of(one ? x[0] : x);
      }, py::arg("tokens"), "int16 tokens [N, h, w] (or one [h, w]) -> RGB uint8 frames [N, H, W, 3] (or [H, W, 3])")
      .def("encode_video", [](TokenizerHandle& h, const std::string& path, int64_t frames) {
        require_path(path, "video");
        if (frames < 1) throw py::value_error(fmt::format("frames: at least 1 expected, got {}", frames));
        const int64_t gh = h.tok->height / h.tok->cfg.downsample, gw = h.tok->width / h.tok->cfg.downsample;
        torch::Tensor z;
        {
          py::gil_scoped_release free;
          z = tokenizer::video_prompt_tokens(h.tok, h.config, path, frames, gh * gw, h.dev);
        }
        return array_of(z.to(torch::kShort).view({z.size(0), gh, gw}));
      }, py::arg("path"), py::arg("frames") = 4,
      "A video file as a prompt, as `gaia generate --video` reads it: up to `frames` frames at the world-model rate "
      "(6.25 Hz), resized and encoded -> int16 tokens [frames, h, w]");

  py::class_<WorldHandle, std::shared_ptr<WorldHandle>>(m, "WorldModel", R"(The world model (§2.3).

WorldModel(path, device="cpu", t5=None): rollouts as `gaia generate` makes them, and bits per token.
t5: the T5 folder of a world model trained on T5 embeddings (needed for its text prompts).)")
      .def(py::init(&load_world_handle), py::arg("path"), py::arg("device") = "cpu", py::arg("t5") = "")
      .def_property_readonly("grid", [](const WorldHandle& h) { return py::make_tuple(h.info.grid_h, h.info.grid_w); })
      .def_property_readonly("K", [](const WorldHandle& h) { return h.info.K; }, "codebook size")
      .def_property_readonly("context", [](const WorldHandle& h) { return h.model->layout.T; }, "steps in the context, T")
      .def_property_readonly("rate_hz", [](const WorldHandle& h) { return h.info.config.data.world_fps; })
      .def_property_readonly("path", [](const WorldHandle& h) { return h.path; })
      .def("rollout", [](WorldHandle& h, std::optional<py::array> prompt, std::optional<py::array> prompt_actions,
                         std::optional<py::array> actions, std::optional<std::string> steer, std::optional<double> speed,
                         const std::string& text, const std::string& negative, int frames, int futures,
                         const std::string& sampling, std::optional<int> top_k, double top_p,
                         std::optional<double> temperature, std::optional<double> guidance,
                         const std::string& action_negative, const std::string& guidance_tokens,
                         const std::string& guidance_frames, int plateau, int window_stride, uint64_t seed,
                         const std::string& precision) {
        const auto gh = h.info.grid_h, gw = h.info.grid_w;
        world::GenerateRequest r;
        if (prompt) r.prompt_tokens = token_rows(*prompt, gh, gw, "prompt");
        const int64_t P = r.prompt_tokens.defined() ? r.prompt_tokens.size(0) : 0;
        if (prompt_actions) {
          if (!prompt) throw py::value_error("prompt_actions: given without a prompt");
          r.prompt_actions = action_rows(*prompt_actions, P, "prompt_actions");
        }
        if (frames < 1) throw py::value_error(fmt::format("frames: at least 1 expected, got {}", frames));
        if (actions && (steer || speed)) throw py::value_error("actions: give actions, or steer / speed, not both");
        if (actions) r.actions = action_rows(*actions, frames, "actions");
        if (speed && !(*speed >= 0 && *speed <= 100))
          throw py::value_error(fmt::format("speed: [0, 100] m/s expected, got {}", *speed));
        if (steer || speed)
          r.actions = world::steer_actions(steer ? *steer : "none", speed ? *speed : -1, r.prompt_actions, frames);
        if (action_negative != "mirror" && action_negative != "null")
          throw py::value_error("action_negative: \"mirror\" or \"null\" expected, got \"" + action_negative + "\"");
        r.mirror_negative = action_negative == "mirror";
        r.text = text;
        r.negative = negative;
        auto& o = r.options;
        o = world::default_options(h.info);
        o.frames = frames;
        o.futures = futures;
        o.window_stride = window_stride;
        o.seed = seed;
        o.sampling.strategy = world::parse_strategy(sampling);
        if (top_k) o.sampling.top_k = *top_k;
        o.sampling.top_p = top_p;
        if (temperature) o.sampling.temperature = *temperature;
        if (guidance) o.guidance.scale = *guidance;
        o.guidance.tokens = world::parse_token_schedule(guidance_tokens);
        o.guidance.frames = world::parse_frame_schedule(guidance_frames);
        o.guidance.plateau = plateau;
        o.precision = precision_arg(precision, h.dev);
        std::shared_ptr<text::TextEncoder> enc;
        if (!text.empty() || !negative.empty()) enc = h.text();
        world::GenerateResult out;
        {
          py::gil_scoped_release free;
          out = world::generate(h.model, h.info, h.path, r, enc);
        }
        return array_of(out.tokens.view({futures, out.tokens.size(1), gh, gw}).to(torch::kShort));
      },
      py::arg("prompt") = py::none(), py::arg("prompt_actions") = py::none(), py::arg("actions") = py::none(),
      py::arg("steer") = py::none(), py::arg("speed") = py::none(), py::arg("text") = "", py::arg("negative") = "",
      py::arg("frames") = 8, py::arg("futures") = 1, py::arg("sampling") = "top-k", py::arg("top_k") = py::none(),
      py::arg("top_p") = 0.9, py::arg("temperature") = py::none(), py::arg("guidance") = py::none(),
      py::arg("action_negative") = "mirror", py::arg("guidance_tokens") = "constant",
      py::arg("guidance_frames") = "constant", py::arg("plateau") = 0, py::arg("window_stride") = 1,
      py::arg("seed") = 0, py::arg("precision") = "fp32",
      R"(Futures of a video prompt, as `gaia generate` rolls them out (the same seed and options, the same tokens).

prompt: int16 tokens [P, h, w]; prompt_actions: float32 [P, 2] (speed m/s, curvature 1/m, NaN unknown);
actions: float32 [frames, 2] commands, or steer ("left", "right", "strong-left", "strong-right", "straight")
and/or speed (m/s); text / negative: prompts; precision: "fp32" or "bf16" (--precision). Returns int16 tokens
[futures, P + frames, h, w].)")
      .def("bits_per_token", [](WorldHandle& h, const py::array& tokens, std::optional<py::array> actions) {
        auto z = token_rows(tokens, h.info.grid_h, h.info.grid_w, "tokens");
        torch::Tensor a;
        if (actions) a = action_rows(*actions, z.size(0), "actions");
        py::gil_scoped_release free;
        return world::score_tokens(h.model, h.info, z, a).bits();
      }, py::arg("tokens"), py::arg("actions") = py::none(),
      "Mean bits per image token of tokens [S, h, w] under the model (windows of its context, action-conditioned "
      "on actions [S, 2] where given), as `gaia world eval` scores.");

  struct VideoDecoderHandle {
    std::string path;
    std::shared_ptr<TokenizerHandle> tok;
  };
  py::class_<VideoDecoderHandle>(m, "VideoDecoder", R"(The video diffusion decoder (§2.4).

VideoDecoder(path, tokenizer): tokens -> video, as `gaia decode` makes it.)")
      .def(py::init([](const std::string& path, std::shared_ptr<TokenizerHandle> tok) {
        require_path(path, "video decoder");
        if (!tok) throw py::value_error("tokenizer: a gaia.Tokenizer expected");
        return VideoDecoderHandle{path, tok};
      }), py::arg("path"), py::arg("tokenizer"))
      .def("decode", [](VideoDecoderHandle& v, const py::array& tokens, int ddim_steps, double fps, double token_fps,
                        uint64_t seed, const std::string& precision) {
        auto& t = *v.tok;
        const Precision p = precision_arg(precision, t.dev);
        const int64_t gh = t.tok->height / t.tok->cfg.downsample, gw = t.tok->width / t.tok->cfg.downsample;
        const bool one = tokens.ndim() == 3;
        auto z = view_of(tokens, Kind::kTokens, {{-1, gh, gw}, {-1, -1, gh, gw}}, "tokens").to(torch::kLong);
        if (one) z = z.unsqueeze(0);
        if (fps != token_fps && fps != 2 * token_fps && fps != 4 * token_fps)
          throw py::value_error(fmt::format("fps: {}, {} or {} expected (the token rate times 1, 2 or 4), got {}",
                                            token_fps, 2 * token_fps, 4 * token_fps, fps));
        torch::Tensor video;
        {
          py::gil_scoped_release free;
          auto coarse = decoder::coarse_frames(t.tok, z, t.dev);
          video = decoder::diffusion_decode(t.tok, v.path, z, coarse, ddim_steps, token_fps, fps, seed, t.dev, {}, {}, p);
        }
        auto rgb = video.clamp(-1, 1).add(1).mul(127.5).round().to(torch::kUInt8).permute({0, 1, 3, 4, 2});
        return array_of(one ? rgb[0] : rgb);
      }, py::arg("tokens"), py::arg("ddim_steps") = 0, py::arg("fps") = 25.0, py::arg("token_fps") = 6.25,
      py::arg("seed") = 0, py::arg("precision") = "fp32",
      "int16 tokens [N, h, w] (or [F, N, h, w] futures) at token_fps -> RGB uint8 video [M, H, W, 3] (or [F, M, "
      "H, W, 3]) at fps (6.25, 12.5 or 25: temporal upsampling, §5.2); ddim_steps <= 0: the decoder's own; "
      "precision \"bf16\" as `gaia decode --precision bf16`.");
}

}  // namespace gaia::python
