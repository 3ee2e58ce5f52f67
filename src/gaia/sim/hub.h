#pragma once
// The JSON protocol of `gaia sim` (docs/sim.md): one request, one answer, the same for the stdin/stdout mode and
// the HTTP server. The hub holds the sessions of one world model, within limits: at most `max_sessions`, each
// answering one request at a time with at most `max_queue` waiting (more: 429, not a pile-up), idle ones closed
// after `idle_s`. A bad request (unknown op or field, wrong type, NaN, out of range, unknown session) is a 4xx
// with one line, and changes nothing.
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "gaia/sim/session.h"

namespace gaia::sim {

struct HubLimits {
  int max_sessions = 8;
  int max_queue = 4;       // requests that may wait while a session answers another
  double idle_s = 600;     // a session untouched this long is closed
  Precision precision = Precision::kFp32;  // not a limit: every session's products (--precision)
};

struct HubReply {
  int status = 200;        // 200; 400 bad request; 404 unknown session or op; 429 full or busy
  nlohmann::json body;     // {"error": "..."} unless 200
};

// What the app supplies: a create request's "prompt" object other than {"tokens": ..., "actions": ...} (which the
// hub reads itself) -> the prompt's tokens [P, n] and actions [P, 2] (m/s, 1/m; undefined = none), failing with one
// line on a bad one; and a frame's tokens [n] and an image format -> what a step returns as "frame" when asked (a
// data: URI of a PNG or a JPEG; null where this build cannot decode).
struct Prompt {
  torch::Tensor tokens, actions;
};
using PromptSource = std::function<Prompt(const nlohmann::json& prompt)>;
using FrameEncoder = std::function<nlohmann::json(const torch::Tensor& tokens, const std::string& format)>;  // "png" | "jpeg"
// What the frames show, read back (the dynamics probe through the tokenizer's decoder): the last `frames` steps'
// tokens [frames, n] -> {"speed": m/s, "curvature": 1/m}, added to each step's answer once there are that many.
struct ReadBack {
  int64_t frames = 0;
  std::function<nlohmann::json(const torch::Tensor& recent)> read;
};

class SessionHub {
 public:
  // `text`: the sessions' text encoder (SimSession; shared by all, so it must be thread-safe).
  SessionHub(world::WorldModel& model, const world::WorldInfo& info, const HubLimits& limits, PromptSource prompts,
             FrameEncoder frames = {}, ReadBack read_back = {}, std::shared_ptr<text::TextEncoder> text = {});
  // op: create | step | command | drive | fork | reset | close | status. "fork" with "plans" steps one copy per
  // plan as one batch (SimSession::fork) and answers each copy's frames. "command" sets a session's standing action
  // (answered at once, even while it steps) and "drive" steps it with that: continuous driving, as the stream does.
  HubReply handle(const std::string& op, const nlohmann::json& request);
  size_t sessions() const;

 private:
  struct Entry {
    std::unique_ptr<SimSession> session;
    std::mutex busy;          // one request at a time
    int pending = 0;          // requests being answered or waiting for `busy` (under the hub's lock)
    std::chrono::steady_clock::time_point used;
    Action command;                           // what "drive" steps with (op "command"; under the hub's lock)
    std::optional<std::string> command_text;  // a text prompt the next "drive" step applies
  };
  world::WorldModel& model_;
  const world::WorldInfo& info_;
  HubLimits limits_;
  PromptSource prompts_;
  FrameEncoder frames_;
  ReadBack read_back_;
  std::shared_ptr<text::TextEncoder> text_;
  mutable std::mutex lock_;  // the map and the queue counts
  std::map<int64_t, std::shared_ptr<Entry>> sessions_;
  int64_t next_id_ = 1;

  void expire();  // under lock_
  HubReply create(const nlohmann::json& r);
  HubReply with_session(const nlohmann::json& r, const std::function<HubReply(Entry&, int64_t id)>& f);
  HubReply add(std::unique_ptr<SimSession> s, nlohmann::json body);
  // Opens all of `s` or none (a 429 when they do not fit); their ids, in order, into `ids`.
  HubReply add_all(std::vector<std::unique_ptr<SimSession>> s, std::vector<int64_t>* ids);
  HubReply branch(const nlohmann::json& r);  // "fork" with "plans"
};

}  // namespace gaia::sim
