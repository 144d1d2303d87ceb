// Tabulated phase function of a polydisperse water cloud, from our Lorenz-Mie solver.
#pragma once

#include <array>
#include <complex>
#include <functional>
#include <memory>
#include <vector>

#include "core/phase/phase_function.h"

namespace cloudbake {

/// How the polydisperse Mie table is built. Defaults describe a typical cumulus cloud.
struct MieTableOptions {
  double effective_radius_um = 10.0;  ///< r_eff of the gamma size distribution, um (1..50)
  double effective_variance = 0.1;    ///< v_eff, [0.01, 0.5)
  /// Wavelength band per channel (R, G, B), micrometres; each band is averaged over
  /// `wavelengths_per_channel` sub-band centres, weighted by their scattering coefficient.
  std::array<std::array<double, 2>, 3> band_um = {{{0.6, 0.7}, {0.5, 0.6}, {0.4, 0.5}}};
  int wavelengths_per_channel = 5;
  /// Refractive index of water per channel at the band centre (Hale & Querry 1973,
  /// Appl. Opt. 12:555: 650, 550, 450 nm); positive imaginary part = absorption.
  std::array<std::complex<double>, 3> refractive_index = {
      {{1.331, 1.64e-8}, {1.333, 1.96e-9}, {1.337, 1.02e-9}}};
  /// Size-parameter step of the radius quadrature. Interference structure (rainbow, glory
  /// fringes) oscillates with a period of order 1 in x, so 0.25 resolves it; narrow resonances
  /// are averaged statistically.
  double dx = 0.25;
  /// Beyond x = dx / relative_dx the step grows as relative_dx x (0: uniform steps of dx), so a
  /// table's cost grows linearly with the largest droplet instead of quadratically
  /// (sizeParameterNodes in mie_table.cpp; measured in tests/core/phase/mie_table_test.cpp).
  double relative_dx = 0.002;
};

/// Angle grid of the table in degrees, ascending from 0 to 180: 0.02 deg steps near the
/// diffraction peak, 0.25 deg across the fogbow, 0.05 deg near the glory.
std::vector<double> mieTableAngleGridDeg();

/// The work of building a table with `options`: Mie terms summed over its size-parameter nodes
/// and channels, times its angles (InputError for options out of range).
double mieTableWork(const MieTableOptions& options);
/// The predicted build time in seconds on `threads` cores (a dry run's estimate; the constant is
/// measured on the reference machine).
double estimateMieTableSeconds(const MieTableOptions& options, int threads);

/// Polydisperse Mie phase function per RGB channel,
///   p_c(theta) = sum_lambda int n(r) (|S1|^2 + |S2|^2)(x, theta) dr / normalisation,
/// tabulated at mieTableAngleGridDeg() and interpolated linearly in cos(theta). Each channel
/// integrates to exactly 1 over the sphere (for the interpolant). Sampling inverts the CDF of the
/// channel average, also piecewise linear in cos(theta), so pdf() == average(eval()) exactly is
/// the density of sampleCosTheta(). Hansen & Travis 1974; Bohren & Huffman 1983.
class MieTablePhase final : public PhaseFunction {
 public:
  /// Builds the table (TBB-parallel over size parameters, deterministic). Throws InputError for
  /// out-of-range options (naming phase.reff / phase.veff / ...). `keep_going` (optional, called
  /// from worker threads between size parameters, so thread safe and cheap) returning false
  /// stops the build with Cancelled: the largest tables take tens of seconds.
  explicit MieTablePhase(const MieTableOptions& options = {},
                         const std::function<bool()>& keep_going = {});

  /// A table from given per-channel values at ascending angles theta_deg (0 first, 180 last);
  /// normalises each channel. Throws InputError on malformed input.
  MieTablePhase(const std::vector<double>& theta_deg, const std::vector<Rgb>& values);

  Rgb eval(double cos_theta) const override;
  double pdf(double cos_theta) const override;
  double sampleCosTheta(double u) const override;
  bool chromatic() const override { return true; }
  Rgb meanCosine() const override { return mean_cosine_; }
  std::string describe() const override { return description_; }

  /// Tabulated nodes, ascending in cos(theta) (so theta descending from 180 deg).
  const std::vector<double>& cosTheta() const { return mu_; }
  const std::vector<Rgb>& values() const { return value_; }
  /// Wall-clock seconds the Mie computation took (0 for tables built from values).
  double buildSeconds() const { return build_seconds_; }

 private:
  void finalize();
  size_t segment(double mu) const;

  std::vector<double> mu_;   // ascending
  std::vector<Rgb> value_;   // per node, sr^-1
  std::vector<double> pdf_;  // channel average per node, sr^-1
  std::vector<double> cdf_;  // P(cos <= mu_j), cdf_.back() == 1
  Rgb mean_cosine_;
  std::string description_ = "table";
  double build_seconds_ = 0;
};

}  // namespace cloudbake
