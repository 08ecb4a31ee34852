#pragma once
// The declarations are the module's interface (the archive updater averages changed regions
// with the same rules): see builder/downsample.h.
#include "builder/downsample.h"
