#pragma once
// Minimal, dependency-free SVG charts for reports: grouped bar charts (histograms) and line plots.
#include <string>
#include <vector>

namespace gaia::eval {

struct Series {
  std::string name;
  std::vector<double> y;
  std::string color;  // "" = from the palette
};

// Grouped bars: one group per category, one bar per series.
std::string svg_bars(const std::string& title, const std::vector<std::string>& categories,
                     const std::vector<Series>& series, int width = 640, int height = 320);

// Lines over shared x values.
std::string svg_lines(const std::string& title, const std::vector<double>& x, const std::vector<Series>& series,
                      const std::string& xlabel, const std::string& ylabel, int width = 640, int height = 320);

// Points and curves on log-log axes with decade ticks (a scaling law, §6). A series with `points` draws markers
// (and, where y_lo / y_hi are given, an error bar at each point); otherwise a line through its (x, y).
struct XYSeries {
  std::string name;
  std::vector<double> x, y;
  std::string color;  // "" = from the palette
  bool points = false;
  std::vector<double> y_lo, y_hi;
};
std::string svg_loglog(const std::string& title, const std::vector<XYSeries>& series, const std::string& xlabel,
                       const std::string& ylabel, int width = 640, int height = 360);

// Stacks several SVG charts vertically into one document.
std::string svg_stack(const std::vector<std::string>& charts, int width = 640, int height_each = 320);

std::string xml_escape(const std::string& s);

}  // namespace gaia::eval
