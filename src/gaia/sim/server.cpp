#include "gaia/sim/server.h"

#include <httplib.h>

#include "gaia/core/error.h"

namespace gaia::sim {

struct SimServer::Impl {
  SessionHub& hub;
  ServerOptions o;
  httplib::Server http;
  Impl(SessionHub& h, const ServerOptions& opt) : hub(h), o(opt) {}
};

namespace {
void answer(httplib::Response& res, const HubReply& r) {
  res.status = r.status;
  res.set_content(r.body.dump(), "application/json");
}
}  // namespace

SimServer::SimServer(SessionHub& hub, const ServerOptions& o) : impl_(std::make_unique<Impl>(hub, o)) {
  auto& http = impl_->http;
  const int threads = std::max(1, o.threads);
  http.new_task_queue = [threads] { return new httplib::ThreadPool(size_t(threads)); };
  http.set_payload_max_length(o.max_body);
  http.Get("/", [](const httplib::Request&, httplib::Response& res) {
    res.set_content(driving_page(), "text/html; charset=utf-8");
  });
  http.Get("/api/status", [this](const httplib::Request&, httplib::Response& res) {
    answer(res, impl_->hub.handle("status", nlohmann::json::object()));
  });
  http.Post(R"(/api/([a-z]+))", [this](const httplib::Request& req, httplib::Response& res) {
    auto body = req.body.empty() ? nlohmann::json::object() : nlohmann::json::parse(req.body, nullptr, false);
    if (body.is_discarded() || !body.is_object())
      return answer(res, {400, {{"error", "the request body must be one JSON object"}}});
    answer(res, impl_->hub.handle(req.matches[1].str(), body));
  });
  // Continuous driving: server-sent events, one per step of the session's standing command (op "command"), until
  // the client goes, the session closes, `frames` are sent, or a step fails (an "error" event, then the end).
  http.Get("/api/stream", [this](const httplib::Request& req, httplib::Response& res) {
    nlohmann::json drive = nlohmann::json::object();
    int64_t frames = 0;
    for (const auto& [k, v] : req.params) {
      if (k == "session" || k == "frames") {
        char* end = nullptr;
        const long long x = std::strtoll(v.c_str(), &end, 10);
        if (v.empty() || *end || x < 0) return answer(res, {400, {{"error", "'" + k + "' must be a whole number"}}});
        if (k == "session") drive["session"] = x;
        else frames = x;
      } else if (k == "frame" && (v == "png" || v == "jpeg")) {
        drive[k] = v;
      } else if (k == "frame" || k == "tokens") {
        if (v != "0" && v != "1" && v != "true" && v != "false")
          return answer(res, {400, {{"error", "'" + k + "' must be 1 or 0" + (k == "frame" ? ", png or jpeg" : "")}}});
        drive[k] = v == "1" || v == "true";
      } else {
        return answer(res, {400, {{"error", "unknown parameter '" + k + "' (session, frames, frame, tokens)"}}});
      }
    }
    if (!drive.contains("session")) return answer(res, {400, {{"error", "'session' must be the id create returned"}}});
    // The first step answers before the stream opens, so that a bad session is a plain 4xx.
    auto first = std::make_shared<HubReply>(impl_->hub.handle("drive", drive));
    if (first->status != 200) return answer(res, *first);
    auto sent = std::make_shared<int64_t>(0);
    res.set_header("Cache-Control", "no-cache");
    res.set_chunked_content_provider("text/event-stream", [this, drive, frames, first, sent](size_t, httplib::DataSink& sink) {
      HubReply r = first->status ? std::move(*first) : impl_->hub.handle("drive", drive);
      first->status = 0;
      const bool ok = r.status == 200;
      const std::string event = (ok ? "data: " : "event: error\ndata: ") + r.body.dump() + "\n\n";
      if (!sink.write(event.data(), event.size())) return false;  // the client went
      if (!ok || (frames > 0 && ++*sent >= frames)) sink.done();
      return true;
    });
  });
  // Whatever else goes wrong in a handler: one line, and the server goes on.
  http.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
    std::string what = "internal error";
    try {
      std::rethrow_exception(ep);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
    }
    answer(res, {500, {{"error", what.substr(0, what.find('\n'))}}});
  });
  http.set_error_handler([](const httplib::Request&, httplib::Response& res) {
    if (!res.body.empty()) return;
    const std::string what = res.status == 413 ? "the request body is too large" : res.status == 404 ? "no such path (/, /api/OP)" : "bad request";
    res.set_content(nlohmann::json({{"error", what}}).dump(), "application/json");
  });
}

SimServer::~SimServer() { stop(); }

int SimServer::bind() {
  auto& i = *impl_;
  const int port = i.o.port == 0 ? i.http.bind_to_any_port(i.o.host) : (i.http.bind_to_port(i.o.host, i.o.port) ? i.o.port : -1);
  if (port <= 0) fail("gaia sim serve: cannot listen on {}:{} (in use, or not an address of this machine)", i.o.host, i.o.port);
  return port;
}

void SimServer::run() { impl_->http.listen_after_bind(); }
void SimServer::stop() {
  if (impl_->http.is_running()) impl_->http.stop();
}

}  // namespace gaia::sim
