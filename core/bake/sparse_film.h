// A view's film traced sparsely where its pixels are much finer than the bake's lattice: every
// s-th pixel in x and y is traced, and the cells between them are traced pixel by pixel only
// where their corners say the image varies there (a silhouette, a shadow's edge, a peak between
// corners); elsewhere the pixels are interpolated bilinearly from the corners.
//
// Why it holds: the cloud's light and transmittance in a view from a bake are marched through
// grids interpolated trilinearly from the lattice, so they have no structure finer than a
// voxel's projection but what the march's own step adds (in optically thick lattices, a few
// per cent at single pixels). Where the farthest voxel still covers s pixels or more
// (sparseFilmSpacing), a traced pixel is at most one voxel from the next, and the test
// (filmCellsToTrace) catches what bilinear interpolation would miss: a second difference across
// traced pixels over a fraction of their magnitude. The sky seen through the cloud is not read
// from the lattice: an interpolated pixel takes it along its own rays (judgedFloat). Measured
// against every pixel traced, and against a march of an eighth of the step, in docs/methods.md
// ("A sparse film").
#pragma once

#include <cstdint>
#include <vector>

namespace cloudbake {

/// Floats of one pixel as renderFromBake stores its layers: beauty RGBA (0-3), background
/// (4-6), sun (7-9), sky (10-12), single (13-15), multiple (16-18).
constexpr int kFilmFloats = 19;

struct FilmPixel {
  float v[kFilmFloats] = {};
};

/// Whether the cells' test judges float k: alpha and the layers read from the lattice (sun, sky,
/// single, multiple). Beauty and background hold the sky seen through the cloud, which is not
/// read from the lattice (a sky map's detail can be finer than any voxel), so an interpolated
/// pixel takes the sky behind it along its own rays, times its interpolated transmittance.
constexpr bool judgedFloat(int k) { return k == 3 || k >= 7; }

/// The largest film spacing a view of a bake may take: 1, 2 or 4 pixels.
constexpr int kMaxFilmSpacing = 4;

/// The spacing of the traced pixels, a power of two up to `max_spacing` (1 disables): the
/// largest s with s pixels at most one voxel wide where a pixel is widest over the lattice
/// (`pixel_footprint`, world units, at the lattice's farthest point from the eye).
int sparseFilmSpacing(double pixel_footprint, double voxel_size, int max_spacing);

/// How much a cell's corners may vary before its pixels are traced. A quantity q (each judged
/// float of a pixel) bends where its second difference at a traced pixel, along x or y, exceeds
/// `curvature` x (the largest |q| of the three + its floor): bilinear interpolation errs by about
/// an eighth of that at the cell's middle, and an edge or a peak between traced pixels bends the
/// ones beside it. A linear ramp, however steep, does not. `light_floor` (radiance) keeps faint
/// light from being traced for differences no image shows.
struct FilmTolerance {
  double curvature = 0.1;
  double light_floor = 0;
  double alpha_floor = 0.5;
};

/// Which cells of a grid of traced pixels (`nx` x `ny`, row-major, at film columns `xs` and
/// rows `ys`) must be traced pixel by pixel: (nx - 1) x (ny - 1) flags, row-major; a cell is
/// where one of its corners bends. A grid under 3 traced pixels along x or y has no second
/// differences along it, so all of its cells are traced.
std::vector<uint8_t> filmCellsToTrace(const std::vector<FilmPixel>& grid,
                                      const std::vector<int>& xs, const std::vector<int>& ys,
                                      const FilmTolerance& tol);

/// The pixel at fractions fx (from x0 towards x1) and fy (from y0 towards y1) of the cell of
/// corners c00 (x0, y0), c10 (x1, y0), c01 (x0, y1) and c11 (x1, y1), interpolated bilinearly.
FilmPixel interpolateFilm(const FilmPixel& c00, const FilmPixel& c10, const FilmPixel& c01,
                          const FilmPixel& c11, double fx, double fy);

}  // namespace cloudbake
