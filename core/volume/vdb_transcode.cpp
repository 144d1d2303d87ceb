#include "core/volume/vdb_transcode.h"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>

#include "core/error.h"
#include "core/volume/vdb_header_check.h"

namespace cloudbake {
namespace {

struct VdbContent {
  openvdb::GridPtrVecPtr grids;
  openvdb::MetaMap::Ptr metadata;
};

VdbContent readAll(const std::string& in) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(in, ec)) {
    throw InputError(in + ": VDB file not found (or not a regular file)");
  }
  checkVdbHeader(in);
  try {
    std::ifstream is(in, std::ios::binary);
    is.exceptions(std::ios::failbit | std::ios::badbit);
    openvdb::io::Stream stream(is, /*delayLoad=*/false);
    VdbContent c;
    c.grids = stream.getGrids();
    c.metadata = stream.getMetadata();
    if (!c.grids) c.grids = std::make_shared<openvdb::GridPtrVec>();
    if (!c.metadata) c.metadata = std::make_shared<openvdb::MetaMap>();
    return c;
  } catch (const openvdb::Exception& e) {
    throw InputError(in + ": not a readable OpenVDB file (" + e.what() + ")");
  } catch (const std::ios_base::failure&) {
    throw InputError(in + ": not a readable OpenVDB file (truncated or corrupt)");
  } catch (const std::exception& e) {
    throw InputError(in + ": failed to read OpenVDB file (" + e.what() + ")");
  }
}

void writeAll(const VdbContent& c, const std::string& out) {
  const std::string tmp = out + ".tmp";
  try {
    {
      std::ofstream os(tmp, std::ios::binary | std::ios::trunc);
      os.exceptions(std::ios::failbit | std::ios::badbit);
      openvdb::io::Stream stream(os);
      stream.setCompression(openvdb::io::COMPRESS_ACTIVE_MASK);
      stream.write(*c.grids, *c.metadata);
      os.flush();
      os.close();
    }
    std::filesystem::rename(tmp, out);
  } catch (const std::exception& e) {
    std::remove(tmp.c_str());
    throw InputError(out + ": cannot write the rewritten VDB file (" + e.what() + ")");
  }
}

}  // namespace

void transcodeVdb(const std::string& in, const std::string& out) {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  writeAll(readAll(in), out);
}

}  // namespace cloudbake
