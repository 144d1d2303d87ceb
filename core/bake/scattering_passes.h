// Method `pointcloud`, internal: seed 000's scattering passes between the points of the cloud,
// under two transfer rules, and the whole point stage (points, neighbours, passes) for tests and
// figures.
//
// ---------------------------------------------------------------------------------------------
// The normalised rule (default): a derivation
// ---------------------------------------------------------------------------------------------
// Everything is per unit sun irradiance E. sigma_t = extinction * D, sigma_s = albedo * sigma_t.
//
// 1. Orders of scattering. The fluence of light scattered k+1 times at y is the volume integral
//    of the radiance scattered out of order k, attenuated on the way and spread as 1/d^2:
//      phi_{k+1}(y) = Int_V S_k(x, w_xy) T(x, y) / |x - y|^2 dV_x,
//      S_k(x, w) = sigma_s(x) Int L_k(x, w') p(w' . w) dw'
//    (L_{k+1}(y, w) = Int_0^inf T S_k ds along -w, and dV = s^2 ds dw). Order 0 is the direct
//    sun: a beam of fluence Ci (the transmittance to the sun) travelling along L^0 = -sun_dir.
// 2. Points as cells. Points are placed with equal mass m (point_cloud.h), so point i stands
//    for the volume V_i = m / D_i and the integral becomes a sum over sources i of
//      V_i S_k(P_i, w_ij) T_ij / max(d_ij^2, r_i^2),   r_i = (3 V_i / 4 pi)^(1/3),
//    the clamp stopping a destination inside a source's own sphere from seeing a 1/d^2 spike.
//    T_ij = exp(-extinction d (D_i + 4 D_mid + D_j) / 6) is Simpson's rule on the segment with
//    one trilinear lookup at its midpoint. sigma_s,i V_i = albedo * extinction * m is the same
//    for every point, so the geometric weight is w_ij = extinction * m * T_ij / max(d^2, r_i^2)
//    (albedo, per channel, is applied in the pass). Pairs with T_ij < 1e-7 are dropped.
// 3. The angular model (Table 1's R and L). The light arriving at a point in order k is modelled
//    as a beam of fraction R along L plus an isotropic rest:
//      L_k(w') = Delta^k [R delta(w' - L) + (1 - R) / (4 pi)],
//    whose phase-convolved emission is exactly S_k(w) = sigma_s Delta^k [R p(L.w) + (1-R)/(4pi)]
//    for any normalised p; the sum over sources uses J_i(w) = Delta^k_i (R p(L_i.w) + (1-R)/4pi).
//    R and L are fixed by matching the first moment (net flux) of the gathered light: every
//    transfer arrives along w_ij, so F_j = sum_i lum(w_ij J_i) w_ij, and the model's flux is
//    R * lum(incoming) * L: L = F / |F|, R = |F| / lum(incoming), in [0, 1] by the triangle
//    inequality. lum(incoming) includes the point's own sphere (below), which arrives from all
//    directions and so adds to the denominator only. This replaces seed 000's Eq. 1,
//    R <- R - R exp(-|Lsum|): that update depends on the absolute size of Lsum (so on E, the
//    point count and the cut-off), can only lower R (light that becomes a beam again, forward
//    scattered into a shadow, cannot regain anisotropy) and has no fixed point tied to the
//    angular distribution; the moment ratio is dimensionless and exact for a pure beam (R = 1,
//    the direct sun) and for isotropic light (R = 0).
// 4. The point's own sphere. A uniform sphere of radius r emitting sigma_s Delta / (4 pi) per
//    steradian has fluence at its centre Int dw Int_0^r sigma_s Delta/(4pi) e^{-sigma_t s} ds =
//    albedo * Delta * (1 - exp(-sigma_t r)) (isotropic: anisotropy inside one cell is ignored).
//    So Delta^{k+1}_j = albedo * (sum_i w_ij J_i(w_ij) + Delta^k_j (1 - exp(-sigma_t,j r_j))).
// 5. Co = sum_{k >= 1} Delta^k (direct sun excluded: that is sun_transmittance). Passes stop when
//    sum lum(Delta^{k+1}) / sum lum(Co) < tolerance or at `passes`. The rest of the Neumann
//    series is added as a geometric tail: with q = sum lum(Delta^K) / sum lum(Delta^{K-1}) < 1,
//    sum_{k > K} Delta^k ~= Delta^K q / (1 - q), exact once the orders decay at the rate of the
//    transfer operator's dominant eigenvalue. In thick clouds q still creeps up for tens of
//    orders, so the tail is low there (the bunny at optical depth ~20, Co summed over the
//    lattice: -15 % after 8 passes, -6 % after 16, -1.3 % after 32, against 119 passes to a
//    1e-4 change), but far better than no tail. light_dir and mie_ratio are the first moment of
//    all orders together (the tail at the last order's shape): normalize(sum_k F) and
//    |sum_k F| / sum_k lum(in).
// 6. Energy conservation. Per source, the discretised transfers collide a fraction
//    c_i = self_i + sum_j w_ij / (4 pi) of its (isotropic) emission; in the medium that fraction
//    is 1 - P_escape(P_i), P_escape the transmittance to outside averaged over all directions
//    (the lattice's sky_visibility, trilinear at P_i). The two differ by the cut-off (light
//    that would collide beyond it is lost: c_i ~ 1 - exp(-sigma_t radius) deep inside, which
//    made more points, hence a shorter default radius, darker) and by the point discretisation
//    (randomly placed neighbours inside a point's own sphere overlap it: c_i > 1 for points
//    thicker than a mean free path, and the passes diverge at albedo 1). Each source's
//    transfers, own sphere included, are scaled by k_i = (1 - P_escape) / c_i: energy is
//    conserved per order, light beyond the cut-off lands on the neighbours in the directions it
//    was going. With a cut-off below the spacing only the own sphere is left, now scaled to
//    1 - P_escape: Co_j = Ci_j sum_k (albedo (1 - P_escape,j))^k.
// 7. Forward-peaked phase functions: the similarity (transport) reduction. Steps 1-6 as such
//    assume the emission's escape probability is the isotropic one; for cloud phase functions
//    (g ~ 0.75-0.9) most scattered light keeps going forwards, escapes far more easily and, with
//    the cut-off, lands on the neighbours in the wrong places: a tau-2 slab (HG 0.75, albedo
//    0.9) came out with Co 2-3x the reference fluence. The passes therefore run on the medium
//    of the similarity relations (van de Hulst; Wyman et al. 1989's delta-isotropic form):
//    isotropic scattering, extinction s sigma_t with s = 1 - a g and albedo a (1 - g) / s per
//    channel (s from luminance-weighted a g). Order 0 is the sun's beam in that medium,
//    Ci' = exp(-s tau) = Ci^s (light scattered into the forward peak counts as unscattered),
//    pairs use T' = T^s and the escape probability is the reduced medium's sky visibility. The
//    scattered fluence is then Co = (Ci' - Ci) + sum_k Delta'^k: the forward-scattered beam
//    (travelling along -sun_dir, which enters the flux and so R and L) plus the diffuse orders.
//    With the same slab, Co now lies within 10-40 % of a Monte Carlo fluence at every depth
//    (high near the lit face, low near the far one: the cut-off keeps light close to its source)
//    and the nadir view's multiple layer within 15 % (with the P1 angular model of
//    render_from_bake.cpp). Isotropic phase functions (g = 0) are unchanged (s = 1).
//    Measured (cloudbake compare vs pathtrace, mean of the multiple layer, tau 2, 65536 points):
//    8x8x1 slab nadir, isotropic: +12 % (albedo 0.5), +16 % (0.9), +18 % (0.99); HG 0.75: +15 %
//    (0.9), +9 % (0.99); unit sphere side view, albedo 0.9: isotropic +1 %, HG 0.75 +40 % (the
//    view term's P1 model, not Co, is the likely cause: forward-peaked light seen at 90 degrees).
// 8. Sky light. The bake is per unit sun irradiance and the sky's radiance is applied when a view
//    is rendered, so the passes are run a second time for a uniform sky of unit radiance (it is
//    linear): order 0 is the reduced medium's sky fluence 4 pi V' (V' its sky visibility), and
//    the scattered sky fluence is Co_sky = 4 pi (V' - V) + sum_k Delta'^k_sky, V the true
//    visibility (whose direct light is the views' ambient term). Views add
//    sigma_s * mean sky radiance * Co_sky / (4 pi): isotropic, as the sky's net flux is not kept.
//    Only with options.sky (a black sky bakes nothing). In the reduced medium (g != 0) each pass
//    gathers both lights' orders in one loop over the pairs, and the sun's flux of every order
//    in one loop after the last (it is linear in what each source emitted, summed over orders).
// Check (a test): a thin homogeneous sphere of radius a, isotropic, albedo 1: the second order
// (first scattered) fluence at the centre is Int sigma_s / (4 pi d^2) dV = sigma_s a.
//
// ---------------------------------------------------------------------------------------------
// The paper rule (options.rule == kPaper): seed 000's Eq. 1-5 as written, with these readings
// ---------------------------------------------------------------------------------------------
// A_d = exp(-|Ps - Pd| (Ds + Dd)/2 extinction) (Eq. 3). A_m = 4 pi p(theta) per channel, theta
// between L_src and the unit vector src -> dst, so isotropic scattering gives the "bare 1" that
// Eq. 4 puts beside it. Eq. 4 read as Co_dst += A_d (A_m R_src + (1 - R_src)) Ci_src (RGB), times
// the medium's albedo (the paper's clouds are conservative: at albedo 1 this is Eq. 4). Eq. 5
// read with the direction of the scattered light, as Figure 7 draws it: Lsum_dst += A_d
// (lum(A_m) R_src + (1 - R_src)) dir(src -> dst); with L_src itself every L would stay the sun
// direction forever. After each pass (Eq. 1 and the text): R <- R - R exp(-|Lsum|),
// L <- normalize(Lsum) when nonzero, Ci += Co, Co = Lsum = 0; the relative change of a pass is
// sum lum(Co) / sum lum(Ci). The output is 1 - exp(-Ci) with output_mapping (Eq. 2), otherwise
// Ci - Ci_initial (the scattered part). No 1/d^2, no volumes: the scale is arbitrary and grows
// with the neighbour count every pass; Ci saturates at 1e30 so grids stay finite.
#pragma once

#include <cstdint>
#include <vector>

#include "core/bake/bake_progress.h"
#include "core/bake/point_cloud.h"
#include "core/bake/pointcloud_bake.h"
#include "core/transport/scene.h"

namespace cloudbake {

/// Largest number of neighbour pairs a bake may store (8 bytes each).
constexpr double kMaxNeighbourPairs = 4e8;

/// The point cloud after its scattering passes.
struct PointCloudResult {
  PointCloud cloud;     ///< P, D, Ci (initial sun transmittance)
  std::vector<Rgb> co;  ///< Co per point (see the rules above)
  /// Normalised rule with a sky: fluence of sky light scattered at least once per unit radiance
  /// of a uniform sky (header, step 8); empty otherwise.
  std::vector<Rgb> co_sky;
  std::vector<Vec3> light_dir;   ///< L per point, unit or zero (travel direction)
  std::vector<float> mie_ratio;  ///< R per point, [0, 1]
  /// Normalised rule: 1 - P_escape per point (the target collision fraction) and the factor k_i
  /// its transfers were scaled by (header, step 6).
  std::vector<float> collision, transfer_scale;
  double radius = 0;               ///< cut-off used, world units
  double mean_neighbours = 0;      ///< points within the cut-off per point
  uint64_t pairs = 0;              ///< stored pairs (negligible transmittance dropped)
  uint64_t pair_interactions = 0;  ///< pairs x passes
  int passes_run = 0;
  double last_relative_change = 0;
  double tail_ratio = 0;  ///< q of the geometric tail (0: none added)
  /// Normalised rule: sum_j lum(Delta^k_j) for k = 0 (direct) .. passes_run; paper rule:
  /// sum_j lum(Ci_j) before the first pass and after each.
  std::vector<double> order_luminance;
  double seconds_points = 0, seconds_neighbours = 0, seconds_passes = 0;
};

/// Throws InputError naming the knob (points, passes, tolerance, radius, step) or the medium
/// field (density, extinction, albedo, phase) that is out of range.
void checkPointcloudInput(const Medium& medium, const PointcloudOptions& options);

/// The point stage of method `pointcloud` on a lattice's density and its sky_visibility grid
/// (the escape probability of the normalised rule; computed here when not of the lattice's size,
/// e.g. empty): places options.points
/// points, their Ci (towards `sun_dir`, unit, from the scene towards the sun), the neighbour
/// pairs within the cut-off, and runs up to options.passes passes of options.rule. With
/// `geometric_tail` false the normalised rule returns exactly the first passes_run orders
/// (for pass-by-pass figures). Progress fractions are within this stage, [0, 1]. InputError for
/// an empty volume or an unusable radius; Cancelled on request. The normalised rule's passes
/// run on a similarity-reduced medium (passExtinction) whose own sky visibility they need where
/// it differs: `pass_sky_visibility`, when the caller computed it alongside the true one
/// (skyVisibilities, one sweep for both), else computed here.
PointCloudResult runPointcloud(const BakeGrid& grid, const std::vector<float>& density,
                               const FirstTouchFloats& sky_visibility, const Medium& medium,
                               const Vec3& sun_dir, const PointcloudOptions& options,
                               bool geometric_tail = true, const BakeProgressFn& progress = {},
                               const FirstTouchFloats& pass_sky_visibility = {});

/// The extinction of the medium the passes run on, per unit density: s sigma_t for the
/// normalised rule (s = 1 - lum(albedo x g), the similarity reduction), sigma_t for the paper
/// rule.
double passExtinction(const Medium& medium, const PointcloudOptions& options);

}  // namespace cloudbake
