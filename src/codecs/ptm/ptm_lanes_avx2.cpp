// ptm's lane coder, the SIMD decoder built for AVX2 (ptm_lanes_simd.h): every processor with
// AVX2 can run it; decode() takes it where avx512::decodeSimd cannot run.
#define TESSERA_LANES_ISA avx2
#define TESSERA_LANES_TARGET __attribute__((target("avx2")))
#include "ptm/ptm_lanes_simd.h"
