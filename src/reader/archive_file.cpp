#include <tessera/archive.h>

namespace tessera {

Result<std::shared_ptr<Archive>> Archive::openFile(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openFileSource(path));
  return open(std::move(source));
}

}  // namespace tessera
