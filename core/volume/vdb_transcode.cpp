#include "core/volume/vdb_transcode.h"

#include <openvdb/io/Stream.h>
#include <openvdb/openvdb.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
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
  if (!std::filesystem::exists(in, ec)) throw MissingFileError(in + ": VDB file not found");
  if (!std::filesystem::is_regular_file(in, ec)) {
    throw InputError(in + ": not a regular file (a VDB file was expected)");
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
    // A stream's failure leaves its errno; a rename's is in its error code.
    const auto* fs_error = dynamic_cast<const std::filesystem::filesystem_error*>(&e);
    const int err = fs_error ? fs_error->code().value() : errno;
    std::remove(tmp.c_str());
    const std::string message = out + ": cannot write the rewritten VDB file (" +
                                (isNoSpaceErrno(err) ? std::strerror(err) : e.what()) + ")";
    throwIfNoSpace(err, message);
    throw InputError(message);
  }
}

}  // namespace

void transcodeVdb(const std::string& in, const std::string& out) {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
  writeAll(readAll(in), out);
}

}  // namespace cloudbake
