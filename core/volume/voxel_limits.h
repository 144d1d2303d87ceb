// The smallest voxel a volume or a bake may have.
#pragma once

namespace cloudbake {

/// World units. OpenVDB refuses a linear transform whose scale's determinant is under 3e-15
/// (voxels under about 1.44e-5), so every grid this product writes needs voxels of at least
/// this; a finer one is refused as the shot is read (scale the scene up instead).
constexpr double kMinVoxelSize = 2e-5;

}  // namespace cloudbake
