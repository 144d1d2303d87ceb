// `cloudbake phase SPEC --out phase.csv [--png phase.png] [--samples N]`: tabulates a phase
// function (per channel and its sampling pdf) and optionally plots it on a log scale.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/io/png_writer.h"
#include "core/job/file_util.h"
#include "core/math/vec3.h"
#include "core/phase/phase_factory.h"
#include "tools/cloudbake/commands.h"

namespace cloudbake::tool {
namespace {

// Scattering angles 0..180 deg, ten times denser at both ends than in the middle (where the
// diffraction peak and the glory are), via theta = 180 (t - a sin(2 pi t) / (2 pi)).
std::vector<double> plotAngles(int n) {
  std::vector<double> theta(n);
  const double a = 0.9;
  for (int i = 0; i < n; ++i) {
    const double t = static_cast<double>(i) / (n - 1);
    theta[i] = 180.0 * (t - a * std::sin(2.0 * kPi * t) / (2.0 * kPi));
  }
  theta.front() = 0.0;
  theta.back() = 180.0;
  return theta;
}

// A tiny raster canvas with a 3x5 pixel font, enough for axis labels.
class Canvas {
 public:
  Canvas(int w, int h) : w_(w), h_(h), px_(static_cast<size_t>(w) * h * 3, 255) {}
  void blend(int x, int y, const std::array<int, 3>& c, double alpha) {
    if (x < 0 || y < 0 || x >= w_ || y >= h_ || alpha <= 0) return;
    uint8_t* p = &px_[(static_cast<size_t>(y) * w_ + x) * 3];
    alpha = std::min(alpha, 1.0);
    for (int k = 0; k < 3; ++k)
      p[k] = static_cast<uint8_t>(std::lround(p[k] + (c[k] - p[k]) * alpha));
  }
  void fillRect(int x0, int y0, int x1, int y1, const std::array<int, 3>& c) {
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) blend(x, y, c, 1.0);
  }
  // Anti-aliased polyline of half-width r: the coverage of a disc swept along it, accumulated as
  // a per-pixel maximum and composited once, so overlapping segments do not darken joints.
  void polyline(const std::vector<std::pair<double, double>>& pts, const std::array<int, 3>& c,
                double r) {
    std::vector<float> cover(static_cast<size_t>(w_) * h_, 0.f);
    for (size_t i = 0; i + 1 < pts.size(); ++i) {
      const auto [x0, y0] = pts[i];
      const auto [x1, y1] = pts[i + 1];
      const double len = std::hypot(x1 - x0, y1 - y0);
      const int steps = std::max(1, static_cast<int>(std::ceil(len * 3.0)));
      for (int s = 0; s <= steps; ++s) {
        const double x = x0 + (x1 - x0) * s / steps, y = y0 + (y1 - y0) * s / steps;
        for (int py = static_cast<int>(std::floor(y - r - 1)); py <= y + r + 1; ++py) {
          for (int px = static_cast<int>(std::floor(x - r - 1)); px <= x + r + 1; ++px) {
            if (px < 0 || py < 0 || px >= w_ || py >= h_) continue;
            const double d = std::hypot(px + 0.5 - x, py + 0.5 - y);
            float& cv = cover[static_cast<size_t>(py) * w_ + px];
            cv = std::max(cv, static_cast<float>(std::clamp(r + 0.5 - d, 0.0, 1.0)));
          }
        }
      }
    }
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) blend(x, y, c, cover[static_cast<size_t>(y) * w_ + x]);
  }
  void text(int x, int y, const std::string& s, const std::array<int, 3>& c, int scale) {
    for (char ch : s) {
      const uint16_t g = glyph(ch);
      for (int row = 0; row < 5; ++row)
        for (int col = 0; col < 3; ++col)
          if (g & (1u << (14 - (row * 3 + col))))
            fillRect(x + col * scale, y + row * scale, x + (col + 1) * scale - 1,
                     y + (row + 1) * scale - 1, c);
      x += 4 * scale;
    }
  }
  static int textWidth(const std::string& s, int scale) {
    return static_cast<int>(s.size()) * 4 * scale - scale;
  }
  const std::vector<uint8_t>& pixels() const { return px_; }

 private:
  static uint16_t glyph(char ch) {
    switch (ch) {  // 3x5 bitmaps, row-major, top row in the high bits
      case '0':
        return 0b111101101101111;
      case '1':
        return 0b010110010010111;
      case '2':
        return 0b111001111100111;
      case '3':
        return 0b111001111001111;
      case '4':
        return 0b101101111001001;
      case '5':
        return 0b111100111001111;
      case '6':
        return 0b111100111101111;
      case '7':
        return 0b111001001001001;
      case '8':
        return 0b111101111101111;
      case '9':
        return 0b111101111001111;
      case '-':
        return 0b000000111000000;
      case '.':
        return 0b000000000000010;
      case 'e':
        return 0b000111101110011;
      default:
        return 0;
    }
  }
  int w_, h_;
  std::vector<uint8_t> px_;
};

// Log-scale plot of the three channels against scattering angle.
void writePlot(const std::string& path, const std::vector<double>& theta,
               const std::vector<Rgb>& v) {
  const int w = 900, h = 540, left = 80, right = 20, top = 20, bottom = 50;
  const int pw = w - left - right, ph = h - top - bottom;
  double vmax = 0, vmin = 1e300;
  for (const Rgb& x : v) {
    for (int c = 0; c < 3; ++c) {
      vmax = std::max(vmax, x[c]);
      if (x[c] > 0) vmin = std::min(vmin, x[c]);
    }
  }
  if (!(vmax > 0)) throw InputError(path + ": phase function is zero everywhere, nothing to plot");
  vmin = std::max(vmin, vmax * 1e-9);
  const int dmin = static_cast<int>(std::floor(std::log10(vmin)));
  const int dmax = std::max(dmin + 1, static_cast<int>(std::ceil(std::log10(vmax))));
  auto px = [&](double th) { return left + th / 180.0 * pw; };
  auto py = [&](double val) {
    const double l = std::log10(std::max(val, std::pow(10.0, dmin)));
    return top + (dmax - l) / (dmax - dmin) * ph;
  };
  Canvas cv(w, h);
  const std::array<int, 3> grid{225, 225, 225}, axis{60, 60, 60};
  for (int d = dmin; d <= dmax; ++d) {
    const int y = static_cast<int>(std::lround(py(std::pow(10.0, d))));
    cv.fillRect(left, y, left + pw, y, grid);
    const std::string label = "1e" + std::to_string(d);
    cv.text(left - 8 - Canvas::textWidth(label, 2), y - 5, label, axis, 2);
  }
  for (int a = 0; a <= 180; a += 30) {
    const int x = static_cast<int>(std::lround(px(a)));
    cv.fillRect(x, top, x, top + ph, grid);
    const std::string label = std::to_string(a);
    cv.text(x - Canvas::textWidth(label, 2) / 2, top + ph + 10, label, axis, 2);
  }
  cv.fillRect(left, top, left + pw, top, axis);
  cv.fillRect(left, top + ph, left + pw, top + ph, axis);
  cv.fillRect(left, top, left, top + ph, axis);
  cv.fillRect(left + pw, top, left + pw, top + ph, axis);
  const std::array<std::array<int, 3>, 3> colour = {{{215, 40, 40}, {30, 150, 50}, {40, 70, 220}}};
  for (int c = 0; c < 3; ++c) {
    std::vector<std::pair<double, double>> pts;
    for (size_t i = 0; i < theta.size(); ++i) pts.emplace_back(px(theta[i]), py(v[i][c]));
    cv.polyline(pts, colour[c], 0.9);
  }
  // Legend swatches in the top right corner: red, green, blue.
  for (int c = 0; c < 3; ++c) {
    cv.fillRect(left + pw - 70 + 22 * c, top + 12, left + pw - 56 + 22 * c, top + 26, colour[c]);
  }
  writePng(path, w, h, 3, cv.pixels());
}

}  // namespace

void addPhaseCommand(CLI::App& app, int* exit_code) {
  struct Options {
    std::string spec, out, png;
    int samples = 721;
  };
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "phase",
      "Tabulate a phase function to CSV (theta_deg,cos_theta,r,g,b,pdf in sr^-1) and "
      "optionally plot it");
  cmd->add_option("spec", opt->spec,
                  "phase function, e.g. isotropic, hg:g=0.75, mie_approx:d=20, "
                  "mie:reff=10,veff=0.1 (any may add ,ratio=R)")
      ->required();
  cmd->add_option("--out", opt->out, "CSV file to write")->required();
  cmd->add_option("--png", opt->png, "also write a log-scale plot (R, G, B curves) to this PNG");
  cmd->add_option("--samples", opt->samples,
                  "number of scattering angles in the table, 2..100000 (default 721; denser "
                  "near 0 and 180 deg)");
  cmd->callback([opt, exit_code] {
    if (opt->samples < 2 || opt->samples > 100000) {
      throw InputError("--samples: must be in [2, 100000], got " + std::to_string(opt->samples));
    }
    // Parse (cheap) and check the output's folder before building, which can take a second
    // for Mie.
    const PhaseSpec spec = parsePhaseSpec(opt->spec);
    const std::filesystem::path folder =
        std::filesystem::absolute(std::filesystem::path(opt->out)).parent_path();
    std::error_code ec;
    if (!std::filesystem::is_directory(folder, ec)) {
      throw InputError(opt->out + ": cannot open for writing (no folder " + folder.string() + ")");
    }
    const auto t0 = std::chrono::steady_clock::now();
    const auto phase = makePhaseFunction(spec);
    const double build_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const std::vector<double> theta = plotAngles(opt->samples);
    std::vector<Rgb> values(theta.size());
    std::ostringstream csv;
    csv << "theta_deg,cos_theta,r,g,b,pdf\n" << std::setprecision(10);
    for (size_t i = 0; i < theta.size(); ++i) {
      const double mu = std::cos(theta[i] * kPi / 180.0);
      values[i] = phase->eval(mu);
      csv << theta[i] << ',' << mu << ',' << values[i].x << ',' << values[i].y << ',' << values[i].z
          << ',' << phase->pdf(mu) << '\n';
    }
    // Written whole through a temporary file and a rename: a full disk leaves no partial file
    // and exits 4 (StorageFullError), any other failure names the file.
    writeFileAtomic(opt->out, csv.str());
    if (!opt->png.empty()) writePlot(opt->png, theta, values);
    const Rgb g = phase->meanCosine();
    const nlohmann::json summary = {{"phase", phase->describe()},
                                    {"mean_cosine", {g.x, g.y, g.z}},
                                    {"build_seconds", build_s},
                                    {"csv", opt->out}};
    std::cout << summary.dump() << std::endl;
    *exit_code = kOk;
  });
}

}  // namespace cloudbake::tool
