#include "gaia/sim/hub.h"

#include <cmath>
#include <set>

#include "gaia/core/error.h"

namespace gaia::sim {

namespace {

using nlohmann::json;

HubReply error(int status, const std::string& message) { return {status, json{{"error", message}}}; }
// A 429 for `more` sessions beyond the `open` ones, where at most `max` fit.
HubReply too_many(size_t open, size_t more, int max) {
  return error(429, more == 1 ? fmt::format("{} sessions are open, the most this server takes: close one first", open)
                              : fmt::format("{} sessions are open and {} more asked for; this server takes at most {}: "
                                            "close some first", open, more, max));
}
HubReply no_session(int64_t id) { return error(404, fmt::format("no session {} (closed, expired or never created)", id)); }

// {"tokens": [[n ids] x P], "actions": [[speed m/s, curvature 1/m] x P]} (actions optional; null = unknown).
Prompt raw_prompt(const json& q, int64_t n) {
  for (const auto& [k, v] : q.items())
    if (k != "tokens" && k != "actions") fail("unknown field 'prompt.{}' next to 'prompt.tokens'", k);
  const auto& t = q.at("tokens");
  if (!t.is_array() || t.size() > 64) fail("'prompt.tokens' must be a list of at most 64 frames of {} ids", n);
  Prompt p;
  p.tokens = torch::empty({int64_t(t.size()), n}, torch::kLong);
  for (size_t i = 0; i < t.size(); ++i) {
    if (!t[i].is_array() || int64_t(t[i].size()) != n) fail("'prompt.tokens[{}]' must be a list of {} ids", i, n);
    for (size_t j = 0; j < t[i].size(); ++j) {
      if (!t[i][j].is_number_integer()) fail("'prompt.tokens[{}][{}]' must be a whole number", i, j);
      p.tokens[int64_t(i)][int64_t(j)] = t[i][j].get<int64_t>();
    }
  }
  if (q.contains("actions")) {
    const auto& a = q.at("actions");
    if (!a.is_array() || a.size() != t.size()) fail("'prompt.actions' must be one [speed, curvature] per frame");
    p.actions = torch::empty({int64_t(a.size()), 2});
    for (size_t i = 0; i < a.size(); ++i) {
      if (!a[i].is_array() || a[i].size() != 2) fail("'prompt.actions[{}]' must be [speed, curvature]", i);
      for (size_t j = 0; j < 2; ++j) {
        const auto& x = a[i][j];
        if (!x.is_null() && !x.is_number()) fail("'prompt.actions[{}][{}]' must be a number or null", i, j);
        p.actions[int64_t(i)][int64_t(j)] = x.is_null() ? std::numeric_limits<double>::quiet_NaN() : x.get<double>();
      }
      check_action({p.actions[int64_t(i)][0].item<double>(), p.actions[int64_t(i)][1].item<double>()});
    }
  }
  return p;
}

// The request's fields, each checked by name: only `allowed` keys, the right types, numbers finite and in range.
struct Fields {
  const json& r;
  void only(const std::set<std::string>& allowed) const {
    if (!r.is_object()) fail("a request must be a JSON object");
    for (const auto& [k, v] : r.items())
      if (!allowed.count(k)) fail("unknown field '{}'", k);
  }
  bool has(const char* k) const { return r.contains(k) && !r.at(k).is_null(); }
  double number(const char* k, double lo, double hi, double fallback) const {
    if (!has(k)) return fallback;
    const auto& v = r.at(k);
    if (!v.is_number()) fail("'{}' must be a number", k);
    const double x = v.get<double>();
    if (!std::isfinite(x) || x < lo || x > hi) fail("'{}' must be in [{}, {}], got {}", k, lo, hi, x);
    return x;
  }
  int64_t integer(const char* k, int64_t lo, int64_t hi, int64_t fallback) const {
    if (!has(k)) return fallback;
    const auto& v = r.at(k);
    if (!v.is_number_integer()) fail("'{}' must be a whole number", k);
    const auto x = v.get<int64_t>();
    if (x < lo || x > hi) fail("'{}' must be in [{}, {}], got {}", k, lo, hi, x);
    return x;
  }
  std::string text(const char* k, const std::string& fallback, size_t max_len = 200) const {
    if (!has(k)) return fallback;
    if (!r.at(k).is_string()) fail("'{}' must be a string", k);
    auto s = r.at(k).get<std::string>();
    if (s.size() > max_len) fail("'{}' is longer than {} characters", k, max_len);
    return s;
  }
  bool flag(const char* k, bool fallback) const {
    if (!has(k)) return fallback;
    if (!r.at(k).is_boolean()) fail("'{}' must be true or false", k);
    return r.at(k).get<bool>();
  }
  // "frame": true or "png" (lossless), "jpeg" (smaller, lossy), false or none ("")
  std::string frame_format() const {
    if (has("frame") && r.at("frame").is_string()) {
      auto f = r.at("frame").get<std::string>();
      if (f != "png" && f != "jpeg") fail("'frame' must be true, false, \"png\" or \"jpeg\"");
      return f;
    }
    if (has("frame") && !r.at("frame").is_boolean()) fail("'frame' must be true, false, \"png\" or \"jpeg\"");
    return flag("frame", false) ? "png" : "";
  }
};

json ids_of(const torch::Tensor& tokens) {  // [n] -> a list of ids
  auto t = tokens.contiguous();
  return std::vector<int64_t>(t.data_ptr<int64_t>(), t.data_ptr<int64_t>() + t.numel());
}

// "plans": [[[speed, curvature] x steps] x branches] (null: no command), at most 16 branches of 64 steps.
std::vector<std::vector<Action>> plans_of(const json& p) {
  if (!p.is_array() || p.empty() || p.size() > 16) fail("'plans' must be a list of 1 to 16 plans");
  std::vector<std::vector<Action>> plans;
  for (size_t i = 0; i < p.size(); ++i) {
    if (!p[i].is_array() || p[i].empty() || p[i].size() > 64)
      fail("'plans[{}]' must be a list of 1 to 64 [speed, curvature] steps", i);
    plans.emplace_back();
    for (size_t j = 0; j < p[i].size(); ++j) {
      const auto& a = p[i][j];
      if (!a.is_array() || a.size() != 2) fail("'plans[{}][{}]' must be [speed, curvature]", i, j);
      double v[2];
      for (size_t k = 0; k < 2; ++k) {
        if (!a[k].is_null() && !a[k].is_number()) fail("'plans[{}][{}][{}]' must be a number or null", i, j, k);
        v[k] = a[k].is_null() ? std::numeric_limits<double>::quiet_NaN() : a[k].get<double>();
      }
      plans.back().push_back({v[0], v[1]});
      try {
        check_action(plans.back().back());
      } catch (const std::exception& e) {
        fail("'plans[{}][{}]': {}", i, j, e.what());
      }
    }
  }
  return plans;
}

}  // namespace

SessionHub::SessionHub(world::WorldModel& model, const world::WorldInfo& info, const HubLimits& limits,
                       PromptSource prompts, FrameEncoder frames, ReadBack read_back,
                       std::shared_ptr<text::TextEncoder> text)
    : model_(model), info_(info), limits_(limits), prompts_(std::move(prompts)), frames_(std::move(frames)),
      read_back_(std::move(read_back)), text_(std::move(text)) {}

size_t SessionHub::sessions() const {
  std::lock_guard<std::mutex> g(lock_);
  return sessions_.size();
}

void SessionHub::expire() {
  const auto now = std::chrono::steady_clock::now();
  for (auto it = sessions_.begin(); it != sessions_.end();) {
    const bool idle = std::chrono::duration<double>(now - it->second->used).count() > limits_.idle_s;
    it = idle && it->second->pending == 0 ? sessions_.erase(it) : std::next(it);
  }
}

HubReply SessionHub::add_all(std::vector<std::unique_ptr<SimSession>> s, std::vector<int64_t>* ids) {
  std::lock_guard<std::mutex> g(lock_);
  expire();
  if (int(sessions_.size() + s.size()) > limits_.max_sessions)
    return too_many(sessions_.size(), s.size(), limits_.max_sessions);
  for (auto& session : s) {
    auto e = std::make_shared<Entry>();
    e->session = std::move(session);
    e->used = std::chrono::steady_clock::now();
    ids->push_back(next_id_++);
    sessions_[ids->back()] = e;
  }
  return {200, json::object()};
}

HubReply SessionHub::add(std::unique_ptr<SimSession> s, json body) {
  const int64_t steps = s->steps();
  std::vector<std::unique_ptr<SimSession>> one;
  one.push_back(std::move(s));
  std::vector<int64_t> ids;
  auto reply = add_all(std::move(one), &ids);
  if (reply.status != 200) return reply;
  body["session"] = ids[0];
  body["steps"] = steps;
  return {200, body};
}

HubReply SessionHub::create(const json& r) {
  Fields f{r};
  f.only({"prompt", "text", "seed", "guidance", "sampling", "top_k", "temperature", "window_stride",
          "action_negative"});
  SessionSettings s;
  s.seed = uint64_t(f.integer("seed", 0, int64_t(1) << 53, 0));
  s.guidance_scale = f.number("guidance", 0, 100, -1);
  s.sampling = f.text("sampling", "top-k");
  s.top_k = int(f.integer("top_k", 1, 1 << 20, -1));
  s.temperature = f.number("temperature", 1e-3, 100, -1);
  s.window_stride = int(f.integer("window_stride", 1, 1 << 20, 1));
  s.precision = limits_.precision;
  const auto negative = f.text("action_negative", "mirror");
  if (negative != "mirror" && negative != "turn" && negative != "null")
    fail("'action_negative' must be \"mirror\", \"turn\" or \"null\"");
  s.mirror_negative = negative != "null";
  s.negative_keeps_speed = negative == "turn";
  Prompt p;
  if (f.has("prompt")) {
    const auto& q = r.at("prompt");
    if (!q.is_object()) fail("'prompt' must be an object");
    if (q.contains("tokens")) p = raw_prompt(q, model_->layout.n);
    else if (prompts_) p = prompts_(q);
    else fail("this server has no token dataset to take a prompt from: give the prompt's \"tokens\"");
  }
  auto session = std::make_unique<SimSession>(model_, info_, s, text_);
  session->start(p.tokens, p.actions, f.text("text", ""));
  json body{{"prompt_frames", session->prompt_frames()}};
  return add(std::move(session), body);
}

HubReply SessionHub::with_session(const json& r, const std::function<HubReply(Entry&, int64_t)>& f) {
  if (!r.is_object() || !r.contains("session") || !r.at("session").is_number_integer())
    fail("'session' must be the id create returned");
  const auto id = r.at("session").get<int64_t>();
  std::shared_ptr<Entry> e;
  {
    std::lock_guard<std::mutex> g(lock_);
    expire();
    auto it = sessions_.find(id);
    if (it == sessions_.end()) return no_session(id);
    e = it->second;
    if (e->pending > limits_.max_queue)
      return error(429, fmt::format("session {} is busy with {} request(s) waiting: wait for their answers", id,
                                    e->pending - 1));
    ++e->pending;
  }
  struct Done {  // whatever happens: one request fewer, and the session was used now
    SessionHub& hub;
    Entry& e;
    ~Done() {
      std::lock_guard<std::mutex> g(hub.lock_);
      --e.pending;
      e.used = std::chrono::steady_clock::now();
    }
  } done{*this, *e};
  std::lock_guard<std::mutex> busy(e->busy);
  return f(*e, id);
}

HubReply SessionHub::branch(const json& r) {
  Fields f{r};
  f.only({"session", "plans", "text", "open", "frame", "tokens"});
  const auto plans = plans_of(r.at("plans"));
  std::optional<std::string> text;
  if (f.has("text")) text = f.text("text", "");
  const bool open = f.flag("open", true), want_tokens = f.flag("tokens", true);
  const std::string frame_format = f.frame_format();
  if (open) {  // fail early, before the work; add_all checks again
    std::lock_guard<std::mutex> g(lock_);
    if (int(sessions_.size() + plans.size()) > limits_.max_sessions)
      return too_many(sessions_.size(), plans.size(), limits_.max_sessions);
  }
  std::vector<SimSession> branches;
  json body{{"branches", json::array()}};
  auto reply = with_session(r, [&](Entry& e, int64_t id) {
    body["forked_from"] = id;
    const auto t0 = std::chrono::steady_clock::now();
    branches = e.session->fork(plans, text);
    body["ms"] = 1000 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return HubReply{200, json::object()};
  });
  if (reply.status != 200) return reply;
  const int64_t h = int64_t(plans[0].size()), K = read_back_.frames;
  for (auto& b : branches) {
    const auto all = b.tokens();  // [steps, n]
    json one{{"steps", b.steps()}};
    if (want_tokens) {
      one["tokens"] = json::array();
      for (int64_t j = all.size(0) - h; j < all.size(0); ++j) one["tokens"].push_back(ids_of(all[j]));
    }
    if (!frame_format.empty()) one["frame"] = frames_ ? frames_(all[all.size(0) - 1], frame_format) : json(nullptr);
    if (read_back_.read && K > 0 && all.size(0) >= K) one["read_back"] = read_back_.read(all.narrow(0, all.size(0) - K, K));
    body["branches"].push_back(one);
  }
  if (open) {
    std::vector<std::unique_ptr<SimSession>> s;
    for (auto& b : branches) s.push_back(std::make_unique<SimSession>(std::move(b)));
    std::vector<int64_t> ids;
    auto added = add_all(std::move(s), &ids);
    if (added.status != 200) return added;
    for (size_t i = 0; i < ids.size(); ++i) body["branches"][i]["session"] = ids[i];
  }
  return {200, body};
}

HubReply SessionHub::handle(const std::string& op, const json& r) {
  try {
    if (op == "create") return create(r);
    if (op == "status") {
      std::lock_guard<std::mutex> g(lock_);
      expire();
      json list = json::array();
      const auto now = std::chrono::steady_clock::now();
      for (const auto& [id, e] : sessions_)
        list.push_back({{"session", id}, {"idle_s", std::chrono::duration<double>(now - e->used).count()}});
      return {200, json{{"sessions", list}, {"max_sessions", limits_.max_sessions}}};
    }
    if (op == "step" || op == "drive")
      return with_session(r, [&](Entry& e, int64_t id) {
        Fields f{r};
        Action a;
        std::optional<std::string> text;
        if (op == "step") {
          f.only({"session", "speed", "curvature", "text", "frame", "tokens"});
          const double nan = std::numeric_limits<double>::quiet_NaN();
          a = {f.number("speed", 0, kMaxSpeed, nan), f.number("curvature", -kMaxCurvature, kMaxCurvature, nan)};
          if (f.has("text")) text = f.text("text", "");
        } else {  // the session's standing command (op "command"); a new text applies once
          f.only({"session", "frame", "tokens"});
          std::lock_guard<std::mutex> g(lock_);
          a = e.command;
          text = std::move(e.command_text);
          e.command_text.reset();
        }
        const std::string frame_format = f.frame_format();
        const bool want_tokens = f.flag("tokens", true);
        const auto t0 = std::chrono::steady_clock::now();
        auto tokens = e.session->step(a, text);
        json body{{"session", id}, {"step", e.session->steps() - 1}, {"text", e.session->text()}};
        if (op == "drive") body["command"] = {{"speed", a.speed}, {"curvature", a.curvature}};
        if (want_tokens) body["tokens"] = ids_of(tokens);
        if (!frame_format.empty()) body["frame"] = frames_ ? frames_(tokens, frame_format) : json(nullptr);
        const int64_t K = read_back_.frames, steps = e.session->steps();
        if (read_back_.read && K > 0 && steps >= K) body["read_back"] = read_back_.read(e.session->tokens().narrow(0, steps - K, K));
        body["ms"] = 1000 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        return HubReply{200, body};
      });
    if (op == "command") {  // answered at once, even while the session steps: the next "drive" step takes it
      Fields f{r};
      f.only({"session", "speed", "curvature", "text"});
      if (!r.contains("session") || !r.at("session").is_number_integer()) fail("'session' must be the id create returned");
      const auto id = r.at("session").get<int64_t>();
      const double nan = std::numeric_limits<double>::quiet_NaN();
      const Action a{f.number("speed", 0, kMaxSpeed, nan), f.number("curvature", -kMaxCurvature, kMaxCurvature, nan)};
      std::optional<std::string> text;
      if (f.has("text")) text = f.text("text", "");
      std::lock_guard<std::mutex> g(lock_);
      auto it = sessions_.find(id);
      if (it == sessions_.end()) return no_session(id);
      it->second->command = a;
      if (text) it->second->command_text = text;
      it->second->used = std::chrono::steady_clock::now();
      return {200, json{{"session", id}, {"command", {{"speed", a.speed}, {"curvature", a.curvature}}}}};
    }
    if (op == "fork" && r.is_object() && r.contains("plans")) return branch(r);
    if (op == "fork") {
      std::unique_ptr<SimSession> copy;
      auto r1 = with_session(r, [&](Entry& e, int64_t) {
        Fields{r}.only({"session"});
        copy = std::make_unique<SimSession>(e.session->fork());
        return HubReply{};
      });
      if (!copy) return r1;
      return add(std::move(copy), json{{"forked_from", r.at("session")}});
    }
    if (op == "reset")
      return with_session(r, [&](Entry& e, int64_t id) {
        Fields{r}.only({"session"});
        e.session->reset();
        return HubReply{200, json{{"session", id}, {"steps", e.session->steps()}}};
      });
    if (op == "close") {
      Fields{r}.only({"session"});
      auto reply = with_session(r, [&](Entry&, int64_t id) { return HubReply{200, json{{"closed", id}}}; });
      if (reply.status == 200) {
        std::lock_guard<std::mutex> g(lock_);
        sessions_.erase(r.at("session").get<int64_t>());
      }
      return reply;
    }
    return error(404, fmt::format("unknown request '{}' (create, step, command, drive, fork, reset, close, status)", op));
  } catch (const std::exception& e) {
    std::string m = e.what();
    return error(400, m.substr(0, m.find('\n')));
  }
}

}  // namespace gaia::sim
