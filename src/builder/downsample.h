#pragma once
// The declarations are the module's interface (the archive updater averages changed regions
// with the same rules): see builder/downsample.h.
#include "include/builder/downsample.h"  // by path: tests reach this file as "builder/downsample.h"
