#include "core/volume/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace cloudbake {
namespace {

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path + ": cannot open mesh file");
  std::ostringstream os;
  os << in.rdbuf();
  if (in.bad()) throw InputError(path + ": error while reading mesh file");
  return os.str();
}

bool parseDouble(const char* b, const char* e, double* out) {
  if (b != e && *b == '+') ++b;
  const auto r = std::from_chars(b, e, *out);
  return r.ec == std::errc() && r.ptr == e;
}

bool parseInt(const char* b, const char* e, long long* out) {
  if (b != e && *b == '+') ++b;
  const auto r = std::from_chars(b, e, *out);
  return r.ec == std::errc() && r.ptr == e;
}

void checkMesh(const TriangleMesh& mesh, const std::string& path) {
  if (mesh.triangles.empty()) throw InputError(path + ": mesh has no triangles");
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    if (!isFinite(mesh.vertices[i])) {
      throw InputError(path + ": vertex " + std::to_string(i) + " has a non-finite coordinate");
    }
  }
}

// ---- OBJ -----------------------------------------------------------------------------------

TriangleMesh parseObj(const std::string& text, const std::string& path) {
  TriangleMesh mesh;
  std::vector<int64_t> face;
  std::vector<const char*> tokens_b, tokens_e;
  size_t pos = 0;
  int64_t line_no = 0;
  auto fail = [&](const std::string& why) {
    throw InputError(path + ":" + std::to_string(line_no) + ": " + why);
  };
  // A UTF-8 byte-order mark (some Windows exporters write one) would make the first line's
  // key unknown, and so silently drop it.
  if (text.compare(0, 3, "\xEF\xBB\xBF") == 0) pos = 3;
  while (pos < text.size()) {
    ++line_no;
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    const char* b = text.data() + pos;
    const char* e = text.data() + end;
    pos = end + 1;
    tokens_b.clear();
    tokens_e.clear();
    for (const char* c = b; c < e;) {
      while (c < e && std::isspace(static_cast<unsigned char>(*c))) ++c;
      if (c >= e || *c == '#') break;
      const char* t = c;
      while (c < e && !std::isspace(static_cast<unsigned char>(*c))) ++c;
      tokens_b.push_back(t);
      tokens_e.push_back(c);
    }
    if (tokens_b.empty()) continue;
    const std::string_view key(tokens_b[0], tokens_e[0] - tokens_b[0]);
    if (key == "v") {
      if (tokens_b.size() < 4) fail("vertex needs 3 coordinates");
      Vec3 v;
      for (int a = 0; a < 3; ++a) {
        if (!parseDouble(tokens_b[a + 1], tokens_e[a + 1], &v[a])) {
          fail("bad vertex coordinate '" + std::string(tokens_b[a + 1], tokens_e[a + 1]) + "'");
        }
      }
      if (!isFinite(v)) fail("non-finite vertex coordinate");
      mesh.vertices.push_back(v);
    } else if (key == "f") {
      face.clear();
      for (size_t t = 1; t < tokens_b.size(); ++t) {
        const char* slash = std::find(tokens_b[t], tokens_e[t], '/');
        long long idx = 0;
        if (!parseInt(tokens_b[t], slash, &idx) || idx == 0) {
          fail("bad face index '" + std::string(tokens_b[t], tokens_e[t]) + "'");
        }
        const int64_t n = static_cast<int64_t>(mesh.vertices.size());
        const int64_t abs_idx = idx < 0 ? n + idx : idx - 1;
        if (abs_idx < 0 || abs_idx >= n) {
          fail("face index " + std::to_string(idx) + " out of range (" + std::to_string(n) +
               " vertices so far)");
        }
        face.push_back(abs_idx);
      }
      if (face.size() < 3) fail("face needs at least 3 vertices");
      for (size_t k = 1; k + 1 < face.size(); ++k) {
        mesh.triangles.push_back({static_cast<int32_t>(face[0]), static_cast<int32_t>(face[k]),
                                  static_cast<int32_t>(face[k + 1])});
      }
    }
  }
  checkMesh(mesh, path);
  return mesh;
}

// ---- PLY -----------------------------------------------------------------------------------

enum class PlyType { kInt8, kUInt8, kInt16, kUInt16, kInt32, kUInt32, kFloat32, kFloat64 };

bool plyType(const std::string& s, PlyType* t) {
  static const struct {
    const char* name;
    PlyType type;
  } kTypes[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUInt8},
      {"uint8", PlyType::kUInt8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUInt16},  {"uint16", PlyType::kUInt16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUInt32},     {"uint32", PlyType::kUInt32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& k : kTypes) {
    if (s == k.name) {
      *t = k.type;
      return true;
    }
  }
  return false;
}

size_t plySize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUInt8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUInt16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUInt32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 1;
}

bool isIntegerType(PlyType t) { return t != PlyType::kFloat32 && t != PlyType::kFloat64; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUInt8;
};

struct PlyElement {
  std::string name;
  int64_t count = 0;
  std::vector<PlyProperty> props;
};

enum class PlyFormat { kAscii, kLittle, kBig };

// Reads scalar values from the body, ASCII tokens or binary, with bounds checks.
class PlyBody {
 public:
  PlyBody(const std::string& text, size_t pos, PlyFormat format, const std::string& path)
      : text_(text), pos_(pos), format_(format), path_(path) {}

  void setContext(const std::string& element, int64_t index) {
    element_ = &element;
    index_ = index;
  }

  double read(PlyType t) {
    if (format_ == PlyFormat::kAscii) return readAscii(t);
    const size_t n = plySize(t);
    if (pos_ + n > text_.size()) fail("file is truncated");
    unsigned char bytes[8];
    std::memcpy(bytes, text_.data() + pos_, n);
    pos_ += n;
    const bool little_host = [] {
      const uint16_t one = 1;
      unsigned char c;
      std::memcpy(&c, &one, 1);
      return c == 1;
    }();
    if ((format_ == PlyFormat::kLittle) != little_host) std::reverse(bytes, bytes + n);
    switch (t) {
      case PlyType::kInt8: {
        int8_t v;
        std::memcpy(&v, bytes, 1);
        return v;
      }
      case PlyType::kUInt8:
        return bytes[0];
      case PlyType::kInt16: {
        int16_t v;
        std::memcpy(&v, bytes, 2);
        return v;
      }
      case PlyType::kUInt16: {
        uint16_t v;
        std::memcpy(&v, bytes, 2);
        return v;
      }
      case PlyType::kInt32: {
        int32_t v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kUInt32: {
        uint32_t v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kFloat32: {
        float v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kFloat64: {
        double v;
        std::memcpy(&v, bytes, 8);
        return v;
      }
    }
    return 0;
  }

  [[noreturn]] void fail(const std::string& why) const {
    throw InputError(path_ + ": " + (element_ ? *element_ : std::string("body")) + " " +
                     std::to_string(index_) + ": " + why);
  }

 private:
  double readAscii(PlyType t) {
    while (pos_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
    if (pos_ >= text_.size()) fail("file is truncated");
    const size_t start = pos_;
    while (pos_ < text_.size() && !std::isspace(static_cast<unsigned char>(text_[pos_]))) ++pos_;
    const char* b = text_.data() + start;
    const char* e = text_.data() + pos_;
    double v = 0;
    if (isIntegerType(t)) {
      long long i = 0;
      if (!parseInt(b, e, &i)) fail("bad integer '" + std::string(b, e) + "'");
      v = static_cast<double>(i);
    } else if (!parseDouble(b, e, &v)) {
      fail("bad number '" + std::string(b, e) + "'");
    }
    return v;
  }

  const std::string& text_;
  size_t pos_;
  PlyFormat format_;
  const std::string& path_;
  const std::string* element_ = nullptr;
  int64_t index_ = 0;
};

// The header: format, elements and their properties, and where the body starts.
struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t body = 0;  // offset of the first byte after end_header
};

// Reads the header line by line; errors name the line.
class PlyHeaderReader {
 public:
  PlyHeaderReader(const std::string& text, const std::string& path) : text_(text), path_(path) {}

  PlyHeader read() {
    if (nextLine() != "ply") fail("not a PLY file (first line must be 'ply')");
    PlyHeader header;
    bool have_format = false;
    for (;;) {
      const std::string line = nextLine();
      std::istringstream ls(line);
      std::string key;
      ls >> key;
      if (key.empty() || key == "comment" || key == "obj_info") continue;
      if (key == "end_header") break;
      if (key == "format") {
        header.format = format(ls);
        have_format = true;
      } else if (key == "element") {
        header.elements.push_back(element(ls, line));
      } else if (key == "property") {
        if (header.elements.empty()) fail("property before any element");
        header.elements.back().props.push_back(property(ls, line));
      } else {
        fail("unknown header keyword '" + key + "'");
      }
    }
    if (!have_format) fail("header has no format line");
    header.body = pos_;
    return header;
  }

 private:
  [[noreturn]] void fail(const std::string& why) const {
    throw InputError(path_ + ":" + std::to_string(line_no_) + ": " + why);
  }

  std::string nextLine() {
    if (pos_ >= text_.size()) fail("header ends before end_header");
    size_t end = text_.find('\n', pos_);
    if (end == std::string::npos) end = text_.size();
    std::string line = text_.substr(pos_, end - pos_);
    pos_ = end + 1;
    ++line_no_;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return line;
  }

  PlyFormat format(std::istringstream& ls) const {
    std::string f, version;
    ls >> f >> version;
    if (f == "ascii") return PlyFormat::kAscii;
    if (f == "binary_little_endian") return PlyFormat::kLittle;
    if (f == "binary_big_endian") return PlyFormat::kBig;
    fail("unknown format '" + f + "'");
  }

  PlyElement element(std::istringstream& ls, const std::string& line) const {
    PlyElement el;
    std::string count;
    ls >> el.name >> count;
    long long c = -1;
    if (el.name.empty() || !parseInt(count.data(), count.data() + count.size(), &c) || c < 0) {
      fail("bad element line '" + line + "'");
    }
    // Every element takes at least one byte, so larger counts mean a corrupt header.
    if (static_cast<unsigned long long>(c) > text_.size()) {
      fail("element count " + count + " exceeds the file size");
    }
    el.count = c;
    return el;
  }

  PlyProperty property(std::istringstream& ls, const std::string& line) const {
    PlyProperty p;
    std::string type;
    ls >> type;
    if (type == "list") {
      std::string count_type, item_type;
      ls >> count_type >> item_type >> p.name;
      p.is_list = true;
      if (!plyType(count_type, &p.count_type) || !isIntegerType(p.count_type) ||
          !plyType(item_type, &p.type)) {
        fail("bad list property '" + line + "'");
      }
    } else {
      ls >> p.name;
      if (!plyType(type, &p.type)) fail("unknown property type '" + type + "'");
    }
    if (p.name.empty()) fail("property without a name");
    return p;
  }

  const std::string& text_;
  const std::string& path_;
  size_t pos_ = 0;
  int line_no_ = 0;
};

// Which properties of an element the mesh reads: x, y, z of a vertex, the index list of a face
// (-1: none).
struct PlyRoles {
  int xyz[3] = {-1, -1, -1};
  int indices = -1;
};

// The roles of `el`'s properties; InputError when a vertex or face element lacks what the mesh
// needs.
PlyRoles plyRoles(const PlyElement& el, const std::string& path) {
  PlyRoles roles;
  for (size_t i = 0; i < el.props.size(); ++i) {
    const PlyProperty& p = el.props[i];
    if (el.name == "vertex" && !p.is_list) {
      for (int a = 0; a < 3; ++a)
        if (p.name == std::string(1, static_cast<char>('x' + a)))
          roles.xyz[a] = static_cast<int>(i);
    }
    if (el.name == "face" && p.is_list &&
        (p.name == "vertex_indices" || p.name == "vertex_index")) {
      roles.indices = static_cast<int>(i);
    }
  }
  if (el.name == "vertex" && (roles.xyz[0] < 0 || roles.xyz[1] < 0 || roles.xyz[2] < 0)) {
    throw InputError(path + ": element vertex needs properties x, y and z");
  }
  if (el.name == "face") {
    if (roles.indices < 0) {
      throw InputError(path + ": element face needs a list property vertex_indices");
    }
    if (!isIntegerType(el.props[roles.indices].type)) {
      throw InputError(path + ": face vertex_indices must have an integer type");
    }
  }
  return roles;
}

// Reads every item of `el` from the body: vertices and faces (fanned into triangles) into
// `mesh`, other elements skipped.
void readPlyElement(const PlyElement& el, const PlyRoles& roles, PlyBody& body,
                    TriangleMesh& mesh) {
  std::vector<int64_t> face;
  for (int64_t n = 0; n < el.count; ++n) {
    body.setContext(el.name, n);
    Vec3 v;
    for (size_t i = 0; i < el.props.size(); ++i) {
      const PlyProperty& p = el.props[i];
      if (!p.is_list) {
        const double value = body.read(p.type);
        for (int a = 0; a < 3; ++a)
          if (static_cast<int>(i) == roles.xyz[a]) v[a] = value;
        continue;
      }
      const double count = body.read(p.count_type);
      if (count < 0 || count > 1e6) body.fail("bad list length " + std::to_string(count));
      const bool is_face = static_cast<int>(i) == roles.indices;
      if (is_face) face.clear();
      for (int k = 0; k < static_cast<int>(count); ++k) {
        const double value = body.read(p.type);
        if (is_face) face.push_back(static_cast<int64_t>(value));
      }
    }
    if (el.name == "vertex") {
      if (!isFinite(v)) body.fail("non-finite coordinate");
      mesh.vertices.push_back(v);
    } else if (el.name == "face") {
      if (face.size() < 3) body.fail("face needs at least 3 vertices");
      for (int64_t idx : face) {
        if (idx < 0 || idx >= static_cast<int64_t>(mesh.vertices.size())) {
          body.fail("vertex index " + std::to_string(idx) + " out of range (" +
                    std::to_string(mesh.vertices.size()) + " vertices)");
        }
      }
      for (size_t k = 1; k + 1 < face.size(); ++k) {
        mesh.triangles.push_back({static_cast<int32_t>(face[0]), static_cast<int32_t>(face[k]),
                                  static_cast<int32_t>(face[k + 1])});
      }
    }
  }
}

TriangleMesh parsePly(const std::string& text, const std::string& path) {
  const PlyHeader header = PlyHeaderReader(text, path).read();
  TriangleMesh mesh;
  bool have_vertices = false, have_faces = false;
  PlyBody body(text, header.body, header.format, path);
  for (const PlyElement& el : header.elements) {
    const PlyRoles roles = plyRoles(el, path);
    if (el.name == "vertex") {
      have_vertices = true;
      mesh.vertices.reserve(el.count);
    }
    if (el.name == "face") have_faces = true;
    readPlyElement(el, roles, body, mesh);
  }
  if (!have_vertices) throw InputError(path + ": PLY file has no vertex element");
  if (!have_faces) throw InputError(path + ": PLY file has no face element");
  checkMesh(mesh, path);
  return mesh;
}

}  // namespace

TriangleMesh readObj(const std::string& path) { return parseObj(readFile(path), path); }

TriangleMesh readPly(const std::string& path) { return parsePly(readFile(path), path); }

TriangleMesh readMesh(const std::string& path) {
  const size_t dot = path.find_last_of('.');
  std::string ext = dot == std::string::npos ? "" : path.substr(dot + 1);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == "obj") return readObj(path);
  if (ext == "ply") return readPly(path);
  throw InputError(path + ": unsupported mesh format '." + ext + "' (expected .obj or .ply)");
}

}  // namespace cloudbake
