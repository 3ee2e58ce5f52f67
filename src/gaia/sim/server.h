#pragma once
// `gaia sim serve`: the session protocol (sim/hub.h) over HTTP on loopback, with a page at / to drive a session
// from the browser (docs/sim.md). POST /api/OP with the request as a JSON body answers as the hub does;
// GET /api/status lists the sessions. Bodies over `max_body` bytes get 413; the server reads and writes no file.
#include <memory>
#include <string>

#include "gaia/sim/hub.h"

namespace gaia::sim {

struct ServerOptions {
  std::string host = "127.0.0.1";  // loopback: nothing outside this machine reaches it unless asked
  int port = 8080;                 // 0: any free port (bind() says which)
  size_t max_body = 1 << 20;       // bytes of a request body
  int threads = 8;                 // requests answered at once
};

class SimServer {
 public:
  SimServer(SessionHub& hub, const ServerOptions& o);
  ~SimServer();
  int bind();   // listens on host:port; returns the port; fails with one line when it cannot
  void run();   // answers requests until stop()
  void stop();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The driving page served at / (keyboard, text prompt, frames, command plots, frame rate).
const std::string& driving_page();

}  // namespace gaia::sim
