// A planted violation: gl code including the stream module's private header by its bare name.
// Must not compile (tests/boundaries/CMakeLists.txt).
#include "residency.h"
