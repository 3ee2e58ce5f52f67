#include "gaia/report/report.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <utility>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "gaia/core/error.h"
#include "gaia/eval/svg_plot.h"

namespace gaia::report {

namespace {

// ordered_json keeps keys in the order the manifest wrote them: metric tables read the way their author meant.
using Json = nlohmann::ordered_json;
using eval::xml_escape;

// Curves with more points than this are thinned (every k-th point, plus the last): a long training log would
// otherwise make a multi-megabyte polyline that looks no different on screen.
constexpr size_t kMaxCurvePoints = 2000;

const char* kStyle = R"css(
:root { --fg: #1d2330; --muted: #5b6475; --bg: #f4f5f7; --ink: #1c2029; --line: #e2e5ea; --accent: #3b6fd8; }
* { box-sizing: border-box; }
body { margin: 0; background: var(--bg); color: var(--fg);
       font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
header { background: var(--ink); color: #f2f3f5; padding: 28px 40px 24px; }
header h1 { margin: 0; font-size: 28px; font-weight: 600; letter-spacing: .2px; }
header p { margin: 6px 0 0; color: #aab2c0; }
main { max-width: 1400px; margin: 0 auto; padding: 4px 32px 32px; }
nav.toc { background: #fff; border-radius: 10px; padding: 12px 24px; margin: 20px 0;
          box-shadow: 0 1px 3px rgba(0,0,0,.08); }
nav.toc h2 { font-size: 15px; margin: 0 0 4px; color: var(--muted); text-transform: uppercase; letter-spacing: .6px; }
nav.toc ol { margin: 0; padding-left: 22px; columns: 2; }
a { color: var(--accent); text-decoration: none; }
a:hover { text-decoration: underline; }
section { background: #fff; border-radius: 10px; box-shadow: 0 1px 3px rgba(0,0,0,.08); padding: 18px 24px 8px;
          margin: 20px 0; }
section h2 { margin: 0 0 10px; font-size: 20px; font-weight: 600; }
.text { white-space: pre-line; max-width: 85ch; margin: 0 0 14px; }
.block { margin: 0 0 18px; }
.caption { color: var(--muted); font-size: 13px; margin: 6px 0 0; }
.videos { display: flex; flex-wrap: wrap; gap: 12px; background: var(--ink); padding: 12px; border-radius: 8px; }
.card { margin: 0; background: #2a2f3a; border-radius: 6px; padding: 8px; color: #e8eaee; }
.card img, .card video { display: block; min-width: 256px; max-width: 100%; height: auto; border-radius: 3px;
                         background: #000; }
.card svg { display: block; }
.card figcaption { text-align: center; font-size: 13px; margin-top: 6px; }
.figures { display: flex; flex-wrap: wrap; gap: 16px; align-items: flex-start; }
.figures figure { margin: 0; max-width: 100%; }
.figures img { display: block; max-width: 100%; height: auto; }
.figures figure.chart { flex: 1 1 460px; max-width: 640px; }
.figures figure.chart svg { display: block; width: 100%; height: auto; }
svg { max-width: 100%; height: auto; }
.note { color: var(--muted); font-style: italic; }
table { border-collapse: collapse; font-size: 14px; }
th, td { padding: 5px 14px; text-align: left; border-bottom: 1px solid var(--line); vertical-align: top; }
th { background: #eceff4; font-weight: 600; }
tbody tr:nth-child(even) { background: #f7f8fa; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
td.key { font-family: ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; font-size: 13px; }
pre { background: var(--ink); color: #e8eaee; padding: 12px 14px; border-radius: 6px; overflow-x: auto;
      font: 13px/1.55 ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; white-space: pre; }
footer { color: var(--muted); font-size: 12px; text-align: center; padding: 8px 0 24px; }
)css";

// Where we are: the manifest's name for error messages and RUN_DIR for resolving paths.
struct Ctx {
  fs::path run_dir;
  std::string manifest;
};

[[noreturn]] void bad(const Ctx& c, const std::string& field, const std::string& what) {
  if (field.empty()) fail("{}: {}", c.manifest, what);
  fail("{}: {}: {}", c.manifest, field, what);
}

std::string join_field(const std::string& field, const std::string& key) {
  return field.empty() ? key : field + "." + key;
}
std::string index_field(const std::string& field, size_t i) { return fmt::format("{}[{}]", field, i); }

// --- manifest access: every accessor checks the type and names the field when it is wrong --------------------

const Json& expect(const Ctx& c, const Json& j, const std::string& field, Json::value_t type, const char* what) {
  if (j.type() != type) bad(c, field, fmt::format("expected {}, got {}", what, j.type_name()));
  return j;
}

// An object whose keys are all in `known` (a typo such as "video" for "videos" would otherwise drop content silently).
void check_keys(const Ctx& c, const Json& obj, const std::string& field, std::initializer_list<const char*> known) {
  expect(c, obj, field, Json::value_t::object, "an object");
  for (const auto& kv : obj.items()) {
    if (std::none_of(known.begin(), known.end(), [&](const char* k) { return kv.key() == k; })) {
      std::string list;
      for (const char* k : known) list += (list.empty() ? "" : ", ") + std::string(k);
      bad(c, field, fmt::format("unknown key '{}' (expected one of: {})", kv.key(), list));
    }
  }
}

const Json* member(const Json& obj, const char* key) {
  auto it = obj.find(key);
  return it == obj.end() ? nullptr : &*it;
}

std::string opt_string(const Ctx& c, const Json& obj, const std::string& field, const char* key,
                       std::string dflt = "") {
  const Json* v = member(obj, key);
  if (!v) return dflt;
  return expect(c, *v, join_field(field, key), Json::value_t::string, "a string").get<std::string>();
}

std::string req_string(const Ctx& c, const Json& obj, const std::string& field, const char* key) {
  if (!member(obj, key)) bad(c, field, fmt::format("missing '{}'", key));
  return opt_string(c, obj, field, key);
}

// The array at obj[key], or an empty one when the key is absent.
const Json& opt_array(const Ctx& c, const Json& obj, const std::string& field, const char* key) {
  static const Json kEmpty = Json::array();
  const Json* v = member(obj, key);
  return v ? expect(c, *v, join_field(field, key), Json::value_t::array, "an array") : kEmpty;
}

// --- referenced files -------------------------------------------------------------------------------------------

std::string lower_ext(const std::string& rel) {
  std::string e = fs::path(rel).extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  return e;
}

std::string read_ref(const Ctx& c, const std::string& field, const std::string& rel) {
  const fs::path p = c.run_dir / rel;
  std::error_code ec;
  if (!fs::exists(p, ec)) bad(c, field, rel + " does not exist");
  if (!fs::is_regular_file(p, ec)) bad(c, field, rel + " is not a regular file");
  std::ifstream in(p, std::ios::binary);
  if (!in) bad(c, field, fmt::format("{}: cannot open ({})", rel, std::strerror(errno)));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) bad(c, field, rel + ": read error");
  return ss.str();
}

// An SVG document made fit for inlining: everything before the <svg> element (XML prolog, DOCTYPE, comments) goes,
// because a prolog inside HTML is at best shown as text.
std::string inline_svg(const Ctx& c, const std::string& field, const std::string& rel, const std::string& bytes) {
  const size_t at = bytes.find("<svg");
  if (at == std::string::npos) bad(c, field, rel + " is not an SVG document (no <svg> element)");
  return bytes.substr(at);
}

// One referenced file as an HTML element: image -> <img>, video -> <video>, SVG -> the SVG itself.
std::string media(const Ctx& c, const std::string& field, const std::string& rel, const std::string& alt) {
  const std::string ext = lower_ext(rel);
  const char* mime = ext == ".png" ? "image/png" : ext == ".gif" ? "image/gif"
                   : (ext == ".jpg" || ext == ".jpeg") ? "image/jpeg" : ext == ".mp4" ? "video/mp4"
                   : ext == ".webm" ? "video/webm" : ext == ".svg" ? "image/svg+xml" : nullptr;
  if (!mime) bad(c, field, rel + ": unsupported file type (expected .gif, .png, .jpg, .jpeg, .svg, .mp4 or .webm)");
  const std::string bytes = read_ref(c, field, rel);
  if (ext == ".svg") return inline_svg(c, field, rel, bytes);
  const std::string uri = fmt::format("data:{};base64,{}", mime, base64_encode(bytes));
  if (std::strncmp(mime, "video/", 6) == 0)
    return fmt::format("<video autoplay loop muted playsinline controls src=\"{}\"></video>", uri);
  return fmt::format("<img src=\"{}\" alt=\"{}\">", uri, xml_escape(alt));
}

// --- values -----------------------------------------------------------------------------------------------------

bool is_scalar(const Json& j) { return !j.is_object() && !j.is_array(); }

std::string value_text(const Json& j) {
  if (j.is_string()) return j.get<std::string>();
  if (j.is_number_unsigned()) return std::to_string(j.get<uint64_t>());
  if (j.is_number_integer()) return std::to_string(j.get<int64_t>());
  if (j.is_number_float()) return format_number(j.get<double>());
  if (j.is_boolean()) return j.get<bool>() ? "true" : "false";
  if (j.is_null()) return "\u2014";  // an em dash: "no value", as tables usually show it
  if (j.is_array() && std::all_of(j.begin(), j.end(), is_scalar)) {
    std::string s;
    for (const auto& v : j) s += (s.empty() ? "" : ", ") + value_text(v);
    return "[" + s + "]";
  }
  return j.dump();
}

std::string cell(const Json& j) {
  return fmt::format(j.is_number() ? "<td class=\"num\">{}</td>" : "<td>{}</td>", xml_escape(value_text(j)));
}

// {"a": {"b": 1, "c": [1, 2]}} -> ("a.b", 1), ("a.c", [1, 2]); arrays of objects are indexed: "runs[0].loss".
void flatten(const Json& j, const std::string& prefix, std::vector<std::pair<std::string, const Json*>>& out) {
  if (j.is_object() && !j.empty()) {
    for (const auto& kv : j.items()) flatten(kv.value(), join_field(prefix, kv.key()), out);
  } else if (j.is_array() && !std::all_of(j.begin(), j.end(), is_scalar)) {
    for (size_t i = 0; i < j.size(); ++i) flatten(j[i], index_field(prefix, i), out);
  } else {
    out.emplace_back(prefix, &j);
  }
}

// --- section elements -------------------------------------------------------------------------------------------

// Charts (inline SVG) shrink to fit two to a row; images keep their own size.
std::string figure(const std::string& content, const std::string& caption_block) {
  const bool chart = content.rfind("<svg", 0) == 0;
  return (chart ? "<figure class=\"chart\">" : "<figure>") + content + caption_block + "</figure>\n";
}

std::string caption_html(const std::string& caption) {
  return caption.empty() ? "" : "<p class=\"caption\">" + xml_escape(caption) + "</p>";
}

std::string render_videos(const Ctx& c, const Json& groups, const std::string& field) {
  std::string out;
  for (size_t g = 0; g < groups.size(); ++g) {
    const std::string gf = index_field(field, g);
    check_keys(c, groups[g], gf, {"caption", "items"});
    const Json& items = opt_array(c, groups[g], gf, "items");
    out += "<div class=\"block\"><div class=\"videos\">\n";
    for (size_t i = 0; i < items.size(); ++i) {
      const std::string itf = index_field(join_field(gf, "items"), i);
      check_keys(c, items[i], itf, {"label", "path"});
      const std::string label = opt_string(c, items[i], itf, "label");
      out += "<figure class=\"card\">" + media(c, join_field(itf, "path"), req_string(c, items[i], itf, "path"), label);
      if (!label.empty()) out += "<figcaption>" + xml_escape(label) + "</figcaption>";
      out += "</figure>\n";
    }
    out += "</div>" + caption_html(opt_string(c, groups[g], gf, "caption")) + "</div>\n";
  }
  return out;
}

// Plots and images: each one a figure with its caption, side by side when they fit.
std::string render_figures(const Ctx& c, const Json& list, const std::string& field) {
  if (list.empty()) return "";
  std::string out = "<div class=\"block figures\">\n";
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string f = index_field(field, i);
    check_keys(c, list[i], f, {"caption", "path"});
    const std::string caption = opt_string(c, list[i], f, "caption");
    out += figure(media(c, join_field(f, "path"), req_string(c, list[i], f, "path"), caption), caption_html(caption));
  }
  return out + "</div>\n";
}

std::string render_tables(const Ctx& c, const Json& tables, const std::string& field) {
  std::string out;
  for (size_t t = 0; t < tables.size(); ++t) {
    const std::string tf = index_field(field, t);
    check_keys(c, tables[t], tf, {"caption", "columns", "rows"});
    const Json& columns = opt_array(c, tables[t], tf, "columns");
    const Json& rows = opt_array(c, tables[t], tf, "rows");
    out += "<div class=\"block\"><table>\n";
    if (!columns.empty()) {
      out += "<thead><tr>";
      for (size_t k = 0; k < columns.size(); ++k)
        out += "<th>" + xml_escape(value_text(columns[k])) + "</th>";
      out += "</tr></thead>\n";
    }
    out += "<tbody>\n";
    for (size_t r = 0; r < rows.size(); ++r) {
      const std::string rf = index_field(join_field(tf, "rows"), r);
      expect(c, rows[r], rf, Json::value_t::array, "an array (one row of cells)");
      if (!columns.empty() && rows[r].size() != columns.size())
        bad(c, rf, fmt::format("has {} cells but there are {} columns", rows[r].size(), columns.size()));
      out += "<tr>";
      for (const auto& v : rows[r]) out += cell(v);
      out += "</tr>\n";
    }
    out += "</tbody></table>" + caption_html(opt_string(c, tables[t], tf, "caption")) + "</div>\n";
  }
  return out;
}

std::string render_metrics(const Ctx& c, const Json& metrics, const std::string& field) {
  expect(c, metrics, field, Json::value_t::object, "an object");
  if (metrics.empty()) return "";
  std::vector<std::pair<std::string, const Json*>> rows;
  flatten(metrics, "", rows);
  std::string out = "<div class=\"block\"><table class=\"metrics\">\n"
                    "<thead><tr><th>metric</th><th>value</th></tr></thead>\n<tbody>\n";
  for (const auto& [key, v] : rows) out += "<tr><td class=\"key\">" + xml_escape(key) + "</td>" + cell(*v) + "</tr>\n";
  return out + "</tbody></table></div>\n";
}

// The value at `key` in a JSONL record: the literal key first, else a dotted path ("val.bits_per_token").
const Json* lookup(const Json& rec, const std::string& key) {
  if (const Json* v = member(rec, key.c_str())) return v;
  const Json* cur = &rec;
  for (size_t start = 0; cur;) {
    const size_t dot = key.find('.', start);
    const std::string part = key.substr(start, dot == std::string::npos ? std::string::npos : dot - start);
    cur = cur->is_object() ? member(*cur, part.c_str()) : nullptr;
    if (dot == std::string::npos) break;
    start = dot + 1;
  }
  return cur;
}

// One JSON object per line. A torn last line (no newline yet: the trainer is still writing it) is skipped, so a
// report can be made while training runs; any other bad line is an error.
std::vector<Json> read_jsonl(const Ctx& c, const std::string& field, const std::string& rel) {
  const std::string text = read_ref(c, field, rel);
  std::vector<Json> recs;
  size_t line_no = 0;
  for (size_t pos = 0; pos < text.size();) {
    const size_t nl = text.find('\n', pos);
    const std::string line = text.substr(pos, nl == std::string::npos ? std::string::npos : nl - pos);
    pos = nl == std::string::npos ? text.size() : nl + 1;
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    Json j = Json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (j.is_discarded() && nl == std::string::npos) break;
    if (j.is_discarded()) bad(c, field, fmt::format("{} line {}: invalid JSON", rel, line_no));
    if (!j.is_object()) bad(c, field, fmt::format("{} line {}: not a JSON object", rel, line_no));
    recs.push_back(std::move(j));
  }
  return recs;
}

// Default curve keys: every numeric leaf except "step", in order of first appearance.
std::vector<std::string> numeric_keys(const std::vector<Json>& recs) {
  std::vector<std::string> keys;
  for (const auto& r : recs) {
    std::vector<std::pair<std::string, const Json*>> leaves;
    flatten(r, "", leaves);
    for (const auto& [k, v] : leaves)
      if (k != "step" && v->is_number() && std::find(keys.begin(), keys.end(), k) == keys.end()) keys.push_back(k);
  }
  return keys;
}

std::string curve_svg(const std::vector<Json>& recs, const std::string& key) {
  std::vector<double> x, y;
  for (const auto& r : recs) {
    const Json* s = member(r, "step");
    const Json* v = lookup(r, key);
    if (!s || !s->is_number() || !v || !v->is_number()) continue;  // missing, null or text: not a point
    x.push_back(s->get<double>());
    y.push_back(v->get<double>());
  }
  if (x.empty()) return "<p class=\"note\">no values of " + xml_escape(key) + "</p>";
  if (x.size() > kMaxCurvePoints) {
    const size_t stride = (x.size() + kMaxCurvePoints - 1) / kMaxCurvePoints;
    std::vector<double> xs, ys;
    for (size_t i = 0; i < x.size(); i += stride) { xs.push_back(x[i]); ys.push_back(y[i]); }
    if (xs.back() != x.back()) { xs.push_back(x.back()); ys.push_back(y.back()); }
    x.swap(xs);
    y.swap(ys);
  }
  return eval::svg_lines(key, x, {eval::Series{key, y, ""}}, "step", key);
}

std::string render_curves(const Ctx& c, const Json& curves, const std::string& field) {
  std::string out;
  for (size_t i = 0; i < curves.size(); ++i) {
    const std::string f = index_field(field, i);
    check_keys(c, curves[i], f, {"caption", "path", "keys"});
    const std::string pf = join_field(f, "path");
    const auto recs = read_jsonl(c, pf, req_string(c, curves[i], f, "path"));
    std::vector<std::string> keys;
    const Json& kj = opt_array(c, curves[i], f, "keys");
    for (size_t k = 0; k < kj.size(); ++k)
      keys.push_back(expect(c, kj[k], index_field(join_field(f, "keys"), k), Json::value_t::string, "a string")
                         .get<std::string>());
    if (!member(curves[i], "keys")) keys = numeric_keys(recs);
    out += "<div class=\"block\"><div class=\"figures\">\n";
    for (const auto& key : keys) out += figure(curve_svg(recs, key), "");
    out += "</div>" + caption_html(opt_string(c, curves[i], f, "caption")) + "</div>\n";
  }
  return out;
}

std::string render_commands(const Ctx& c, const Json& cmds, const std::string& field) {
  if (cmds.empty()) return "";
  std::string text;
  for (size_t i = 0; i < cmds.size(); ++i) {
    const Json& cmd = expect(c, cmds[i], index_field(field, i), Json::value_t::string, "a string");
    text += xml_escape(cmd.get<std::string>()) + "\n";
  }
  return "<div class=\"block\"><pre class=\"commands\">" + text + "</pre></div>\n";
}

// Visuals first, then numbers, then the commands that reproduce them.
std::string render_section(const Ctx& c, const Json& s, const std::string& f, size_t n, const std::string& title) {
  check_keys(c, s, f, {"title", "text", "videos", "plots", "images", "tables", "metrics", "curves", "commands"});
  std::string out = fmt::format("<section id=\"s{}\">\n<h2>{}. {}</h2>\n", n, n, xml_escape(title));
  const std::string text = opt_string(c, s, f, "text");
  if (!text.empty()) out += "<p class=\"text\">" + xml_escape(text) + "</p>\n";
  out += render_videos(c, opt_array(c, s, f, "videos"), join_field(f, "videos"));
  out += render_figures(c, opt_array(c, s, f, "plots"), join_field(f, "plots"));
  out += render_curves(c, opt_array(c, s, f, "curves"), join_field(f, "curves"));
  out += render_figures(c, opt_array(c, s, f, "images"), join_field(f, "images"));
  out += render_tables(c, opt_array(c, s, f, "tables"), join_field(f, "tables"));
  if (const Json* m = member(s, "metrics")) out += render_metrics(c, *m, join_field(f, "metrics"));
  out += render_commands(c, opt_array(c, s, f, "commands"), join_field(f, "commands"));
  return out + "</section>\n";
}

Json load_manifest(const Ctx& c, const fs::path& path) {
  std::error_code ec;
  if (!fs::is_directory(c.run_dir, ec)) fail("{}: no such run directory", c.run_dir.string());
  if (!fs::exists(path, ec)) fail("{}: does not exist (gaia eval and gaia demo write it)", c.manifest);
  const std::string text = read_file(path);
  try {
    return Json::parse(text);
  } catch (const Json::parse_error& e) {
    // "[json.exception.parse_error.101] parse error at line 2, column 3: ..." without the library's tag.
    std::string msg = e.what();
    const size_t tag_end = msg.find("] ");
    if (msg.rfind("[json.exception", 0) == 0 && tag_end != std::string::npos) msg = msg.substr(tag_end + 2);
    fail("{}: invalid JSON: {}", c.manifest, msg);
  }
}

}  // namespace

std::string base64_encode(std::string_view bytes) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  auto byte = [&](size_t k) { return static_cast<uint32_t>(static_cast<unsigned char>(bytes[k])); };
  for (; i + 3 <= bytes.size(); i += 3) {
    const uint32_t n = byte(i) << 16 | byte(i + 1) << 8 | byte(i + 2);
    for (int shift : {18, 12, 6, 0}) out += kAlphabet[(n >> shift) & 63];
  }
  const size_t rest = bytes.size() - i;
  if (rest > 0) {
    const uint32_t n = byte(i) << 16 | (rest == 2 ? byte(i + 1) << 8 : 0);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += rest == 2 ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

std::string format_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  if (v == 0) return "0";  // also -0
  // Integral values and large ones read best in full (12346, not 1.235e+04); beyond 1e15 doubles are not exact.
  if (std::abs(v) < 1e15 && (v == std::floor(v) || std::abs(v) >= 1e4)) return fmt::format("{:.0f}", v);
  return fmt::format("{:.4g}", v);
}

std::string render_report(const fs::path& run_dir) {
  const fs::path path = run_dir / "report.json";
  const Ctx c{run_dir, path.string()};
  const Json m = load_manifest(c, path);
  if (!m.is_object()) bad(c, "", fmt::format("expected a JSON object at the top level, got {}", m.type_name()));
  check_keys(c, m, "", {"title", "subtitle", "sections"});
  const std::string title = req_string(c, m, "", "title");
  const std::string subtitle = opt_string(c, m, "", "subtitle");
  if (!member(m, "sections")) bad(c, "", "missing 'sections'");
  const Json& sections = opt_array(c, m, "", "sections");

  std::string toc, body;
  for (size_t i = 0; i < sections.size(); ++i) {
    const std::string f = index_field("sections", i);
    expect(c, sections[i], f, Json::value_t::object, "an object");
    const std::string st = opt_string(c, sections[i], f, "title", fmt::format("Section {}", i + 1));
    toc += fmt::format("<li><a href=\"#s{}\">{}</a></li>\n", i + 1, xml_escape(st));
    body += render_section(c, sections[i], f, i + 1, st);
  }
  std::string html = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
                     "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
                     "<title>" + xml_escape(title) + "</title>\n<style>" + kStyle + "</style>\n</head>\n<body>\n";
  html += "<header><h1>" + xml_escape(title) + "</h1>";
  if (!subtitle.empty()) html += "<p>" + xml_escape(subtitle) + "</p>";
  html += "</header>\n<main>\n";
  if (!sections.empty()) html += "<nav class=\"toc\"><h2>Contents</h2><ol>\n" + toc + "</ol></nav>\n";
  html += body + "</main>\n<footer>made by gaia report from report.json</footer>\n</body>\n</html>\n";
  return html;
}

void write_report(const fs::path& run_dir, const fs::path& out) { write_file_atomic(out, render_report(run_dir)); }

}  // namespace gaia::report
