// Lorenz-Mie scattering by a homogeneous sphere.
#pragma once

#include <complex>
#include <vector>

namespace cloudbake {

/// Efficiencies and asymmetry of one sphere (Bohren & Huffman 1983, ch. 4).
struct MieEfficiencies {
  double qext = 0;   ///< extinction efficiency C_ext / (pi r^2)
  double qsca = 0;   ///< scattering efficiency
  double qback = 0;  ///< backscatter efficiency, 4 |S1(180 deg)|^2 / x^2 (Bohren & Huffman 4.82)
  double g = 0;      ///< asymmetry parameter <cos theta>
  int terms = 0;     ///< number of series terms N used
};

/// The largest |m| accepted: beyond every material's in the optics of clouds (water about 1.33,
/// metals some tens), and a bound on the recurrence's length.
constexpr double kMaxRefractiveIndex = 1000;
/// The largest |m| x accepted: the downward recurrence holds about 1.1 |m x| complex terms
/// (35 MB here).
constexpr double kMaxMieMx = 2e6;

/// Series length N = x + 4 x^(1/3) + 2 (Wiscombe 1980), at least 1.
int mieTermCount(double x);

/// Returns the refractive index in the e^{-i omega t} convention of Bohren & Huffman,
/// m = n + i k with k >= 0 absorbing. Both signs of the imaginary part are accepted as the same
/// absorption |k| (Wiscombe's MIEV0 writes m = n - i k), so 1.33 - 1e-5i == 1.33 + 1e-5i.
/// Throws InputError ("mie.m: ...") unless n > 0, both parts are finite and |m| <=
/// kMaxRefractiveIndex.
std::complex<double> normalizeRefractiveIndex(std::complex<double> m);

/// Mie coefficients a_n, b_n for n = 1..N (stored at index n - 1) for size parameter
/// x = 2 pi r / lambda and relative refractive index m (any sign convention, see above).
/// The logarithmic derivative D_n(m x) uses downward recurrence from well above max(N, |m x|),
/// which is stable for all m and x (Wiscombe 1980; Bohren & Huffman app. A).
/// Throws InputError ("mie.x: ...") unless 1e-8 <= x <= 1e5, ("mie.m: ...") unless |m| x <=
/// kMaxMieMx.
void mieCoefficients(double x, std::complex<double> m, std::vector<std::complex<double>>* a,
                     std::vector<std::complex<double>>* b);

/// Qext, Qsca, Qback and g from the coefficients of mieCoefficients().
MieEfficiencies mieEfficiencies(double x, const std::vector<std::complex<double>>& a,
                                const std::vector<std::complex<double>>& b);

/// Convenience: coefficients and efficiencies in one call.
MieEfficiencies mieEfficiencies(double x, std::complex<double> m);

/// Angular functions pi_n(mu), tau_n(mu) for n = 1..n_max by upward recurrence (Bohren &
/// Huffman 4.47), stored row-major as pi[(n - 1) * mu.size() + j].
void mieAngularFunctions(int n_max, const std::vector<double>& mu, std::vector<double>* pi,
                         std::vector<double>* tau);

/// Amplitude functions S1, S2 (Bohren & Huffman 4.74) at each cos(theta) in `mu`, where theta is
/// the scattering angle (0 = forward). The unpolarised phase function is
/// (|S1|^2 + |S2|^2) / (2 pi x^2 Qsca) in sr^-1.
void mieAmplitudes(const std::vector<std::complex<double>>& a,
                   const std::vector<std::complex<double>>& b, const std::vector<double>& mu,
                   std::vector<std::complex<double>>* s1, std::vector<std::complex<double>>* s2);

}  // namespace cloudbake
