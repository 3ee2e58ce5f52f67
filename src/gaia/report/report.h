#pragma once
// `gaia report`: turns RUN_DIR/report.json (a manifest written by gaia eval / gaia demo, or by hand) into ONE
// self-contained HTML page: every image, video and plot is embedded (data: URIs, inline SVG), so the file can be
// mailed, archived or opened offline and still shows everything. No LibTorch here (part of gaia_base).
//
// Manifest (paths relative to RUN_DIR; every key except "title" and "sections" optional; unknown keys are errors,
// so a typo does not silently drop content):
//   {"title": "...", "subtitle": "...",
//    "sections": [{"title": "...", "text": "plain text",
//                  "videos":  [{"caption": "...", "items": [{"label": "...", "path": "a.gif|a.mp4|a.png"}]}],
//                  "plots":   [{"caption": "...", "path": "p.svg"}],          // SVG inlined; PNG/JPEG/GIF embedded
//                  "images":  [{"caption": "...", "path": "sheet.png"}],
//                  "tables":  [{"caption": "...", "columns": ["a", "b"], "rows": [["x", 0.93]]}],
//                  "metrics": {"any": {"nested": 1.2}},                     // flattened to "any.nested" | 1.2
//                  "curves":  [{"caption": "...", "path": "metrics.jsonl", "keys": ["loss", "val.bpt"]}],
//                  "commands": ["gaia ..."]}]}
// Every problem (missing manifest, wrong type, missing file) throws gaia::Error with one line naming the manifest
// and the field, e.g. "run/report.json: sections[1].videos[0].items[2].path: videos/f3.mp4 does not exist".
#include <string>
#include <string_view>

#include "gaia/core/fs.h"

namespace gaia::report {

// The HTML page for RUN_DIR/report.json.
std::string render_report(const fs::path& run_dir);

// render_report, then written atomically to `out` (nothing is written if rendering fails).
void write_report(const fs::path& run_dir, const fs::path& out);

// Standard base64 (RFC 4648, with '=' padding), for data: URIs.
std::string base64_encode(std::string_view bytes);

// Numbers for people: integral values as integers, large ones without exponent, others to 4 significant digits.
std::string format_number(double v);

}  // namespace gaia::report
