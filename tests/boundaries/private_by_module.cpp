// A planted violation: gl code including the stream module's private header by its path under
// src/. Must not compile (tests/boundaries/CMakeLists.txt).
#include "stream/residency.h"
