#include "core/animation/precomputed_io.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <type_traits>

#include "core/error.h"

namespace cloudbake {
namespace {
namespace fs = std::filesystem;

static_assert(kPrecomputedFileVersion == 2, "update the magic numbers with the version");
constexpr char kSharedMagic[8] = {'C', 'B', 'P', 'C', 'S', 'H', '0', '2'};
constexpr char kBasicMagic[8] = {'C', 'B', 'P', 'C', 'B', 'V', '0', '2'};
constexpr char kLayoutMagic[8] = {'C', 'B', 'P', 'C', 'L', 'Y', '0', '2'};
constexpr char kDensityMagic[8] = {'C', 'B', 'P', 'C', 'D', 'N', '0', '2'};
// Far above any lattice the limits allow, so a corrupt size fails here, not in an allocation.
constexpr uint64_t kMaxCount = uint64_t(1) << 34;

class Writer {
 public:
  explicit Writer(const std::string& path) : path_(path), out_(path, std::ios::binary) {
    if (!out_) fail("cannot open for writing");
  }
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable<T>::value, "plain data only");
    out_.write(reinterpret_cast<const char*>(&v), sizeof(T));
    noteError();
  }
  template <class T>
  void array(const std::vector<T>& v) {
    put(uint64_t(v.size()));
    out_.write(reinterpret_cast<const char*>(v.data()), std::streamsize(v.size() * sizeof(T)));
    noteError();
  }
  void close() {
    out_.close();
    if (!out_) fail("write failed");
  }

 private:
  // The system's reason where the stream failed first (a later call may overwrite errno).
  void noteError() {
    if (!out_ && error_ == 0) error_ = errno;
  }
  // A full volume is StorageFullError (the server's "no space", exit 4), as every other write
  // to the cache reports it; a database of basic volumes was an internal error there.
  [[noreturn]] void fail(const std::string& what) {
    const int err = error_ != 0 ? error_ : errno;
    const std::string detail =
        path_ + ": " + what + (err != 0 ? ": " + std::string(std::strerror(err)) : "");
    throwIfNoSpace(err, detail);
    throw std::runtime_error(detail);
  }

  std::string path_;
  std::ofstream out_;
  int error_ = 0;
};

class Reader {
 public:
  explicit Reader(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    if (!in_) throw InputError(path + ": cannot open the precomputed file");
  }
  template <class T>
  T get() {
    T v;
    in_.read(reinterpret_cast<char*>(&v), sizeof(T));
    if (!in_) throw InputError(path_ + ": truncated");
    return v;
  }
  template <class T>
  std::vector<T> array(uint64_t expected = UINT64_MAX) {
    const uint64_t n = get<uint64_t>();
    if (n > kMaxCount || (expected != UINT64_MAX && n != expected)) {
      throw InputError(path_ + ": array of " + std::to_string(n) + " values does not fit");
    }
    std::vector<T> v(n);
    in_.read(reinterpret_cast<char*>(v.data()), std::streamsize(n * sizeof(T)));
    if (!in_) throw InputError(path_ + ": truncated");
    return v;
  }
  void magic(const char (&m)[8]) {
    char got[8];
    in_.read(got, 8);
    if (!in_ || std::memcmp(got, m, 8) != 0) {
      throw InputError(path_ + ": not a cloudbake precomputed file of this version");
    }
  }
  void end() {
    in_.peek();
    if (!in_.eof()) throw InputError(path_ + ": trailing bytes");
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ifstream in_;
};

void putGrid(Writer& w, const BakeGrid& g) {
  w.put(g.origin);
  w.put(g.voxel_size);
  w.put(int32_t(g.nx));
  w.put(int32_t(g.ny));
  w.put(int32_t(g.nz));
}

BakeGrid getGrid(Reader& r) {
  BakeGrid g;
  g.origin = r.get<Vec3>();
  g.voxel_size = r.get<double>();
  g.nx = r.get<int32_t>();
  g.ny = r.get<int32_t>();
  g.nz = r.get<int32_t>();
  if (!(g.voxel_size > 0) || g.nx < 1 || g.ny < 1 || g.nz < 1 || g.voxelCount() > kMaxCount) {
    throw InputError(r.path() + ": lattice is not valid");
  }
  return g;
}

std::string basicName(size_t i) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "basic_%04zu.bin", i);
  return buf;
}

// What the layout and the whole database share: the lattices, extinction, the count, the
// receiver mask and the sample tree.
void putLayout(Writer& w, const PrecomputedDatabase& db, uint64_t count) {
  putGrid(w, db.volumes.grid);
  putGrid(w, db.receivers);
  w.put(db.extinction);
  w.put(count);
  w.array(db.receiver_mask);
  w.array(db.tree.points);
  w.array(db.tree.nodes);
  w.put(db.tree.volume);
  w.put(db.tree.cell_radius);
}

uint64_t getLayout(Reader& r, PrecomputedDatabase& db) {
  db.volumes.grid = getGrid(r);
  db.receivers = getGrid(r);
  db.extinction = r.get<double>();
  const uint64_t count = r.get<uint64_t>();
  if (count < 1 || count > 100000) throw InputError(r.path() + ": basic volume count invalid");
  db.receiver_mask = r.array<uint8_t>(db.receivers.voxelCount());
  db.tree.points = r.array<Vec3>();
  const uint64_t k = db.tree.points.size();
  if (k < 1) throw InputError(r.path() + ": no sample points");
  db.tree.nodes = r.array<SampleTreeNode>(2 * k - 1);
  for (const SampleTreeNode& n : db.tree.nodes) {
    const bool leaf = n.left < 0;
    if (n.begin < 0 || n.end > int64_t(k) || n.begin >= n.end ||
        (!leaf && (n.left >= int64_t(2 * k - 1) || n.right < 0 || n.right >= int64_t(2 * k - 1)))) {
      throw InputError(r.path() + ": sample tree is not valid");
    }
  }
  db.tree.volume = r.get<double>();
  db.tree.cell_radius = r.get<double>();
  return count;
}

void putBasic(const std::string& dir, const PrecomputedDatabase& db, size_t i) {
  const BasicVolumePrecompute& b = db.basic[i];
  Writer w((fs::path(dir) / basicName(i)).string());
  w.put(kBasicMagic);
  w.array(db.volumes.frames[i]);
  w.array(b.optical_depth_sh);
  w.array(b.cuts.offsets);
  w.array(b.cuts.nodes);
  w.array(b.cuts.values);
  w.put(b.seconds);
  w.close();
}

void getBasic(const std::string& dir, PrecomputedDatabase& db, size_t i) {
  const size_t n = db.volumes.grid.voxelCount(), nr = db.receivers.voxelCount();
  BasicVolumePrecompute& b = db.basic[i];
  Reader r((fs::path(dir) / basicName(i)).string());
  r.magic(kBasicMagic);
  db.volumes.frames[i] = r.array<float>(n);
  b.optical_depth_sh = r.array<ShCoefficients>(n);
  b.cuts.offsets = r.array<uint64_t>(nr + 1);
  b.cuts.nodes = r.array<uint32_t>(b.cuts.offsets.back());
  b.cuts.values = r.array<float>(b.cuts.offsets.back());
  for (size_t v = 0; v < nr; ++v) {
    if (b.cuts.offsets[0] != 0 || b.cuts.offsets[v] > b.cuts.offsets[v + 1]) {
      throw InputError(r.path() + ": cut offsets are not ordered");
    }
  }
  for (uint32_t node : b.cuts.nodes) {
    if (node >= db.tree.nodes.size()) throw InputError(r.path() + ": cut node out of range");
  }
  b.seconds = r.get<double>();
  r.end();
}

std::string densityName(size_t i) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "density_%04zu.bin", i);
  return buf;
}

void checkRange(const PrecomputedDatabase& db, size_t begin, size_t end, const char* what) {
  if (begin >= end || end > db.volumes.frames.size()) {
    throw InternalError(std::string(what) + ": basic volumes [" + std::to_string(begin) + ", " +
                        std::to_string(end) + ") outside the database's " +
                        std::to_string(db.volumes.frames.size()));
  }
}

}  // namespace

void writePrecomputedDatabase(const std::string& dir, const PrecomputedDatabase& db) {
  fs::create_directories(dir);
  {
    Writer w((fs::path(dir) / "shared.bin").string());
    w.put(kSharedMagic);
    putLayout(w, db, db.basic.size());
    w.array(db.shexp.a());
    w.array(db.shexp.b());
    w.put(db.shexp.range());
    w.close();
  }
  for (size_t i = 0; i < db.basic.size(); ++i) putBasic(dir, db, i);
}

PrecomputedDatabase readPrecomputedDatabase(const std::string& dir) {
  PrecomputedDatabase db;
  uint64_t count = 0;
  {
    Reader r((fs::path(dir) / "shared.bin").string());
    r.magic(kSharedMagic);
    count = getLayout(r, db);
    std::vector<double> a = r.array<double>(), b = r.array<double>();
    db.shexp = ShExp::fromTables(std::move(a), std::move(b), r.get<double>());
    r.end();
  }
  db.basic.resize(count);
  db.volumes.frames.resize(count);
  for (size_t i = 0; i < count; ++i) getBasic(dir, db, i);
  return db;
}

void writePrecomputedLayout(const std::string& dir, const PrecomputedDatabase& db) {
  fs::create_directories(dir);
  {
    Writer w((fs::path(dir) / "layout.bin").string());
    w.put(kLayoutMagic);
    putLayout(w, db, db.volumes.frames.size());
    w.close();
  }
  for (size_t i = 0; i < db.volumes.frames.size(); ++i) {
    Writer w((fs::path(dir) / densityName(i)).string());
    w.put(kDensityMagic);
    w.array(db.volumes.frames[i]);
    w.close();
  }
}

PrecomputedDatabase readPrecomputedLayout(const std::string& dir) {
  PrecomputedDatabase db;
  Reader r((fs::path(dir) / "layout.bin").string());
  r.magic(kLayoutMagic);
  const uint64_t count = getLayout(r, db);
  r.end();
  db.volumes.frames.resize(count);
  return db;
}

void readLayoutDensities(const std::string& dir, PrecomputedDatabase& db, size_t begin,
                         size_t end) {
  checkRange(db, begin, end, "readLayoutDensities");
  for (size_t i = begin; i < end; ++i) {
    Reader d((fs::path(dir) / densityName(i)).string());
    d.magic(kDensityMagic);
    db.volumes.frames[i] = d.array<float>(db.volumes.grid.voxelCount());
    d.end();
  }
}

void writeBasicVolumes(const std::string& dir, const PrecomputedDatabase& db, size_t begin,
                       size_t end) {
  checkRange(db, begin, end, "writeBasicVolumes");
  fs::create_directories(dir);
  for (size_t i = begin; i < end; ++i) putBasic(dir, db, i);
}

void readBasicVolumes(const std::string& dir, PrecomputedDatabase& db, size_t begin, size_t end) {
  checkRange(db, begin, end, "readBasicVolumes");
  db.basic.resize(db.volumes.frames.size());
  for (size_t i = begin; i < end; ++i) getBasic(dir, db, i);
}

}  // namespace cloudbake
