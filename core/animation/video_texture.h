// Endless animation from a finite database of basic volumes (Iwasaki et al. 2011, seed 002,
// after Schoedl et al. 2000's video textures): frame similarities, transition probabilities, a
// seeded random walk and the cross-dissolve that hides each jump.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

namespace cloudbake {

/// A database of basic volumes: `frames` density arrays of equal size (one lattice), in their
/// original time order. At least 2 frames.
using BasicVolumes = std::vector<std::vector<float>>;

/// D_kl = sum over voxels of (rho_k - rho_l)^2 for every pair, as an n x n row-major matrix
/// (symmetric, zero diagonal). InputError for fewer than 2 frames, frames of different sizes, or
/// non-finite densities (naming the frame). Parallel over rows; deterministic. `keep_going`
/// (called from worker threads, once a row) returning false cancels (Cancelled).
std::vector<double> frameDistances(const BasicVolumes& frames,
                                   const std::function<bool()>& keep_going = {});

/// The largest future-cost weight: the walk looks about 1 / (1 - alpha) frames ahead.
constexpr double kMaxFutureCost = 0.999;

/// Options of the walk. `sigma` is the seed's temperature relative to the mean sqrt(D_kl) over
/// k != l (so one value suits any lattice size): P_kl proportional to exp(-D''_kl / (sigma mean
/// sqrt(D))). `dissolve_frames` H: frames over which a jump is cross-dissolved (0: a hard cut).
/// `future_cost` alpha: Schoedl et al.'s weight of what a transition leads to (0: the jump's own
/// cost only, which loops at the end of the input).
struct VideoTextureOptions {
  double sigma = 0.05;      ///< (0, 1e6]; small: only near-identical continuations; large: uniform
  int dissolve_frames = 8;  ///< H in [0, n - 2]
  double future_cost = 0.99;  ///< alpha in [0, kMaxFutureCost]
  uint64_t seed = 1;
};

/// P as an n x n row-major matrix: row k gives the probabilities of the frames that may follow
/// frame k. A transition's own cost is D'_kl = sqrt(D_{k+1,l}) (Schoedl et al.'s exponent p =
/// 1/2): the natural successor k+1 costs 0; a jump target l must leave room for the dissolve
/// (l + H <= n - 1). The last frame has no successor: its row uses sqrt(D_{n-1,l-1}) (jump to a
/// frame whose predecessor looks like it), and sqrt(D_{n-1,0}) for frame 0. Schoedl et al. 2000
/// (Section 3.3) add what the transition leads to: D''_kl = D'_kl + alpha min_m D''_{j,m},
/// where j is the frame the walk goes on from (l, or l + H - 1 after a dissolve). The last
/// frame's jump then goes back far enough to spread its cost over the stretch before the end
/// comes round again, instead of the shortest jump that loops the last H + 1 frames (the dead
/// end). Rows sum to 1. InputError naming sigma, H or future_cost when out of range;
/// `keep_going` (once per sweep of the future costs) returning false cancels (Cancelled).
std::vector<double> transitionProbabilities(const std::vector<double>& distances, int n,
                                            const VideoTextureOptions& options,
                                            const std::function<bool()>& keep_going = {});

/// One output frame: rho = w rho_a + (1 - w) rho_b (w = 1: frame a alone).
struct BlendFrame {
  int a = 0, b = 0;
  double w = 1;
};

/// A walk of `length` output frames starting at frame 0, drawn with P and options.seed (the same
/// seed gives the same walk). A jump from k to l (l != k + 1) is played as H blended frames:
/// t = 0..H-1 blends the old continuation min(k + 1 + t, n - 1) (weight w_t = 1 - (t + 1) /
/// (H + 1)) with the new sequence l + t; the walk then continues from l + H - 1 (H = 0: from l).
std::vector<BlendFrame> endlessWalk(const std::vector<double>& probabilities, int n, int length,
                                    const VideoTextureOptions& options);

/// The densities of one output frame.
std::vector<float> blendFrame(const BasicVolumes& frames, const BlendFrame& f);

/// The largest frame-to-frame change of a sequence of output frames: the maximum over
/// consecutive pairs of the RMS density difference per voxel (sqrt(D / voxels)).
double maxFrameChange(const BasicVolumes& frames, const std::vector<BlendFrame>& walk);

/// The same for the input sequence played in order (0, 1, ..., n - 1).
double maxInputFrameChange(const BasicVolumes& frames);

}  // namespace cloudbake
