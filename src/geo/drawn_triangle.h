#pragma once
// DrawnTriangle: a triangle as a renderer draws it, the straight (planar) triangle between
// its three corners in ECEF, and where a DEM pixel's vertical meets it (DESIGN.md 5; the
// vertical and the DEM point come from DemOnGlobe).
//
// Two measures, both exact in double:
//   offset   the signed distance along the vertical `up` from a point to the triangle's
//            PLANE (positive: the plane is above the point). At a DEM point it is the
//            triangle's vertical error there. Where the TIN and the simplifier take the
//            triangle that holds a pixel in the DEM's grid, they measure this offset.
//   meets    whether that vertical meets the triangle ITSELF (closed, with a relative
//            tolerance of 1e-9 of the barycentric weights): what the renderer draws above
//            the pixel. Tiles and `terratiles check` measure the pixels whose verticals meet
//            a triangle, so the build and the check see exactly the same pairs.
// Degenerate triangles meet nothing and have no plane (offset NaN): corners on a line or a
// pair of corners that coincide, as at a pole, where every pixel of a geographic DEM's pole
// row is placed within a nanometre of the axis. Degenerate means twice the area below 1e-12
// of the longest edge squared (a real sliver of a grid of W pixels is above about 1 / W^2).

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "src/geo/crs_transform.h"

namespace terratiles {

struct DrawnTriangle {
  EcefPoint a;
  std::array<double, 3> ab{}, ac{};  // b - a, c - a
  std::array<double, 3> normal{};    // ab x ac (not unit)

  DrawnTriangle() = default;
  // Corners in any rotation of one order: the triangle starts at its smallest corner (by x,
  // then y, then z), so every measure gives the same bits whichever corner a mesh (or its
  // Draco encoding) lists first.
  DrawnTriangle(const EcefPoint& p, const EcefPoint& q, const EcefPoint& r) {
    const auto less = [](const EcefPoint& u, const EcefPoint& v) {
      return u.x != v.x ? u.x < v.x : u.y != v.y ? u.y < v.y : u.z < v.z;
    };
    if (less(q, p) && !less(r, q)) set(q, r, p);
    else if (less(r, p) && less(r, q)) set(r, p, q);
    else set(p, q, r);
  }

  bool degenerate() const { return degenerate_; }
  // The corners in the triangle's own order (a first).
  const EcefPoint& corner(int k) const { return k == 0 ? a : k == 1 ? b_ : c_; }
  // The longest edge, metres.
  double longestEdge() const { return std::sqrt(longest2_); }

  // Signed distance along `up` (unit) from `point` to the plane; NaN when up runs along it.
  // A corner's own point is on the plane: 0 (whatever the rounding, which a plane that nearly
  // holds the vertical, at a pole, would blow up).
  template <typename Up>
  double offset(const EcefPoint& point, const Up& up) const {
    if (isCorner(point)) return 0;
    const double along = normal[0] * up[0] + normal[1] * up[1] + normal[2] * up[2];
    if (along == 0) return std::numeric_limits<double>::quiet_NaN();
    return (normal[0] * (a.x - point.x) + normal[1] * (a.y - point.y) + normal[2] * (a.z - point.z)) / along;
  }

  // Whether the line point + t * up meets the closed triangle within kReach of the point; if
  // so, *offset = t. (Every vertical crosses the polar axis some 6,400 km down and reaches the
  // far side of the globe: what it meets there is not drawn above the point.)
  // Moeller-Trumbore: a + u ab + v ac = point + t up.
  static constexpr double kReach_m = 3.2e6;
  template <typename Up>
  bool meets(const EcefPoint& point, const Up& up, double* offset_m) const {
    constexpr double kTolerance = 1e-9;
    if (degenerate_) return false;
    const double ux = up[0], uy = up[1], uz = up[2];
    const double px = uy * ac[2] - uz * ac[1], py = uz * ac[0] - ux * ac[2], pz = ux * ac[1] - uy * ac[0];
    const double det = ab[0] * px + ab[1] * py + ab[2] * pz;
    if (det == 0 || !std::isfinite(det)) return false;
    const double inverse = 1.0 / det;
    const double tx = point.x - a.x, ty = point.y - a.y, tz = point.z - a.z;
    const double u = (tx * px + ty * py + tz * pz) * inverse;
    if (u < -kTolerance || u > 1 + kTolerance) return false;
    const double qx = ty * ab[2] - tz * ab[1], qy = tz * ab[0] - tx * ab[2], qz = tx * ab[1] - ty * ab[0];
    const double v = (ux * qx + uy * qy + uz * qz) * inverse;
    if (v < -kTolerance || u + v > 1 + kTolerance) return false;
    // The plane's offset from the point, as offset() computes it (the same bits for the
    // same pair, whichever of the two a caller uses).
    *offset_m = offset(point, up);
    return std::fabs(*offset_m) <= kReach_m;
  }

 private:
  bool isCorner(const EcefPoint& p) const {
    return (p.x == a.x && p.y == a.y && p.z == a.z) || (p.x == b_.x && p.y == b_.y && p.z == b_.z) ||
           (p.x == c_.x && p.y == c_.y && p.z == c_.z);
  }

  void set(const EcefPoint& pa, const EcefPoint& pb, const EcefPoint& pc) {
    a = pa;
    b_ = pb;
    c_ = pc;
    ab = {pb.x - pa.x, pb.y - pa.y, pb.z - pa.z};
    ac = {pc.x - pa.x, pc.y - pa.y, pc.z - pa.z};
    normal = {ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]};
    const double bc[3] = {ac[0] - ab[0], ac[1] - ab[1], ac[2] - ab[2]};
    longest2_ = std::max({ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2], ac[0] * ac[0] + ac[1] * ac[1] + ac[2] * ac[2],
                          bc[0] * bc[0] + bc[1] * bc[1] + bc[2] * bc[2]});
    const double area2_squared = normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2];
    degenerate_ = !(area2_squared > 1e-24 * longest2_ * longest2_);
  }

  EcefPoint b_, c_;
  double longest2_ = 0;
  bool degenerate_ = true;
};

}  // namespace terratiles
