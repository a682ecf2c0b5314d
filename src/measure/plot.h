// Small drawing tools for the measurement instruments, no dependencies: an 8-bit RGB
// canvas with lines and a 5x7 bitmap font (digits, A-Z with lower case drawn as upper
// case, and common symbols), and log-log line plots written as SVG or rasterised to the
// canvas (then PNG through write_png8).
#pragma once
#include <string>
#include <vector>

namespace tuile {

struct Color {
  unsigned char r = 0, g = 0, b = 0;
};
// A distinct colour per series (cycles after 12).
Color series_color(int i);

struct Canvas {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;  // row-major, top row first, 3 bytes per pixel
  int clip_x0 = 0, clip_y0 = 0, clip_x1 = 0, clip_y1 = 0;  // drawing limited to [x0, x1) x [y0, y1)

  Canvas() = default;
  Canvas(int w, int h, Color background);
  void set_clip(int x0, int y0, int x1, int y1);
  void reset_clip() { set_clip(0, 0, width, height); }
  void set(int x, int y, Color c);
  void fill_rect(int x, int y, int w, int h, Color c);
  // A line of the given thickness in pixels; dash > 0 draws dash pixels on, dash off.
  void line(double x0, double y0, double x1, double y1, Color c, int thickness = 1, int dash = 0);
  // Copies a w x h block of RGB bytes with its top-left corner at (x, y).
  void blit(int x, int y, int w, int h, const unsigned char* src);
};

// The 5x7 font: each glyph advances 6 columns; scale multiplies everything.
inline constexpr int font_width = 5, font_height = 7, font_advance = 6;
int text_width(const std::string& s, int scale = 1);
// Draws s with its top-left corner at (x, y). Characters without a glyph draw as '?'.
void draw_text(Canvas& c, int x, int y, const std::string& s, Color color, int scale = 1);
// True when the font has a glyph for ch (after folding lower case to upper case).
bool font_has_glyph(char ch);

struct PlotSeries {
  std::string name;
  std::vector<double> x, y;  // points with x <= 0 or y <= 0 are left out (log axes)
};

struct Plot {
  std::string title, xlabel, ylabel;
  std::vector<PlotSeries> series;
  // A dashed guide y ~ x^guide_slope through half the middle point of the first series; 0 = none.
  double guide_slope = 0;
  std::string guide_label;
};

// Log-log plot: decade ticks with labels (1e-3, 0.01, 1, 10, ...), one polyline per
// series (<polyline> elements, one per series, nothing else uses <polyline>), a legend
// to the right, the guide as a dashed <path>.
std::string plot_svg(const Plot& p, int width = 760, int height = 480);
void write_plot_svg(const std::string& path, const Plot& p, int width = 760, int height = 480);
Canvas plot_raster(const Plot& p, int width = 760, int height = 480);
void write_plot_png(const std::string& path, const Plot& p, int width = 760, int height = 480);

// "1e-3", "0.01", "0.1", "1", "10", "100", "1e3" for 10^k.
std::string decade_label(int k);

}  // namespace tuile
