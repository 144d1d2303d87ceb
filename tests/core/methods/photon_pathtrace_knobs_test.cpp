// The knobs of methods photon and pathtrace added this round: parsed, validated with the field
// named, checked against the server's limits, and described in the dry-run plan.
#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "core/methods/pathtrace.h"
#include "core/methods/photon.h"
#include "core/shot/shot_parser.h"

namespace cloudbake {
namespace {

std::string shot(const std::string& bake) {
  return R"({"version": 1, "name": "k",
    "volume": {"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}},
    "medium": {"extinction": 3, "albedo": 0.95, "phase": {"type": "hg", "g": 0.6}},
    "lighting": {"sun": {"direction": [0, 0, 1], "irradiance": [1, 1, 1]},
                 "sky": {"radiance": [0.1, 0.1, 0.1]}},
    "bake": )" +
         bake + R"(,
    "views": [{"name": "v", "camera": {"type": "orthographic", "position": [0, -5, 0],
               "look_at": [0, 0, 0], "up": [0, 0, 1], "width": 2.5}, "resolution": [8, 8]}]})";
}

void expectRejected(const std::string& bake, const std::string& field) {
  try {
    parseShot(shot(bake), "");
    ADD_FAILURE() << bake << ": accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(field), std::string::npos) << e.what();
  }
}

TEST(PhotonKnobs, ParsedAndValidated) {
  const ShotSpec s = parseShot(
      shot(R"({"method": "photon", "photons": 5000, "order": 5, "light_resolution": 40})"), "");
  const PhotonBakeOptions o = photonBakeOptions(s);
  EXPECT_EQ(o.photons, 5000);
  EXPECT_EQ(o.order, 5);
  EXPECT_EQ(o.light_resolution, 40);
  EXPECT_TRUE(o.sky);
  expectRejected(R"({"method": "photon", "order": 9})", "/bake/order");
  expectRejected(R"({"method": "photon", "order": 0})", "/bake/order");
  EXPECT_EQ(o.zonal_order, PhotonBakeOptions{}.zonal_order);
  EXPECT_EQ(photonBakeOptions(parseShot(shot(R"({"method": "photon", "zonal_order": 0})"), ""))
                .zonal_order,
            0);
  expectRejected(R"({"method": "photon", "order": 5, "zonal_order": 5})", "/bake/zonal_order");
  expectRejected(R"({"method": "photon", "zonal_order": 65})", "/bake/zonal_order");
  expectRejected(R"({"method": "photon", "tally_resolution": 4})", "/bake/tally_resolution");
  expectRejected(R"({"method": "photon", "tally_resolution": 2048})", "/bake/tally_resolution");
  EXPECT_EQ(
      photonBakeOptions(parseShot(shot(R"({"method": "photon", "tally_resolution": 24})"), ""))
          .tally_resolution,
      24);
  expectRejected(R"({"method": "photon", "zonal_order": -1})", "/bake/zonal_order");
  expectRejected(R"({"method": "photon", "photons": 10})", "/bake/photons");
  expectRejected(R"({"method": "photon", "photons": "many"})", "/bake/photons");
  expectRejected(R"({"method": "photon", "light_resolution": 4})", "/bake/light_resolution");
}

// A backward peak, which photon cannot split off, is refused when the shot is parsed (at submit
// and in the dry run), naming the phase; a forward peak it splits off is accepted.
TEST(PhotonKnobs, ABackwardPeakIsRefusedAtParse) {
  std::string s = shot(R"({"method": "photon"})");
  const std::string hg = R"("g": 0.6)";
  auto with_g = [&](const std::string& g) {
    std::string t = s;
    t.replace(t.find(hg), hg.size(), "\"g\": " + g);
    return t;
  };
  try {
    parseShot(with_g("-0.99"), "shot.json");
    ADD_FAILURE() << "HG -0.99 accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shot.json: /medium/phase: "), std::string::npos)
        << e.what();
  }
  EXPECT_NO_THROW(parseShot(with_g("0.99"), "shot.json"));
  EXPECT_NO_THROW(parseShot(with_g("-0.5"), "shot.json"));
}

TEST(PhotonKnobs, LimitsNameTheLatticeAndTheOrder) {
  MethodLimits limits;
  limits.max_voxels = 25000000;  // the bake's lattice at 128 fits, order 8's tallies do not
  for (const char* knobs : {R"("order": 8)", R"("order": 8, "tally_resolution": 0)"}) {
    const ShotSpec s = parseShot(shot(std::string(R"({"method": "photon", )") + knobs + "}"), "");
    const bool own = photonBakeOptions(s).tally_resolution > 0;
    try {
      photonMethod().checkLimits(s, limits, "shot.json");
      ADD_FAILURE() << knobs << ": no error";
    } catch (const InputError& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(own ? "/bake/tally_resolution" : "/bake/light_resolution"),
                std::string::npos)
          << m;
      EXPECT_NE(m.find("/bake/order 8"), std::string::npos) << m;
    }
    limits.max_voxels = 0;  // no limit
    EXPECT_NO_THROW(photonMethod().checkLimits(s, limits, "shot.json"));
    limits.max_voxels = 25000000;
  }
  // (A sphere at 1024 is refused as it is parsed: its lattice is over kMaxBakeVoxels.)
  const ShotSpec big =
      parseShot(shot(R"({"method": "photon", "light_resolution": 300, "order": 1})"), "");
  try {
    photonMethod().checkLimits(big, limits, "shot.json");
    ADD_FAILURE() << "no error for light_resolution 300";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/bake/light_resolution"), std::string::npos) << e.what();
  }
}

// A lattice the run would refuse (over kMaxBakeVoxels) is refused as the shot is parsed (at
// submit and in a dry run) where the shot gives the volume's bounds, whatever --max-voxels says;
// a flat box at the same resolution fits and is accepted.
TEST(LatticeKnobs, ALatticeOverTheLimitOnASphereOrBoxIsRefusedAtParse) {
  for (const char* method : {"single", "pointcloud", "photon", "precomputed"}) {
    SCOPED_TRACE(method);
    const std::string m = std::string(R"({"method": ")") + method + '"';
    expectRejected(m + R"(, "light_resolution": 400})",
                   "/bake/light_resolution: 400 gives a lattice of 402x402x402 voxels, more than "
                   "the limit of 33554432");
    EXPECT_NO_THROW(parseShot(shot(m + R"(, "light_resolution": 300})"), ""));
    std::string slab = shot(m + R"(, "light_resolution": 1024})");
    const std::string sphere = R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
    slab.replace(slab.find(sphere), sphere.size(),
                 R"({"box": {"min": [-5, -5, 0], "max": [5, 5, 0.04], "density": 1}})");
    EXPECT_NO_THROW(parseShot(slab, ""));
  }
  expectRejected(R"({"method": "photon", "light_resolution": 64, "tally_resolution": 1000})",
                 "/bake/tally_resolution: 1000 gives a lattice of");
  // Bounds whose extent overflows a double name the volume, not the resolution: since positions
  // are held within +-1e15, its corner.
  std::string wide = shot(R"({"method": "single"})");
  const std::string sphere = R"({"sphere": {"center": [0, 0, 0], "radius": 1, "density": 1}})";
  wide.replace(wide.find(sphere), sphere.size(),
               R"({"box": {"min": [-1e308, 0, 0], "max": [1e308, 1, 1], "density": 1}})");
  try {
    parseShot(wide, "");
    ADD_FAILURE() << "a box 2e308 wide was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/volume/box/min/0: must be within +-1e+15 world units"),
              std::string::npos)
        << e.what();
  }
}

TEST(PathtraceKnobs, TrackingAndMajorantCell) {
  const ShotSpec s =
      parseShot(shot(R"({"method": "pathtrace", "tracking": "delta", "majorant_cell": 4})"), "");
  const PathTracerOptions o = pathTracerOptions(s, 1);
  EXPECT_FALSE(o.decomposition_tracking);
  EXPECT_EQ(o.majorant_cell, 4);
  const PathTracerOptions d =
      pathTracerOptions(parseShot(shot(R"({"method": "pathtrace"})"), ""), 1);
  EXPECT_TRUE(d.decomposition_tracking);
  EXPECT_EQ(d.majorant_cell, 0);
  expectRejected(R"({"method": "pathtrace", "majorant_cell": 3})", "/bake/majorant_cell");
  expectRejected(R"({"method": "pathtrace", "majorant_cell": 128})", "/bake/majorant_cell");
  expectRejected(R"({"method": "pathtrace", "tracking": "ratio"})", "/bake/tracking");
}

}  // namespace
}  // namespace cloudbake
