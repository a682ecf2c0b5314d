// The pictures of the measurement commands (`tuile converge --plot`, `tuile figures`),
// drawn by matplotlib through the Python module's plotting code (python/tuile/plot.py):
// the commands render and measure, write what is to be drawn (series as JSON, images as
// .npy float arrays) and run that script once. A user restyles the same pictures from
// Python with tuile.plot.
#pragma once
#include <string>
#include <vector>

namespace tuile {

struct PlotSeries {
  std::string name;
  std::vector<double> x, y;
};

// A log-log line plot, one line per series, with a guide of the given slope.
struct Plot {
  std::string output;  // .png, .svg or .pdf
  std::string title, xlabel, ylabel;
  std::vector<PlotSeries> series;
  double guide_slope = 0;  // 0: no guide
  std::string guide_label;
};

// An image of a contact sheet: linear RGB shown as sRGB ("srgb"), a [0, 1] quantity
// shown as grey ("grey", 1 channel), or a signed quantity's luminance, positive as grey
// and negative in red ("signed", RGB).
struct SheetPanel {
  std::string label, display = "srgb";
  int width = 0, height = 0, channels = 3;
  std::vector<float> data;  // row-major, top row first
};

// Panels in rows of at most `columns`, each under its label, under a title.
struct Sheet {
  std::string output, title;
  int columns = 3;
  std::vector<SheetPanel> panels;
};

// The Python interpreter that draws (TUILE_PYTHON in the environment, else the one the
// build found) and the script (python/tuile/plot.py of the source tree).
std::string plot_python();
std::string plot_script();

// Draws the plots and sheets in one run of the script; throws std::runtime_error naming
// the interpreter, the script and what it printed when it fails (matplotlib missing,
// an unwritable output).
void draw_with_matplotlib(const std::vector<Plot>& plots, const std::vector<Sheet>& sheets);

// A float32 array as a NumPy .npy file (format 1.0, little-endian, C order).
void write_npy(const std::string& path, const std::vector<size_t>& shape, const float* data);

}  // namespace tuile
