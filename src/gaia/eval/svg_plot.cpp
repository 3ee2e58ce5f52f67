#include "gaia/eval/svg_plot.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace gaia::eval {

namespace {
const char* kPalette[] = {"#4C78A8", "#F58518", "#54A24B", "#E45756", "#72B7B2", "#B279A2"};
constexpr int kLeft = 56, kRight = 16, kTop = 32, kBottom = 72;

std::string color_of(const Series& s, size_t i) { return s.color.empty() ? kPalette[i % 6] : s.color; }

std::string header(int w, int h, const std::string& title) {
  return fmt::format(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\" "
      "font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"{0}\" height=\"{1}\" fill=\"white\"/>\n"
      "<text x=\"{2}\" y=\"18\" font-size=\"14\" text-anchor=\"middle\">{3}</text>\n",
      w, h, w / 2, xml_escape(title));
}

std::string y_axis(double ymin, double ymax, int w, int h) {
  std::string s;
  for (int i = 0; i <= 4; ++i) {
    double v = ymin + (ymax - ymin) * i / 4.0;
    double y = h - kBottom - (h - kTop - kBottom) * i / 4.0;
    s += fmt::format("<line x1=\"{}\" x2=\"{}\" y1=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"#ddd\"/>\n", kLeft, w - kRight, y, y);
    s += fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.3g}</text>\n", kLeft - 4, y + 4, v);
  }
  return s;
}

std::string legend(const std::vector<Series>& series, int w) {
  std::string s;
  for (size_t i = 0; i < series.size(); ++i) {
    int x = w - kRight - 140, y = kTop + 4 + static_cast<int>(i) * 14;
    s += fmt::format("<rect x=\"{}\" y=\"{}\" width=\"10\" height=\"10\" fill=\"{}\"/>", x, y, color_of(series[i], i));
    s += fmt::format("<text x=\"{}\" y=\"{}\">{}</text>\n", x + 14, y + 9, xml_escape(series[i].name));
  }
  return s;
}
}  // namespace

std::string xml_escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string svg_bars(const std::string& title, const std::vector<std::string>& cats, const std::vector<Series>& series,
                     int w, int h) {
  // The axis always contains 0; negative values (e.g. a right turn's curvature) hang below the zero line.
  double ymin = 0, ymax = 0;
  for (auto& s : series)
    for (double v : s.y)
      if (std::isfinite(v)) ymin = std::min(ymin, v), ymax = std::max(ymax, v);
  if (ymax - ymin <= 0) ymax = 1;
  std::string out = header(w, h, title) + y_axis(ymin, ymax, w, h);
  const double plot_w = w - kLeft - kRight, plot_h = h - kTop - kBottom;
  const double zero_y = h - kBottom - plot_h * (0 - ymin) / (ymax - ymin);
  const double group = cats.empty() ? plot_w : plot_w / static_cast<double>(cats.size());
  const double bar = group * 0.8 / std::max<size_t>(1, series.size());
  for (size_t c = 0; c < cats.size(); ++c) {
    double gx = kLeft + group * static_cast<double>(c) + group * 0.1;
    for (size_t s = 0; s < series.size(); ++s) {
      double v = c < series[s].y.size() && std::isfinite(series[s].y[c]) ? series[s].y[c] : 0;
      double bh = plot_h * std::abs(v) / (ymax - ymin);
      out += fmt::format("<rect x=\"{:.1f}\" y=\"{:.1f}\" width=\"{:.1f}\" height=\"{:.1f}\" fill=\"{}\"/>\n",
                         gx + bar * static_cast<double>(s), v >= 0 ? zero_y - bh : zero_y, bar, bh,
                         color_of(series[s], s));
    }
    double lx = gx + group * 0.4, ly = h - kBottom + 12;
    out += fmt::format("<text x=\"{:.1f}\" y=\"{:.1f}\" text-anchor=\"end\" transform=\"rotate(-35 {:.1f} {:.1f})\">{}</text>\n",
                       lx, ly, lx, ly, xml_escape(cats[c]));
  }
  return out + legend(series, w) + "</svg>\n";
}

std::string svg_lines(const std::string& title, const std::vector<double>& x, const std::vector<Series>& series,
                      const std::string& xlabel, const std::string& ylabel, int w, int h) {
  double ymin = INFINITY, ymax = -INFINITY;
  for (auto& s : series)
    for (double v : s.y)
      if (std::isfinite(v)) { ymin = std::min(ymin, v); ymax = std::max(ymax, v); }
  if (!(ymin <= ymax)) { ymin = 0; ymax = 1; }
  if (ymax == ymin) { ymax += 0.5; ymin -= 0.5; }
  double xmin = x.empty() ? 0 : *std::min_element(x.begin(), x.end());
  double xmax = x.empty() ? 1 : *std::max_element(x.begin(), x.end());
  if (xmax == xmin) xmax = xmin + 1;
  const double plot_w = w - kLeft - kRight, plot_h = h - kTop - kBottom;
  std::string out = header(w, h, title) + y_axis(ymin, ymax, w, h);
  for (size_t s = 0; s < series.size(); ++s) {
    std::string pts;
    for (size_t i = 0; i < x.size() && i < series[s].y.size(); ++i) {
      if (!std::isfinite(series[s].y[i])) continue;
      pts += fmt::format("{:.1f},{:.1f} ", kLeft + plot_w * (x[i] - xmin) / (xmax - xmin),
                         h - kBottom - plot_h * (series[s].y[i] - ymin) / (ymax - ymin));
    }
    out += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" points=\"{}\"/>\n", color_of(series[s], s), pts);
  }
  for (int i = 0; i <= 4; ++i) {
    double v = xmin + (xmax - xmin) * i / 4.0;
    out += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">{:.3g}</text>\n", kLeft + plot_w * i / 4.0,
                       h - kBottom + 14, v);
  }
  out += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", kLeft + plot_w / 2, h - kBottom + 32, xml_escape(xlabel));
  out += fmt::format("<text x=\"12\" y=\"{}\" transform=\"rotate(-90 12 {})\" text-anchor=\"middle\">{}</text>\n",
                     kTop + plot_h / 2, kTop + plot_h / 2, xml_escape(ylabel));
  return out + legend(series, w) + "</svg>\n";
}

std::string svg_loglog(const std::string& title, const std::vector<XYSeries>& series, const std::string& xlabel,
                       const std::string& ylabel, int w, int h) {
  double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY;
  for (auto& s : series) {
    for (double v : s.x)
      if (v > 0 && std::isfinite(v)) { x0 = std::min(x0, v); x1 = std::max(x1, v); }
    for (const auto* ys : {&s.y, &s.y_lo, &s.y_hi})
      for (double v : *ys)
        if (v > 0 && std::isfinite(v)) { y0 = std::min(y0, v); y1 = std::max(y1, v); }
  }
  if (!(x0 <= x1)) { x0 = 1; x1 = 10; }
  if (!(y0 <= y1)) { y0 = 1; y1 = 10; }
  // Decades that hold the data, with a margin of a tenth of the span on the y axis (losses span little).
  const double lx0 = std::floor(std::log10(x0)), lx1 = std::max(lx0 + 1, std::ceil(std::log10(x1)));
  const double pad = std::max(0.02, 0.1 * (std::log10(y1) - std::log10(y0)));
  const double ly0 = std::log10(y0) - pad, ly1 = std::log10(y1) + pad;
  const double plot_w = w - kLeft - kRight, plot_h = h - kTop - kBottom;
  auto px = [&](double x) { return kLeft + plot_w * (std::log10(x) - lx0) / (lx1 - lx0); };
  auto py = [&](double y) { return h - kBottom - plot_h * (std::log10(y) - ly0) / (ly1 - ly0); };
  std::string out = header(w, h, title);
  for (double e = lx0; e <= lx1; e += 1) {
    const double x = kLeft + plot_w * (e - lx0) / (lx1 - lx0);
    out += fmt::format("<line x1=\"{0:.1f}\" x2=\"{0:.1f}\" y1=\"{1}\" y2=\"{2}\" stroke=\"#ddd\"/>\n", x, kTop, h - kBottom);
    out += fmt::format("<text x=\"{:.1f}\" y=\"{}\" text-anchor=\"middle\">1e{}</text>\n", x, h - kBottom + 14, int(e));
  }
  for (int i = 0; i <= 4; ++i) {  // the loss axis: five ticks at round values
    const double v = std::pow(10.0, ly0 + (ly1 - ly0) * i / 4.0), y = py(v);
    out += fmt::format("<line x1=\"{}\" x2=\"{}\" y1=\"{:.1f}\" y2=\"{:.1f}\" stroke=\"#ddd\"/>\n", kLeft, w - kRight, y, y);
    out += fmt::format("<text x=\"{}\" y=\"{:.1f}\" text-anchor=\"end\">{:.3g}</text>\n", kLeft - 4, y + 4, v);
  }
  std::vector<Series> names;
  for (size_t s = 0; s < series.size(); ++s) {
    const auto& S = series[s];
    const std::string color = S.color.empty() ? kPalette[s % 6] : S.color;
    names.push_back({S.name, {}, color});
    std::string pts;
    for (size_t i = 0; i < S.x.size() && i < S.y.size(); ++i) {
      if (!(S.x[i] > 0 && S.y[i] > 0)) continue;
      if (!S.points) {
        pts += fmt::format("{:.1f},{:.1f} ", px(S.x[i]), py(S.y[i]));
        continue;
      }
      out += fmt::format("<circle cx=\"{:.1f}\" cy=\"{:.1f}\" r=\"4\" fill=\"{}\"/>\n", px(S.x[i]), py(S.y[i]), color);
      if (i < S.y_lo.size() && i < S.y_hi.size() && S.y_lo[i] > 0 && S.y_hi[i] > 0)
        out += fmt::format("<line x1=\"{0:.1f}\" x2=\"{0:.1f}\" y1=\"{1:.1f}\" y2=\"{2:.1f}\" stroke=\"{3}\" "
                           "stroke-width=\"2\"/>\n", px(S.x[i]), py(S.y_lo[i]), py(S.y_hi[i]), color);
    }
    if (!S.points && !pts.empty())
      out += fmt::format("<polyline fill=\"none\" stroke=\"{}\" stroke-width=\"1.5\" points=\"{}\"/>\n", color, pts);
  }
  out += fmt::format("<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">{}</text>\n", kLeft + plot_w / 2, h - kBottom + 32, xml_escape(xlabel));
  out += fmt::format("<text x=\"12\" y=\"{}\" transform=\"rotate(-90 12 {})\" text-anchor=\"middle\">{}</text>\n",
                     kTop + plot_h / 2, kTop + plot_h / 2, xml_escape(ylabel));
  return out + legend(names, w) + "</svg>\n";
}

std::string svg_stack(const std::vector<std::string>& charts, int w, int h) {
  std::string out = fmt::format("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\">\n",
                                w, h * static_cast<int>(charts.size()));
  for (size_t i = 0; i < charts.size(); ++i)
    out += fmt::format("<g transform=\"translate(0 {})\">\n{}</g>\n", h * static_cast<int>(i), charts[i]);
  return out + "</svg>\n";
}

}  // namespace gaia::eval
