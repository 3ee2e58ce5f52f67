// gaia: a C++ implementation of GAIA-1 (Hu et al. 2023), a generative world model for autonomous driving.
// One binary with git-style subcommands; each file cmd_*.cpp registers one of them.
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <new>

#include <unistd.h>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/torch/tensor_io.h"

namespace {

// GAIA_DEBUG=1 lets LibTorch's backtraces and the default crash behaviour (core dumps) through.
bool debug() {
  const char* e = std::getenv("GAIA_DEBUG");
  return e && *e && std::strcmp(e, "0") != 0;
}

// The first line of a message, so that a library's multi-line text (a backtrace) never reaches the user.
std::string first_line(const std::string& m) {
  const auto nl = m.find('\n');
  std::string s = m.substr(0, nl);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\r' || s.back() == ':')) s.pop_back();
  return s;
}

// Every failure ends as one line: a gaia::Error says what the user can fix; anything else is a bug of ours, said
// as such, with the way to see more.
int report_current_exception() {
  std::string msg;
  try {
    throw;
  } catch (const gaia::Error& e) {
    std::fprintf(stderr, "gaia: error: %s\n", e.what());
    return 1;
  } catch (const std::filesystem::filesystem_error& e) {
    // A path the user gave cannot be created, read or renamed: theirs to fix, so said without "internal".
    std::fprintf(stderr, "gaia: error: %s: %s\n", e.path1().string().c_str(), e.code().message().c_str());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "gaia: error: out of memory (try a smaller batch, fewer futures or a smaller config)\n");
    return 1;
  } catch (const c10::Error& e) {
    if (debug()) std::fprintf(stderr, "%s\n", e.what());
    msg = first_line(e.what_without_backtrace());
  } catch (const std::exception& e) {
    msg = first_line(e.what());
  } catch (...) {
    msg = "unknown exception";
  }
  std::fprintf(stderr, "gaia: error: internal error: %s (a bug in gaia; GAIA_DEBUG=1 shows more)\n", msg.c_str());
  return 1;
}

// An exception that escapes where it cannot be caught (a destructor, a worker thread) still ends as one line.
[[noreturn]] void on_terminate() {
  if (std::current_exception()) {
    std::_Exit(report_current_exception());
  }
  std::fputs("gaia: error: internal error: terminated (a bug in gaia; GAIA_DEBUG=1 shows more)\n", stderr);
  std::_Exit(1);
}

extern "C" void on_fatal_signal(int sig) {
  // Only async-signal-safe calls here: write(2), then the default action (exit status and core as usual).
  const char* name = sig == SIGSEGV ? "SIGSEGV" : sig == SIGFPE ? "SIGFPE" : sig == SIGBUS ? "SIGBUS" : "SIGILL";
  char buf[160];
  int n = std::snprintf(buf, sizeof buf, "gaia: error: internal error: crashed with %s (a bug in gaia; GAIA_DEBUG=1 "
                                         "keeps the core dump)\n", name);
  if (n > 0) (void)!::write(STDERR_FILENO, buf, static_cast<size_t>(n));
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

void install_last_resort_handlers() {
  std::set_terminate(on_terminate);
  // Past a file-size limit a write fails with EFBIG (an error line naming the file) instead of killing the process.
  std::signal(SIGXFSZ, SIG_IGN);
  if (debug()) return;
  for (int sig : {SIGSEGV, SIGFPE, SIGBUS, SIGILL}) std::signal(sig, on_fatal_signal);
}

// LibTorch's OpenMP threads spin at every barrier unless OMP_WAIT_POLICY says otherwise, and beside OpenBLAS's
// threads or another process on the same cores the spinning threads take the cores from the ones with work: a run
// slows down several times over. libgomp reads the variable once, as it loads. The `gaia` launcher sets it before
// starting gaia-core; gaia-core run directly starts itself again with it set (once: the variable is then present).
// A value the user set wins.
void exec_with_passive_openmp(char** argv) {
  if (std::getenv("OMP_WAIT_POLICY")) return;
  ::setenv("OMP_WAIT_POLICY", "PASSIVE", /*overwrite=*/1);
  ::execv("/proc/self/exe", argv);  // returns only on failure: then run as we are
}

}  // namespace

int main(int argc, char** argv) {
  exec_with_passive_openmp(argv);
  install_last_resort_handlers();
  // FFmpeg's own log lines would break the "one clear error line" rule; our errors say what went wrong.
  ::setenv("OPENCV_FFMPEG_LOGLEVEL", "-8", /*overwrite=*/0);
  gaia::configure_allocator();
  for (int i = 1; i < argc; ++i) gaia::app::g_command_line += std::string(" ") + argv[i];
  gaia::app::g_args.assign(argv, argv + argc);
  CLI::App app{"gaia: generative world model for autonomous driving (GAIA-1 in C++)", "gaia"};
  app.set_version_flag("--version", std::string("gaia ") + GAIA_VERSION);
  app.require_subcommand(1);
  gaia::app::register_demo(app);
  gaia::app::register_plan(app);
  gaia::app::register_ingest(app);
  gaia::app::register_data(app);
  gaia::app::register_synth(app);
  gaia::app::register_tokenizer(app);
  gaia::app::register_world(app);
  gaia::app::register_generate(app);
  gaia::app::register_decoder(app);
  gaia::app::register_decode(app);
  gaia::app::register_probe(app);
  gaia::app::register_convert(app);
  gaia::app::register_eval(app);
  gaia::app::register_train_all(app);
  gaia::app::register_report(app);
  gaia::app::register_sim(app);
  gaia::app::register_text(app);
  gaia::app::register_scaling(app);
  gaia::app::check_numbers(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // A usage error: one line and exit status 2, whatever CLI11's own code for the kind of error.
    std::fprintf(stderr, "gaia: error: %s (see --help)\n", first_line(e.what()).c_str());
    return 2;
  } catch (...) {
    return report_current_exception();
  }
  return 0;
}
