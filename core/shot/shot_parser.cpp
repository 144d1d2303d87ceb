// Shot format v1 reader. The limits below are documented in docs/shot-format.md; keep the two in
// step (tests/core/shot checks the examples and the schema against this file).
#include "core/shot/shot_parser.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <system_error>

#include "core/format.h"
#include "core/io/exr_compression.h"
#include "core/methods/registry.h"
#include "core/phase/henyey_greenstein.h"
#include "core/shot/json_reader.h"
#include "core/shot/shot_sections.h"

namespace cloudbake {
namespace fs = std::filesystem;
using shotjson::Json;
using shotjson::kMaxDensity;
using shotjson::Object;
using shotjson::parseVolume;
using shotjson::Reader;

namespace {

// Limits that keep one shot from exhausting the machine or the user's patience.
constexpr int64_t kMaxImageSide = 16384;  // as core/transport/camera.h
constexpr int64_t kMaxImagePixels = int64_t(1) << 26;
constexpr int64_t kMaxSamples = 1000000;
constexpr int64_t kMaxViews = 256;
constexpr double kMaxVdbVoxels = 512.0 * 512.0 * 512.0;  // matches voxelize()'s default bound
constexpr size_t kMaxShotBytes = 16u << 20;

PhaseSpec parsePhase(const Object& o) {
  const Reader& r = o.reader();
  PhaseSpec p;
  // Without a type, a misspelt "type" is the likelier mistake than a missing one.
  if (!o.has("type")) {
    o.allowOnly(
        {"type", "g", "diameter_um", "effective_radius_um", "effective_variance", "mie_ratio"});
  }
  const std::string type = r.string(o.required("type"), o.path("type"));
  if (type == "isotropic") {
    p.type = PhaseSpec::Type::kIsotropic;
    o.allowOnly({"type", "mie_ratio"}, "for phase type 'isotropic'");
  } else if (type == "hg") {
    p.type = PhaseSpec::Type::kHenyeyGreenstein;
    o.allowOnly({"type", "g", "mie_ratio"}, "for phase type 'hg'");
    p.g = r.numberIn(o.required("g"), o.path("g"), -kMaxHgAsymmetry, kMaxHgAsymmetry);
  } else if (type == "mie_approx") {
    p.type = PhaseSpec::Type::kMieApprox;
    o.allowOnly({"type", "diameter_um", "mie_ratio"}, "for phase type 'mie_approx'");
    p.diameter_um = r.numberIn(o.required("diameter_um"), o.path("diameter_um"), 5, 50);
  } else if (type == "mie") {
    p.type = PhaseSpec::Type::kMie;
    o.allowOnly({"type", "effective_radius_um", "effective_variance", "mie_ratio"},
                "for phase type 'mie'");
    // Ranges of the gamma size distribution the Mie table integrates over.
    p.effective_radius_um =
        r.numberIn(o.required("effective_radius_um"), o.path("effective_radius_um"), 1, 50);
    p.effective_variance = r.numberIn(o.required("effective_variance"),
                                      o.path("effective_variance"), 0.01, 0.5, false, true);
  } else {
    r.fail(o.path("type"),
           "unknown phase type '" + type + "' (known: isotropic, hg, mie_approx, mie)");
  }
  if (auto* v = o.find("mie_ratio")) p.mie_ratio = r.numberIn(*v, o.path("mie_ratio"), 0, 1);
  return p;
}

MediumSpec parseMedium(const Object& o) {
  const Reader& r = o.reader();
  MediumSpec m;
  m.extinction = densityNumber(r, o.required("extinction"), o.path("extinction"), false);
  if (auto* v = o.find("albedo")) m.albedo = r.rgb(*v, o.path("albedo"), 0, 1, true);
  if (auto* v = o.find("phase")) {
    m.phase = parsePhase(Object(r, *v, o.path("phase")));
  }
  return m;
}

Sky parseSky(const Object& o) {
  const Reader& r = o.reader();
  Sky sky;
  constexpr double kMaxRadiance = 1e12;
  if (o.has("radiance")) {
    o.allowOnly({"radiance"}, "beside 'radiance' (a constant sky)");
    sky.type = Sky::Type::kConstant;
    sky.radiance = r.rgb(o.required("radiance"), o.path("radiance"), 0, kMaxRadiance);
  } else if (o.has("map")) {
    o.allowOnly({"map", "scale"}, "beside 'map' (a lat-long EXR sky)");
    sky.type = Sky::Type::kMap;
    sky.map_path = r.filePath(o.required("map"), o.path("map"));
    if (auto* v = o.find("scale")) sky.map_scale = r.numberIn(*v, o.path("scale"), 0, 1e12);
  } else if (o.has("zenith") || o.has("horizon") || o.has("ground")) {
    o.allowOnly({"zenith", "horizon", "ground"}, "beside 'zenith'/'horizon' (a gradient sky)");
    sky.type = Sky::Type::kGradient;
    sky.zenith = r.rgb(o.required("zenith"), o.path("zenith"), 0, kMaxRadiance);
    sky.horizon = r.rgb(o.required("horizon"), o.path("horizon"), 0, kMaxRadiance);
    if (auto* v = o.find("ground")) sky.ground = r.rgb(*v, o.path("ground"), 0, kMaxRadiance);
  } else {
    o.allowOnly({"radiance", "zenith", "horizon", "ground", "map", "scale"});
    r.fail(o.ptr(), "needs radiance, zenith + horizon (+ ground), or map (+ scale)");
  }
  return sky;
}

// The unit vector along `v`, scaled by its largest component first so that neither huge
// components ([1e200, 1e200, 1e200]: its length overflows) nor tiny ones (1e-300: it underflows)
// look like a zero vector; (0, 0, 0) for a zero or non-finite vector.
LightingSpec parseLighting(const Object& o) {
  const Reader& r = o.reader();
  LightingSpec l;
  if (!o.has("sun") && !o.has("sky")) r.fail(o.ptr(), "needs a sun, a sky, or both");
  if (auto* v = o.find("sun")) {
    Object sun(r, *v, o.path("sun"), {"direction", "irradiance"});
    l.has_sun = true;
    const Vec3 d = r.vec3(sun.required("direction"), sun.path("direction"));
    // A vector already of unit length (as serializeShot writes it) is kept bit for bit, so that
    // parseShot(serializeShot(s)) gives back s: normalising again can move the last bit.
    const Vec3 unit = std::abs(length(d) - 1.0) <= 4 * std::numeric_limits<double>::epsilon()
                          ? d
                          : directionOf(d);
    if (!(length(unit) > 0)) {
      r.fail(sun.path("direction"), "must be a non-zero vector (towards the sun), got [" +
                                        exactNumber(d.x) + ", " + exactNumber(d.y) + ", " +
                                        exactNumber(d.z) + "]");
    }
    l.sun.direction = unit;
    l.sun.irradiance = r.rgb(sun.required("irradiance"), sun.path("irradiance"), 0, 1e12);
  }
  if (auto* v = o.find("sky")) l.sky = parseSky(Object(r, *v, o.path("sky")));
  return l;
}

// One knob's value, checked against its table entry.
KnobValue parseKnob(const Object& o, const Knob& k, const Json& v) {
  const Reader& r = o.reader();
  const std::string ptr = o.path(k.key);
  switch (k.type) {
    case Knob::Type::kInteger:
      return r.integer(v, ptr, int64_t(k.min), int64_t(k.max));
    case Knob::Type::kNumber:
      return r.numberIn(v, ptr, k.min, k.max, k.exclusive_min, k.exclusive_max);
    case Knob::Type::kBoolean:
      return r.boolean(v, ptr);
    case Knob::Type::kChoice: {
      const std::string s = r.string(v, ptr);
      if (std::find(k.choices.begin(), k.choices.end(), s) == k.choices.end()) {
        std::string allowed;
        for (size_t i = 0; i < k.choices.size(); ++i) {
          allowed += (i == 0                      ? "'"
                      : i + 1 == k.choices.size() ? " or '"
                                                  : ", '") +
                     k.choices[i] + "'";
        }
        r.fail(ptr, "must be " + allowed + ", got '" + s + "'");
      }
      return s;
    }
  }
  return {};
}

// The method's own knobs, checked against its table; the keys every method has are read by
// parseBake.
KnobValues parseMethodKnobs(const Object& o, const MethodInfo& info) {
  std::vector<std::string> allowed = {"method", "samples", "seed"};
  for (const Knob& k : info.knobs) allowed.push_back(k.key);
  o.allowOnly(allowed, "for method '" + info.name + "'");
  KnobValues knobs = defaultKnobValues(info.knobs);
  for (const Knob& k : info.knobs) {
    if (const Json* v = o.find(k.key.c_str())) {
      knobs.set(k.key, parseKnob(o, k, *v));
    } else if (k.required) {
      o.required(k.key.c_str());  // fails "<ptr>: missing (required)"
    }
  }
  return knobs;
}

BakeSpec parseBake(const Object& o) {
  const Reader& r = o.reader();
  BakeSpec b;
  if (auto* v = o.find("method")) {
    b.method = r.string(*v, o.path("method"));
    if (!findMethod(b.method)) {
      r.fail(o.path("method"),
             "unknown method '" + b.method + "' (known: " + joinedMethodNames() + ")");
    }
  }
  const MethodInfo& info = findMethod(b.method)->info();
  b.samples = info.default_samples;
  if (auto* v = o.find("samples")) {
    // auto chooses the samples with the method; a number here would be ignored or would break
    // the tolerance it promises.
    if (info.name == "auto") {
      r.fail(o.path("samples"),
             "method 'auto' chooses the samples with the method, from /bake/tolerance: leave it "
             "out (the command line's --samples overrides the choice)");
    }
    b.samples =
        int(r.integer(*v, o.path("samples"), 1, std::min(kMaxSamples, int64_t(info.max_samples))));
  }
  if (auto* v = o.find("seed")) b.seed = r.unsignedInteger(*v, o.path("seed"));
  b.knobs = parseMethodKnobs(o, info);
  return b;
}

bool isSafeNameChar(char c) {
  return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.' || c == '-';
}

Camera parseView(const Object& o) {
  const Reader& r = o.reader();
  Camera cam;
  cam.name = r.string(o.required("name"), o.path("name"));
  if (cam.name.empty() || cam.name.size() > 128) {
    r.fail(o.path("name"), "must be 1 to 128 characters");
  }
  if (!std::all_of(cam.name.begin(), cam.name.end(), isSafeNameChar) || cam.name[0] == '.') {
    r.fail(o.path("name"), "'" + cam.name +
                               "' is not a safe file name (use A-Z a-z 0-9 _ . -, not starting "
                               "with '.')");
  }
  std::string lower = cam.name;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (lower == "bake") r.fail(o.path("name"), "'bake' is reserved (DIR/bake.vdb)");

  Object c(r, o.required("camera"), o.path("camera"));
  if (!c.has("type")) c.allowOnly({"type", "fov_deg", "width", "position", "look_at", "up"});
  const std::string type = r.string(c.required("type"), c.path("type"));
  if (type == "perspective") {
    cam.type = Camera::Type::kPerspective;
    c.allowOnly({"type", "fov_deg", "position", "look_at", "up"}, "for a perspective camera");
    if (auto* v = c.find("fov_deg"))
      cam.fov_deg = r.numberIn(*v, c.path("fov_deg"), 0, 180, true, true);
  } else if (type == "orthographic") {
    cam.type = Camera::Type::kOrthographic;
    c.allowOnly({"type", "width", "position", "look_at", "up"}, "for an orthographic camera");
    cam.width = r.numberIn(c.required("width"), c.path("width"), 0, 1e12, true);
  } else {
    r.fail(c.path("type"), "unknown camera type '" + type + "' (known: perspective, orthographic)");
  }
  cam.position = r.point(c.required("position"), c.path("position"));
  cam.look_at = r.point(c.required("look_at"), c.path("look_at"));
  if (auto* v = c.find("up")) cam.up = r.vec3(*v, c.path("up"));
  const Vec3 forward = cam.look_at - cam.position;
  if (!(length(directionOf(forward)) > 0)) r.fail(c.path("look_at"), "must differ from position");
  if (!(length(directionOf(cam.up)) > 0)) r.fail(c.path("up"), "must be a non-zero vector");
  if (length(cross(directionOf(forward), directionOf(cam.up))) < 1e-6) {
    r.fail(c.path("up"), "must not be parallel to the view direction (look_at - position)");
  }

  const Json& res = o.required("resolution");
  const std::string rp = o.path("resolution");
  if (!res.is_array() || res.size() != 2) {
    r.fail(rp, "must be [width, height] in pixels, got " +
                   (res.is_array() ? "an array of " + std::to_string(res.size())
                                   : shotjson::typeName(res)));
  }
  const int64_t w = r.integer(res[0], rp + "/0", 1, kMaxImageSide);
  const int64_t h = r.integer(res[1], rp + "/1", 1, kMaxImageSide);
  if (w * h > kMaxImagePixels) {
    r.fail(rp, std::to_string(w) + "x" + std::to_string(h) + " is more than " +
                   std::to_string(kMaxImagePixels) + " pixels");
  }
  cam.width_px = int(w);
  cam.height_px = int(h);
  return cam;
}

// A non-empty list of distinct names of kExrLayerNames, kept in the file's order.
std::vector<std::string> parseExrLayers(const Reader& r, const Json& v, const std::string& ptr) {
  const std::string known = "known: cloud, background, beauty, sun, sky, single, multiple";
  if (!v.is_array()) {
    r.fail(ptr, "must be an array of layer names (" + known + "), got " + shotjson::typeName(v));
  }
  if (v.empty()) r.fail(ptr, "must name at least one layer (" + known + ")");
  std::vector<bool> chosen(kExrLayerNames.size(), false);
  for (size_t i = 0; i < v.size(); ++i) {
    const std::string item = ptr + "/" + std::to_string(i);
    const std::string name = r.string(v[i], item);
    const auto it = std::find(kExrLayerNames.begin(), kExrLayerNames.end(), name);
    if (it == kExrLayerNames.end()) r.fail(item, "unknown layer '" + name + "' (" + known + ")");
    const size_t k = size_t(it - kExrLayerNames.begin());
    if (chosen[k]) r.fail(item, "layer '" + name + "' is listed twice");
    chosen[k] = true;
  }
  std::vector<std::string> layers;
  for (size_t k = 0; k < kExrLayerNames.size(); ++k) {
    if (chosen[k]) layers.push_back(kExrLayerNames[k]);
  }
  return layers;
}

OutputSpec parseOutputs(const Object& o) {
  const Reader& r = o.reader();
  OutputSpec out;
  if (auto* v = o.find("exr")) out.exr = r.boolean(*v, o.path("exr"));
  if (auto* v = o.find("vdb")) out.vdb = r.boolean(*v, o.path("vdb"));
  if (auto* v = o.find("vdb_voxel_size")) {
    out.vdb_voxel_size = r.numberIn(*v, o.path("vdb_voxel_size"), 0, 1e12, true);
  }
  if (auto* v = o.find("exr_compression")) {
    const std::string ptr = o.path("exr_compression");
    out.exr_compression = r.string(*v, ptr);
    if (!exrCompressionFromName(out.exr_compression)) {
      r.fail(ptr, "unknown EXR compression '" + out.exr_compression +
                      "' (known: " + exrCompressionNamesList() + "; lossless only)");
    }
    if (!out.exr) r.fail(ptr, "applies only when /outputs/exr is true");
  }
  if (auto* v = o.find("exr_layers")) {
    out.exr_layers = parseExrLayers(r, *v, o.path("exr_layers"));
    if (!out.exr) r.fail(o.path("exr_layers"), "applies only when /outputs/exr is true");
  }
  // A shot that writes nothing would bake, succeed and hand back no file (an outside probe of
  // the server found such a job "succeeded" with no outputs).
  if (!out.exr && !out.vdb) {
    r.fail(o.ptr(), "asks for nothing: exr and vdb are both false (set one of them to true)");
  }
  return out;
}

// Cross-section checks: they need more than one part of the shot.
void checkOutputsAgainstVolume(const Reader& r, const ShotSpec& shot) {
  const std::optional<Bounds3> b = statedBounds(shot.volume);
  const OutputSpec& out = shot.outputs;
  // Bake methods write their own lattice (light_resolution), whatever the volume.
  if (methodOf(shot).info().bakes_light) {
    if (out.vdb_voxel_size > 0) {
      r.fail("/outputs/vdb_voxel_size",
             std::string("does not apply to method '") + shot.bake.method +
                 "' (its bake.vdb is the bake lattice; set bake.light_resolution instead)");
    }
    return;
  }
  if (!b) {
    if (out.vdb_voxel_size > 0) {
      r.fail("/outputs/vdb_voxel_size", std::string("only applies to box and sphere volumes (a ") +
                                            volumeTypeName(shot.volume) +
                                            " volume keeps its own voxels)");
    }
    return;
  }
  if (!out.vdb) return;
  if (!(out.vdb_voxel_size > 0)) {
    r.fail("/outputs/vdb_voxel_size",
           std::string("missing: required when outputs.vdb is true for a ") +
               volumeTypeName(shot.volume) + " volume");
  }
  // A voxel wider than the volume's thinnest side cannot hold its shape: a 4 x 4 x 1 box at a
  // voxel of 3 came out a 3 x 3 x 3 cube, at 1e12 one voxel 1e12 across, and the run succeeded.
  const double thinnest = std::min({b->extent().x, b->extent().y, b->extent().z});
  if (out.vdb_voxel_size > thinnest) {
    r.fail("/outputs/vdb_voxel_size",
           "is " + exactNumber(out.vdb_voxel_size) + ", wider than the volume's thinnest side (" +
               exactNumber(thinnest) +
               "): its grid could not hold the shape (use at most that, and a few voxels across "
               "for a recognisable one)");
  }
  double voxels = 1;
  for (int a = 0; a < 3; ++a) voxels *= std::ceil(b->extent()[a] / out.vdb_voxel_size);
  if (!(voxels <= kMaxVdbVoxels)) {
    std::ostringstream os;
    os << "gives " << voxels << " voxels over the volume's bounds; the limit is "
       << std::int64_t(kMaxVdbVoxels) << " (use a larger voxel size)";
    r.fail("/outputs/vdb_voxel_size", os.str());
  }
}

}  // namespace

std::vector<std::string> shotTopLevelKeys() {
  return {"version", "name", "volume", "medium", "lighting", "bake", "views", "outputs"};
}

ShotSpec parseShot(const std::string& json_text, const std::string& base_dir,
                   const ParseOptions& options) {
  const std::string& src = options.source_name;
  if (json_text.size() > kMaxShotBytes) {
    throw InputError(src + ": /: larger than " + std::to_string(kMaxShotBytes) + " bytes");
  }
  shotjson::PathPolicy policy;
  std::error_code ec;
  policy.base_dir = fs::absolute(base_dir.empty() ? fs::path(".") : fs::path(base_dir), ec);
  if (ec) throw InputError(src + ": cannot resolve folder '" + base_dir + "': " + ec.message());
  for (const std::string& root : options.allowed_roots) {
    fs::path c = fs::weakly_canonical(fs::absolute(root, ec), ec);
    if (ec) throw InputError("allowed root '" + root + "' cannot be resolved: " + ec.message());
    policy.allowed_roots.push_back(c);
  }
  policy.check_exists = options.check_files_exist;
  const Reader r(src, std::move(policy));

  const Json doc = shotjson::parseStrict(json_text, src);
  if (!doc.is_object()) r.fail("/", "a shot must be a JSON object, got " + shotjson::typeName(doc));
  Object root(r, doc, "");
  // The version decides which keys are valid, so it is checked before anything else.
  const Json* version = root.find("version");
  if (!version) r.fail("/version", "missing (required; this build reads version 1)");
  if (!version->is_number())
    r.fail("/version", "must be the number 1, got " + shotjson::typeName(*version));
  if (version->get<double>() != 1.0) {
    r.fail("/version",
           "unsupported shot format version " + version->dump() + " (this build reads version 1)");
  }
  root.allowOnly({"version", "name", "volume", "medium", "lighting", "bake", "views", "outputs"});

  ShotSpec shot;
  if (auto* v = root.find("name")) {
    shot.name = r.string(*v, "/name");
    if (shot.name.empty() || shot.name.size() > 128 ||
        !std::all_of(shot.name.begin(), shot.name.end(), isSafeNameChar)) {
      r.fail("/name", "must be 1 to 128 characters of A-Z a-z 0-9 _ . -");
    }
  }
  shot.volume = parseVolume(Object(r, root.required("volume"), "/volume"));
  shot.medium =
      parseMedium(Object(r, root.required("medium"), "/medium", {"extinction", "albedo", "phase"}));
  shot.lighting = parseLighting(Object(r, root.required("lighting"), "/lighting", {"sun", "sky"}));
  const Json no_bake = Json::object();
  const Json* bake = root.find("bake");
  shot.bake = parseBake(Object(r, bake ? *bake : no_bake, "/bake"));
  if (auto* v = root.find("outputs")) {
    shot.outputs = parseOutputs(Object(
        r, *v, "/outputs", {"exr", "vdb", "vdb_voxel_size", "exr_compression", "exr_layers"}));
  }
  if (auto* v = root.find("views")) {
    if (!v->is_array())
      r.fail("/views", "must be an array of views, got " + shotjson::typeName(*v));
    if (int64_t(v->size()) > kMaxViews) {
      r.fail("/views", "at most " + std::to_string(kMaxViews) + " views");
    }
    std::map<std::string, std::string> seen;  // lower-case name -> pointer
    for (size_t i = 0; i < v->size(); ++i) {
      const std::string ptr = "/views/" + std::to_string(i);
      shot.views.push_back(parseView(Object(r, (*v)[i], ptr, {"name", "camera", "resolution"})));
      std::string key = shot.views.back().name;
      std::transform(key.begin(), key.end(), key.begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
      auto [it, inserted] = seen.emplace(key, ptr + "/name");
      if (!inserted) {
        r.fail(ptr + "/name", "duplicate view name '" + shot.views.back().name + "' (also " +
                                  it->second + "; names are compared ignoring case)");
      }
    }
  }
  if (shot.views.empty() && shot.outputs.exr) {
    r.fail("/views", "needs at least one view when outputs.exr is true");
  }
  checkOutputsAgainstVolume(r, shot);
  // Knobs that depend on each other or on the volume: the method's own checks.
  methodOf(shot).validate(shot, src);
  return shot;
}

ShotSpec parseShotFile(const std::string& path, ParseOptions options) {
  options.source_name = path;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (!fs::exists(st)) throw MissingFileError(path + ": file not found");
  if (!fs::is_regular_file(st)) throw InputError(path + ": not a regular file");
  const auto size = fs::file_size(path, ec);
  if (ec) throw InputError(path + ": cannot read: " + ec.message());
  if (size > kMaxShotBytes) {
    throw InputError(path + ": larger than " + std::to_string(kMaxShotBytes) + " bytes");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open for reading");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw InputError(path + ": read error");
  fs::path base = fs::absolute(fs::path(path), ec).parent_path();
  return parseShot(text.str(), base.string(), options);
}

}  // namespace cloudbake
