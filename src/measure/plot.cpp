// The plots of `tuile converge` (SVG, or PNG through the raster canvas) and the canvas,
// lines and bitmap font the figures label their sheets with.
#include "measure/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "scene/image_io.h"

namespace tuile {

Color series_color(int i) {
  static const Color pal[12] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44},  {214, 39, 40},
                                {148, 103, 189}, {140, 86, 75}, {227, 119, 194}, {127, 127, 127},
                                {188, 189, 34}, {23, 190, 207}, {0, 0, 128},    {128, 128, 0}};
  return pal[((i % 12) + 12) % 12];
}

// ---------------------------------------------------------------------------- canvas

Canvas::Canvas(int w, int h, Color bg) : width(w), height(h), rgb(static_cast<size_t>(w) * h * 3) {
  for (size_t i = 0; i < rgb.size(); i += 3) rgb[i] = bg.r, rgb[i + 1] = bg.g, rgb[i + 2] = bg.b;
  reset_clip();
}

void Canvas::set_clip(int x0, int y0, int x1, int y1) {
  clip_x0 = std::max(0, x0), clip_y0 = std::max(0, y0);
  clip_x1 = std::min(width, x1), clip_y1 = std::min(height, y1);
}

void Canvas::set(int x, int y, Color c) {
  if (x < clip_x0 || y < clip_y0 || x >= clip_x1 || y >= clip_y1) return;
  unsigned char* p = &rgb[(static_cast<size_t>(y) * width + x) * 3];
  p[0] = c.r, p[1] = c.g, p[2] = c.b;
}

void Canvas::fill_rect(int x, int y, int w, int h, Color c) {
  for (int j = y; j < y + h; ++j)
    for (int i = x; i < x + w; ++i) set(i, j, c);
}

void Canvas::line(double x0, double y0, double x1, double y1, Color c, int thickness, int dash) {
  if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) return;
  // keep absurd coordinates (a guide far off the axes) from looping for ever
  const double lim = 4.0 * (width + height);
  if (std::fabs(x0) > lim || std::fabs(x1) > lim || std::fabs(y0) > lim || std::fabs(y1) > lim) {
    // clip to a generous box in parametric form (Liang-Barsky)
    double t0 = 0, t1 = 1;
    const double dx = x1 - x0, dy = y1 - y0;
    const double p[4] = {-dx, dx, -dy, dy}, q[4] = {x0 + lim, lim - x0, y0 + lim, lim - y0};
    for (int k = 0; k < 4; ++k) {
      if (p[k] == 0) {
        if (q[k] < 0) return;
        continue;
      }
      const double r = q[k] / p[k];
      if (p[k] < 0) t0 = std::max(t0, r);
      else t1 = std::min(t1, r);
    }
    if (t0 > t1) return;
    const double nx0 = x0 + t0 * dx, ny0 = y0 + t0 * dy;
    x1 = x0 + t1 * dx, y1 = y0 + t1 * dy, x0 = nx0, y0 = ny0;
  }
  const double len = std::max(std::fabs(x1 - x0), std::fabs(y1 - y0));
  const int n = std::max(1, static_cast<int>(std::ceil(len)));
  const int lo = -(thickness - 1) / 2, hi = thickness / 2;
  for (int s = 0; s <= n; ++s) {
    if (dash > 0 && (s / dash) % 2 == 1) continue;
    const double t = static_cast<double>(s) / n;
    const int x = static_cast<int>(std::lround(x0 + t * (x1 - x0)));
    const int y = static_cast<int>(std::lround(y0 + t * (y1 - y0)));
    for (int j = lo; j <= hi; ++j)
      for (int i = lo; i <= hi; ++i) set(x + i, y + j, c);
  }
}

void Canvas::blit(int x, int y, int w, int h, const unsigned char* src) {
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      const unsigned char* s = src + (static_cast<size_t>(j) * w + i) * 3;
      set(x + i, y + j, Color{s[0], s[1], s[2]});
    }
}

// ---------------------------------------------------------------------------- font

namespace {

struct Glyph {
  char c;
  unsigned char rows[7];  // top to bottom; bit 4 is the leftmost column
};

// Drawn for tuile (5 x 7 cells).
constexpr Glyph glyphs[] = {
#include "measure/plot_font.inc"
};

const Glyph* find_glyph(char ch) {
  if (ch >= 'a' && ch <= 'z') ch = static_cast<char>(ch - 'a' + 'A');
  for (const Glyph& g : glyphs)
    if (g.c == ch) return &g;
  return nullptr;
}

}  // namespace

bool font_has_glyph(char ch) { return find_glyph(ch) != nullptr; }

int text_width(const std::string& s, int scale) {
  if (s.empty()) return 0;
  return (static_cast<int>(s.size()) * font_advance - 1) * scale;
}

void draw_text(Canvas& c, int x, int y, const std::string& s, Color color, int scale) {
  int cx = x;
  for (char ch : s) {
    const Glyph* g = find_glyph(ch);
    if (!g) g = find_glyph('?');
    for (int row = 0; row < font_height; ++row)
      for (int col = 0; col < font_width; ++col)
        if (g->rows[row] & (1u << (font_width - 1 - col))) c.fill_rect(cx + col * scale, y + row * scale, scale, scale, color);
    cx += font_advance * scale;
  }
}

// ---------------------------------------------------------------------------- plots

std::string decade_label(int k) {
  switch (k) {
    case -2: return "0.01";
    case -1: return "0.1";
    case 0: return "1";
    case 1: return "10";
    case 2: return "100";
    default: return "1e" + std::to_string(k);
  }
}

namespace {

struct Layout {
  int width = 0, height = 0;
  int left = 78, right = 0, top = 40, bottom = 0;  // plot area in pixels
  int dx0 = 0, dx1 = 1, dy0 = 0, dy1 = 1;  // decades spanned
  double px(double x) const { return left + (std::log10(x) - dx0) / (dx1 - dx0) * (right - left); }
  double py(double y) const { return bottom - (std::log10(y) - dy0) / (dy1 - dy0) * (bottom - top); }
};

Layout layout(const Plot& p, int width, int height) {
  Layout l;
  l.width = width, l.height = height;
  l.right = width - 190;
  l.bottom = height - 56;
  double xmin = HUGE_VAL, xmax = -HUGE_VAL, ymin = HUGE_VAL, ymax = -HUGE_VAL;
  for (const PlotSeries& s : p.series)
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!(s.x[i] > 0) || !(s.y[i] > 0) || !std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      xmin = std::min(xmin, s.x[i]), xmax = std::max(xmax, s.x[i]);
      ymin = std::min(ymin, s.y[i]), ymax = std::max(ymax, s.y[i]);
    }
  if (!(xmin <= xmax)) xmin = 1, xmax = 10;
  if (!(ymin <= ymax)) ymin = 1, ymax = 10;
  l.dx0 = static_cast<int>(std::floor(std::log10(xmin) + 1e-9));
  l.dx1 = static_cast<int>(std::ceil(std::log10(xmax) - 1e-9));
  l.dy0 = static_cast<int>(std::floor(std::log10(ymin) + 1e-9));
  l.dy1 = static_cast<int>(std::ceil(std::log10(ymax) - 1e-9));
  if (l.dx1 <= l.dx0) l.dx1 = l.dx0 + 1;
  if (l.dy1 <= l.dy0) l.dy1 = l.dy0 + 1;
  return l;
}

int label_step(int decades) { return decades > 12 ? 3 : decades > 7 ? 2 : 1; }

// The guide's two ends in data space, across the whole x range, through the middle point
// of the first series with at least one point.
bool guide_ends(const Plot& p, const Layout& l, double& x0, double& y0, double& x1, double& y1) {
  if (p.guide_slope == 0) return false;
  for (const PlotSeries& s : p.series) {
    std::vector<size_t> ok;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i)
      if (s.x[i] > 0 && s.y[i] > 0 && std::isfinite(s.x[i]) && std::isfinite(s.y[i])) ok.push_back(i);
    if (ok.empty()) continue;
    const size_t m = ok[ok.size() / 2];
    x0 = std::pow(10.0, l.dx0), x1 = std::pow(10.0, l.dx1);
    // half-way below the point, so the guide runs beside the data instead of under it
    y0 = 0.5 * s.y[m] * std::pow(x0 / s.x[m], p.guide_slope);
    y1 = 0.5 * s.y[m] * std::pow(x1 / s.x[m], p.guide_slope);
    return true;
  }
  return false;
}

std::string esc(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '&') o += "&amp;";
    else if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '"') o += "&quot;";
    else o += c;
  }
  return o;
}

std::string hex(Color c) {
  char b[8];
  std::snprintf(b, sizeof b, "#%02x%02x%02x", c.r, c.g, c.b);
  return b;
}

std::string num(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.2f", v);
  return b;
}

}  // namespace

std::string plot_svg(const Plot& p, int width, int height) {
  const Layout l = layout(p, width, height);
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
    << "\" viewBox=\"0 0 " << width << " " << height << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  o << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<defs><clipPath id=\"plotarea\"><rect x=\"" << l.left << "\" y=\"" << l.top << "\" width=\""
    << l.right - l.left << "\" height=\"" << l.bottom - l.top << "\"/></clipPath></defs>\n";
  if (!p.title.empty())
    o << "<text x=\"" << (l.left + l.right) / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">"
      << esc(p.title) << "</text>\n";
  // grid and ticks
  o << "<g stroke=\"#dddddd\" stroke-width=\"1\">\n";
  for (int k = l.dx0; k <= l.dx1; ++k) {
    const double x = l.px(std::pow(10.0, k));
    o << "<line x1=\"" << num(x) << "\" y1=\"" << l.top << "\" x2=\"" << num(x) << "\" y2=\"" << l.bottom << "\"/>\n";
  }
  for (int k = l.dy0; k <= l.dy1; ++k) {
    const double y = l.py(std::pow(10.0, k));
    o << "<line x1=\"" << l.left << "\" y1=\"" << num(y) << "\" x2=\"" << l.right << "\" y2=\"" << num(y) << "\"/>\n";
  }
  o << "</g>\n<g stroke=\"black\" stroke-width=\"1\">\n";
  for (int k = l.dx0; k <= l.dx1; ++k)
    for (int m = 1; m <= (k < l.dx1 ? 9 : 1); ++m) {
      const double x = l.px(m * std::pow(10.0, k));
      o << "<line x1=\"" << num(x) << "\" y1=\"" << l.bottom << "\" x2=\"" << num(x) << "\" y2=\""
        << l.bottom + (m == 1 ? 6 : 3) << "\"/>\n";
    }
  for (int k = l.dy0; k <= l.dy1; ++k)
    for (int m = 1; m <= (k < l.dy1 ? 9 : 1); ++m) {
      const double y = l.py(m * std::pow(10.0, k));
      o << "<line x1=\"" << l.left - (m == 1 ? 6 : 3) << "\" y1=\"" << num(y) << "\" x2=\"" << l.left << "\" y2=\""
        << num(y) << "\"/>\n";
    }
  o << "</g>\n";
  o << "<rect x=\"" << l.left << "\" y=\"" << l.top << "\" width=\"" << l.right - l.left << "\" height=\""
    << l.bottom - l.top << "\" fill=\"none\" stroke=\"black\"/>\n";
  const int xs = label_step(l.dx1 - l.dx0), ys = label_step(l.dy1 - l.dy0);
  for (int k = l.dx0; k <= l.dx1; ++k)
    if ((k - l.dx0) % xs == 0)
      o << "<text x=\"" << num(l.px(std::pow(10.0, k))) << "\" y=\"" << l.bottom + 20
        << "\" text-anchor=\"middle\">" << decade_label(k) << "</text>\n";
  for (int k = l.dy0; k <= l.dy1; ++k)
    if ((k - l.dy0) % ys == 0)
      o << "<text x=\"" << l.left - 9 << "\" y=\"" << num(l.py(std::pow(10.0, k)) + 4) << "\" text-anchor=\"end\">"
        << decade_label(k) << "</text>\n";
  if (!p.xlabel.empty())
    o << "<text x=\"" << (l.left + l.right) / 2 << "\" y=\"" << height - 14 << "\" text-anchor=\"middle\">"
      << esc(p.xlabel) << "</text>\n";
  if (!p.ylabel.empty())
    o << "<text transform=\"translate(18," << (l.top + l.bottom) / 2
      << ") rotate(-90)\" text-anchor=\"middle\">" << esc(p.ylabel) << "</text>\n";
  // guide
  double gx0, gy0, gx1, gy1;
  const bool guide = guide_ends(p, l, gx0, gy0, gx1, gy1);
  if (guide)
    o << "<path class=\"guide\" d=\"M " << num(l.px(gx0)) << " " << num(l.py(gy0)) << " L " << num(l.px(gx1)) << " "
      << num(l.py(gy1)) << "\" stroke=\"#555555\" stroke-width=\"1.2\" stroke-dasharray=\"6 4\" fill=\"none\" "
      << "clip-path=\"url(#plotarea)\"/>\n";
  // series
  for (size_t si = 0; si < p.series.size(); ++si) {
    const PlotSeries& s = p.series[si];
    o << "<polyline class=\"series\" data-name=\"" << esc(s.name) << "\" fill=\"none\" stroke=\""
      << hex(series_color(static_cast<int>(si))) << "\" stroke-width=\"1.8\" clip-path=\"url(#plotarea)\" points=\"";
    bool first = true;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!(s.x[i] > 0) || !(s.y[i] > 0) || !std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      o << (first ? "" : " ") << num(l.px(s.x[i])) << "," << num(l.py(s.y[i]));
      first = false;
    }
    o << "\"/>\n";
  }
  // legend
  int ly = l.top + 8;
  const int lx = l.right + 14;
  for (size_t si = 0; si < p.series.size(); ++si, ly += 18) {
    o << "<line x1=\"" << lx << "\" y1=\"" << ly << "\" x2=\"" << lx + 22 << "\" y2=\"" << ly << "\" stroke=\""
      << hex(series_color(static_cast<int>(si))) << "\" stroke-width=\"2.5\"/>\n";
    o << "<text x=\"" << lx + 28 << "\" y=\"" << ly + 4 << "\">" << esc(p.series[si].name) << "</text>\n";
  }
  if (guide) {
    o << "<line x1=\"" << lx << "\" y1=\"" << ly << "\" x2=\"" << lx + 22 << "\" y2=\"" << ly
      << "\" stroke=\"#555555\" stroke-width=\"1.2\" stroke-dasharray=\"6 4\"/>\n";
    o << "<text x=\"" << lx + 28 << "\" y=\"" << ly + 4 << "\">" << esc(p.guide_label) << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

void write_plot_svg(const std::string& path, const Plot& p, int width, int height) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << plot_svg(p, width, height);
  if (!f) throw std::runtime_error("error writing " + path);
}

Canvas plot_raster(const Plot& p, int width, int height) {
  const Layout l = layout(p, width, height);
  const Color white{255, 255, 255}, black{0, 0, 0}, grid{221, 221, 221}, guide_c{85, 85, 85};
  Canvas c(width, height, white);
  for (int k = l.dx0; k <= l.dx1; ++k) c.line(l.px(std::pow(10.0, k)), l.top, l.px(std::pow(10.0, k)), l.bottom, grid);
  for (int k = l.dy0; k <= l.dy1; ++k) c.line(l.left, l.py(std::pow(10.0, k)), l.right, l.py(std::pow(10.0, k)), grid);
  for (int k = l.dx0; k <= l.dx1; ++k)
    for (int m = 1; m <= (k < l.dx1 ? 9 : 1); ++m) {
      const double x = l.px(m * std::pow(10.0, k));
      c.line(x, l.bottom, x, l.bottom + (m == 1 ? 6 : 3), black);
    }
  for (int k = l.dy0; k <= l.dy1; ++k)
    for (int m = 1; m <= (k < l.dy1 ? 9 : 1); ++m) {
      const double y = l.py(m * std::pow(10.0, k));
      c.line(l.left - (m == 1 ? 6 : 3), y, l.left, y, black);
    }
  c.line(l.left, l.top, l.right, l.top, black);
  c.line(l.left, l.bottom, l.right, l.bottom, black);
  c.line(l.left, l.top, l.left, l.bottom, black);
  c.line(l.right, l.top, l.right, l.bottom, black);
  const int xs = label_step(l.dx1 - l.dx0), ys = label_step(l.dy1 - l.dy0);
  for (int k = l.dx0; k <= l.dx1; ++k)
    if ((k - l.dx0) % xs == 0) {
      const std::string s = decade_label(k);
      draw_text(c, static_cast<int>(l.px(std::pow(10.0, k))) - text_width(s) / 2, l.bottom + 11, s, black);
    }
  for (int k = l.dy0; k <= l.dy1; ++k)
    if ((k - l.dy0) % ys == 0) {
      const std::string s = decade_label(k);
      draw_text(c, l.left - 9 - text_width(s), static_cast<int>(l.py(std::pow(10.0, k))) - 3, s, black);
    }
  if (!p.title.empty()) draw_text(c, (l.left + l.right - text_width(p.title, 2)) / 2, 12, p.title, black, 2);
  if (!p.xlabel.empty()) draw_text(c, (l.left + l.right - text_width(p.xlabel)) / 2, height - 22, p.xlabel, black);
  if (!p.ylabel.empty()) draw_text(c, 4, l.top - 16, p.ylabel, black);
  c.set_clip(l.left + 1, l.top + 1, l.right, l.bottom);
  double gx0, gy0, gx1, gy1;
  const bool guide = guide_ends(p, l, gx0, gy0, gx1, gy1);
  if (guide) c.line(l.px(gx0), l.py(gy0), l.px(gx1), l.py(gy1), guide_c, 1, 6);
  for (size_t si = 0; si < p.series.size(); ++si) {
    const PlotSeries& s = p.series[si];
    bool have = false;
    double qx = 0, qy = 0;
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!(s.x[i] > 0) || !(s.y[i] > 0) || !std::isfinite(s.x[i]) || !std::isfinite(s.y[i])) continue;
      const double x = l.px(s.x[i]), y = l.py(s.y[i]);
      if (have) c.line(qx, qy, x, y, series_color(static_cast<int>(si)), 2);
      qx = x, qy = y, have = true;
    }
  }
  c.reset_clip();
  int ly = l.top + 8;
  const int lx = l.right + 14;
  for (size_t si = 0; si < p.series.size(); ++si, ly += 16) {
    c.line(lx, ly, lx + 22, ly, series_color(static_cast<int>(si)), 3);
    draw_text(c, lx + 28, ly - 3, p.series[si].name, black);
  }
  if (guide) {
    c.line(lx, ly, lx + 22, ly, guide_c, 1, 4);
    draw_text(c, lx + 28, ly - 3, p.guide_label, black);
  }
  return c;
}

void write_plot_png(const std::string& path, const Plot& p, int width, int height) {
  const Canvas c = plot_raster(p, width, height);
  write_png8(path, c.width, c.height, c.rgb);
}

}  // namespace tuile
