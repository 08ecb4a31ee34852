// The control: gl code including interface headers of modules it depends on compiles, so the
// probes' failures are the boundary at work, not a broken probe.
#include "format/header.h"
#include "stream/footprint.h"

namespace tessera::detail {

uint32_t boundaryProbeHeaderBytes() {
  return kHeaderBytes;
}

}  // namespace tessera::detail
