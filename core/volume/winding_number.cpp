#include "core/volume/winding_number.h"

#include <algorithm>
#include <cmath>

namespace cloudbake {

double triangleSolidAngle(const Vec3& a0, const Vec3& b0, const Vec3& c0, const Vec3& p) {
  const Vec3 a = a0 - p, b = b0 - p, c = c0 - p;
  const double la = length(a), lb = length(b), lc = length(c);
  const double det = dot(a, cross(b, c));
  const double den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
  return 2.0 * std::atan2(det, den);
}

double windingNumberExact(const TriangleMesh& mesh, const Vec3& p) {
  double sum = 0;
  for (const auto& t : mesh.triangles) {
    sum += triangleSolidAngle(mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]], p);
  }
  return sum * kInv4Pi;
}

FastWindingNumber::FastWindingNumber(const TriangleMesh& mesh, double beta) : beta_(beta) {
  tris_.reserve(mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    tris_.push_back({mesh.vertices[t[0]], mesh.vertices[t[1]], mesh.vertices[t[2]]});
  }
  nodes_.reserve(tris_.size() / 2 + 16);
  if (!tris_.empty()) build(0, static_cast<int32_t>(tris_.size()));
}

int32_t FastWindingNumber::build(int32_t first, int32_t count) {
  const int32_t id = static_cast<int32_t>(nodes_.size());
  nodes_.emplace_back();
  Vec3 area_sum, weighted;
  double total_area = 0;
  Bounds3 centroid_box, box;
  for (int32_t i = first; i < first + count; ++i) {
    const auto& t = tris_[i];
    const Vec3 av = cross(t[1] - t[0], t[2] - t[0]) * 0.5;
    const double area = length(av);
    const Vec3 centroid = (t[0] + t[1] + t[2]) / 3.0;
    area_sum += av;
    weighted += centroid * area;
    total_area += area;
    centroid_box.expand(centroid);
    for (const Vec3& v : t) box.expand(v);
  }
  Node node;
  node.area = area_sum;
  node.center = total_area > 0 ? weighted / total_area : box.center();
  double r2 = 0;
  for (int32_t i = first; i < first + count; ++i)
    for (const Vec3& v : tris_[i]) r2 = std::max(r2, dot(v - node.center, v - node.center));
  node.radius = std::sqrt(r2);
  node.first = first;
  node.count = count;
  if (count > 8) {
    const Vec3 ext = centroid_box.extent();
    const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    const int32_t mid = first + count / 2;
    std::nth_element(tris_.begin() + first, tris_.begin() + mid, tris_.begin() + first + count,
                     [axis](const std::array<Vec3, 3>& a, const std::array<Vec3, 3>& b) {
                       return a[0][axis] + a[1][axis] + a[2][axis] <
                              b[0][axis] + b[1][axis] + b[2][axis];
                     });
    node.left = build(first, mid - first);
    node.right = build(mid, first + count - mid);
  }
  nodes_[id] = node;
  return id;
}

double FastWindingNumber::operator()(const Vec3& p) const {
  if (nodes_.empty()) return 0.0;
  double solid_angle = 0;
  int32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    const Vec3 d = n.center - p;
    const double dist2 = dot(d, d);
    if (dist2 > beta_ * beta_ * n.radius * n.radius) {
      solid_angle += dot(d, n.area) / (dist2 * std::sqrt(dist2));
    } else if (n.left < 0) {
      for (int32_t i = n.first; i < n.first + n.count; ++i) {
        solid_angle += triangleSolidAngle(tris_[i][0], tris_[i][1], tris_[i][2], p);
      }
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  return solid_angle * kInv4Pi;
}

}  // namespace cloudbake
