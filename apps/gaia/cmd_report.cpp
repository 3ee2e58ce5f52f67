// gaia report: one self-contained HTML page (videos, plots, tables, the commands) from RUN_DIR/report.json.
#include <cstdio>

#include "common.h"
#include "gaia/core/error.h"
#include "gaia/report/report.h"

namespace gaia::app {

void register_report(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "report", "render RUN_DIR/report.json (written by gaia eval / gaia demo) as one self-contained HTML page");
  cmd->footer(
      "Every video, image and plot is embedded (data: URIs, inline SVG), so the page works offline and can be\n"
      "mailed or archived as one file. Manifest format: src/gaia/report/report.h.");
  auto flags = std::make_shared<SharedFlags>();
  auto run_dir = std::make_shared<std::string>();
  cmd->add_option("RUN_DIR", *run_dir, "run directory holding report.json (paths in it are relative to RUN_DIR)")
      ->required();
  add_shared_flags(cmd, flags.get(), "output HTML file (default: RUN_DIR/report.html)", WithPrecision::kNo);
  cmd->callback([=] {
    resolve_config(*flags);  // no config is used, but a bad --set or --config must still be an error
    const fs::path out = flags->out.empty() ? fs::path(*run_dir) / "report.html" : fs::path(flags->out);
    report::write_report(*run_dir, out);
    std::printf("%s -> %s (%.1f MB)\n", (fs::path(*run_dir) / "report.json").c_str(), out.c_str(),
                static_cast<double>(fs::file_size(out)) / 1e6);
  });
}

}  // namespace gaia::app
