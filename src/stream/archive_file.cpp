// Archive::openFile lives in the stream module: the format module reads through a ByteSource
// it is given and never opens files itself.
#include <tessera/archive.h>

namespace tessera {

Result<std::shared_ptr<Archive>> Archive::openFile(const std::string& path) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openFileSource(path));
  return open(std::move(source));
}

Result<std::shared_ptr<Archive>> Archive::openUri(const std::string& path_or_url) {
  TESSERA_ASSIGN_OR_RETURN(std::shared_ptr<ByteSource> source, openByteSource(path_or_url));
  return open(std::move(source));
}

}  // namespace tessera
