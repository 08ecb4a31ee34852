#pragma once
/// \file
/// Opening an archive wherever it is: a local path, an http(s):// URL or an s3:// URL. What the
/// command-line tools accept wherever they take an archive.

#include <memory>
#include <string>

#include <tessera/archive.h>
#include <tessera/byte_source.h>
#include <tessera/result.h>

namespace tessera {

/// True when `path_or_url` starts with http://, https:// (case-insensitive scheme) or s3://.
bool isRemoteUri(const std::string& path_or_url);

/// Opens an archive's bytes: an http:// or https:// URL through openHttpSource
/// (tessera/http_source.h) with default HttpOptions, plus from the environment when set: the
/// bearer token in TESSERA_TOKEN, the trusted CA file in TESSERA_CA_FILE, and no certificate
/// check at all when TESSERA_TLS_INSECURE is "1", HTTP/1.1 only when TESSERA_HTTP2 is "0"; an
/// s3:// URL through openS3Source (its endpoint, region and credentials from the environment,
/// and the TLS settings above); anything else as a local file (openFileSource). Fails as those do,
/// naming the path or URL.
[[nodiscard]] Result<std::shared_ptr<ByteSource>> openByteSource(const std::string& path_or_url);

/// openByteSource, then Archive::open. Over HTTP the open costs one request, the ranged GET of
/// the first 16 KiB the HTTP source makes when it opens (docs/remote.md), plus one per block
/// outside it. Thread-safe.
[[nodiscard]] Result<std::shared_ptr<Archive>> openArchive(const std::string& path_or_url);

}  // namespace tessera
